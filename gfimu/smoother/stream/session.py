"""One stream through the fixed-lag smoother: readings in, finished states out.

:class:`StreamSession` is the whole streaming path of ``gfimu estimate --method fixed-lag``
(:meth:`gfimu.smoother.stream.fixed_lag.FixedLagEstimator.result`) and of ``gfimu live``
(:func:`gfimu.live.run`): the rate (given, or measured on the first :data:`RATE_ROWS` timestamps), the
screening of the readings (:class:`gfimu.readings.StreamScreen`), the smoother (:class:`FixedLagSmoother`),
late, repeated and missing samples, clock resets, a rate that changes mid-stream, and the counts of all
of it. It does no input or output: what it has to say is kept in :meth:`StreamSession.take_notes`, the
caller reads the readings and writes the states. The same readings in the same order give the same states,
whatever their timing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ...errors import DataError
from ..model.parts import delegated
from .states import as_states

RATE_ROWS = 64
"""Samples from whose timestamps the rate is taken when neither array.toml nor the caller gives it
(the median period, as :attr:`gfimu.log.Log.rate_hz` takes it over a whole log)."""

BLOCK_ROWS = 4
"""Rows the screening decides at once (or a log hands over) from which they go to the smoother as a block."""

RATE_WATCH_STEPS = 32
"""Consecutive steps forward at one steady period, away from the nominal one, after which the rate is
measured again from them (:class:`RateWatch`)."""

TIMES_KEPT = 200_000
"""At most this many per-sample times are kept for the summary (the oldest half dropped beyond): :class:`Kept`."""


def rate_from_timestamps(timestamps_ns) -> float | None:
    """The rate [Hz] of the median step between increasing timestamps (None with fewer than two steps
    forward): the rule of :attr:`gfimu.log.Log.rate_hz`."""
    t = np.asarray(timestamps_ns, dtype=np.int64)
    dt = np.diff(t) * 1e-9
    dt = dt[dt > 0]
    if dt.size < 1:
        return None
    return 1.0 / float(np.median(dt))


def check_rate(rate_hz: float, name: str = "source") -> None:
    """A rate beyond any IMU's (timestamps 1 ns apart) would size the smoother's window at hundreds of
    millions of samples: refused (:class:`gfimu.errors.DataError` naming ``name``)."""
    from ...io.plausibility import MAX_RATE_HZ

    if rate_hz > MAX_RATE_HZ:
        raise DataError(f"{name}: a rate of {rate_hz:.4g} Hz (steps of {1e9 / rate_hz:.4g} ns), beyond any IMU's "
                        f"({MAX_RATE_HZ:g} Hz at most): check the unit of the timestamps (or --rate-hz)")


class RateWatch:
    """Tells when a stream's rate has changed: the last :data:`RATE_WATCH_STEPS` steps forward all within
    10 % of their median, and that median more than 1.5 times longer or shorter than the nominal step
    (every step a gap, or two samples per step). Returns the new rate once, then watches against it."""

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
        # a changed rate puts every step, the newest too, within 10 % of a median outside [1/1.5, 1.5] nominal
        # steps: a newest step inside [1.1/1.5, 0.9 × 1.5] rules it out without the median (the steady case)
        newest = self.steps[-1] * 1e-9 * self.rate_hz
        if 1.1 / 1.5 <= newest <= 0.9 * 1.5:
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


class Kept:
    """The newest values of a quantity counted per sample or per block (times, for a summary): at most
    :data:`TIMES_KEPT` of them, the oldest half dropped beyond, in one float array made at the start
    (``width`` values each). Its memory is the same whatever the stream's length: a list of Python floats
    would grow to 32 bytes a value (6 MB per 200,000, 22 MB as pairs) before its cap, and its summary copy."""

    def __init__(self, width: int = 1):
        self._rows = np.empty(TIMES_KEPT + 1 if width == 1 else (TIMES_KEPT + 1, int(width)))
        self._n = 0

    def append(self, value) -> None:
        self._rows[self._n] = value
        self._n += 1
        if self._n > TIMES_KEPT:
            drop = TIMES_KEPT // 2
            self._rows[:self._n - drop] = self._rows[drop:self._n]
            self._n -= drop

    def extend(self, value, count: int) -> None:
        """``value`` appended ``count`` times (as many :meth:`append` calls would keep)."""
        count = int(count)
        while count > 0:
            take = min(count, TIMES_KEPT + 1 - self._n)
            self._rows[self._n:self._n + take] = value
            self._n += take
            count -= take
            if self._n > TIMES_KEPT:
                drop = TIMES_KEPT // 2
                self._rows[:self._n - drop] = self._rows[drop:self._n]
                self._n -= drop

    def __len__(self) -> int:
        return self._n

    @property
    def values(self) -> np.ndarray:
        """The values kept, oldest first (a view: read it before the next :meth:`append`)."""
        return self._rows[:self._n]


@dataclass(frozen=True)
class SessionCounts:
    """What a stream's samples did: ``late_or_repeated`` (dropped), ``clock_resets`` (window restarts),
    ``missing`` (samples that never came: gaps of more than 1.5 nominal steps), ``replaced_readings``
    (by the screening), ``choice_waits`` (times the stream waited for a model chosen off it that was not
    ready at its sample) and ``choice_wait_s`` (their total)."""

    late_or_repeated: int
    clock_resets: int
    missing: int
    replaced_readings: int
    choice_waits: int
    choice_wait_s: float


@dataclass(frozen=True)
class SessionSettings:
    """How a :class:`StreamSession` takes its stream: ``name`` (in errors), ``screening`` (the readings are
    screened as they come), ``use_gyro`` (the gyroscope's rows go in), ``follow_rate`` (the rate is measured
    again when it changes)."""

    name: str
    screening: bool
    use_gyro: bool
    follow_rate: bool


@dataclass
class SessionTally:
    """What a :class:`StreamSession` counted beside its current smoother: rows dropped as late (``late``),
    window restarts (``resets``), samples that never came (``missing``), readings the screenings before the
    current one replaced (``replaced``), and the models and choice waits of the smoothers at the rates
    before the current one (``retired_models``, ``retired_waits``)."""

    late: int = 0
    resets: int = 0
    missing: int = 0
    replaced: int = 0
    retired_models: list = field(default_factory=list)
    retired_waits: list = field(default_factory=list)


@dataclass
class SessionTimings:
    """The times a :class:`StreamSession` kept: the smoother's per sample (``processing_s``) and the
    screening's per block (``screening_s``), each [s] in a :class:`Kept`."""

    processing_s: Kept = field(default_factory=Kept)
    screening_s: Kept = field(default_factory=Kept)


class StreamSession:
    """The fixed-lag ``estimator``'s smoother on one stream of ``array``'s readings.

    ``rate_hz``: the nominal rate; None takes it from the first :data:`RATE_ROWS` timestamps (the readings
    are held until then; a note says so). ``screen``: screen the readings as they come
    (:class:`gfimu.readings.StreamScreen`; default: the estimator's ``screen_readings``; False for readings
    already screened, as ``gfimu estimate`` screens a log with the same rule). ``follow_rate``: measure the
    rate again when it changes mid-stream (:class:`RateWatch`; a note says so), the window restarting once
    at the new rate. ``name`` names the stream in errors. ``upcoming``: the readings the stream will be
    pushed, where they are known (a log's times, readings and gyro readings or None): the smoother then makes
    its scheduled model choices ahead (:meth:`FixedLagSmoother.look_ahead
    <gfimu.smoother.stream.fixed_lag.FixedLagSmoother.look_ahead>`), the same states sooner.

    :meth:`push` each reading, :meth:`finish` at the end; both return the states that are final, oldest
    first (:class:`~gfimu.smoother.stream.fixed_lag.StateEstimate`). :meth:`take_notes` gives the messages
    (one line each) since the last call; :attr:`counts`, :attr:`processing_s` (the smoother's time per
    sample [s], :class:`Kept`), :attr:`screening_s` (the screening's time per block) and :attr:`models`
    (every model chosen) say what happened.
    """

    def __init__(self, array, estimator, rate_hz: float | None = None, *, screen: bool | None = None,
                 follow_rate: bool = True, name: str = "source", upcoming: tuple | None = None):
        self.array, self.estimator = array, estimator
        self.settings = SessionSettings(
            name, bool(getattr(estimator, "screen_readings", False) if screen is None else screen),
            bool(estimator.use_gyro and array.gyroscope is not None), bool(follow_rate))
        self.rate_hz: float | None = None
        self.rate_from = "given" if rate_hz is not None else "stream"
        self.smoother = None
        self.screen = None
        self.watch: RateWatch | None = None
        self._pending: list[tuple] = []  # readings held until the rate is known
        self._notes: list[str] = []
        self._last_t: int | None = None
        self._tally = SessionTally()
        self._timings = SessionTimings()
        self._upcoming = upcoming
        if rate_hz is not None:
            self._start(float(rate_hz))

    name = delegated("settings", "name", "The stream's name in errors.")
    screening = delegated("settings", "screening", "Whether the readings are screened as they come.")
    use_gyro = delegated("settings", "use_gyro", "Whether the gyroscope's rows go in.")
    follow_rate = delegated("settings", "follow_rate", "Whether the rate is measured again when it changes.")
    processing_s = delegated("_timings", "processing_s", "The smoother's time per sample [s] (:class:`Kept`).")
    screening_s = delegated("_timings", "screening_s", "The screening's time per block [s] (:class:`Kept`).")

    # --- the readings in --------------------------------------------------------------------------
    def push(self, timestamp_ns: int, accel, gyro=None) -> list:
        """One reading; the states it makes final."""
        row = (int(timestamp_ns), np.asarray(accel, dtype=float), gyro if self.settings.use_gyro else None)
        if self.smoother is None:
            self._pending.append(row)
            if len(self._pending) < RATE_ROWS:
                return []
            rate = rate_from_timestamps([r[0] for r in self._pending])
            if rate is None:
                self._pending.pop(0)
                return []
            self._notes.append(f"rate {rate:.6g} Hz, from the median period of the first {len(self._pending)} "
                               "samples (array.toml states no rate_hz; --rate-hz sets it)")
            return self._start(rate)
        return self._push(row)

    def push_block(self, timestamps_ns: np.ndarray, accel: np.ndarray, start: int, stop: int) -> tuple[int, list]:
        """Readings ``start …`` (before ``stop``) of ``timestamps_ns`` (n,) int64 and ``accel`` (n, axes), without
        gyroscope readings, as :meth:`push` takes them one by one: a run of them at once where the smoother
        can take a block (:meth:`FixedLagSmoother.push_block
        <gfimu.smoother.stream.fixed_lag.FixedLagSmoother.push_block>`: readings not screened here, a steady
        rate), at least one. Returns (the next reading's index, the states made final: :class:`StateEstimate
        <gfimu.smoother.stream.states.StateEstimate>` objects and :class:`~.states.StateRows`). The time a
        block took is counted in :attr:`processing_s` as its mean per sample."""
        if self.smoother is None or self.screen is not None or self.settings.use_gyro or self._last_t is None:
            return start + 1, self.push(int(timestamps_ns[start]), accel[start])
        # the readings the rate watch and the time-order check take without a word (RateWatch.step's steady
        # case: a step within [1.1/1.5, 0.9 × 1.5] nominal steps; a longer or a backward one goes one by one)
        times = timestamps_ns[start:stop]
        steps = np.diff(times, prepend=np.int64(self._last_t))
        if self.watch is not None:
            nominal = steps * (1e-9 * self.watch.rate_hz)
            quiet = (nominal >= 1.1 / 1.5) & (nominal <= 0.9 * 1.5)
        else:
            quiet = steps > 0
        run = int(np.argmin(quiet)) if not quiet.all() else len(times)
        if run == 0:
            return start + 1, self.push(int(timestamps_ns[start]), accel[start])
        t0 = time.perf_counter()
        end, states = self.smoother.push_block(timestamps_ns, accel, start, start + run)
        self._timings.processing_s.extend((time.perf_counter() - t0) / (end - start), end - start)
        if self.watch is not None:
            watch = self.watch
            if watch.last is None:
                taken = steps[1:end - start]
            else:
                taken = steps[:end - start]
            watch.steps.extend(int(v) for v in taken[-RATE_WATCH_STEPS:])
            del watch.steps[:-RATE_WATCH_STEPS]
            watch.last = int(timestamps_ns[end - 1])
        self._last_t = int(timestamps_ns[end - 1])
        return end, states

    def finish(self) -> list:
        """Every state still held (the readings waiting for the rate, the screening's, the window's)."""
        if self.smoother is None:
            if not self._pending:
                return []
            rate = rate_from_timestamps([r[0] for r in self._pending])
            if rate is None:
                self._notes.append(f"{len(self._pending)} sample(s) with no step forward in time: no rate, nothing "
                                   "estimated (--rate-hz sets the rate)")
                self._pending = []
                return []
            self._notes.append(f"rate {rate:.6g} Hz, from the median period of the first {len(self._pending)} samples")
            states = self._start(rate)
        else:
            states = []
        states += self._flush()
        self.smoother.end_choice_process()
        if self.screen is not None and self.screen.count:
            self._notes.append(f"warning: {self.screen.describe()}")
        return states

    def take_notes(self) -> list[str]:
        """The messages since the last call (the rate taken or measured again, the readings replaced)."""
        notes, self._notes = self._notes, []
        return notes

    # --- what happened ------------------------------------------------------------------------------
    @property
    def started(self) -> bool:
        """Whether the rate is known (the smoother runs)."""
        return self.smoother is not None

    @property
    def counts(self) -> SessionCounts:
        tally = self._tally
        late, resets, waits = tally.late, tally.resets, list(tally.retired_waits)
        if self.smoother is not None:
            c = self.smoother.counts
            late += c["duplicates"] + c["out_of_order"]
            resets += c["clock_resets"]
            waits += self.smoother.choice_waits
        replaced = tally.replaced + (self.screen.count if self.screen is not None else 0)
        return SessionCounts(late, resets, tally.missing, replaced, len(waits), float(sum(waits)))

    @property
    def models(self) -> list:
        """Every model chosen on the stream, oldest first (over every rate it had)."""
        return self._tally.retired_models + (list(self.smoother.models) if self.smoother is not None else [])

    @property
    def stream_model(self):
        """The model in use (None before one is chosen)."""
        return None if self.smoother is None else self.smoother.stream_model

    # --- internals -----------------------------------------------------------------------------------
    def _start(self, rate_hz: float) -> list:
        """The smoother (and screening) at ``rate_hz``; the readings held meanwhile go in."""
        check_rate(rate_hz, self.name)
        self.rate_hz = float(rate_hz)
        self.smoother = self._new_smoother()
        self.screen = self._new_screen()
        self.watch = RateWatch(self.rate_hz) if self.follow_rate else None
        held, self._pending = self._pending, []
        states = []
        for row in held:
            states += self._push(row)
        return states

    def _new_smoother(self):
        smoother = self.estimator.smoother(self.array, self.rate_hz)
        if self._upcoming is not None:
            smoother.look_ahead(*self._upcoming)
        return smoother

    def _new_screen(self):
        if not self.screening:
            return None
        from ...readings import StreamScreen

        return StreamScreen(self.array, self.rate_hz)

    def _push(self, row) -> list:
        states = self._take(row)
        if self.watch is not None:
            old = self.watch.rate_hz
            new = self.watch.step(row[0])
            if new is not None:
                self._notes.append(
                    f"warning: the stream's rate changed: {RATE_WATCH_STEPS} steps in a row of {1e3 / new:.4g} ms "
                    f"where {old:.6g} Hz was taken; the rate is measured again, {new:.6g} Hz, and the window "
                    "restarts once at it")
                states += self._rerate(new)
        return states

    def _take(self, row) -> list:
        """``row`` through the screening and the smoother, time order checked."""
        t = row[0]
        last = self._last_t
        if last is not None and t <= last:
            if last - t <= self.smoother.clock_reset_s * 1e9:
                if self.screen is None:  # the smoother drops and counts it
                    return list(self.smoother.push(*row).smoothed)
                self._tally.late += 1  # the rows before it are still in the screening: dropped here
                return []
            if self.screen is not None:  # a clock reset: the rows held go first, then a new screening
                states = self._smooth(self.screen.flush())
                self._tally.replaced += self.screen.count
                self.screen = self._new_screen()
                states += self._smooth(self._screened(row))
                self._last_t = t
                return states
        states = self._smooth(self._screened(row)) if self.screen is not None else self._smooth_one(row)
        if last is not None and t > last:
            steps = (t - last) * 1e-9 * self.rate_hz
            if steps > 1.5:  # samples that never came (lost datagrams, a sensor pause)
                self._tally.missing += int(round(steps)) - 1
        self._last_t = t
        return states

    def _screened(self, row) -> list:
        """The rows the screening decides on ``row``'s arrival (a block, or none), its time kept per block."""
        t0 = time.perf_counter()
        rows = self.screen.push(*row)
        if rows:
            self._timings.screening_s.append(time.perf_counter() - t0)
        return rows

    def _smooth(self, rows) -> list:
        """The smoother's update on each row, its time kept per row (not for a row it drops); several rows
        without gyroscope readings at once where the smoother takes them so (:meth:`_smooth_block`)."""
        if len(rows) >= BLOCK_ROWS and all(row[2] is None for row in rows):
            return self._smooth_block(rows)
        states = []
        kept, push = self._timings.processing_s, self.smoother.push
        for row in rows:
            t0 = time.perf_counter()
            update = push(*row)
            if update.dropped is None:
                kept.append(time.perf_counter() - t0)
            states.extend(update.smoothed)
        return states

    def _smooth_block(self, rows) -> list:
        """:meth:`_smooth` of ``rows`` through :meth:`FixedLagSmoother.push_block
        <gfimu.smoother.stream.fixed_lag.FixedLagSmoother.push_block>` (the same states), as
        :class:`~gfimu.smoother.stream.states.StateEstimate` objects; each row's time the mean of its run."""
        times = np.fromiter((row[0] for row in rows), dtype=np.int64, count=len(rows))
        accel = np.vstack([row[1] for row in rows])
        states: list = []
        kept, i = self._timings.processing_s, 0
        while i < len(rows):
            t0 = time.perf_counter()
            j, out = self.smoother.push_block(times, accel, i, len(rows))
            kept.extend((time.perf_counter() - t0) / (j - i), j - i)
            states.extend(as_states(out))
            i = j
        return states

    def _smooth_one(self, row) -> list:
        """:meth:`_smooth` of the one row ``row`` (readings not screened: the row of every sample)."""
        t0 = time.perf_counter()
        update = self.smoother.push(*row)
        if update.dropped is None:
            self._timings.processing_s.append(time.perf_counter() - t0)
        return list(update.smoothed)

    def _flush(self) -> list:
        """The rows still held by the screening, then the window: every state left."""
        states = self._smooth(self.screen.flush()) if self.screen is not None else []
        return states + list(self.smoother.flush())

    def _rerate(self, rate_hz: float) -> list:
        """On at ``rate_hz``: the states still held at the old rate, then a new smoother and screening."""
        states = self._flush()
        tally = self._tally
        if self.screen is not None:
            tally.replaced += self.screen.count
        old = self.smoother
        c = old.counts
        tally.late += c["duplicates"] + c["out_of_order"]
        tally.resets += c["clock_resets"]
        tally.retired_models += old.models
        tally.retired_waits += old.choice_waits
        old.end_choice_process()
        self.rate_hz = float(rate_hz)
        self.smoother = self._new_smoother()
        self.screen = self._new_screen()
        return states

