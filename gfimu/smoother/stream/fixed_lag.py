"""Fixed-lag smoothing of ω, ω̇ and f from an accelerometer array, streaming.

The states of each sample k are ω_k, ω̇_k and f_k (all in B). They are tied
together by

- the array measurement (Ho & Lin 2009, eq. 6): ``y_k = S [f_k, ω̇_k, q(ω_k)] + v``;
- a white-jerk process model: ``ω_{k+1} = ω_k + h (ω̇_k + ω̇_{k+1}) / 2``
  (trapezoidal integration) and random walks on ω̇ and f;
- weak priors on the first state of every segment, and an optional gyroscope;
- the factor groups given in ``SmootherOptions.factor_groups`` whose rows each
  depend on one sample's state (:attr:`gfimu.smoother.model.groups.FactorGroup.per_sample`),
  evaluated by their own vectorised residual and Jacobian on each sample as it
  comes (:meth:`gfimu.smoother.stream.array_model.ArrayModel.sample_terms`);

the same factors and options (:class:`~gfimu.smoother.model.problem.SmootherOptions`)
as the batch smoother (method ``"smoother"``). The first states of a segment
(``warmup_s`` of data) are initialised by the batch smoother's sign-resolving
initialiser (:mod:`gfimu.smoother.solve.initialise`); every later state starts from
the previous filtered one (``ω + h ω̇``, then ``[f, ω̇]`` from the readings
given that ω), so the sign of ω is carried through zero crossings.

:class:`FixedLagSmoother` solves the window of these factors with one of two
engines: ``numpy`` (default; :mod:`gfimu.smoother.stream.window_filter`, a Kalman
filter on the state augmented with the window, keeping the cross-covariances
of the window with the newest state: the same least-squares minimum for the
linear parts, each reading linearised once by a Gauss-Newton update; about
0.15 ms per sample at 500 Hz with a 0.2 s lag, with no periodic spikes) or
``gtsam`` (``IncrementalFixedLagSmoother``, iSAM2 underneath, about 1 ms per
sample; kept as the reference the numpy engine is tested against). Each
:meth:`push` adds one sample, returns the newest (filtered) state and every
state that has just reached the lag (smoothed with ``lag_s`` seconds of
future data), after which it leaves the window. Memory stays bounded: the
engine keeps only the window and this module keeps only deques of window length.

The first rows of a segment are held (numpy engine, at most ``hold_max_s``): kept back past the
lag until the data decide ω (the branch log-likelihood ratio, the stream agreeing with a re-solve of
the held stretch, that re-solve no longer moving with the data; :meth:`FixedLagSmoother._release_start`),
then given re-solved, with the window going on from the re-solved states (``docs/fixed-lag.md``).

Time gaps (a step longer than ``gap_factor`` times the nominal step, as
:meth:`gfimu.log.Log.gaps`) are not integrated across: the window is flushed
(its states are emitted, smoothed with the data they have) and a new segment
starts with a fresh initialisation.

The model chosen from the data (``auto_model``, on in :class:`FixedLagEstimator`):
the batch smoother's model check and noise choice (:mod:`gfimu.smoother.tuning.model_choice`) made on
the stream's own recent past and made again as the motion changes
(:mod:`gfimu.smoother.stream.model_choice`; ``docs/fixed-lag.md``). The first
``tune_window_s`` of data are buffered and the model is chosen on them; for a
consistent stretch whose process noise is tuned, the states of the stretch that come
out then are the batch solution of the stretch and the stream continues from the
fixed-lag smoother run over it. Every ``retune_every_s`` the choice is made again on
the last ``model_window_s``, and at once when a model chosen at rest is outgrown: in a process
of its own (:mod:`.choice_worker`; a thread where none may be forked), on the history (:mod:`.history`),
the new model used :data:`CHOICE_DELAY_S` of samples after the
sample that asked for it (a sample fixed by the data: a log and a live stream of it give the same rows).
Without ``auto_model`` (the class's default), ``tune_process_noise`` chooses the
process noise once on the first ``tune_window_s``, as the batch tuner would on that
stretch alone. Densities given explicitly (any of
``omega_dot_random_walk_radps2_per_sqrt_s``,
``specific_force_random_walk_mps2_per_sqrt_s``, ``process_axis_factors`` not at its
default) are used as given and disable the tuning, as does
``tune_process_noise=False``; the model check still sets the noise levels.

If an update fails (gtsam's ``IndeterminantLinearSystem``, a singular innovation covariance), the window
is rebuilt once from its raw samples with a ``RuntimeWarning`` naming the
time; a second failure raises :class:`FixedLagSmootherError`.

With the gtsam engine, gtsam marginalises in blocks of ``marginalise_every_s`` (keys carry the start
time of their block): marginalising one sample per update made gtsam 4.3
re-eliminate the window and relinearise most of its factors at every update
(about 30 ms per sample at 500 Hz with a 0.2 s lag); in blocks, one update in
``marginalise_every_s × rate`` pays for it. Only ω is ever relinearised (ω̇
and f enter every factor linearly). The window holds between ``lag_s`` and
``lag_s + 2 marginalise_every_s`` of states.

:class:`FixedLagEstimator` (method ``"fixed-lag"``) streams a whole log
through the smoother and returns one row per sample.
"""

from __future__ import annotations

import functools
import math
import warnings
import weakref
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from ...array import SensorArray
from ...errors import DataError, InputError
from ...estimate import Estimate, Report
from ...log import Log
from ...parallel import cpu_count
from ...motion import Motion
from ...progress import progress as progress_bar
from . import array_model as model
from .choice_worker import ChoiceProcess, ForkedChoice
from .history import History, Stretch, same_samples
from .window_filter import FilterFailure, WindowFilter
from .gtsam_window import GtsamWindow
from ..solve.banded import solve
from ..model.parts import delegated
from ..model.problem import check_oscillators, options_reason
from ...option import check_declared
from ..model.option_groups import (GROUPS, BatchModelOptions, Engine, ModelGroups, ModelOptions, StreamOptions,
                                   TuningOptions, assemble)
from ..solve.initialise import initial_estimate, still_start
from ..model.layout import OMEGA, OMEGA_DOT, SPECIFIC_FORCE
from ..result import SmootherEstimator
from . import model_choice as stream_model
from ..tuning.model_choice import measured_noise_options
from ..solve.restarts import branch, plane_normal
from .model_choice import OUTGROWN_FACTOR, LocalDensity, StreamModel, StreamSignChain
from .states import StateEstimate, StateRows, _state
from ..solve.sigma_scale import RunningSigmaScale, calibrates_stream, jerk_density
from ..tuning.evidence import make_problem, tuned_problem
from ...estimators.ml import MLEstimator

BLOCK_SAMPLES = 2048
"""Samples a log's stream hands the smoother at most at once (:meth:`FixedLagSmoother.push_block`; the progress
bar moves by as many)."""

SIGN_ERROR_PROBABILITY = 1e-3
"""The start of a segment is held until the branch of ω it is on is this unlikely to be the wrong one
(:meth:`FixedLagSmoother._start_evidence`): with equal prior odds, the posterior probability of the other
branch is ``1 / (1 + e^Λ)`` for a log-likelihood ratio Λ, so the sign is decided once Λ exceeds
:data:`SIGN_DECISION_NATS`."""
SIGN_DECISION_NATS = math.log((1.0 - SIGN_ERROR_PROBABILITY) / SIGN_ERROR_PROBABILITY)
"""ln(999) = 6.9 nats."""


AGREEMENT_CHI2 = 3.0
"""The filter's ω at the lag (the next row it would give) agrees with the re-solve of the held stretch
when their difference, in the re-solve's posterior covariance of that ω (3 values), is at most the mean
of χ²₃: the stream's departure from the data's answer is then no larger than that answer's own
uncertainty (their sum at most twice its variance), and the recursion, which linearises each reading
once, has taken in what the start told.
Before that (slow rotation: the readings see ω through q(ω), whose slope 2|ω| is small, so a poor
first linearisation fades over seconds) the stream would carry the start's error on."""
SAME_BRANCH = 0.5
"""Two solutions of the held stretch are one minimum (not two branches) when the RMS of their ω
difference is below this fraction of the RMS of ω: the branches of ω differ by about 2 |ω|."""


CHOICE_DELAY_S = 0.5
"""A model chosen again on the stream (every ``retune_every_s``, or when the motion outgrows the model) is
computed off the stream, on the history (:mod:`.history`), while the samples go on with the model in use; it
replaces that model this long (of samples, at the nominal rate) after the sample that asked for it. The
sample at which it changes is fixed by the data, never by the clock, so that a log and a live stream of it
give the same rows (:class:`PendingChoice`)."""


STRETCH_RATE_HZ = 2000.0
"""Above this rate the stretches given in seconds that the stream solves as a whole are cut to the samples
they hold at this rate: the first tuning stretch (``tune_window_s``: 3 s, 6,000 samples), the history the
model is chosen on (``model_window_s``: 30 s, 60,000 samples) and the held start (``hold_max_s``: 4 s,
8,000 samples). Each costs its length in samples, not in seconds: at 20 kHz, 3 s of samples took the first
choice 20 s and kept every row waiting for it, and 30 s of history held 600,000 samples in memory. A few
thousand samples decide a noise density or a branch of ω as well at any rate (the evidence grows with the
samples); the span of motion they see is shorter, and a motion that outgrows the model asks for a new
choice at once (:data:`OUTGROWN_FACTOR`)."""


PER_SAMPLE_AHEAD_MAX = 2_000_000
"""Longest log [samples] whose per-sample estimate for the guard is made beside the stream
(:meth:`FixedLagEstimator._per_sample_ahead`): its rows (ω, ω̇, f and their σ, about 150 bytes a sample) come
back through a pipe, a second copy of them for a moment; longer logs (100 s at 20 kHz) have it made after the
stream, as the guard makes it."""


def stretch_samples(seconds: float, rate_hz: float) -> int:
    """The samples of a stretch of ``seconds`` at ``rate_hz``, at most those it holds at
    :data:`STRETCH_RATE_HZ` (at least 2)."""
    return max(2, int(round(seconds * min(rate_hz, STRETCH_RATE_HZ))))


class PendingChoice:
    """A model being chosen in a worker thread (:meth:`FixedLagSmoother._choose`, where no process may be forked
    for it: :class:`~.choice_worker.ForkedChoice`): ``compute()`` (returning
    the chosen :class:`~gfimu.smoother.stream.model_choice.StreamModel`) runs at once in a daemon thread;
    :meth:`result` waits for it (the seconds waited in ``waited_s``) and gives its model, or
    raises what it raised. ``swap_at``: the count of samples at which the model is to be used."""

    def __init__(self, compute, swap_at: int, outgrown: bool, finish=None):
        import threading

        self._finish = finish
        self.swap_at = int(swap_at)
        self.outgrown = bool(outgrown)
        self.waited_s = 0.0
        self._value = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(compute,), name="gfimu-model-choice", daemon=True)
        self._thread.start()

    def _run(self, compute) -> None:
        try:
            self._value = compute()
        except BaseException as exc:  # noqa: BLE001 - raised again where the model is used
            self._error = exc

    @property
    def done(self) -> bool:
        return not self._thread.is_alive()

    def result(self):
        if self._thread.is_alive():
            import time

            t0 = time.perf_counter()
            self._thread.join()
            self.waited_s = time.perf_counter() - t0
        if self._error is not None:
            raise self._error
        return self._value if self._finish is None else self._finish(self._value)


def auto_model_reason(array: SensorArray, batch_model: BatchModelOptions) -> str | None:
    """Why the fixed-lag smoother cannot check its model on the data (None if it can): the check
    needs the per-sample ML fit of the accelerometers."""
    if batch_model.measurement != "accelerometer":
        return "measurement is not 'accelerometer'"
    return MLEstimator().applicable(array)


class FixedLagSmootherError(DataError, RuntimeError):
    """The smoother could not solve an update (names the time and the cause)."""


class FixedLagSmootherClosed(InputError, RuntimeError):
    """:meth:`FixedLagSmoother.push` or :meth:`FixedLagSmoother.flush` after :meth:`FixedLagSmoother.close`."""


class ClockResetWarning(RuntimeWarning):
    """The stream's time went back by more than ``clock_reset_s``: the window was restarted."""


class FixedLagUpdate:
    """What one :meth:`FixedLagSmoother.push` gives back.

    ``smoothed``: states that reached the lag (final values, oldest first;
    usually one, several after a warm-up, a gap or a clock reset, none at the start; the first rows of a
    segment all at once when its start is released, :meth:`FixedLagSmoother._release_start`).
    ``filtered``: the newest state given data up to now (``None`` while the
    first samples of a segment are being gathered for the initialisation, and
    when the sample was dropped).
    ``dropped``: why this sample was not used: ``None`` (it was used),
    ``"duplicate"`` (same timestamp as the previous sample) or ``"out-of-order"``
    (earlier than the previous sample by at most ``clock_reset_s``).

    ``filtered`` is made when it is first read (``newest``: the values it is made of, (timestamp_ns, ω,
    ω̇, f)): a stream that reads only the smoothed states does not pay for it at every sample.
    """

    __slots__ = ("smoothed", "dropped", "_filtered", "_newest")

    def __init__(self, smoothed: tuple[StateEstimate, ...], filtered: StateEstimate | None,
                 dropped: str | None = None, newest: tuple | None = None) -> None:
        self.smoothed, self.dropped, self._filtered, self._newest = smoothed, dropped, filtered, newest

    @property
    def filtered(self) -> StateEstimate | None:
        if self._newest is not None:
            self._filtered, self._newest = StateEstimate(*self._newest), None
        return self._filtered

    def __repr__(self) -> str:
        return f"FixedLagUpdate(smoothed={self.smoothed!r}, filtered={self.filtered!r}, dropped={self.dropped!r})"


ENGINES = tuple(engine.value for engine in Engine)
"""Window solvers: ``numpy`` (:mod:`gfimu.smoother.stream.window_filter`, the default) and ``gtsam``
(``IncrementalFixedLagSmoother``, iSAM2)."""

PROCESS_NOISE_OPTIONS = ("omega_dot_random_walk_radps2_per_sqrt_s", "specific_force_random_walk_mps2_per_sqrt_s",
                         "process_axis_factors", "process_axis_frequencies_hz")
"""Options that, set away from their defaults, give the process noise explicitly (no tuning)."""
_MODEL_DEFAULTS, _BATCH_MODEL_DEFAULTS = ModelOptions(), BatchModelOptions()


def explicit_process_noise(model: ModelOptions) -> list[str]:
    """Names of the process-noise options of the ``model`` that differ from their defaults."""
    return [name for name in PROCESS_NOISE_OPTIONS
            if tuple(np.atleast_1d(getattr(model, name))) != tuple(np.atleast_1d(getattr(_MODEL_DEFAULTS, name)))]


def tunes_process_noise(model: ModelOptions, tuning: TuningOptions) -> bool:
    """Whether the fixed-lag smoother chooses the process noise of the ``model`` from the data as ``tuning`` asks."""
    return bool(tuning.tune_process_noise) and not explicit_process_noise(model)


def fixed_lag_reason(array: SensorArray, options: ModelGroups) -> str | None:
    """Why the fixed-lag smoother cannot run on ``array`` with the option groups of the model ``options``
    (None if it can).

    Model options the stream cannot honour, set away from their defaults, are refused with the reason,
    never silently ignored (:class:`FixedLagEstimator` has no batch option, and gives the batch model's
    groups at their defaults)."""
    unsupported = [name for part, name in ((options.self_calibration, "self_calibrate_bias"),
                                           (options.self_calibration, "self_calibrate_scale"),
                                           (options.batch_model, "free_flight"), (options.attitude, "use_inclinometer"),
                                           (options.attitude, "estimate_attitude")) if getattr(part, name)]
    if unsupported:
        return f"the fixed-lag smoother does not support {', '.join(unsupported)} (use method 'smoother')"
    whole = [getattr(g, "name", repr(g)) for g in options.model.factor_groups
             if not (getattr(g, "per_sample", False) or getattr(g, "steps", False))]
    if whole:
        return (f"factor_groups {', '.join(whole)}: the fixed-lag smoother streams only groups whose rows each depend on "
                "one sample's state (FactorGroup.per_sample) or on two consecutive samples' (FactorGroup.steps; "
                "use method 'smoother')")
    if options.model.motion_model != "jerk":
        return f"the fixed-lag smoother uses motion_model='jerk' only, got {options.model.motion_model!r} (use method 'smoother')"
    if options.batch_model.measurement != "accelerometer":
        return "the fixed-lag smoother uses measurement='accelerometer' only"
    if options.tuning.tune_motion_model:
        return "tune_motion_model: the fixed-lag smoother has the 'jerk' motion model only (use method 'smoother')"
    if options.batch_model.accel_noise_slope_mps2_per_radps > 0:
        return ("accel_noise_slope_mps2_per_radps: the motion-dependent accelerometer noise is re-weighted from a whole "
                "solution, which a stream does not have (use method 'smoother')")
    for name in ("accel_robust_threshold", "process_robust_threshold", "robust_loss"):
        if getattr(options.batch_model, name) != getattr(_BATCH_MODEL_DEFAULTS, name):
            return (f"{name}: the robust re-weighting is iterated over whole solutions, which a stream does not "
                    "have (use method 'smoother')")
    has_gyro = array.gyroscope is not None and options.model.use_gyro
    if array.n_axes < 6 and not has_gyro:
        return (f"array {array.name!r} has {array.n_axes} accelerometer axes; without a gyroscope ω cannot be "
                "observed (free flight needs method 'smoother' with free_flight=True)")
    return options_reason(array, options)


@dataclass(frozen=True)
class GtsamSettings:
    """The gtsam engine's settings: ``relinearize_threshold`` [rad/s] and ``relinearize_skip`` (iSAM2),
    ``block_s`` (the marginalisation blocks), ``factorization``."""

    relinearize_threshold: float
    relinearize_skip: int
    block_s: float
    factorization: str = "QR"


@dataclass
class StreamClock:
    """The stream's time as :class:`FixedLagSmoother` sees it: the last timestamp taken (``last_ns``), the
    segment's origin, the samples dropped as repeated or out of order, the clock resets (time going back by
    more than ``reset_s``)."""

    reset_s: float
    last_ns: int | None = None
    origin_ns: int | None = None
    duplicates: int = 0
    out_of_order: int = 0
    clock_resets: int = 0


@dataclass(frozen=True)
class StreamConfig:
    """How :class:`FixedLagSmoother` runs its stream, fixed when it is made: ``lag_s`` [s] (a state is given
    smoothed this long after its sample), ``rate_hz`` (the nominal rate), ``gap_factor`` (a step longer than this
    many nominal steps, :attr:`nominal_dt_ns`, ends the segment), ``warmup_n`` (the samples a segment's first
    states are initialised on), the window ``engine`` (:data:`ENGINES`; with ``gtsam`` its ``gtsam`` settings),
    ``branches`` (the numpy engine follows the other branches of ω), ``fast_measurement`` and ``compute_sigma``
    (σ of every state given out)."""

    lag_s: float
    rate_hz: float
    gap_factor: float
    warmup_n: int
    engine: str
    gtsam: GtsamSettings
    branches: bool
    fast_measurement: bool
    compute_sigma: bool

    @property
    def nominal_dt_ns(self) -> float:
        """The nominal step [ns]."""
        return 1e9 / self.rate_hz

    @functools.cached_property
    def lag_ns(self) -> int:
        """The lag [ns], rounded to the nanosecond."""
        return int(round(self.lag_s * 1e9))

    @functools.cached_property
    def gap_ns(self) -> float:
        """A step longer than this [ns] ends the segment (``gap_factor`` nominal steps)."""
        return self.gap_factor * self.nominal_dt_ns


@dataclass
class Segment:
    """The stream since its start, its last gap, clock reset or flush: the window ``engine`` (a
    :class:`WindowFilter` or a :class:`GtsamWindow`; None while ``warmup`` gathers the samples the first states
    are initialised on), ``window`` ((index, timestamp_ns) of the states not yet given out, oldest first),
    ``raw`` ((timestamp_ns, accel, gyro) of the same samples, to solve the window again), ``k`` (the index of
    the newest state), ``prev`` ((timestamp_ns, ω, ω̇, f) of the newest state, filtered; ``prev_x`` the
    one array [ω, ω̇, f] those are views of) and ``prev_sample`` (its sample)."""

    engine: WindowFilter | GtsamWindow | None = None
    window: deque = field(default_factory=deque)
    raw: deque = field(default_factory=deque)
    warmup: list = field(default_factory=list)
    k: int = -1
    prev: tuple | None = None
    prev_x: np.ndarray | None = None
    prev_sample: tuple | None = None


def _taken_back(answer, previous):
    """The model of a choice's ``answer`` (:meth:`FixedLagSmoother._chosen_in_process`) as a choice in a thread
    gives it: the tuning of ``previous`` itself where the model kept it (one tuning, not a copy of it per
    choice, in the report)."""
    chosen, kept = answer
    return replace(chosen, tuning=previous.tuning) if kept else chosen


def _solved_each(request) -> list:
    """``solve(problem, x0)`` for each start of ``request`` = (problem, starts), in order (a helper process's
    work: :meth:`FixedLagSmoother._solved_from`)."""
    problem, starts = request
    return [solve(problem, x0) for x0 in starts]


@dataclass
class AheadOfChoice:
    """The next scheduled model choice made before it is asked for, where the samples to come are known (a
    log, :meth:`FixedLagSmoother.look_ahead`). In the stream: the samples to come (``upcoming``: times, readings,
    gyro readings or None), those sent with the pending request up to the next scheduled choice (``sent``,
    :meth:`~.history.History.ahead`), once its model is in use that model (``model``), and how many choices
    made ahead it asked for (``used``). In the choice's
    process: the request's samples and model to work ahead from (``start``) and what that gave (``guess``:
    the history with the samples taken in, the stretch read, the answer or the error, the warnings)."""

    upcoming: tuple | None = None
    sent: tuple | None = None
    model: object = None
    used: int = 0
    start: tuple | None = None
    guess: tuple | None = None


@dataclass
class WorkerSlot:
    """The process the stream's later model choices are made in (:class:`~.choice_worker.ChoiceProcess`),
    forked when the first is asked for (``tried``); None where none may be forked. ``finalizer`` ends it
    (with the smoother, or when the smoother is gone)."""

    tried: bool = False
    process: ChoiceProcess | None = None
    finalizer: object = None

    def close(self) -> None:
        """End the process; a later choice is made in a thread."""
        if self.finalizer is not None:
            self.finalizer()
        self.process = self.finalizer = None


class StartHold:
    """The first rows of each segment held back past the lag until the data decide the branch of ω (numpy
    engine; :meth:`FixedLagSmoother._release_start`).

    Settings: ``max_s`` (the longest hold [s]; 0: rows are never held) and ``check_every_ns`` (the shortest
    span at which the evidence is first weighed; then at doubling spans, :meth:`due`). Of the current segment:
    ``deciding`` (its first rows are being held), ``held`` ((timestamp_ns, raw sample, filtered state) of the rows held
    so far), ``next_check_ns`` (when the evidence is weighed next), ``last_resolve`` ((timestamps, ω) of the
    previous check's re-solve) and ``waiting_for_batch`` (the rows held are to be released from a batch
    solution of the stretch: no check meanwhile). Of every segment so far: ``starts`` (how its start was decided) and
    ``still_starts`` (the std of the prior ω = 0 of each segment that started still)."""

    def __init__(self, max_s: float, check_every_ns: int) -> None:
        self.max_s = max_s
        self.check_every_ns = check_every_ns
        self.starts: list[dict] = []
        self.still_starts: list[float] = []
        self.begin_segment()

    def begin_segment(self) -> None:
        """A new segment: its first rows are held (when holding at all), nothing held yet."""
        self.waiting_for_batch = False
        self.deciding = self.max_s > 0
        self.held: list = []
        self.next_check_ns: int | None = None
        self.level = 0  # the next check's j: at the span top / 2^j (:meth:`due`)
        self.last_resolve: tuple | None = None

    @property
    def held_s(self) -> float:
        """The span of the rows held [s]."""
        return (self.held[-1][0] - self.held[0][0]) * 1e-9 if self.held else 0.0

    def due(self, newest_ns: int) -> bool:
        """Whether the evidence is to be weighed now, the newest sample at ``newest_ns``: at the spans ``top / 2^j``
        of the stretch from the first row held to the newest sample, j = J, J - 1, … 0, ``top`` the span once the
        rows span ``max_s`` (the newest sample runs ahead of the last row held by the lag) and ``top / 2^J`` the
        shortest at least ``check_every_ns``; and at once when the rows span ``max_s``. Each check solves the
        whole stretch again, so checks at doubling spans cost at most twice the last one together (at even
        spacing the cost grows with the square of the hold); counted back from the last check, which the
        longest hold makes anyway, none falls just before it (a check nearly as long would cost as much and
        decide no sooner)."""
        first = self.held[0][0]
        top = self.max_s * 1e9 + (newest_ns - self.held[-1][0])
        if self.next_check_ns is None:
            self.level = math.floor(math.log2(top / self.check_every_ns)) if top > self.check_every_ns else 0
            self.next_check_ns = first + int(math.ceil(top / 2.0 ** self.level))
        if newest_ns < self.next_check_ns and self.held_s < self.max_s:
            return False
        self.level = max(self.level - 1, 0)
        self.next_check_ns = first + int(math.ceil(top / 2.0 ** self.level))
        return True

    def record(self, held_s: float, evidence_nats: float, agreement_chi2: float, moved_chi2: float,
               open_: bool) -> None:
        """How the start of the segment was decided, kept in :attr:`starts`."""
        self.starts.append({"held_s": held_s, "evidence_nats": evidence_nats, "agreement_chi2": agreement_chi2,
                            "moved_chi2": moved_chi2, "open": open_})

    def release(self) -> list:
        """The raw samples of the rows held; the hold ends."""
        held = [h[1] for h in self.held]
        self.held, self.deciding = [], False
        return held

    def moved(self, times: np.ndarray, omega: np.ndarray, cov: np.ndarray | None) -> float:
        """How far the rows of the previous check's re-solve moved with the data since: the mean over
        them of the change of ω in the new re-solve's covariance (``cov``, (N, 3, 3); not read at the
        first check); inf at the first check (or when the rows are not the same). Kept for the next check."""
        last, self.last_resolve = self.last_resolve, (times, omega.copy())
        if last is None or len(last[0]) > len(times) or not np.array_equal(last[0], times[:len(last[0])]):
            return math.inf
        m = len(last[0])
        d = omega[:m] - last[1]
        try:
            return float(np.mean(np.einsum("ni,ni->n", d, np.linalg.solve(cov[:m], d[..., None])[..., 0])))
        except np.linalg.LinAlgError:
            return math.inf


@dataclass(frozen=True)
class ChoiceRules:
    """How :class:`FixedLagSmoother` chooses its model on the stream, fixed when it is made: the model, batch
    model and tuning as given (``given``), whether it tunes the process noise (``tune``) and checks the model
    (``auto``, with the per-sample ML fit ``ml``), the first choice's stretch (``tune_n`` samples; a stretch cut
    short is tuned on from ``tune_min_n``), a later choice every ``retune_ns`` and used ``delay_n`` samples after
    the one that asked for it."""

    given: ModelGroups
    tune: bool
    auto: bool
    retune_ns: int
    tune_n: int
    tune_min_n: int
    delay_n: int
    ml: MLEstimator | None = None


@dataclass
class ChoiceState:
    """The model :class:`FixedLagSmoother` uses and how it chooses it on the stream (``rules``, :class:`ChoiceRules`).

    In use: ``groups`` (the model, batch model and tuning of the model in use), ``model`` (the
    :class:`~.array_model.ArrayModel` they make), ``stream_model`` (the model chosen,
    :mod:`gfimu.smoother.stream.model_choice`; None before the first choice), ``models`` (every model chosen so
    far, oldest first), ``tuning`` (the newest process-noise selection,
    :class:`gfimu.smoother.tuning.evidence.Tuning`, or None), ``jerk_factor`` (the local motion density's factor
    on the motion model's stds, robust model).

    Choosing: whether the first choice is still to be made (``first_pending``, on ``buffer``, the first
    ``rules.tune_n`` samples), the ``history`` later choices are made on (:class:`~.history.History`), every
    ``rules.retune_ns`` or when the ``local`` motion density outgrows the model; the choice being made off the
    stream (``pending``, used when ``accepted``, the samples taken in, reaches its sample) and the waits for late
    ones."""

    rules: ChoiceRules
    first_pending: bool
    history: History
    local: LocalDensity
    groups: ModelGroups
    model: model.ArrayModel
    stream_model: StreamModel | None = None
    models: list = field(default_factory=list)
    tuning: object = None
    jerk_factor: float = 1.0
    buffer: list = field(default_factory=list)
    pending: PendingChoice | None = None
    accepted: int = 0
    waits: list = field(default_factory=list)
    turn_checked_ns: int = -(2**62)
    """When :meth:`FixedLagSmoother._turn_began` last looked [ns]."""

    def use(self, chosen: StreamModel, array: SensorArray, fast_measurement: bool) -> None:
        """``chosen`` becomes the model in use."""
        self.stream_model = chosen
        self.models.append(chosen)
        self.tuning = chosen.tuning if chosen.tuning is not None else self.tuning
        self.groups = chosen.groups
        previous = self.model
        self.model = model.ArrayModel(array, chosen.groups, fast_measurement,
                                      chosen.accel_noise_scale)
        if previous is not None:  # the step lengths the stream has met, made at once for the new model
            self.model.prepare_steps(previous.caches.steps.keys())


class SigmaRescale:
    """σ of the states given out scaled by the misfit of their readings (:mod:`gfimu.smoother.solve.sigma_scale`):
    the running ``scale`` and the ``readings`` of the samples not yet given out, by timestamp."""

    def __init__(self, array: SensorArray) -> None:
        self.scale = RunningSigmaScale(array)
        self.readings: dict = {}

    def scaled(self, states, m) -> tuple[StateEstimate, ...]:
        """``states`` with σ scaled by the misfit of the readings given out so far, ``m`` the model in use."""
        out = []
        for s in states:
            y = self.readings.pop(s.timestamp_ns, None)
            if s.sigma_omega_b_radps is None or y is None:
                out.append(s)
                continue
            x = np.concatenate([s.omega_b_radps, s.omega_dot_b_radps2, s.specific_force_b_mps2])
            std = np.sqrt(m.accel_sigma_mps2 ** 2 + m.accel_noise_slope_mps2_per_radps ** 2 * float(x[:3] @ x[:3]))
            self.scale.robust = (m.robust_loss, m.accel_robust_threshold) if m.accel_robust_threshold > 0 else None
            sd = self.scale.scaled(y, x, np.concatenate([s.sigma_omega_b_radps, s.sigma_omega_dot_b_radps2,
                                                         s.sigma_specific_force_b_mps2]), std,
                                   jerk_density(m.model), s.timestamp_ns * 1e-9)
            out.append(replace(s, sigma_omega_b_radps=sd[0:3], sigma_omega_dot_b_radps2=sd[3:6],
                               sigma_specific_force_b_mps2=sd[6:9]))
        return tuple(out)


class FixedLagSmoother:
    """Streaming fixed-lag smoother.

    ``push(timestamp_ns, accel_row, gyro_row=None, tilt_row=None)`` for each
    sample as it comes (``accel_row`` ordered as ``array.accel_columns``, each
    axis in its sensor's own frame); ``flush()`` at the end. ``rate_hz`` is the
    nominal sample rate, used to detect gaps. Tilt rows are accepted for
    interface symmetry but not used (the state has no orientation). Usage::

        smoother = FixedLagSmoother(array, ModelGroups.defaults(), lag_s=0.2, rate_hz=500.0)
        for timestamp_ns, accel_row in stream:
            update = smoother.push(timestamp_ns, accel_row)
            for state in update.smoothed:      # final, lag_s behind
                use(state.omega_b_radps)
            newest = update.filtered           # now, from the data so far
        remaining = smoother.flush()

    Solver settings: ``relinearize_threshold`` [rad/s] and ``relinearize_skip``
    (iSAM2), ``marginalise_every_s`` (size of the marginalisation blocks),
    ``warmup_s`` (data gathered to initialise a segment), ``gap_factor``,
    ``fast_measurement``, ``tune_window_s`` (see :class:`FixedLagEstimator`).

    With ``options.tuning.tune_process_noise`` and no explicit density (module
    docstring) the first ``tune_window_s`` of data are buffered (``push``
    returns nothing meanwhile), the process noise is chosen on them by the
    batch smoother's tuner, and the push that fills the buffer returns all
    buffered states that have reached the lag. :attr:`tuning` then holds the
    selection and :attr:`options` the option groups in use.

    Its state, in parts each with one job: ``config`` (:class:`StreamConfig`, fixed: lag, rate, gaps, engine),
    ``_segment`` (:class:`Segment`: the window engine, its states and raw samples, the newest state; a new one at
    each gap, clock reset or flush), ``_hold`` (:class:`StartHold`: the rows held at a segment's start and how
    each start was decided), ``_choice`` (:class:`ChoiceState`: the model in use and how it is chosen on the
    stream), ``_clock`` (:class:`StreamClock`: the stream's time and the samples dropped), ``_signs`` (the
    streaming sign chain of ω, :class:`~gfimu.smoother.stream.model_choice.StreamSignChain`) and ``_sigma``
    (:class:`SigmaRescale`, when σ is scaled by the misfit of the readings). The attributes tests, tools and
    sessions read (:attr:`lag_s`, :attr:`options`, :attr:`model`, :attr:`models`, :attr:`starts`, ...) are
    read-only views of these parts.
    """

    def __init__(self, array: SensorArray, options: ModelGroups | None = None, lag_s: float = 0.2,
                 rate_hz: float = 500.0, *, relinearize_threshold: float = 0.1, relinearize_skip: int = 10,
                 marginalise_every_s: float | None = None, warmup_s: float = 0.2, gap_factor: float = 1.5,
                 fast_measurement: bool = True, tune_window_s: float = 3.0, engine: str = "numpy",
                 clock_reset_s: float = 1.0, auto_model: bool = False, retune_every_s: float = 10.0,
                 model_window_s: float = 30.0, branches: bool = True, hold_max_s: float = 4.0,
                 choice_delay_s: float = CHOICE_DELAY_S) -> None:
        options = options or ModelGroups.defaults()
        if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
            raise InputError(f"fixed-lag smoother: rate_hz must be a positive number, got {rate_hz!r}")
        if marginalise_every_s is None:  # about 125 updates per block, at most 0.25 s
            marginalise_every_s = min(0.25, 125.0 / rate_hz)
        # the stream options, each checked by its declaration (gfimu.smoother.model.option_groups.StreamOptions)
        check_declared(StreamOptions(lag_s=lag_s, relinearize_threshold=relinearize_threshold,
                                     relinearize_skip=relinearize_skip, marginalise_every_s=marginalise_every_s,
                                     warmup_s=warmup_s, hold_max_s=hold_max_s, gap_factor=gap_factor,
                                     fast_measurement=fast_measurement, engine=engine, tune_window_s=tune_window_s,
                                     retune_every_s=retune_every_s, model_window_s=model_window_s),
                       "fixed-lag smoother")
        if not (isinstance(clock_reset_s, (int, float)) and math.isfinite(clock_reset_s) and clock_reset_s >= 0):
            raise InputError(f"fixed-lag smoother: clock_reset_s must be >= 0, got {clock_reset_s!r}")
        reason = fixed_lag_reason(array, options)
        if reason:
            raise InputError(reason)
        if not (isinstance(choice_delay_s, (int, float)) and math.isfinite(choice_delay_s) and choice_delay_s > 0):
            raise InputError(f"fixed-lag smoother: choice_delay_s must be a positive number, got {choice_delay_s!r}")
        self.array = array
        rate_hz = float(rate_hz)
        self.config = StreamConfig(float(lag_s), rate_hz, float(gap_factor), max(2, int(round(warmup_s * rate_hz))),
                                   engine, GtsamSettings(float(relinearize_threshold), int(relinearize_skip),
                                                         max(float(marginalise_every_s), 2.0 / rate_hz)),
                                   bool(branches), bool(fast_measurement), bool(options.solve.compute_sigma))
        given = options
        array_model = model.ArrayModel(array, given, fast_measurement)
        tune = tunes_process_noise(given.model, given.tuning)
        auto = bool(auto_model) and engine == "numpy" and auto_model_reason(array, given.batch_model) is None
        tune_n = stretch_samples(tune_window_s, rate_hz)  # (cut above STRETCH_RATE_HZ)
        rules = ChoiceRules(
            given, tune, auto, int(round(retune_every_s * 1e9)), tune_n,
            # a shorter stretch (before a gap or the end) is tuned on only if it holds this much
            min(tune_n, max(2, int(round(1.0 * rate_hz)))),
            max(1, int(math.ceil(choice_delay_s * rate_hz))), MLEstimator(workers=1) if auto else None)
        self._choice = ChoiceState(rules, tune or auto,
                                   History(stretch_samples(max(model_window_s, tune_window_s), rate_hz), array.n_axes),
                                   LocalDensity(array), given, array_model)
        self._signs = StreamSignChain(int(math.ceil(self.config.lag_s * rate_hz)) + 2, plane_normal(np.concatenate(
            [np.atleast_2d(acc.position_m) for acc in array.accelerometers])))
        self._squares_row = stream_model.squares_row(array)  # 2|ω|² of a sample's readings (slow_turn's test)
        self._clock = StreamClock(float(clock_reset_s))
        self._worker = WorkerSlot()
        self._ahead = AheadOfChoice()
        self._solver = WorkerSlot()
        self.closed = False
        self._sigma = (SigmaRescale(array) if self.config.compute_sigma and calibrates_stream(array,
                                                                                             given)
                       else None)
        # the held start's longest span [s] (cut above STRETCH_RATE_HZ; the numpy engine only)
        self._hold = StartHold(float(hold_max_s) * min(1.0, STRETCH_RATE_HZ / rate_hz) if engine == "numpy" else 0.0,
                               int(round(max(self.config.lag_s, 0.5) * 1e9)))
        # numba loaded with the smoother (in the background while a command reads its log,
        # gfimu.smoother.preload): the batch solves of the stream (its first model's stretch, the held start)
        # take the compiled kernels wherever numba is loaded (gfimu.smoother.model.groups), and so take them
        # from the first one on, whatever was imported before: the same rows pushed one by one or in blocks
        import numba  # noqa: F401

        self._start_segment()

    @classmethod
    def of_groups(cls, array: SensorArray, options: ModelGroups | None, stream: StreamOptions, rate_hz: float,
                  **settings) -> FixedLagSmoother:
        """A smoother of the model's option groups ``options`` and the stream group ``stream`` (:class:`StreamOptions`: its
        lag, window engine, warm-up, hold, gaps and model updates; ``screen_readings`` is the session's, not the
        smoother's); ``settings`` ( ``lag_s``, ``auto_model``, ``clock_reset_s``, ...) override or add to them."""
        taken = {name: getattr(stream, name) for name in GROUPS["stream"] if name != "screen_readings"}
        return cls(array, options, rate_hz=rate_hz, **{**taken, **settings})

    # --- public API ---------------------------------------------------------
    lag_s = delegated("config", "lag_s", "A state is given smoothed this long [s] after its sample.")
    rate_hz = delegated("config", "rate_hz", "The nominal sample rate [Hz].")
    gap_factor = delegated("config", "gap_factor", "A step longer than this many nominal steps ends the segment.")
    engine = delegated("config", "engine", "The window engine (:data:`ENGINES`).")
    fast_measurement = delegated("config", "fast_measurement", "The measurement's fast kernels are used.")
    compute_sigma = delegated("config", "compute_sigma", "Every state given out carries its σ.")
    options = delegated("_choice", "groups", "The option groups of the model in use (:class:`ModelGroups`: model, "
                        "batch model, tuning).")
    model = delegated("_choice", "model", "The model in use (:class:`~gfimu.smoother.stream.array_model.ArrayModel`).")
    stream_model = delegated("_choice", "stream_model", "The model chosen on the stream "
                             "(:mod:`gfimu.smoother.stream.model_choice`), once chosen.")
    models = delegated("_choice", "models", "Every model chosen so far, oldest first.")
    tuning = delegated("_choice", "tuning", "The newest process-noise selection "
                       "(:class:`gfimu.smoother.tuning.evidence.Tuning`), once chosen from the data.")
    hold_max_s = delegated("_hold", "max_s", "The held start's longest span [s] (0: rows are never held; cut above "
                           ":data:`STRETCH_RATE_HZ`).")
    starts = delegated("_hold", "starts", """How the start of each segment was decided (:meth:`_release_start`): ``held_s``
        (how long its first rows were held), ``evidence_nats`` (the log-likelihood ratio of its branch of ω over the
        next best; inf: no other minimum), ``agreement_chi2``, ``moved_chi2``, ``open`` (True: released at
        ``hold_max_s`` or at the segment's end without reaching :data:`SIGN_DECISION_NATS`).""")
    still_starts = delegated("_hold", "still_starts", "The std [rad/s] of the prior ω = 0 of each segment that started "
                             "still (:meth:`_still_start`).")

    @property
    def n_keys(self) -> int:
        """Number of variables currently held by the window solver (three per state)."""
        return 0 if self._segment.engine is None else self._segment.engine.n_keys

    @property
    def n_factor_slots(self) -> int:
        """Number of factor slots in gtsam's graph (freed slots are reused); with the numpy
        engine, the number of preallocated window slots."""
        return 0 if self._segment.engine is None else self._segment.engine.n_slots

    @property
    def window_length(self) -> int:
        """Number of samples in the current window (Python side)."""
        return len(self._segment.window) + len(self._segment.warmup)

    @property
    def choice_waits(self) -> list[float]:
        """Seconds the stream waited for a model chosen off the stream that was not ready at its sample."""
        return self._choice.waits

    @property
    def counts(self) -> dict:
        """Dropped samples and clock resets so far: ``{"duplicates", "out_of_order", "clock_resets"}``."""
        c = self._clock
        return {"duplicates": c.duplicates, "out_of_order": c.out_of_order, "clock_resets": c.clock_resets}

    @property
    def n_duplicates(self) -> int:
        """Samples dropped because their timestamp equals the previous one."""
        return self._clock.duplicates

    @property
    def n_out_of_order(self) -> int:
        """Samples dropped because they are earlier than the previous one (by at most ``clock_reset_s``)."""
        return self._clock.out_of_order

    @property
    def n_clock_resets(self) -> int:
        """Times the clock went back by more than ``clock_reset_s`` (each restarted the window)."""
        return self._clock.clock_resets

    @property
    def clock_reset_s(self) -> float:
        """Time going back by more than this [s] restarts the window (less: the sample is dropped)."""
        return self._clock.reset_s

    def push(self, timestamp_ns: int, accel_row, gyro_row=None, tilt_row=None) -> FixedLagUpdate:
        """Add one sample; return the states that reached the lag and the newest one.

        While the tuning stretch is being gathered nothing comes out (``filtered``
        is None); the push that completes it returns every buffered state that has
        reached the lag.

        Time going backwards (defined, never an error): a sample with the previous
        sample's timestamp is dropped (``dropped="duplicate"``, counted in
        :attr:`n_duplicates`); one earlier than the previous sample by at most
        ``clock_reset_s`` is dropped (``"out-of-order"``, :attr:`n_out_of_order`);
        one earlier by more is a clock reset: a :class:`ClockResetWarning`, the
        window is flushed (its states come out in ``smoothed``) and a new segment
        starts with this sample (:attr:`n_clock_resets`). After :meth:`close`,
        :class:`FixedLagSmootherClosed`."""
        if self.closed:
            raise FixedLagSmootherClosed("fixed-lag smoother: push after close(); create a new smoother to start "
                                         "another stream")
        t_ns = int(timestamp_ns)
        y = np.asarray(accel_row, dtype=float)
        if y.ndim != 1:
            y = y.reshape(-1)
        array = self.array
        if y.shape[0] != array.n_axes:
            raise InputError(f"sample at {t_ns} ns: accel_row has {y.size} values, the array has {array.n_axes} axes")
        # a finite sum of squares: every value finite (the cheapest of numpy's reductions on a row)
        if not math.isfinite(y.dot(y)) and not np.all(np.isfinite(y)):
            bad = [array.accel_columns[i] for i in np.nonzero(~np.isfinite(y))[0]]
            raise DataError(f"sample at {t_ns} ns: non-finite accelerometer reading(s) in {bad}")
        gyro = None
        if gyro_row is not None and array.gyroscope is not None and self.options.model.use_gyro:
            gyro = np.asarray(gyro_row, dtype=float).reshape(-1)
            if gyro.shape != (3,):
                raise InputError(f"sample at {t_ns} ns: gyro_row must have 3 values, got {gyro.size}")
            if not np.all(np.isfinite(gyro)):
                gyro = None  # a missing gyro sample: the accelerometers alone carry on
        smoothed: list[StateEstimate] = []
        clock = self._clock
        if clock.last_ns is not None:
            dt_ns = t_ns - clock.last_ns
            if dt_ns == 0:
                clock.duplicates += 1
                return FixedLagUpdate((), None, "duplicate")
            if 0 > dt_ns >= -clock.reset_s * 1e9:
                clock.out_of_order += 1
                return FixedLagUpdate((), None, "out-of-order")
            if dt_ns < 0:
                clock.clock_resets += 1
                warnings.warn(f"fixed-lag smoother: the clock went back by {-dt_ns * 1e-9:.6f} s (from "
                              f"{clock.last_ns} to {t_ns} ns, more than clock_reset_s = {self.clock_reset_s:g} s); the window was "
                              "flushed and a new segment starts", ClockResetWarning, stacklevel=2)
                self._settle_choice()
                smoothed.extend(self._end_segment())
                clock.origin_ns = t_ns
            elif dt_ns > self.config.gap_ns:
                self._settle_choice()
                smoothed.extend(self._end_segment())
        else:
            clock.origin_ns = t_ns
        clock.last_ns = t_ns
        choice = self._choice
        choice.accepted += 1
        if choice.pending is not None:
            self._swap_choice()
        sample = (t_ns, y, gyro)
        if self._sigma is not None:
            self._sigma.readings[t_ns] = y
        if choice.first_pending:
            choice.buffer.append(sample)
            if len(choice.buffer) < choice.rules.tune_n:
                return FixedLagUpdate(self._scaled(smoothed), None)
            smoothed.extend(self._tune_and_replay())
        else:
            smoothed.extend(self._process(sample))
        seg = self._segment
        if seg.engine is None:
            return FixedLagUpdate(self._scaled(smoothed), None)
        if seg.prev is not None and seg.window[-1][0] == seg.k:  # the newest state's values, kept already
            return FixedLagUpdate(self._scaled(smoothed), None, newest=seg.prev)
        return FixedLagUpdate(self._scaled(smoothed), self._read(seg.window[-1]))

    def _scaled(self, states) -> tuple[StateEstimate, ...]:
        """``states`` with σ scaled by the misfit of the readings emitted so far (:mod:`gfimu.smoother.solve.sigma_scale`)."""
        return tuple(states) if self._sigma is None else self._sigma.scaled(states, self.model)

    def _process(self, sample) -> list[StateEstimate]:
        """One sample into the current segment (no tuning, no gap check); the states due."""
        self._observe(sample)
        seg = self._segment
        if seg.engine is None:
            seg.warmup.append(sample)
            if len(seg.warmup) < self.config.warmup_n:
                return []
            self._initialise()
        else:
            self._add_sample(sample)
        return self._emit_due()

    def _tune_and_replay(self, final: bool = False) -> list[StateEstimate]:
        """Choose the process noise on the buffered stretch, then smooth the buffer with it.

        The states of the stretch that come out now are the batch smoother's
        solution on the whole stretch (they are emitted at its end, so all of it
        is past data for them); the buffer is also streamed through the
        fixed-lag smoother, which carries that information on.

        ``final``: the stretch ends early (a gap or the end of the stream); it is
        tuned on only if it holds at least ``min(tune_window_s, 1 s)`` of samples,
        otherwise it is smoothed with the given densities and the tuning waits
        for the next segment."""
        samples, self._choice.buffer = self._choice.buffer, []
        batch = None
        if not final or len(samples) >= self._choice.rules.tune_min_n:
            batch = self._choose(samples, first=True)
            self._choice.first_pending = False
        if batch is not None and self._sigma is not None:  # σ's common gain from the stretch's batch solution, at once
            self._sigma.scale.gain.seed(np.array([b.timestamp_ns for b in batch]) * 1e-9, np.array(
                [np.concatenate([b.omega_b_radps, b.omega_dot_b_radps2, b.specific_force_b_mps2]) for b in batch]))
        if batch is not None and final:  # the segment ends here: the batch solution is all there is to say
            return batch
        out = []
        # with the stretch's batch solution, the rows held while it is streamed are released from it
        # (:meth:`_start_from_batch`: the batch smoother saw the whole stretch): no evidence is weighed meanwhile
        self._hold.waiting_for_batch = batch is not None
        try:
            for sample in samples:
                out.extend(self._process(sample))
        finally:
            self._hold.waiting_for_batch = False
        if batch is not None:
            out = batch[:len(out) + self._start_from_batch(batch)]
        return out

    def _stretch_log(self, stretch: Stretch, source: str = "fixed-lag tuning stretch") -> Log:
        """The samples of ``stretch`` as a log (with its gyro readings where every sample has one and the
        options use them)."""
        gyro = stretch.gyro if self.array.gyroscope is not None and self.options.model.use_gyro else None
        return Log(self.array, stretch.times_ns, stretch.accel, gyro_b_radps=gyro, source=source)

    def _choose(self, samples=None, first: bool = False, outgrown: bool = False):
        """Choose the model and go on with it (:mod:`gfimu.smoother.stream.model_choice`). The ``first``
        choice of a segment is made at once on ``samples`` ((t_ns, accel, gyro) tuples, oldest first, the
        first stretch) and, for a consistent stretch whose process noise is tuned, also returns the batch
        smoother's states of the stretch (else None). A later choice is made on the history, off the stream
        (in a process of its own, :class:`~.choice_worker.ForkedChoice`, else in a thread on a copy of it,
        :class:`PendingChoice`) and used :data:`CHOICE_DELAY_S` of samples later (:meth:`_swap_choice`); one
        asked for while another is pending is not made."""
        if first:
            self._settle_choice()
            chosen, batch = self._chosen_model(Stretch.of_samples(samples), self.stream_model, first=True,
                                               outgrown=outgrown)
            self._use(chosen)
            if outgrown:
                self._replay_window()
            return batch
        if self._choice.pending is not None:
            return None
        history, previous = self._choice.history, self.stream_model
        swap_at = self._choice.accepted + self._choice.rules.delay_n
        process = self._choice_process()
        if process is not None:  # in a process of its own (:mod:`.choice_worker`), which keeps a history of its own
            ahead = self._ahead
            since, sent = history.since(), self._samples_ahead(history)
            if (not outgrown and ahead.model is not None and previous is ahead.model and ahead.sent is not None
                    and same_samples(since, ahead.sent)):
                request = ("ahead", sent)  # the choice the process made ahead, on these very samples
                ahead.used += 1
            else:
                request = ("choose", since, previous, outgrown, sent)
            ahead.sent, ahead.model = sent, None
            self._choice.pending = ForkedChoice(process, request, lambda answer: _taken_back(answer, previous),
                                                swap_at, outgrown)
            return None
        stretch = history.stretch()

        def kept(chosen):  # (in the stream's thread: the rows the choice computed kept for the next)
            history.keep_rows(stretch)
            return chosen

        self._choice.pending = PendingChoice(lambda: self._chosen_model(stretch, previous, outgrown=outgrown)[0],
                                             swap_at, outgrown, kept)
        return None

    def _choice_process(self) -> ChoiceProcess | None:
        """The process the later choices are made in, forked at the first (None where none may be)."""
        if self._worker.tried:
            return self._worker.process
        self._worker.tried = True
        self._worker.process = ChoiceProcess.start(self._chosen_in_process, self._work_ahead)
        if self._worker.process is not None:
            self._worker.finalizer = weakref.finalize(self, self._worker.process.close)
        return self._worker.process

    def _solved_from(self, problem, starts: list) -> list:
        """``solve(problem, x0)`` from each start, the later half in a forked process of its own (forked at
        the first call, kept for the stream's later ones) while this one solves the first half: the same
        solutions as one after the other, in the order of ``starts``. (Threads would run them one after the
        other: the banded solver's many small numpy calls hold the interpreter's lock.) One after the other
        here where no process may be forked or the machine has one core."""
        slot = self._solver
        if not slot.tried:
            slot.tried = True
            if cpu_count() > 1:
                slot.process = ChoiceProcess.start(_solved_each)
                if slot.process is not None:
                    slot.finalizer = weakref.finalize(self, slot.process.close)
        if slot.process is None or len(starts) < 2:
            return _solved_each((problem, starts))
        k = (len(starts) + 1) // 2
        slot.process.submit((problem, starts[k:]))
        return _solved_each((problem, starts[:k])) + slot.process.result()

    def look_ahead(self, timestamps_ns, accel, gyro=None) -> None:
        """The samples this smoother will be pushed, in order (a log's times (n,), readings (n, axes) and gyro
        readings (n, 3) or None): the choice's process then makes each scheduled model choice while it waits
        for the request (:class:`AheadOfChoice`), and the stream waits for none that was made ahead. The
        rows are the same: a choice made ahead is used only when the samples the stream took are those it
        was made on, bit for bit, and nothing else asked for a choice meanwhile."""
        self._ahead.upcoming = (np.asarray(timestamps_ns, dtype=np.int64), np.asarray(accel, dtype=float),
                                       None if gyro is None else np.asarray(gyro, dtype=float))

    def _samples_ahead(self, history: History) -> tuple | None:
        """The samples to come up to the next scheduled choice (the first ``retune_every_s`` after the newest
        one the history holds), as the history will send them (:meth:`~.history.History.ahead`); None where
        they are not known."""
        upcoming = self._ahead.upcoming
        if upcoming is None or not history.total:
            return None
        times, accel, gyro = upcoming
        t_end = int(history.times_ns[(history.total - 1) % history.capacity])
        p = int(np.searchsorted(times, t_end))
        q = int(np.searchsorted(times, t_end + self._choice.rules.retune_ns))
        if p >= len(times) or times[p] != t_end or q >= len(times):
            return None
        cut = slice(p + 1, q + 1)
        g = np.zeros((q - p, 3)) if gyro is None else gyro[cut]
        has_gyro = np.zeros(q - p, dtype=bool) if gyro is None else np.isfinite(g).all(axis=1)
        return history.ahead(times[cut], accel[cut], g, has_gyro)

    def _chosen_in_process(self, request):
        """In the choice's process: the model and whether it kept the previous one's tuning. A ``"choose"``
        request carries the samples since the last (:meth:`~.history.History.since`), taken into the process's
        own history (its copy of the stream's, as it was forked, kept up since), then :meth:`_chosen_model`
        runs on it; an ``"ahead"`` one asks for the choice the process made ahead (:meth:`_work_ahead`) on the
        samples the last request sent, the same numbers (made now where it was not). Either may send the
        samples up to the next scheduled choice, to work ahead on."""
        ahead = self._ahead
        if request[0] == "ahead":
            sent = request[1]
            (samples, previous), guess = ahead.start, ahead.guess
            if guess is None:
                chosen = self._chosen_after(self._choice.history, samples, previous)
            else:
                self._choice.history, chosen, error, raised = guess
                for message, category in raised:
                    warnings.warn(message, category, stacklevel=2)
                if error is not None:
                    raise error
        else:
            _, since, previous, outgrown, sent = request
            chosen = self._chosen_after(self._choice.history, since, previous, outgrown)
        kept = previous is not None and chosen.tuning is not None and chosen.tuning is previous.tuning
        ahead.start, ahead.guess = (None if sent is None else (sent, chosen)), None
        return chosen, kept

    def _work_ahead(self) -> None:
        """In the choice's process, between requests: the next scheduled choice made on the samples the last
        request sent and the model it gave (:class:`AheadOfChoice`), on a copy of the history, kept for an
        ``"ahead"`` request."""
        ahead = self._ahead
        if ahead.start is None or ahead.guess is not None:
            return
        samples, previous = ahead.start
        history = self._choice.history.copy()
        chosen = error = None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                chosen = self._chosen_after(history, samples, previous)
            except Exception as exc:  # noqa: BLE001 - raised when the choice is asked for
                error = exc
        ahead.guess = (history, chosen, error, [(str(w.message), w.category) for w in caught])

    def _chosen_after(self, history: History, samples: tuple, previous, outgrown: bool = False):
        """``samples`` (:meth:`~.history.History.since`'s form) taken into ``history``, then :meth:`_chosen_model`
        on it, the ML rows it computed kept there: the model chosen."""
        history.extend(*samples)
        stretch = history.stretch()
        chosen = self._chosen_model(stretch, previous, outgrown=outgrown)[0]
        history.keep_rows(stretch)
        return chosen

    def _swap_choice(self, final: bool = False) -> None:
        """The pending choice's model put in use when its sample has come (waiting for it when it is not
        ready: the wait is counted in :attr:`choice_waits`); ``final``: at the end of a segment, whatever the
        sample (the window is flushed: not solved again)."""
        pending = self._choice.pending
        if pending is None or not (final or self._choice.accepted >= pending.swap_at):
            return
        self._choice.pending = None
        late = not pending.done
        chosen = pending.result()
        if isinstance(pending, ForkedChoice):
            self._ahead.model = chosen  # (the model the process's work ahead starts from)
        if late:
            self._choice.waits.append(pending.waited_s)
        self._use(chosen)
        if pending.outgrown and not final:
            self._replay_window()

    def _settle_choice(self) -> None:
        """A pending choice put in use now (the segment ends, or a first choice is made)."""
        self._swap_choice(final=True)

    def _chosen_model(self, stretch: Stretch, previous, first: bool = False, outgrown: bool = False):
        """(the model chosen on ``stretch`` after ``previous``, the batch states of the stretch or None): the
        choice itself, reading nothing of the stream that changes while it runs (the ML rows it computes
        are written into ``stretch``).

        A consistent stretch keeps the Gaussian model in use when that was chosen on motion and the
        motion has not outgrown it (the tuner is the costly part of a choice); otherwise the tuner
        runs on the newest ``tune_window_s`` of the stretch."""
        rules = self._choice.rules
        part = self._stretch_log(stretch)
        ml = self._ml_motion(stretch, part) if rules.auto else None
        check = stream_model.check_of(part, ml)
        batch = None
        base = rules.given if check is None else rules.given._replace(model=measured_noise_options(rules.given.model, check))
        t_end = int(part.timestamps_ns[-1])
        if check is not None and not check.consistent:
            chosen = stream_model.robust(part, rules.given, check, ml, rules.tune, previous)
        elif not rules.tune or (check is not None and check.constant):
            chosen = stream_model.StreamModel(base, 1.0, check, None, t_end, len(part))
        elif (not first and not outgrown and previous is not None and not previous.robust and previous.moving
              and previous.tuning is not None):
            chosen = replace(previous, check=check, chosen_at_ns=t_end, samples=len(part))
        elif ml is not None and stream_model.is_still(*(newest := self._newest(part, ml)), check):
            # a still stretch tells nothing of how the body will move: the motion seen before, else the
            # level of a turn too slow for each sample (:meth:`_slow_motion`), else the densities as given;
            # the next motion asks for a choice at once
            if previous is not None and not previous.robust and previous.moving:
                chosen = replace(previous, check=check, chosen_at_ns=t_end, samples=len(part))
            else:
                chosen = (self._slow_motion(newest[0], base, check, t_end)
                          or stream_model.StreamModel(base, 1.0, check, None, t_end, len(part), moving=False))
        else:
            n = rules.tune_n
            span = part if len(part) <= n else part.select(slice(len(part) - n, None))
            tuning, problem, x0 = self._tuned(span, base)
            chosen = stream_model.from_tuning(tuning, base._replace(model=problem.model, batch_model=problem.batch_model),
                                              check, span)
            chosen = replace(chosen, chosen_at_ns=t_end, moving=True)
            if first:
                batch = self._batch_states(span, problem, x0)
        if chosen.sign_scale_radps is None and ml is not None:
            chosen = replace(chosen, sign_scale_radps=stream_model.sign_scale(part, ml))
        return chosen, batch

    def _slow_motion(self, span: Log, base: ModelGroups, check, t_end: int):
        """The model of a stretch that looks still sample by sample but whose mean |ω|² tells a turn from rest
        (:func:`~.model_choice.slow_turn`: a turn too slow for each sample to show, as a car's yaw): the common
        jerk density and the specific-force density tuned on ``span`` (its newest ``tune_window_s``), on every
        axis alike and without oscillators (3 s of slow motion fix a level, not a shape per axis: on a slow random
        rotation, the per-axis factors and the 0.7-0.8 Hz oscillators tuned on its first 3 s doubled the
        stream's error); None for a body at rest. It counts as a still choice (``moving`` False): the next
        choice is made afresh. Without it the stream keeps the densities as given, 100 times looser than a
        car's yaw, and its ω wanders through zero onto the other branch."""
        if not stream_model.turning(span.accel_mps2, self._squares_row):
            return None
        tuning, _, _ = self._tuned(span, base)
        level = replace(tuning, axis_factors=(1.0, 1.0, 1.0), axis_frequencies_hz=(0.0, 0.0, 0.0),
                        axis_frequency_std_hz=(0.0, 0.0, 0.0), axis_amplitude_radps=(0.0, 0.0, 0.0))
        chosen = stream_model.from_tuning(level, level.apply(base), check, span)
        return replace(chosen, chosen_at_ns=t_end, moving=False)

    def _replay_window(self) -> None:
        """The window solved again from its raw samples with the model just chosen because the motion
        outgrew the one before: its states, not yet emitted, were filtered with a model the motion
        had outgrown (the first second of a motion that speeds up), and are emitted only when they
        reach the lag. The oldest state starts again from its readings, linearised at its current
        value (so it keeps its branch), the others from the prediction as they came; a window that
        fails to solve again is kept as it was. Where the engine replays (``replays``: the numpy
        engine; gtsam's keeps its states)."""
        seg = self._segment
        if seg.engine is None or not seg.engine.replays or len(seg.window) < 2:
            return
        entries, raws = list(seg.window), list(seg.raw)
        k0 = entries[0][0]
        start = seg.engine.mean(k0)
        engine = self._new_smoother()
        try:
            t, y, g = raws[0]
            engine.begin(k0, t, y, g, start=start, extra=self.model.sample_terms(t, y, g))
            for j in range(1, len(entries)):
                k, t = entries[j]
                _, y, g = raws[j]
                step = self._step(raws[j - 1], raws[j], engine.mean(entries[j - 1][0]), self._choice.jerk_factor)
                engine.advance(k, step, t, y, g, extra=self.model.sample_terms(t, y, g))
            engine.commit()
        except FilterFailure:
            return
        self._go_on_with(engine)

    def _go_on_with(self, engine) -> None:
        """The window solved again (``engine``) replaces the stream's: the sign chain starts again from it."""
        self._segment.engine = engine
        self._signs.reset()
        self._remember_newest()

    def _newest(self, part: Log, ml):
        """The newest ``tune_window_s`` of ``part`` and of its ML estimate ``ml``."""
        if len(part) <= self._choice.rules.tune_n:
            return part, ml
        sl = slice(len(part) - self._choice.rules.tune_n, None)
        return part.select(sl), ml.select(sl)

    def _use(self, chosen: StreamModel) -> None:
        self._choice.use(chosen, self.array, self.config.fast_measurement)
        if self._segment.engine is not None:
            self._segment.engine.set_model(self.model)

    def _ml_motion(self, stretch: Stretch, part: Log):
        """The per-sample ML estimate of ``stretch`` (``part`` its log), each sample's computed once: the
        rows it has already, the others computed here and written into it (kept in the history:
        :meth:`~.history.History.keep_rows`)."""
        todo = np.nonzero(~stretch.has_row)[0]
        if todo.size:
            fresh = self._choice.rules.ml.estimate_motion(part.select(todo))
            stretch.rows[todo] = np.hstack([fresh.omega_b_radps, fresh.omega_dot_b_radps2, fresh.specific_force_b_mps2])
            stretch.has_row[todo] = True
        x = stretch.rows
        return Motion(part.timestamps_ns, omega_b_radps=x[:, 0:3], omega_dot_b_radps2=x[:, 3:6],
                      specific_force_b_mps2=x[:, 6:9])

    def _tuned(self, part: Log, given: ModelGroups | None = None):
        """The batch smoother's process-noise selection on ``part`` from the model groups ``given`` (default: the
        smoother's): (Tuning, problem, initial states)."""
        tunings: list = []
        given = given or self._choice.rules.given
        problem, x0 = tuned_problem(part, given._replace(tuning=replace(given.tuning, tune_process_noise=True)),
                                    tunings)
        return tunings[-1], problem, x0

    def _batch_states(self, part: Log, problem, x0) -> list[StateEstimate]:
        """The batch smoother's states of ``part`` with ``problem``."""
        res = solve(problem, x0, None, compute_sigma=self.config.compute_sigma)
        X = res.states
        sd = np.sqrt(np.einsum("nii->ni", res.covariance)) if self.config.compute_sigma else None
        return [StateEstimate(int(t), X[j, OMEGA].copy(), X[j, OMEGA_DOT].copy(), X[j, SPECIFIC_FORCE].copy(),
                              *((None,) * 3 if sd is None else (sd[j, OMEGA], sd[j, OMEGA_DOT], sd[j, SPECIFIC_FORCE])))
                for j, t in enumerate(part.timestamps_ns)]

    def tune(self, samples) -> tuple:
        """The batch smoother's process-noise selection on ``samples`` ((t_ns, accel, gyro) tuples):
        (:class:`gfimu.smoother.tuning.evidence.Tuning`, the model groups carrying it)."""
        tuning, problem, _ = self._tuned(self._stretch_log(Stretch.of_samples(samples)))
        given = self._choice.rules.given
        return tuning, problem.options._replace(model=tuning.for_stream(problem.model),
                                                tuning=replace(given.tuning, tune_process_noise=False))

    def _observe(self, sample) -> None:
        """Keep ``sample`` in the history the model is chosen on; the local motion density it shows;
        choose again when due (every ``retune_every_s``) or when the motion outgrows the model."""
        taken, local = self._observe_data(sample)
        if taken:
            self._observe_decide(sample[0], local)

    def _observe_data(self, sample) -> tuple[bool, float | None]:
        """:meth:`_observe`'s data: ``sample`` into the history, the local motion density and the jerk factor it
        gives (robust model). Returns (whether the stream observes: it does once a model is chosen, when it
        tunes or checks the model; the local density or None)."""
        choice = self._choice
        chosen = choice.stream_model
        if not (choice.rules.auto or choice.rules.tune) or chosen is None:
            return False, None
        t_ns, y, gyro = sample
        choice.history.append(t_ns, y, gyro)
        robust = chosen.robust
        if robust:
            c = chosen.check
            prev = self._segment.prev
            w = None if prev is None else prev[1]  # (|ω|² summed in order: the block's kernel takes it so)
            w2 = 0.0 if w is None else float(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
            var = c.noise_floor_mps2 ** 2 + c.noise_slope_mps2_per_radps ** 2 * w2
        else:
            var = choice.model.noise.mean_accel_var_mps2
        local = choice.local.push(t_ns, y, var)
        choice.jerk_factor = 1.0
        if local is not None and robust:  # the batch smoother's local density (robust model)
            choice.jerk_factor = min(1.0, local / chosen.groups.model.omega_dot_random_walk_radps2_per_sqrt_s)
        return True, local

    def _observe_decide(self, t_ns: int, local: float | None) -> None:
        """:meth:`_observe`'s decision at the sample at ``t_ns`` whose local density is ``local``: a model choice
        when due, when the motion outgrew the model, or when a slow turn began."""
        choice = self._choice
        chosen = choice.stream_model
        q = chosen.groups.model.omega_dot_random_walk_radps2_per_sqrt_s
        due = t_ns - chosen.chosen_at_ns >= choice.rules.retune_ns
        # a model the body now outmoves (chosen on a still stretch, or on the first slow motion): choose
        # again at once (at most once a second), on the history that now holds the motion
        outgrown = (local is not None and choice.local.resolved and local > OUTGROWN_FACTOR * q
                    and t_ns - chosen.chosen_at_ns >= 1e9)
        # a turn too slow for each sample, begun under the densities as given: choose again at once (the
        # window goes on as it is: solved again from its newest states, a slow 3-D motion came out worse)
        turn = (not (due or outgrown) and not chosen.moving and chosen.tuning is None and not chosen.robust
                and self._turn_began(t_ns))
        if (due or outgrown or turn) and len(choice.history) >= choice.rules.tune_min_n:
            self._choose(outgrown=outgrown)

    def _turn_began(self, t_ns: int) -> bool:
        """Whether a turn too slow for each sample has begun under a model chosen on a still stretch with the
        densities as given: once a second, :func:`~.model_choice.slow_turn`'s test on the newest
        ``tune_window_s`` of the history. A turn that grows between two scheduled choices (10 s apart) is
        otherwise carried on the loose densities until the next one, on whichever branch of ω they wandered
        onto while the body crept."""
        choice = self._choice
        if t_ns - choice.turn_checked_ns < 1_000_000_000 or len(choice.history) < choice.rules.tune_min_n:
            return False
        choice.turn_checked_ns = t_ns
        return stream_model.turning(choice.history.newest_accel(choice.rules.tune_n), self._squares_row)

    def push_block(self, timestamps_ns: np.ndarray, accel: np.ndarray, start: int = 0, stop: int | None = None):
        """Samples ``start …`` (before ``stop``) of ``timestamps_ns`` (n,) and ``accel`` (n, axes) pushed as
        :meth:`push` takes them one by one (no gyroscope readings), as many as go on in one compiled call
        (:mod:`gfimu.smoother.stream.block`: the steady state of a segment) and at least one: returns (the next
        sample's index, the states that reached the lag, oldest first: :class:`~.states.StateRows` of a block and
        :class:`StateEstimate` of samples pushed one by one). The same states, to the last bit, as pushing each
        sample (``tests/test_stream_block.py``)."""
        from . import block

        times = np.ascontiguousarray(timestamps_ns, dtype=np.int64)
        rows = np.ascontiguousarray(accel, dtype=float)
        stop = len(times) if stop is None else int(stop)
        if not 0 <= start < stop <= len(times) or rows.shape != (len(times), self.array.n_axes):
            raise InputError(f"fixed-lag smoother: push_block needs 0 <= start < stop <= {len(times)} and readings of "
                             f"shape ({len(times)}, {self.array.n_axes}), got start {start}, stop {stop}, {rows.shape}")
        if not block.ready(self):
            return start + 1, list(self.push(int(times[start]), rows[start]).smoothed)
        return block.run(self, times, rows, int(start), stop)

    def flush(self) -> tuple[StateEstimate, ...]:
        """Emit every state still in the window (smoothed with the data so far) and reset.

        The next :meth:`push` starts a new segment with a fresh initialisation, at any
        timestamp (the stream's clock starts again). A tuning stretch still being
        gathered is tuned on (if long enough) and smoothed first.
        """
        if self.closed:
            raise FixedLagSmootherClosed("fixed-lag smoother: flush after close()")
        self._settle_choice()
        out = self._scaled(self._end_segment())
        self._clock.last_ns = None
        if self._sigma is not None:
            self._sigma.scale.reset()
        return out

    def end_choice_process(self) -> None:
        """End the process the later model choices are made in (:mod:`.choice_worker`), at the end of a
        stream: a choice after this is made in a thread."""
        self._settle_choice()
        self._end_processes()

    def _end_processes(self) -> None:
        """End the processes of the later model choices and of the held start's re-solves (a later one made in
        this process)."""
        self._worker.close()
        self._solver.close()

    def close(self) -> tuple[StateEstimate, ...]:
        """:meth:`flush`, then refuse any further push (closing twice returns nothing)."""
        if self.closed:
            return ()
        out = self.flush()
        self.closed = True
        self._choice.buffer = []
        self._end_processes()
        return out

    def __enter__(self) -> FixedLagSmoother:
        return self

    def __exit__(self, *exc) -> None:
        if not self.closed:
            self.closed = True
            self._choice.pending = None  # a choice still being made is not used
            self._end_processes()
            self._start_segment()

    def _end_segment(self) -> tuple[StateEstimate, ...]:
        """Every state of the current segment (and of a pending tuning stretch), and a fresh segment."""
        replayed = self._tune_and_replay(final=True) if self._choice.buffer else []
        if self._segment.engine is None and self._segment.warmup:
            self._initialise()
        if self._hold.deciding and self._segment.engine is not None and self._hold.held:
            replayed = list(replayed) + self._release_start(final=True)
        sigma = self.config.compute_sigma
        out = tuple(replayed) + tuple(self._read(entry, with_sigma=sigma) for entry in self._segment.window)
        self._start_segment()
        return out

    # --- internals ------------------------------------------------------------
    def _start_segment(self) -> None:
        self._segment = Segment()
        self._signs.reset()
        self._hold.begin_segment()

    def _new_smoother(self):
        """The window engine of a new segment (:data:`ENGINES`)."""
        if self.config.engine == "numpy":
            lag_n = int(math.ceil(self.config.lag_s * self.config.rate_hz * self.config.gap_factor)) + 4
            return WindowFilter(self.model, capacity=4 * lag_n, branches=self.config.branches)
        # Keys carry block-quantised timestamps, so gtsam marginalises one block of
        # states at a time (one re-elimination of the window per block rather than
        # per sample, which would also relinearise the window's factors). Every
        # state must be read at t + lag before its block goes: gtsam's lag is the
        # requested lag plus one block plus the longest step that is not a gap.
        margin_s = (self.config.gap_factor + 0.5) / self.config.rate_hz
        g = self.config.gtsam
        return GtsamWindow(self.model, self.config.lag_s + g.block_s + margin_s, self._stamp, g.relinearize_threshold,
                           g.relinearize_skip, g.factorization)

    def _time_s(self, t_ns: int) -> float:
        return (t_ns - self._clock.origin_ns) * 1e-9

    def _stamp(self, t_ns: int) -> float:
        """Timestamp given to gtsam: the start of the sample's marginalisation block."""
        block_s = self.config.gtsam.block_s
        return math.floor(self._time_s(t_ns) / block_s) * block_s

    def _initialise(self, omega_hint=None) -> None:
        """First states of a segment, from the batch smoother's sign-resolving initialiser.

        ``omega_hint`` (ω expected at the second-to-last warm-up sample) picks the
        sign of ω when re-initialising after a solver failure.

        A segment whose warm-up shows the body at rest (:meth:`_still_start`) starts from ω = 0 with a
        prior ω = 0 on its first state; its start is not held (the sign of ω is moot at ω = 0).
        """
        seg = self._segment
        part = self._stretch_log(Stretch.of_samples(seg.warmup), "fixed-lag warm-up")
        times_ns, accel, gyro = part.timestamps_ns, part.accel_mps2, part.gyro_b_radps
        if len(times_ns) >= 2:
            x0 = initial_estimate(part, self.options)  # 'sign-resolving' or 'ml'
        else:  # a lone sample before a gap or the end: ω from the gyro or 0, [f, ω̇] from the readings
            w = gyro[0] if gyro is not None else np.zeros(3)
            x0 = np.concatenate(self.model.predict(w, np.zeros(3), np.zeros(3), 0.0, accel[0]))[None]
        still_sigma = None  # std [rad/s] of a prior ω = 0 on the first state of a segment that starts still
        if omega_hint is None:
            still_sigma = self._still_start(times_ns, accel, gyro)
            if still_sigma is not None:
                x0[:, OMEGA] = 0.0
                self._hold.deciding = False
                self._hold.still_starts.append(still_sigma)
        if omega_hint is not None and len(x0) >= 2:
            if np.sum((x0[-2, OMEGA] + omega_hint) ** 2) < np.sum((x0[-2, OMEGA] - omega_hint) ** 2):
                x0[:, OMEGA] *= -1.0
        seg.engine = engine = self._new_smoother()
        t_ns = seg.warmup[0][0]
        try:
            for j, (t_ns, y, g) in enumerate(seg.warmup):
                seg.k += 1
                extra = self.model.sample_terms(t_ns, y, g)
                if j == 0:
                    engine.begin(seg.k, t_ns, y, g, start=x0[j], extra=extra)
                    if still_sigma is not None:
                        H = np.zeros((3, 9))
                        H[:, OMEGA] = np.eye(3) / still_sigma
                        engine.update_linear(H, np.zeros(3))
                else:
                    engine.advance(seg.k, self._step(seg.warmup[j - 1], (t_ns, y, g), x0[j - 1], 1.0), t_ns, y, g,
                                   extra=extra, start=x0[j])
                seg.window.append((seg.k, t_ns))
                seg.raw.append((t_ns, y, g))
            engine.commit()
        except FilterFailure as err:
            raise self._failure(t_ns, err) from err
        seg.warmup = []
        self._remember_newest()

    def _still_start(self, times_ns: np.ndarray, accel: np.ndarray, gyro) -> float | None:
        """The std [rad/s] of a prior ω = 0 on the segment's first state when its warm-up shows the body
        at rest (:func:`~gfimu.smoother.solve.initialise.still_start`, tested against the noise the model
        check measured on the stream, :attr:`ModelCheck.noise_floor_mps2`, shared among the axes as the
        model's noise is), else None: without a model check (nothing measured), on a log
        the check found inconsistent with a rigid body or constant, with a gyroscope (it measures ω),
        or with the gtsam engine."""
        check = None if self.stream_model is None else self.stream_model.check
        if self.config.engine != "numpy" or gyro is not None or check is None or not check.consistent or check.constant:
            return None
        sigma = np.asarray(self.model.accel_sigma_mps2, dtype=float)
        rms = math.sqrt(float(np.mean(sigma ** 2)))
        # the per-axis shape of the model's noise at the level the check measured on the stream
        sigma = sigma * (check.noise_floor_mps2 / rms) if rms > 0 else np.full(len(sigma), check.noise_floor_mps2)
        return still_start((times_ns - times_ns[0]) * 1e-9, accel, self.array.structure_matrix(), sigma)

    def _failure(self, t_ns: int, err: Exception, what: str = "failed") -> FixedLagSmootherError:
        return FixedLagSmootherError(f"fixed-lag smoother {what} at t = {self._time_s(t_ns):.6f} s after the stream "
                                     f"start ({t_ns} ns): {err}".strip())

    def _add_sample(self, sample) -> None:
        t_ns, y, gyro = sample
        seg = self._segment
        k_prev = seg.k
        seg.k += 1
        k = seg.k
        try:
            step = self._step(seg.prev_sample, sample, seg.prev_x, self._choice.jerk_factor)
            seg.engine.advance(k, step, t_ns, y, gyro, extra=self.model.sample_terms(t_ns, y, gyro), prev=seg.prev[1:])
            seg.engine.commit()
            x = self._follow_sign(k, t_ns)
        except FilterFailure as err:
            seg.k = k_prev
            self._recover(sample, self._failure(t_ns, err))
            return
        seg.window.append((k, t_ns))
        seg.raw.append(sample)
        self._remember_newest(x)

    def _step(self, previous, sample, x0: np.ndarray, motion_factor: float):
        """The step from sample ``previous`` to ``sample`` (each (t_ns, accel, gyro)) as the model's step
        groups give it (:meth:`ArrayModel.step`), linearised at the newest state ``x0``; ``motion_factor``:
        the local motion density's factor on the motion model's stds."""
        model = self.model
        h = (sample[0] - previous[0]) * 1e-9
        if not model.factor_sets.other_steps:  # the built-in groups alone: nothing read of the samples
            return model.step(h, motion_factor, rows=self.config.engine != "numpy")
        return model.step(h, motion_factor, (previous[0], sample[0]),
                          ((previous[1], previous[2]), (sample[1], sample[2])), x0)

    def _follow_sign(self, k: int, t_ns: int) -> np.ndarray | None:
        """The streaming sign chain on the newest filtered state; flip ω where it says so. Returns the newest
        state's mean as it stands after (None when there is no chain: nothing read)."""
        scale = None if self.stream_model is None else self.stream_model.sign_scale_radps
        if scale is None:
            return None
        seg = self._segment
        engine = seg.engine
        x = engine.mean(k)
        moved = self._signs.push(k, t_ns, x[0:3], x[3:6], scale, seg.window[0][0] if seg.window else k)
        if moved is not None:
            engine.move_branch(*moved)
            x = engine.mean(k)
        return x

    def _recover(self, sample, err: FixedLagSmootherError) -> None:
        """After a failed update: rebuild the window from its raw samples, once.

        gtsam's state is unknown after an exception, so a new smoother is
        initialised on the samples not yet emitted plus the new one (sign of ω
        kept from the last filtered state). If that fails too the error is raised.
        """
        warnings.warn(f"{err}; re-initialising the fixed-lag window", RuntimeWarning, stacklevel=3)
        samples = list(self._segment.raw) + [sample]
        hint = self._segment.prev[1]
        held, deciding = self._hold.held, self._hold.deciding
        self._start_segment()
        self._hold.held, self._hold.deciding = held, deciding  # the rows held stay held
        self._segment.warmup = samples
        self._initialise(omega_hint=hint)

    def _remember_newest(self, x: np.ndarray | None = None) -> None:
        """The newest state's values kept (``x``: its mean as read already, else read here), copied once."""
        seg = self._segment
        k, t_ns = seg.window[-1]
        x = self._values_of(k, t_ns) if x is None else np.array(x, dtype=float)
        seg.prev = (t_ns, x[0:3], x[3:6], x[6:9])
        seg.prev_x = x
        seg.prev_sample = seg.raw[-1]

    def _values_of(self, k: int, t_ns: int):
        try:
            x = self._segment.engine.mean(k)
        except FilterFailure as err:
            raise self._failure(t_ns, err, "could not solve the state") from err
        return np.array(x, dtype=float)  # one copy: ω, ω̇ and f are views of it

    def _read(self, entry, with_sigma: bool = False) -> StateEstimate:
        k, t_ns = entry
        seg = self._segment
        prev = seg.prev
        if prev is not None and k == seg.k:
            w, dw, f = prev[1], prev[2], prev[3]
        else:
            try:
                x = seg.engine.mean(k)
            except FilterFailure as err:
                raise self._failure(t_ns, err, "could not solve the state") from err
            if x.base is not None:  # a view of the window's arrays: copied once (a mean computed for the call is ours)
                x = x.copy()
            w, dw, f = x[0:3], x[3:6], x[6:9]
        if not with_sigma:
            return _state(t_ns, w, dw, f)
        try:
            sd = seg.engine.sigma(k)
        except FilterFailure as err:
            raise self._failure(t_ns, err, "could not compute the uncertainty") from err
        return _state(t_ns, w, dw, f, sd[0:3], sd[3:6], sd[6:9])

    def _emit_due(self) -> list[StateEstimate]:
        """States at or before newest - lag: final now, marginalised at the next update."""
        seg, hold = self._segment, self._hold
        window, raw, engine = seg.window, seg.raw, seg.engine
        newest_ns = window[-1][1]
        cutoff_ns = newest_ns - self.config.lag_ns + 1000  # 1 µs tolerance
        out = []
        if len(window) < 2 or window[0][1] > cutoff_ns:
            return self._hold_start(newest_ns) if hold.deciding else out
        readings = lambda i: raw[i][1]  # noqa: E731 (the window's readings, for the branch decision)
        with_sigma = self.config.compute_sigma
        while len(window) > 1 and window[0][1] <= cutoff_ns:
            engine.settle(readings)
            if hold.deciding:  # held: its filtered value is kept as the start of the re-solve
                k, t_ns = window.popleft()
                hold.held.append((t_ns, raw.popleft(), engine.mean(k).copy()))
                engine.drop_oldest()
                continue
            out.append(self._read(window.popleft(), with_sigma))
            raw.popleft()
            engine.drop_oldest()
        if hold.deciding:
            return self._hold_start(newest_ns)
        return out

    # --- the start of a segment, held until the data decide the sign of ω -------------------------
    def _hold_start(self, newest_ns: int) -> list[StateEstimate]:
        """While the start of the segment is held (its rows past the lag kept back): ``max(lag_s, 0.5 s)``
        after the first held row, then at doubling spans (:meth:`StartHold.due`), the evidence for the branch
        of ω is weighed (:meth:`_release_start`)."""
        if not self._hold.held or self._hold.waiting_for_batch or not self._hold.due(newest_ns):
            return []
        return self._release_start(final=False)

    def _start_evidence(self):
        """The held rows and the window solved as the batch smoother solves a stretch (the stream's model,
        Levenberg-Marquardt on the whole stretch), from the filtered states, from the batch smoother's own
        initial states of the stretch (:func:`~gfimu.smoother.solve.initialise.initial_estimate`) and from the
        filtered states moved onto each other branch of ω (:func:`~gfimu.smoother.solve.restarts.branch`: flipped, mirrored through the array's
        plane, both). Returns (problem, best solution, the best other minimum's solution or None,
        log-likelihood ratio of the best over it [nats]: the difference of their costs, each the negative
        log-likelihood of the stretch up to one constant; inf when every start ends in the best minimum)."""
        samples = [h[1] for h in self._hold.held] + list(self._segment.raw)
        X = np.vstack([h[2] for h in self._hold.held] + [self._segment.engine.mean(k) for k, _ in self._segment.window])
        part = self._stretch_log(Stretch.of_samples(samples))
        scale = 1.0 if self.stream_model is None else float(self.stream_model.accel_noise_scale)
        problem = make_problem(part, self.options, scale, X[:, OMEGA])
        starts = [X, initial_estimate(part, self.options)]
        for kind in (1, 2, 3):
            Xb = X.copy()
            Xb[:, OMEGA], Xb[:, OMEGA_DOT] = branch(kind, X[:, OMEGA], X[:, OMEGA_DOT], self._signs.normal)
            starts.append(Xb)
        solutions = self._solved_from(problem, starts)
        order = sorted(range(len(solutions)), key=lambda i: solutions[i].cost)
        best = solutions[order[0]]
        w = best.states[:, OMEGA]
        size = math.sqrt(float(np.mean(np.sum(w * w, axis=1))))
        for i in order[1:]:
            d = solutions[i].states[:, OMEGA] - w
            if math.sqrt(float(np.mean(np.sum(d * d, axis=1)))) > SAME_BRANCH * size:
                return problem, best, solutions[i], float(solutions[i].cost - best.cost)
        return problem, best, None, math.inf

    def _release_start(self, final: bool) -> list[StateEstimate]:
        """The held rows, re-solved on the branch the data chose, once the data have decided them: the
        log-likelihood ratio of that branch over the next best reaches :data:`SIGN_DECISION_NATS`, the
        filter's ω at the lag agrees with the re-solve's, and the rows of the previous check's re-solve
        moved with the data since by no more than their uncertainty (both :data:`AGREEMENT_CHI2`, the
        second a mean over the rows: a short stretch of slow rotation, whose Gaussian posterior is far
        too narrow, is re-solved differently as data come); else once they span ``hold_max_s``, or at the
        segment's end (``final``: then the window's rows too, and the segment ends); else nothing.

        The window goes on from the re-solved states (:meth:`_restart_window`). σ (with
        ``compute_sigma``) is the solve's, widened by the other branch's share of the posterior, ``p (1 -
        p) (ω - ω')²`` per axis with ``p = 1 / (1 + e^Λ)``: a start released undecided says so in its σ
        (and in :attr:`starts`)."""
        hold = self._hold
        if not hold.held:
            return []
        try:
            problem, best, other, evidence = self._start_evidence()
        except (np.linalg.LinAlgError, FloatingPointError, ValueError):  # not solvable: the rows as filtered
            out = [StateEstimate(int(t), x[0:3].copy(), x[3:6].copy(), x[6:9].copy()) for t, _, x in hold.held]
            hold.record(hold.held_s, math.nan, math.nan, math.nan, True)
            hold.release()
            return out
        held_s = hold.held_s
        X = best.states
        times = [h[0] for h in hold.held] + [t for _, t in self._segment.window]
        if hold.last_resolve is None and not (final or held_s >= hold.max_s):
            # the first check cannot decide (nothing to tell how far its re-solve moves with the data): its
            # re-solve is kept for the next check, and its covariance not made
            hold.moved(np.asarray(times, dtype=np.int64), X[:, OMEGA], None)
            return []
        cov = solve(problem, X, compute_sigma=True, max_iterations=1).covariance
        j = len(hold.held)  # the next row the stream would give, lag_s behind
        d = self._segment.engine.mean(self._segment.window[0][0])[0:3] - X[j, OMEGA]
        try:
            chi2 = float(d @ np.linalg.solve(cov[j][OMEGA, OMEGA], d))
        except np.linalg.LinAlgError:
            chi2 = math.inf
        moved = hold.moved(np.asarray(times, dtype=np.int64), X[:, OMEGA], cov[:, OMEGA, OMEGA])
        decided = evidence >= SIGN_DECISION_NATS and chi2 <= AGREEMENT_CHI2 and moved <= AGREEMENT_CHI2
        if not (decided or final or held_s >= hold.max_s):
            return []
        sd = None
        if self.config.compute_sigma:
            sd = np.sqrt(np.einsum("nii->ni", cov))
            if other is not None:
                p = 1.0 / (1.0 + math.exp(min(evidence, 700.0)))
                sd[:, OMEGA] = np.sqrt(sd[:, OMEGA] ** 2 + p * (1.0 - p) * (X[:, OMEGA] - other.states[:, OMEGA]) ** 2)
        n_out = len(times) if final else len(hold.held)
        out = [StateEstimate(int(times[j]), X[j, OMEGA].copy(), X[j, OMEGA_DOT].copy(), X[j, SPECIFIC_FORCE].copy(),
                             *((None,) * 3 if sd is None else (sd[j, OMEGA], sd[j, OMEGA_DOT], sd[j, SPECIFIC_FORCE])))
               for j in range(n_out)]
        hold.record(held_s, evidence, chi2, moved, not decided)
        held = hold.release()
        if final:
            self._segment.window.clear()
            return out
        self._restart_window(X, held)
        return out

    def _start_from_batch(self, batch: list) -> int:
        """The held rows of a tuning stretch whose batch solution ``batch`` comes out (:meth:`_tune_and_replay`):
        the batch smoother has decided them on the whole stretch; the window goes on from its states. Returns
        the number of held rows so released (0 when nothing is held or the rows are not the stretch's)."""
        hold = self._hold
        n = len(hold.held)
        rows = [h[0] for h in hold.held] + [t for _, t in self._segment.window]
        if not (hold.deciding and n) or len(batch) < len(rows) or any(
                batch[j].timestamp_ns != t for j, t in enumerate(rows)):
            return 0
        X = np.array([np.concatenate([s.omega_b_radps, s.omega_dot_b_radps2, s.specific_force_b_mps2])
                      for s in batch[:len(rows)]])
        hold.record(hold.held_s, math.nan, math.nan, math.nan, False)
        self._restart_window(X, hold.release())
        return n

    def _restart_window(self, X: np.ndarray, held: list) -> None:
        """The window solved again from the held samples ``held`` and its own, each linearised once at its
        re-solved state (rows of ``X``; not iterated from it: :meth:`WindowFilter.measure`'s ``once``), the
        held ones then marginalised: the stream goes on from the decided branch with what the held rows
        told. A window that fails to solve again is kept as it was."""
        raws = held + list(self._segment.raw)
        k0 = self._segment.window[0][0] - len(held)
        engine = self._new_smoother()
        try:
            for j, (t, y, g) in enumerate(raws):
                extra = self.model.sample_terms(t, y, g)
                if j == 0:
                    engine.begin(k0, t, y, g, start=X[0], extra=extra, once=True)
                    continue
                engine.advance(k0 + j, self._step(raws[j - 1], raws[j], X[j - 1], 1.0), t, y, g, extra=extra,
                               start=X[j], once=True)
                if j <= len(held):
                    engine.drop_oldest()
            engine.commit()
        except FilterFailure:
            return
        self._go_on_with(engine)


@dataclass(frozen=True)
@assemble("model", "solve", "stream", "tuning", tune_process_noise=True)
class FixedLagEstimator(SmootherEstimator):
    """Fixed-lag smoother over a log (method ``"fixed-lag"``).

    Options: the groups model, solve, stream, tuning and guard of :mod:`gfimu.smoother.model.option_groups`
    (``gfimu estimate --method fixed-lag --list-options``); the batch smoother's group (``window_s``,
    ``overlap_s``, ``reweight_iterations``, ...) is not among them, so such an option is refused where the
    options are read. Each sample's estimate is its
    smoothed value ``lag_s`` seconds later (and, at the end of the log or
    before a gap, the last window's smoothed values), exactly what a live
    stream would give with that delay.

    Model and process noise: as in the batch smoother, chosen from the data by
    default (``auto_model``, ``tune_process_noise``): on the first
    ``tune_window_s`` of data (its first outputs come that late), then again
    every ``retune_every_s`` on the last ``model_window_s`` and when the motion
    outgrows a model chosen at rest (module docstring). The choices are in the
    report's ``tunings`` and ``model_check``. Giving
    any of ``omega_dot_random_walk_radps2_per_sqrt_s``,
    ``specific_force_random_walk_mps2_per_sqrt_s`` or ``process_axis_factors``
    (a value other than the default) uses the given densities and skips the
    tuning, as does ``tune_process_noise=False``.

    Model options the stream cannot honour are refused by :meth:`applicable` with the reason when
    set away from their defaults: ``motion_model='snap'``, ``tune_motion_model``,
    ``accel_noise_slope_mps2_per_radps`` and the robust re-weighting (the stream's model sets them itself),
    self-calibration, free flight, the attitude and the inclinometer, ``measurement='quadratic'``, factor
    groups that are not per sample.
    ``initialisation='ml'`` is honoured (initial states of each segment and of
    the tuning), and so are ``max_iterations`` and ``relative_tolerance`` (the
    batch solves of the tuning stretch).
    """

    method = "fixed-lag"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_oscillators(self.model)  # (each option is checked by its declaration)

    def window_lag_s(self, rate_hz: float) -> float:
        """The smoother's own lag [s] at ``rate_hz``: ``lag_s`` less the stream screening's wait
        (:func:`gfimu.readings.stream_wait_s`) when the readings are screened and that wait is at most half of
        ``lag_s``, so that each estimate leaves ``lag_s`` after its sample arrived, the screening's look-ahead
        inside it; where the wait is longer (low rates: the spike rule's 28 samples are 0.45 s at 62.5 Hz) the
        smoother keeps ``lag_s`` and an estimate leaves ``lag_s`` plus the wait after its sample."""
        if not self.screen_readings:
            return self.lag_s
        from ...readings import stream_wait_s

        wait = stream_wait_s(rate_hz)
        return self.lag_s - wait if wait <= 0.5 * self.lag_s else self.lag_s

    def smoother(self, array: SensorArray, rate_hz: float) -> FixedLagSmoother:
        """A streaming smoother with these options (its lag :meth:`window_lag_s`)."""
        return FixedLagSmoother.of_groups(array, self.model_groups, self.stream, rate_hz, lag_s=self.window_lag_s(rate_hz),
                                          auto_model=self.auto_model)

    def applicable(self, array: SensorArray) -> str | None:
        return fixed_lag_reason(array, self.model_groups)

    def preload(self, size_bytes: int | None = None) -> None:
        """Begin loading the compiled kernels in the background (:mod:`gfimu.smoother.preload`), while
        the log is read and screened or the stream starts (whatever the log's ``size_bytes``: the stream's
        kernels run on every log)."""
        from ..preload import start

        start("stream")

    def screen(self, log: Log):
        """(``log`` screened as a stream of its rows, :class:`~gfimu.readings.Screening`): the readings
        :meth:`result` is given by ``gfimu estimate`` are those ``gfimu live`` gives the smoother
        (:func:`gfimu.readings.screen_stream`); with ``screen_readings=False``, the log as it is."""
        from ...readings import OUT_OF_ANY_RANGE_MPS2, Screening, screen_stream

        if self.screen_readings:
            return screen_stream(log)
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(log.accel_mps2) | (np.abs(log.accel_mps2) > OUT_OF_ANY_RANGE_MPS2)
        if bad.any():
            row, col = (int(v) for v in np.argwhere(bad)[0])
            where = f"{log.source}/imu.csv:{row + 2}" if log.source else f"sample {row}"
            raise DataError(f"{where}: column {log.array.accel_columns[col]!r} reads {log.accel_mps2[row, col]:g} "
                            f"({int(bad.sum())} such reading(s)): not a reading; with screen_readings=False the "
                            "readings are used as they are (True, the default, replaces such readings)")
        return log, Screening(np.zeros(log.accel_mps2.shape, bool), 0, 0, 0)

    def _per_sample_ahead(self, log: Log):
        """The guard's per-sample estimate of the whole log (:func:`gfimu.smoother.result.guarded`: ML, as it
        computes it) begun in a forked process of its own, which makes it on the other core while the stream
        runs on this one; None where the guard will not judge the run (:func:`~gfimu.smoother.result.unguarded`),
        the machine has one core, no process may be forked, or the log is longer than
        :data:`PER_SAMPLE_AHEAD_MAX` (the estimate comes back pickled: a copy of it on the way)."""
        from ..result import unguarded

        if cpu_count() < 2 or len(log) > PER_SAMPLE_AHEAD_MAX or unguarded(log, self.model) is not None:
            return None
        process = ChoiceProcess.start(lambda _: MLEstimator().estimate_motion(log))
        if process is not None:
            process.submit(())  # (None would end it)
        return process

    def result(self, log: Log, progress: bool = False) -> Estimate:
        """The fixed-lag smoother over ``log`` sample by sample, before the guard (:meth:`estimate` is the entry)."""
        n = len(log)
        if n < 2:
            raise DataError(f"{log.source}: the log has {n} sample(s); the fixed-lag smoother needs at least 2 "
                            "(a single reading does not tell the angular velocity)")
        reason = self.applicable(log.array)
        if reason:
            raise InputError(f"{log.source}: {reason}")
        from .session import StreamSession

        # the log's readings are screened already (screen(), the same rule as the stream's): not again here
        gyro = log.gyro_b_radps if (self.use_gyro and log.array.gyroscope is not None) else None
        session = StreamSession(log.array, self, log.rate_hz, screen=False, name=str(log.source or "log"),
                                upcoming=(log.timestamps_ns, log.accel_mps2, gyro))
        out = np.full((n, 9), np.nan)
        sig = np.full((n, 9), np.nan) if self.compute_sigma else None
        cursor = 0  # smoothed states come out in time order, one per sample

        def store(states) -> None:
            nonlocal cursor
            for s in states:
                if isinstance(s, StateRows):  # a block's states (gfimu.smoother.stream.block)
                    m = len(s)
                    if cursor + m > n or not np.array_equal(log.timestamps_ns[cursor:cursor + m], s.timestamp_ns):
                        raise FixedLagSmootherError(f"{log.source}: internal ordering error at sample {cursor}")
                    out[cursor:cursor + m] = s.values
                    cursor += m
                    continue
                if cursor >= n or log.timestamps_ns[cursor] != s.timestamp_ns:
                    raise FixedLagSmootherError(f"{log.source}: internal ordering error at sample {cursor}")
                row = out[cursor]  # (its three parts written in place: no concatenated copy of them)
                row[0:3], row[3:6], row[6:9] = s.omega_b_radps, s.omega_dot_b_radps2, s.specific_force_b_mps2
                if sig is not None and s.sigma_omega_b_radps is not None:
                    row = sig[cursor]
                    row[0:3], row[3:6], row[6:9] = (s.sigma_omega_b_radps, s.sigma_omega_dot_b_radps2,
                                                    s.sigma_specific_force_b_mps2)
                cursor += 1

        times, accel = np.ascontiguousarray(log.timestamps_ns, dtype=np.int64), np.ascontiguousarray(log.accel_mps2,
                                                                                                    dtype=float)
        if gyro is None and sig is None:  # runs of samples at once where the stream is steady (the same states)
            for c0 in progress_bar(range(0, n, BLOCK_SAMPLES), total=-(-n // BLOCK_SAMPLES), desc="fixed-lag",
                                   enable=progress):
                i, c1 = c0, min(n, c0 + BLOCK_SAMPLES)
                while i < c1:
                    i, states = session.push_block(times, accel, i, c1)
                    store(states)
        else:  # (σ of each state, or gyroscope rows: sample by sample)
            for i in progress_bar(range(n), total=n, desc="fixed-lag", enable=progress):
                store(session.push(times[i], accel[i], None if gyro is None else gyro[i]))
        store(session.finish())
        for note in session.take_notes():
            if note.startswith("warning: "):
                warnings.warn(f"{log.source}: {note[len('warning: '):]}", RuntimeWarning, stacklevel=2)
        if cursor != n:
            raise FixedLagSmootherError(f"{log.source}: {n - cursor} samples were not estimated")
        sigma = {}
        if sig is not None:
            sigma = {"omega_b_radps": sig[:, :3], "omega_dot_b_radps2": sig[:, 3:6], "specific_force_b_mps2": sig[:, 6:]}
        motion = Motion(log.timestamps_ns, omega_b_radps=out[:, :3], omega_dot_b_radps2=out[:, 3:6],
                        specific_force_b_mps2=out[:, 6:], sigma=sigma)
        tunings = []
        for m in session.models:
            if m.tuning is not None and all(m.tuning is not t for t in tunings):
                tunings.append(m.tuning)
        return Estimate(motion, Report.of(self.method, self, tunings=tunings, iterations=0, cost=float("nan"), windows=0,
                                          model_check=None if session.stream_model is None else session.stream_model.check))
