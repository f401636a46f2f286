"""Live estimation: readings in as they come, estimates out as they leave the lag window.

Three parts: a source (:mod:`gfimu.io.sources`: standard input, UDP, TCP,
a serial port), :func:`run` (the fixed-lag smoother on the stream, with the
counts of what happened), and a sink (:class:`EstimateSink`: the estimate
table ``gfimu estimate`` writes, row by row, flushed as each sample leaves the
window; in groups when samples wait, :data:`ROWS_AT_ONCE`). :func:`run` returns a :class:`LiveResult`.

Faults are contained: a row that cannot be read (text in a number field, a
timestamp beyond 64-bit nanoseconds or not finite, a line of binary bytes)
is skipped and counted, with the first few reasons kept; a sample going back
in time or repeating one is dropped and counted by the smoother; time going
back by more than its ``clock_reset_s`` restarts the window; a broken stream
(a connection reset) ends the session with what was estimated; SIGINT and
SIGTERM end it at once (the window flushed, every estimate written), also
while the source is waiting for data; samples already waiting are estimated
first, and a second signal drops them (counted as dropped).
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .io.sources import BadRow, Reading, Source, SourceNote
from .io.tables import motion_csv_chunks
from .motion import Motion
from .smoother.stream.session import RATE_ROWS, Kept, StreamSession, rate_from_timestamps  # noqa: F401 - re-exported

REASONS_KEPT = 5
"""Bad rows whose reason is kept (and reported as it happens); the others are only counted."""

STEADY_AFTER_S = 10.0
"""Latency is also summarised for samples arriving this long after the first [s]: past the start,
where the first seconds are held while the process noise is chosen on them."""

_SIGNAL_EXIT = {"SIGINT": 130, "SIGTERM": 143}

ROWS_AT_ONCE = 64
"""When samples wait (the input came in a burst, or faster than the smoother), the rows they finish are written
in groups of at most this many (a write and a flush per group instead of per row)."""

WRITE_EVERY_S = 0.005
"""... and at least this often [s] while a burst is worked through."""

QUEUE_S = 10.0
"""By default the source's queue holds this many seconds of samples at the stream's rate [s] (a start held while
the data decide the sign of ω, a model chosen, a busy machine: caught up after, not dropped) ..."""

QUEUE_MIN = 5000
"""... and at least this many samples (the rate unknown yet, or a slow one)."""

ITEMS_AT_ONCE = 1024
"""At most this many waiting items are taken from the source's queue at once (between status lines)."""

SWITCH_INTERVAL_S = 0.001
"""Python's thread switch interval during a session (5 ms by default): the source's reader, and a model
being chosen in a thread where no process may be forked for it (:class:`gfimu.smoother.stream.fixed_lag.PendingChoice`),
give the interpreter up to the stream's thread within this, so the rows keep leaving at the lag."""


@dataclass(frozen=True)
class LiveCounts:
    """What a live session counted.

    ``rows_in``: samples read from the source; ``rows_out``: estimate rows written; ``bad_rows``: rows that could
    not be read (skipped), ``bad_reasons`` the first :data:`REASONS_KEPT` of them (``"line 7: ..."``);
    ``late_or_repeated``, ``clock_resets``: samples the smoother dropped, window restarts; ``missing``: samples that
    never came (gaps of more than 1.5 nominal steps); ``overrun_dropped``: samples dropped because the input outran
    the smoother; ``replaced_readings``: accelerometer readings the screening replaced (gross errors,
    :class:`gfimu.readings.StreamScreen`); ``choice_waits``: times the stream waited for a model chosen off it that
    was not ready at its sample (:data:`gfimu.smoother.stream.fixed_lag.CHOICE_DELAY_S`: the machine was too busy).
    """

    rows_in: int = 0
    rows_out: int = 0
    bad_rows: int = 0
    bad_reasons: tuple[str, ...] = ()
    late_or_repeated: int = 0
    clock_resets: int = 0
    missing: int = 0
    overrun_dropped: int = 0
    replaced_readings: int = 0
    choice_waits: int = 0


@dataclass(frozen=True)
class LiveTimes:
    """How long a live session's work took, each (p50, p99, max) [ms] or None when there was none: ``processing_ms``
    the smoother's time per sample; ``screening_ms`` the screening's per block of samples it decides; ``latency_ms``
    a sample's arrival → its estimate written (samples that left the window while the stream went on; not those
    flushed at its end); ``steady_latency_ms`` the same after the first :data:`STEADY_AFTER_S` s; and
    ``choice_wait_ms`` [ms] the total of the stream's waits for a model chosen off it."""

    processing_ms: tuple[float, float, float] | None = None
    screening_ms: tuple[float, float, float] | None = None
    latency_ms: tuple[float, float, float] | None = None
    steady_latency_ms: tuple[float, float, float] | None = None
    choice_wait_ms: float = 0.0


@dataclass(frozen=True)
class LiveResult:
    """What a live session did: its ``counts`` (:class:`LiveCounts`) and ``times`` (:class:`LiveTimes`); the
    ``rate_hz`` it ran at and where that came from, ``rate_from`` (``"given"`` or ``"stream"``); ``ended``: how
    the session ended (``"end of input"``, ``"EOF datagram"``, ``"SIGINT"``, ``"SIGTERM"``, ``"connection lost"``,
    ``"input refused"``, ``"stopped by an error"`` (the estimator or the output failed), ...); ``failure``: a
    message when the stream broke, could not be read on, or the session failed (None otherwise)."""

    counts: LiveCounts
    times: LiveTimes
    rate_hz: float | None
    rate_from: str
    ended: str
    failure: str | None = None

    @property
    def signal_exit(self) -> int | None:
        """128 + the signal number when a signal ended the session (130 SIGINT, 143 SIGTERM), else None."""
        return _SIGNAL_EXIT.get(self.ended)

    def summary(self) -> str:
        """One line: the counts, the times and how it ended."""
        c, t = self.counts, self.times
        text = (f"{c.rows_in} samples in, {c.rows_out} estimates out; {c.bad_rows} bad rows, "
                f"{c.late_or_repeated} late or repeated, {c.missing} missing (gaps), {c.overrun_dropped} "
                f"dropped (input faster than the smoother), {c.clock_resets} clock resets, "
                f"{c.replaced_readings} readings replaced by the screening")
        if t.processing_ms is not None:
            text += "; processing per sample p50 {:.3f} ms, p99 {:.3f} ms, max {:.3f} ms".format(*t.processing_ms)
        if t.screening_ms is not None:
            text += "; screening per block p50 {:.3f} ms, p99 {:.3f} ms, max {:.3f} ms".format(*t.screening_ms)
        if t.latency_ms is not None:
            text += "; latency arrival -> estimate written p50 {:.1f} ms, p99 {:.1f} ms, max {:.1f} ms".format(
                *t.latency_ms)
        if t.steady_latency_ms is not None:
            text += "; after the first {:g} s: p50 {:.1f} ms, p99 {:.1f} ms, max {:.1f} ms".format(
                STEADY_AFTER_S, *t.steady_latency_ms)
        if c.choice_waits:
            text += (f"; waited {c.choice_waits} time(s) for a model chosen off the stream, "
                     f"{t.choice_wait_ms:.1f} ms in all")
        return text + f"; ended: {self.ended}"


class EstimateSink:
    """The estimate table of ``gfimu estimate`` (:func:`gfimu.io.tables.motion_csv_chunks`: the same header,
    columns and number format) written to a text stream as the states come, flushed after each."""

    def __init__(self, stream, sigma: bool = False):
        self.stream = stream
        self.sigma = bool(sigma)
        self._started = False

    def _motion(self, states) -> Motion:
        n = len(states)
        t = np.fromiter((s.timestamp_ns for s in states), dtype=np.int64, count=n)
        v = np.array([np.concatenate([s.omega_b_radps, s.omega_dot_b_radps2, s.specific_force_b_mps2])
                      for s in states]).reshape(n, 9)
        sigma = {}
        if self.sigma:
            sig = np.full((n, 9), np.nan)
            for k, s in enumerate(states):
                if s.sigma_omega_b_radps is not None:
                    sig[k] = np.concatenate([s.sigma_omega_b_radps, s.sigma_omega_dot_b_radps2,
                                             s.sigma_specific_force_b_mps2])
            sigma = {"omega_b_radps": sig[:, :3], "omega_dot_b_radps2": sig[:, 3:6], "specific_force_b_mps2": sig[:, 6:]}
        return Motion(t, omega_b_radps=v[:, :3], omega_dot_b_radps2=v[:, 3:6], specific_force_b_mps2=v[:, 6:],
                      sigma=sigma)

    def start(self) -> None:
        """The header line (written once, before any row)."""
        if not self._started:
            self._started = True
            self.stream.write(next(iter(motion_csv_chunks(self._motion([])))))
            self.stream.flush()

    def write(self, states) -> None:
        if not states:
            return
        self.start()
        chunks = iter(motion_csv_chunks(self._motion(states)))
        next(chunks)  # the header, written once by start()
        for chunk in chunks:
            self.stream.write(chunk)
        self.stream.flush()


UNIT_CHECK_S = 3.0
"""Seconds of the first readings (of stream time) on which the units are checked, as ``gfimu estimate`` checks
a log's (:func:`gfimu.io.plausibility.check_gravity`)."""

UNIT_CHECK_ROWS = 20_000
"""At most this many first readings are held for that check."""


class _FirstRowsCheck:
    """The plausibility check ``gfimu estimate`` makes of a log's readings (gravity's magnitude at rest, or the
    median |f| of a moving log: readings in another unit than their header says, by whatever factor), made once
    on the first :data:`UNIT_CHECK_S` s of the stream; its warnings go to ``say`` with the same words."""

    def __init__(self, array, source: Source, say: Callable[[str], None]):
        self.array, self.source, self.say = array, source, say
        self.t: list[int] = []
        self.accel: list[np.ndarray] = []
        self.done = False

    def add(self, r: Reading) -> None:
        if self.done:
            return
        t = int(r.timestamp_ns)
        if self.t and t <= self.t[-1]:
            return  # late, repeated or a clock reset: not part of the stretch checked
        self.t.append(t)
        self.accel.append(np.asarray(r.accel, dtype=float))
        if t - self.t[0] >= UNIT_CHECK_S * 1e9 or len(self.t) >= UNIT_CHECK_ROWS:
            self.finish()

    def finish(self) -> None:
        if self.done:
            return
        self.done = True
        if len(self.t) < 5:
            return
        from .io.plausibility import check_gravity
        from .log import Log

        name = getattr(self.source, "name", "source")
        unit = getattr(self.source, "accel_unit", None) or "m s^-2"
        log = Log(self.array, np.asarray(self.t, dtype=np.int64), np.vstack(self.accel), source=name)
        try:
            for message in check_gravity(log, f"{name} (first {len(self.t)} rows)", unit):
                self.say(f"warning: {message}")
        finally:
            self.t, self.accel = [], []


OUTPUT_CLOSED = "output closed by its reader"
""":attr:`LiveResult.ended` when writing a row met a broken pipe (the reader of standard output went away)."""


def _stats(values_ms) -> tuple[float, float, float] | None:
    if len(values_ms) == 0:
        return None
    p = np.asarray(values_ms, dtype=float)
    return float(np.percentile(p, 50)), float(np.percentile(p, 99)), float(p.max())




class _Reader:
    """The source read in its own thread, a batch per read (:meth:`Source.batches`): (reading or bad row, arrival
    time) items on a queue of at most ``size``, None at its end; when the queue is full the oldest waiting items
    are dropped and counted."""

    def __init__(self, source: Source, stop: threading.Event, size: int):
        self.source, self.stop = source, stop
        self.size = max(int(size), 1)
        self.hurry = threading.Event()
        """Set (a second signal): once stopped, the items still waiting are dropped and counted, not handed out."""
        self.grows = False
        """Whether :meth:`fit` may raise :attr:`size` to :data:`QUEUE_S` of samples at the stream's rate."""
        self.items: deque = deque()
        self.ready = threading.Condition()
        self.fatal: list[BaseException] = []
        self.overrun = 0
        self.thread = threading.Thread(target=self._read, name="gfimu-live-source", daemon=True)

    def _read(self) -> None:
        try:
            for batch in self.source.batches(self.stop):
                at = time.perf_counter()
                self._put([(item, at) for item in batch])
                if self.stop.is_set():
                    break
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread
            self.fatal.append(exc)
        finally:
            self._put([None])

    def _put(self, batch: list) -> None:
        with self.ready:
            self.items.extend(batch)
            end = bool(self.items) and self.items[-1] is None  # (the end's mark takes no sample's place)
            while len(self.items) - end > self.size:  # the smoother falls behind: drop the oldest waiting samples
                self.items.popleft()
                self.overrun += 1
            self.ready.notify()

    def get(self) -> list | None:
        """The items waiting (at most :data:`ITEMS_AT_ONCE`); an empty list when none came within 0.2 s; None at the end
        (or, once stopped, when the queue is empty: what already arrived is still estimated). The end's None
        comes alone, after every item before it."""
        with self.ready:
            if not self.items and not self.stop.is_set():
                self.ready.wait(timeout=0.2)
            if self.stop.is_set() and self.hurry.is_set():
                while self.items and self.items[0] is not None:
                    self.items.popleft()
                    self.overrun += 1
            if not self.items:
                return None if self.stop.is_set() else []
            if self.items[0] is None:
                return None
            out = []
            while self.items and self.items[0] is not None and len(out) < ITEMS_AT_ONCE:
                out.append(self.items.popleft())
            return out

    def fit(self, rate_hz: float | None) -> None:
        """The queue made to hold :data:`QUEUE_S` of samples at ``rate_hz`` where it :attr:`grows` (never smaller)."""
        if self.grows and rate_hz:
            self.size = max(self.size, int(QUEUE_S * rate_hz))

    def join(self) -> None:
        if self.thread.ident is not None:  # started (the output may fail before: its header is written first)
            self.thread.join(timeout=2 * 0.2 + 0.5)


class _Signals:
    """SIGINT and SIGTERM set ``stop`` (the first one's name kept in ``caught``) while installed (with
    ``enabled``, from the main thread); a second one sets ``hurry`` too (the samples still waiting are dropped
    rather than estimated); the previous handlers come back on :meth:`restore`."""

    def __init__(self, stop: threading.Event, enabled: bool):
        self.stop = stop
        self.hurry = threading.Event()
        self.caught: list[str] = []
        self.previous = {}
        if enabled and threading.current_thread() is threading.main_thread():
            self.previous = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}

    def _on_signal(self, signum, frame) -> None:  # noqa: ARG002
        if self.caught:
            self.hurry.set()
        else:
            self.caught.append(signal.Signals(signum).name)
        self.stop.set()

    def restore(self) -> None:
        for s, h in self.previous.items():
            signal.signal(s, h)


class _Rows:
    """The states written to the sink, with each one's latency (its sample's arrival → written)."""

    def __init__(self, sink: EstimateSink):
        self.sink = sink
        self.out = 0
        self.arrival: dict[int, float] = {}
        self.latency = Kept(width=2)  # (arrival, latency) [s] of the newest TIMES_KEPT rows

    def arrived(self, t_ns: int, at: float) -> None:
        self.arrival[t_ns] = at

    def write(self, states, timed: bool = True) -> None:
        if not states:
            return
        self.sink.write(states)
        self.out += len(states)
        if not timed:  # the window flushed at the end: their wait is the stream's end, not the lag
            return
        now = time.perf_counter()
        for s in states:  # arrival of a sample -> its estimate written
            t = self.arrival.pop(int(s.timestamp_ns), None)
            if t is not None:
                self.latency.append((t, now - t))
        if len(self.arrival) > 100_000:  # samples that never left (dropped): forget the oldest
            for key in list(self.arrival)[:50_000]:
                del self.arrival[key]

    def stats(self):
        """(latency (p50, p99, max) [ms], the same after the first :data:`STEADY_AFTER_S` s), None for none."""
        if not len(self.latency):
            return None, None
        pairs = self.latency.values
        later = pairs[pairs[:, 0] > pairs[0, 0] + STEADY_AFTER_S, 1]
        return _stats(pairs[:, 1] * 1e3), _stats(later * 1e3)


class _Live:
    """One live run: the source's items into the :class:`StreamSession`, its states to the sink, what it
    says through ``say``."""

    def __init__(self, source: Source, estimator, sink: EstimateSink, rate_hz, say, status_s):
        self.source, self.estimator, self.rate_hz, self.say, self.status_s = source, estimator, rate_hz, say, status_s
        getattr(estimator, "preload", lambda: None)()  # (the fixed-lag smoother's compiled kernels)
        self.session: StreamSession | None = None
        self.rows = _Rows(sink)
        self.units = _FirstRowsCheck(source.array, source, say)
        self.rows_in = self.bad = 0
        self.reasons: list[str] = []
        self.warned_behind = False
        self.told_stopping = False

    def loop(self, reader: _Reader) -> None:
        """Items until the source ends or the run is stopped, then every state left."""
        self.session = StreamSession(self.source.array, self.estimator, self.rate_hz,
                                     name=getattr(self.source, "name", "source"))  # a rate beyond any IMU's refused
        last_status = time.monotonic()
        while True:
            items = reader.get()
            if items is None:
                break
            self.take_all(items)
            reader.fit(self.session.rate_hz)
            self.behind(reader)
            self.stopping(reader)
            if self.status_s and time.monotonic() - last_status >= self.status_s:
                last_status = time.monotonic()
                self.status(reader)
        self.units.finish()
        self.rows.write(self.session.finish(), timed=False)
        self.tell()

    def take_all(self, items: list) -> None:
        """The items waiting, in turn; the rows they finish written together, at the latest every
        :data:`ROWS_AT_ONCE` rows or :data:`WRITE_EVERY_S` (when the stream keeps up, one item waits and each
        row is written as it is made), and before an error is raised."""
        rows: list = []
        since = time.perf_counter()
        try:
            for thing, arrived in items:
                rows += self.take(thing, arrived)
                if rows and (len(rows) >= ROWS_AT_ONCE or time.perf_counter() - since >= WRITE_EVERY_S):
                    done, rows = rows, []  # (not written twice when writing them fails)
                    self.rows.write(done)
                    since = time.perf_counter()
        finally:
            done, rows = rows, []
            self.rows.write(done)

    def take(self, thing, arrived: float) -> list:
        """One item: the rows it finished (a reading's), to be written."""
        if isinstance(thing, SourceNote):  # something the source saw (the stream goes on)
            self.say(f"warning: {thing.message}")
            return []
        if isinstance(thing, BadRow):
            self.bad_row(thing)
            return []
        self.rows_in += 1
        self.units.add(thing)
        self.rows.arrived(int(thing.timestamp_ns), arrived)
        states = self.session.push(thing.timestamp_ns, thing.accel, thing.gyro)
        self.tell()
        return states

    def tell(self) -> None:
        for note in self.session.take_notes():
            self.say(note)

    def bad_row(self, row: BadRow) -> None:
        self.bad += 1
        if len(self.reasons) < REASONS_KEPT:
            self.reasons.append(f"{row.where}: {row.reason}")
            self.say(f"warning: {row.where} skipped: {row.reason}")
            if len(self.reasons) == REASONS_KEPT:
                self.say("warning: further bad rows are counted, not shown")

    def _waiting(self, reader: _Reader) -> str:
        """The samples waiting in the source's queue, and how far behind the stream that is."""
        waiting = len(reader.items)
        waiting -= bool(waiting) and reader.items[-1] is None  # (the end's mark)
        rate = self.session.rate_hz if self.session is not None else None
        return f"{waiting} waiting" + (f" ({waiting / rate:.1f} s behind)" if rate else "")

    def behind(self, reader: _Reader) -> None:
        """Said once: the smoother falls behind the stream, half its queue waiting, samples about to be dropped."""
        if self.warned_behind or 2 * len(reader.items) < reader.size:
            return
        self.warned_behind = True
        self.say(f"warning: the smoother runs behind the stream: {self._waiting(reader)}; beyond {reader.size} "
                 "(--queue) the oldest are dropped (a faster machine, a lower rate or fewer sensors keep up)")

    def stopping(self, reader: _Reader) -> None:
        """Said once, when the run is stopped with more samples waiting than one take: they are estimated first,
        and a second signal drops them."""
        if self.told_stopping or not reader.stop.is_set() or reader.hurry.is_set() or len(reader.items) <= ITEMS_AT_ONCE:
            return
        self.told_stopping = True
        self.say(f"stopping: {self._waiting(reader)}, estimated first; a second SIGINT or SIGTERM drops them")

    def status(self, reader: _Reader) -> None:
        p = _stats(self.session.processing_s.values * 1e3)
        nan = float("nan")
        self.say(f"{self.rows_in} in, {self.rows.out} out, processing p50 {p[0] if p else nan:.2f} ms "
                 f"p99 {p[1] if p else nan:.2f} ms, {reader.overrun} dropped, {self.session.counts.late_or_repeated} "
                 f"late, {self.bad} bad, {self._waiting(reader)}")

    def result(self, ended: str, failure: str | None, overrun: int) -> LiveResult:
        session = self.session
        if session is None:  # refused before the first reading
            session = StreamSession(self.source.array, self.estimator, None)
            session.rate_hz, session.rate_from = self.rate_hz, "given" if self.rate_hz is not None else "stream"
        c = session.counts
        latency, steady = self.rows.stats()
        counts = LiveCounts(rows_in=self.rows_in, rows_out=self.rows.out, bad_rows=self.bad,
                            bad_reasons=tuple(self.reasons), late_or_repeated=c.late_or_repeated,
                            clock_resets=c.clock_resets, missing=c.missing, overrun_dropped=overrun,
                            replaced_readings=c.replaced_readings, choice_waits=c.choice_waits)
        times = LiveTimes(processing_ms=_stats(session.processing_s.values * 1e3),
                          screening_ms=_stats(session.screening_s.values * 1e3), latency_ms=latency,
                          steady_latency_ms=steady, choice_wait_ms=1e3 * c.choice_wait_s)
        return LiveResult(counts, times, rate_hz=session.rate_hz, rate_from=session.rate_from, ended=ended,
                          failure=failure)


def _ending(source: Source, reader: _Reader, caught: list[str], closed: bool, crash: list[Exception]):
    """(``ended``, ``failure``) of a run: the output closed, the session failed, a signal, or the source's."""
    failure = source.failure
    if closed:
        return OUTPUT_CLOSED, "the output was closed by its reader (a broken pipe); the session ended there"
    if crash:
        from .errors import DataError, InputError

        exc = crash[0]
        if isinstance(exc, (InputError, DataError)):  # the stream's own data refused, as estimate refuses a log's
            return "input refused", str(exc)
        return "stopped by an error", (f"{exc.filename}: {exc.strerror}" if isinstance(exc, OSError) and exc.filename
                                       else f"{type(exc).__name__}: {exc}")
    if caught:
        return caught[0], failure
    if reader.fatal:
        exc = reader.fatal[0]
        return ("input refused" if isinstance(exc, ValueError) else "source failed"), str(exc) or type(exc).__name__
    return source.ended, failure


def run(source: Source, estimator, sink: EstimateSink, *, rate_hz: float | None = None, queue_size: int | None = None,
        stop: threading.Event | None = None, signals: bool = True, report: Callable[[str], None] | None = None,
        status_s: float | None = None) -> LiveResult:
    """The fixed-lag ``estimator`` on ``source``'s readings, estimates to ``sink``, until the source ends,
    ``stop`` is set, SIGINT or SIGTERM (with ``signals``, from the main thread) or the stream breaks.

    ``rate_hz``: the nominal rate (array.toml's ``rate_hz`` or the caller's); None takes it from the
    timestamps of the first :data:`RATE_ROWS` samples (said through ``report``). At most
    ``queue_size`` samples wait while the smoother is busy (None: :data:`QUEUE_S` of samples at the stream's rate
    once it is known, at least :data:`QUEUE_MIN`); beyond that the oldest is dropped and counted. ``report`` receives one-line messages (the first bad rows, the rate taken, status lines
    every ``status_s`` seconds when given). The source is closed at the end. A header that cannot be
    read ends the session: ``ended`` is ``"input refused"`` and ``failure`` names the source and line;
    a source that fails otherwise gives ``"source failed"``. The readings go through a
    :class:`~gfimu.smoother.stream.session.StreamSession`, as ``gfimu estimate --method fixed-lag`` sends a log's.
    """
    say = report or (lambda message: None)
    stop = stop or threading.Event()
    # readings that are not finite or beyond any range: replaced by the screening, or bad rows without it
    source.keep_gross_errors = bool(getattr(estimator, "screen_readings", False))
    handlers = _Signals(stop, signals)
    reader = _Reader(source, stop, QUEUE_MIN if queue_size is None else queue_size)
    reader.hurry = handlers.hurry
    reader.grows = queue_size is None
    reader.fit(rate_hz)
    closed, crash = False, []
    live = _Live(source, estimator, sink, rate_hz, say, status_s)
    switch = sys.getswitchinterval()
    sys.setswitchinterval(min(switch, SWITCH_INTERVAL_S))
    try:
        sink.start()  # an output that fails here (its header) fails the call
        reader.thread.start()
        try:
            live.loop(reader)
        except BrokenPipeError:  # the output (standard output) closed by its reader: the session ends there
            closed = True
        except Exception as exc:  # noqa: BLE001 - the estimator or the output failed: end with the counts
            crash.append(exc)
    finally:
        stop.set()
        sys.setswitchinterval(switch)
        handlers.restore()
        reader.join()
        try:
            source.close()
        except OSError:
            pass
    ended, failure = _ending(source, reader, handlers.caught, closed, crash)
    result = live.result(ended, failure, reader.overrun)
    if reader.fatal and not isinstance(reader.fatal[0], Exception):
        raise reader.fatal[0]
    return result
