"""Live estimation: readings in as they come, estimates out as they leave the lag window.

Three parts: a source (:mod:`gfimu.io.sources`: standard input, UDP, TCP,
a serial port), :func:`run` (the fixed-lag smoother on the stream, with the
counts of what happened), and a sink (:class:`EstimateSink`: the estimate
table ``gfimu estimate`` writes, row by row, flushed as each sample leaves the
window). :func:`run` returns a :class:`LiveResult`.

Faults are contained: a row that cannot be read (text in a number field, a
timestamp beyond 64-bit nanoseconds or not finite, a line of binary bytes)
is skipped and counted, with the first few reasons kept; a sample going back
in time or repeating one is dropped and counted by the smoother; time going
back by more than its ``clock_reset_s`` restarts the window; a broken stream
(a connection reset) ends the session with what was estimated; SIGINT and
SIGTERM end it at once (the window flushed, every estimate written), also
while the source is waiting for data.
"""

from __future__ import annotations

import queue
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .io.sources import BadRow, Reading, Source, SourceNote
from .io.tables import motion_csv_chunks
from .motion import Motion
from .readings import StreamScreen

RATE_ROWS = 64
"""Samples from whose timestamps the rate is taken when neither array.toml nor the caller gives it
(the median period, as :attr:`gfimu.log.Log.rate_hz` takes it over a whole log)."""

REASONS_KEPT = 5
"""Bad rows whose reason is kept (and reported as it happens); the others are only counted."""

STEADY_AFTER_S = 10.0
"""Latency is also summarised for samples arriving this long after the first [s]: past the start,
where the first seconds are held while the process noise is chosen on them."""

_SIGNAL_EXIT = {"SIGINT": 130, "SIGTERM": 143}


@dataclass(frozen=True)
class LiveResult:
    """What a live session did.

    ``rows_in``: samples read from the source; ``rows_out``: estimate rows written;
    ``bad_rows``: rows that could not be read (skipped), ``bad_reasons`` the first
    :data:`REASONS_KEPT` of them (``"line 7: ..."``); ``late_or_repeated``, ``clock_resets``:
    samples the smoother dropped, window restarts; ``missing``: samples that never came (gaps of
    more than 1.5 nominal steps); ``overrun_dropped``: samples dropped because the input outran
    the smoother; ``processing_ms``, ``latency_ms``, ``steady_latency_ms``: (p50, p99, max) of the
    smoother's time per sample, of arrival → estimate written (samples that left the window while
    the stream went on; not those flushed at its end), and of the latter after the first
    :data:`STEADY_AFTER_S` s (None when there is none); ``rate_hz`` and ``rate_from``
    (``"given"`` or ``"stream"``); ``ended``: how the session ended (``"end of input"``,
    ``"EOF datagram"``, ``"SIGINT"``, ``"SIGTERM"``, ``"connection lost"``, ``"input refused"``,
    ``"stopped by an error"`` (the estimator or the output failed), ...); ``failure``: a message when
    the stream broke, could not be read on, or the session failed (None otherwise).
    """

    rows_in: int
    rows_out: int
    bad_rows: int
    bad_reasons: tuple[str, ...]
    late_or_repeated: int
    clock_resets: int
    missing: int
    overrun_dropped: int
    processing_ms: tuple[float, float, float] | None
    latency_ms: tuple[float, float, float] | None
    steady_latency_ms: tuple[float, float, float] | None
    rate_hz: float | None
    rate_from: str
    ended: str
    failure: str | None = None
    replaced_readings: int = 0
    """Accelerometer readings the screening replaced (gross errors, :class:`gfimu.readings.StreamScreen`)."""
    screening_ms: tuple[float, float, float] | None = None
    """(p50, p99, max) of the screening's time per block of samples it decides (None without screening)."""

    @property
    def signal_exit(self) -> int | None:
        """128 + the signal number when a signal ended the session (130 SIGINT, 143 SIGTERM), else None."""
        return _SIGNAL_EXIT.get(self.ended)

    def summary(self) -> str:
        """One line: the counts, the times and how it ended."""
        text = (f"{self.rows_in} samples in, {self.rows_out} estimates out; {self.bad_rows} bad rows, "
                f"{self.late_or_repeated} late or repeated, {self.missing} missing (gaps), {self.overrun_dropped} "
                f"dropped (input faster than the smoother), {self.clock_resets} clock resets, "
                f"{self.replaced_readings} readings replaced by the screening")
        if self.processing_ms is not None:
            text += "; processing per sample p50 {:.3f} ms, p99 {:.3f} ms, max {:.3f} ms".format(*self.processing_ms)
        if self.screening_ms is not None:
            text += "; screening per block p50 {:.3f} ms, p99 {:.3f} ms, max {:.3f} ms".format(*self.screening_ms)
        if self.latency_ms is not None:
            text += "; latency arrival -> estimate written p50 {:.1f} ms, p99 {:.1f} ms, max {:.1f} ms".format(
                *self.latency_ms)
        if self.steady_latency_ms is not None:
            text += "; after the first {:g} s: p50 {:.1f} ms, p99 {:.1f} ms, max {:.1f} ms".format(
                STEADY_AFTER_S, *self.steady_latency_ms)
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


class _Session:
    """The fixed-lag smoother on one stream: samples in, screened (:class:`gfimu.readings.StreamScreen`, unless
    the estimator's ``screen_readings`` is off), states out, counts kept."""

    def __init__(self, array, estimator, rate_hz: float):
        self.rate_hz = float(rate_hz)
        self.array = array
        self.smoother = estimator.smoother(array, self.rate_hz)
        self.use_gyro = bool(estimator.use_gyro and array.gyroscope is not None)
        self.screen = StreamScreen(array, self.rate_hz) if getattr(estimator, "screen_readings", False) else None
        self.replaced = 0
        """Readings the screening replaced (in screens ended by a clock reset and the current one)."""
        self.last_t: int | None = None
        self.late = 0  # samples late or repeated, dropped before the screening
        self.missing = 0
        self.processing: list[float] = []  # the smoother's update per sample [s]
        self.screening: list[float] = []  # the screening's decision per block [s]

    def push(self, r: Reading) -> list:
        t = int(r.timestamp_ns)
        row = (t, np.asarray(r.accel, dtype=float), r.gyro if self.use_gyro else None)
        if self.last_t is not None and t <= self.last_t:
            if self.last_t - t <= self.smoother.clock_reset_s * 1e9:
                if self.screen is None:  # the smoother drops and counts it
                    return list(self.smoother.push(*row).smoothed)
                self.late += 1  # the rows before it are still in the screening: dropped here
                return []
            if self.screen is not None:  # a clock reset: the rows held go first, then a new screening
                states = self._smooth(self.screen.flush())
                self._new_screen()
                states += self._smooth(self._screened(row))
                self.last_t = t
                return states
        states = self._smooth(self._screened(row) if self.screen is not None else [row])
        if self.last_t is not None and t > self.last_t:
            steps = (t - self.last_t) * 1e-9 * self.rate_hz
            if steps > 1.5:  # samples that never came (lost datagrams, a sensor pause)
                self.missing += int(round(steps)) - 1
        self.last_t = t
        return states

    def _new_screen(self) -> None:
        self.replaced += self.screen.count
        self.screen = StreamScreen(self.array, self.rate_hz)

    def _screened(self, row) -> list:
        """The rows the screening decides on ``row``'s arrival (a block, or none), its time kept per block."""
        t0 = time.perf_counter()
        rows = self.screen.push(*row)
        if rows:
            _keep(self.screening, time.perf_counter() - t0)
        return rows

    def _smooth(self, rows) -> list:
        """The smoother's update on each row, its time kept per row (not for a row it drops)."""
        states = []
        for row in rows:
            t0 = time.perf_counter()
            update = self.smoother.push(*row)
            if update.dropped is None:
                _keep(self.processing, time.perf_counter() - t0)
            states.extend(update.smoothed)
        return states

    def flush(self) -> list:
        """The rows still held by the screening, then the window: every state left."""
        states = self._smooth(self.screen.flush()) if self.screen is not None else []
        return states + list(self.smoother.flush())

    @property
    def replaced_readings(self) -> int:
        return self.replaced + (self.screen.count if self.screen is not None else 0)

    def counts(self) -> tuple[int, int]:
        c = self.smoother.counts
        return self.late + c["duplicates"] + c["out_of_order"], c["clock_resets"]


def _keep(times: list, value: float) -> None:
    times.append(value)
    if len(times) > 200_000:  # bounded memory on long streams
        del times[:100_000]


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


RATE_WATCH_STEPS = 32
"""Consecutive steps forward at one steady period, away from the nominal one, after which the rate is measured
again from them (:class:`_RateWatch`)."""


class _RateWatch:
    """Tells when a stream's rate has changed: the last :data:`RATE_WATCH_STEPS` steps forward all within 10 %
    of their median, and that median more than 1.5 times longer or shorter than the nominal step (every step a
    gap, or two samples per step). Returns the new rate once, then watches against it."""

    def __init__(self, rate_hz: float):
        self.rate_hz = float(rate_hz)
        self.steps: list[int] = []
        self.last: int | None = None

    def step(self, t_ns: int) -> float | None:
        t = int(t_ns)
        if self.last is None or t <= self.last:
            self.last = t if self.last is None or t < self.last - int(1e9) else self.last
            return None
        self.steps.append(t - self.last)
        self.last = t
        if len(self.steps) > RATE_WATCH_STEPS:
            del self.steps[0]
        if len(self.steps) < RATE_WATCH_STEPS:
            return None
        steps = np.asarray(self.steps, dtype=float)
        median = float(np.median(steps))
        if median <= 0 or np.max(np.abs(steps - median)) > 0.1 * median:
            return None
        ratio = median * 1e-9 * self.rate_hz
        if 1 / 1.5 <= ratio <= 1.5:
            return None
        self.rate_hz = 1e9 / median
        self.steps.clear()
        return self.rate_hz


def _rerate(session: "_Session", array, estimator, rate_hz: float) -> list:
    """``session`` on at ``rate_hz``: the states still held at the old rate (its screening, its window), then a
    new smoother and screening at the new rate; the counts so far are kept."""
    states = session.flush()
    old = session.smoother.counts
    session.late += old["duplicates"] + old["out_of_order"]
    if session.screen is not None:
        session.replaced += session.screen.count
    session.rate_hz = float(rate_hz)
    session.smoother = estimator.smoother(array, session.rate_hz)
    if session.screen is not None:
        session.screen = StreamScreen(array, session.rate_hz)
    return states


def _on_rate_change(session: "_Session", watch: _RateWatch, r: Reading, array, estimator,
                    say: Callable[[str], None], emit: Callable) -> None:
    """After each sample: when ``watch`` finds the stream's rate changed, say so and go on at the new rate."""
    old = watch.rate_hz
    new = watch.step(r.timestamp_ns)
    if new is None:
        return
    say(f"warning: the stream's rate changed: {RATE_WATCH_STEPS} steps in a row of {1e3 / new:.4g} ms where "
        f"{old:.6g} Hz was taken; the rate is measured again, {new:.6g} Hz, and the window restarts once at it")
    emit(_rerate(session, array, estimator, new), timed=False)


OUTPUT_CLOSED = "output closed by its reader"
""":attr:`LiveResult.ended` when writing a row met a broken pipe (the reader of standard output went away)."""


def _check_rate(rate_hz: float, source: Source) -> None:
    """A rate beyond any IMU's (timestamps 1 ns apart) would size the smoother's window at hundreds of millions
    of samples: refused (the session ends with the message) instead of running out of memory."""
    from .errors import DataError
    from .io.plausibility import MAX_RATE_HZ

    if rate_hz > MAX_RATE_HZ:
        raise DataError(f"{getattr(source, 'name', 'source')}: a rate of {rate_hz:.4g} Hz (steps of "
                        f"{1e9 / rate_hz:.4g} ns), beyond any IMU's ({MAX_RATE_HZ:g} Hz at most): check the unit of "
                        "the timestamps (or --rate-hz)")


def rate_from_timestamps(timestamps_ns) -> float | None:
    """The rate [Hz] of the median step between increasing timestamps (None with fewer than two steps
    forward): the rule of :attr:`gfimu.log.Log.rate_hz`."""
    t = np.asarray(timestamps_ns, dtype=np.int64)
    dt = np.diff(t) * 1e-9
    dt = dt[dt > 0]
    if dt.size < 1:
        return None
    return 1.0 / float(np.median(dt))


def _stats(values_ms) -> tuple[float, float, float] | None:
    if len(values_ms) == 0:
        return None
    p = np.asarray(values_ms, dtype=float)
    return float(np.percentile(p, 50)), float(np.percentile(p, 99)), float(p.max())


def run(source: Source, estimator, sink: EstimateSink, *, rate_hz: float | None = None, queue_size: int = 5000,
        stop: threading.Event | None = None, signals: bool = True, report: Callable[[str], None] | None = None,
        status_s: float | None = None) -> LiveResult:
    """The fixed-lag ``estimator`` on ``source``'s readings, estimates to ``sink``, until the source ends,
    ``stop`` is set, SIGINT or SIGTERM (with ``signals``, from the main thread) or the stream breaks.

    ``rate_hz``: the nominal rate (array.toml's ``rate_hz`` or the caller's); None takes it from the
    timestamps of the first :data:`RATE_ROWS` samples (said through ``report``). At most
    ``queue_size`` samples wait while the smoother is busy; beyond that the oldest is dropped and
    counted. ``report`` receives one-line messages (the first bad rows, the rate taken, status lines
    every ``status_s`` seconds when given). The source is closed at the end. A header that cannot be
    read ends the session: ``ended`` is ``"input refused"`` and ``failure`` names the source and line;
    a source that fails otherwise gives ``"source failed"``.
    """
    say = report or (lambda message: None)
    stop = stop or threading.Event()
    array = source.array
    # readings that are not finite or beyond any range: replaced by the screening, or bad rows without it
    source.keep_gross_errors = bool(getattr(estimator, "screen_readings", False))
    q: queue.Queue = queue.Queue(maxsize=max(int(queue_size), 1))
    fatal: list[BaseException] = []
    closed = False
    overrun = [0]
    caught: list[str] = []

    def reader():
        try:
            for item in source.items(stop):
                _put((item, time.perf_counter()))
                if stop.is_set():
                    break
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread
            fatal.append(exc)
        finally:
            _put(None)

    def _put(item):
        while True:
            try:
                q.put_nowait(item)
                return
            except queue.Full:  # the smoother falls behind: drop the oldest waiting sample
                try:
                    dropped = q.get_nowait()
                    if dropped is not None:
                        overrun[0] += 1
                except queue.Empty:
                    pass

    def on_signal(signum, frame):  # noqa: ARG001
        if not caught:
            caught.append(signal.Signals(signum).name)
        stop.set()

    previous = {}
    if signals and threading.current_thread() is threading.main_thread():
        previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}

    session: _Session | None = None
    pending: list[tuple[Reading, float]] = []  # samples held until the rate is known
    rate_from = "given" if rate_hz is not None else "stream"
    rows_in = bad = 0
    reasons: list[str] = []
    arrival: dict[int, float] = {}
    latency: list[tuple[float, float]] = []
    rows_out = 0

    def emit(states, timed: bool = True) -> None:
        nonlocal rows_out
        if not states:
            return
        sink.write(states)
        rows_out += len(states)
        if not timed:  # the window flushed at the end: their wait is the stream's end, not the lag
            return
        now = time.perf_counter()
        for s in states:  # arrival of a sample -> its estimate written
            t = arrival.pop(int(s.timestamp_ns), None)
            if t is not None:
                latency.append((t, now - t))
        if len(arrival) > 100_000:  # samples that never left (dropped): forget the oldest
            for key in list(arrival)[:50_000]:
                del arrival[key]
        if len(latency) > 200_000:
            del latency[:100_000]

    units = _FirstRowsCheck(array, source, say)
    watch: list[_RateWatch] = []

    def start_session(rate: float) -> None:
        nonlocal session
        _check_rate(rate, source)
        session = _Session(array, estimator, rate)
        watch[:] = [_RateWatch(rate)]
        for r, arrived in pending:
            feed(r, arrived)
        pending.clear()

    def feed(r: Reading, arrived: float) -> None:
        arrival[int(r.timestamp_ns)] = arrived
        emit(session.push(r))
        _on_rate_change(session, watch[0], r, array, estimator, say, emit)

    thread = threading.Thread(target=reader, name="gfimu-live-source", daemon=True)
    ended = None
    crash: list[Exception] = []
    try:
        sink.start()
        thread.start()
        try:
            last_status = time.monotonic()
            while True:
                if stop.is_set():  # a signal or the caller: what already arrived is still estimated
                    try:
                        item = q.get_nowait()
                    except queue.Empty:
                        break
                else:
                    try:
                        item = q.get(timeout=0.2)
                    except queue.Empty:
                        item = False
                if item is None:
                    break
                if item is not False:
                    thing, arrived = item
                    if isinstance(thing, SourceNote):
                        say(f"warning: {thing.message}")
                    elif isinstance(thing, BadRow):
                        bad += 1
                        if len(reasons) < REASONS_KEPT:
                            reasons.append(f"{thing.where}: {thing.reason}")
                            say(f"warning: {thing.where} skipped: {thing.reason}")
                            if len(reasons) == REASONS_KEPT:
                                say("warning: further bad rows are counted, not shown")
                    else:
                        rows_in += 1
                        units.add(thing)
                        if session is not None:
                            feed(thing, arrived)
                        else:
                            pending.append((thing, arrived))
                            if len(pending) >= RATE_ROWS:
                                rate = rate_from_timestamps([r.timestamp_ns for r, _ in pending])
                                if rate is not None:
                                    say(f"rate {rate:.6g} Hz, from the median period of the first {len(pending)} "
                                        f"samples (array.toml states no rate_hz; --rate-hz sets it)")
                                    start_session(rate)
                                else:
                                    pending.pop(0)
                if session is None and rate_hz is not None:
                    start_session(rate_hz)
                if status_s and time.monotonic() - last_status >= status_s:
                    last_status = time.monotonic()
                    p = _stats(np.asarray(session.processing) * 1e3) if session else None
                    late = session.counts()[0] if session else 0
                    say(f"{rows_in} in, {rows_out} out, processing p50 {p[0] if p else float('nan'):.2f} ms "
                        f"p99 {p[1] if p else float('nan'):.2f} ms, {overrun[0]} dropped, {late} late, {bad} bad")
            units.finish()
            if session is None and pending:  # the stream ended before RATE_ROWS samples
                rate = rate_from_timestamps([r.timestamp_ns for r, _ in pending])
                if rate is None:
                    say(f"{len(pending)} sample(s) with no step forward in time: no rate, nothing estimated "
                        "(--rate-hz sets the rate)")
                else:
                    say(f"rate {rate:.6g} Hz, from the median period of the first {len(pending)} samples")
                    start_session(rate)
            if session is not None:
                emit(session.flush(), timed=False)
                if session.screen is not None and session.screen.count:
                    say(f"warning: {session.screen.describe()}")
        except BrokenPipeError:  # the output (standard output) closed by its reader: the session ends there
            closed = True
        except Exception as exc:  # noqa: BLE001 - the estimator or the output failed: end with the counts
            crash.append(exc)
        ended = caught[0] if caught else None
    finally:
        stop.set()
        for s, h in previous.items():
            signal.signal(s, h)
        if thread.ident is not None:  # started (the output may fail before: its header is written first)
            thread.join(timeout=2 * 0.2 + 0.5)
        try:
            source.close()
        except OSError:
            pass
    failure = source.failure
    if closed:
        ended, failure = OUTPUT_CLOSED, "the output was closed by its reader (a broken pipe); the session ended there"
    elif crash:
        from .errors import DataError, InputError

        exc = crash[0]
        if isinstance(exc, (InputError, DataError)):  # the stream's own data refused, as estimate refuses a log's
            ended, failure = "input refused", str(exc)
        else:
            ended = "stopped by an error"
            failure = (f"{exc.filename}: {exc.strerror}" if isinstance(exc, OSError) and exc.filename
                       else f"{type(exc).__name__}: {exc}")
    elif ended is None:
        ended = source.ended
        if fatal:
            exc = fatal[0]
            ended = "input refused" if isinstance(exc, ValueError) else "source failed"
            failure = str(exc) or type(exc).__name__
    late, resets = session.counts() if session else (0, 0)
    steady = None
    if latency:
        pairs = np.asarray(latency)
        later = pairs[pairs[:, 0] > pairs[0, 0] + STEADY_AFTER_S, 1]
        steady = _stats(later * 1e3)
    result = LiveResult(
        rows_in=rows_in, rows_out=rows_out, bad_rows=bad, bad_reasons=tuple(reasons), late_or_repeated=late,
        clock_resets=resets, missing=session.missing if session else 0, overrun_dropped=overrun[0],
        processing_ms=_stats(np.asarray(session.processing) * 1e3) if session else None,
        latency_ms=_stats(np.asarray([d for _, d in latency]) * 1e3) if latency else None,
        steady_latency_ms=steady, rate_hz=session.rate_hz if session else rate_hz, rate_from=rate_from,
        ended=ended, failure=failure, replaced_readings=session.replaced_readings if session else 0,
        screening_ms=_stats(np.asarray(session.screening) * 1e3) if session and session.screening else None)
    if fatal and not isinstance(fatal[0], Exception):
        raise fatal[0]
    return result
