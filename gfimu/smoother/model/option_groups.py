"""The smoothers' options, each declared once with its unit, default and help, in nine groups.

- :class:`ModelOptions` (``model``): the model both smoothers solve (motion model, noise, gyroscope, priors);
- :class:`SolveOptions` (``solve``): how both smoothers start and stop a solve and what it gives out (initial
  states, iteration limits, σ);
- :class:`BatchModelOptions` (``batch_model``): the parts of the model only the batch smoother has beside the
  two below (white snap, the per-sample inversion, free flight, motion-dependent noise, robust losses);
- :class:`AttitudeOptions` (``attitude``): the batch smoother's attitude and inclinometer;
- :class:`SelfCalibrationOptions` (``self_calibration``): the batch smoother's self-calibration;
- :class:`BatchOptions` (``batch``): the batch smoother's solve windows, re-weighting, restarts and workers;
- :class:`StreamOptions` (``stream``): the fixed-lag smoother's lag, window engine and model updates;
- :class:`TuningOptions` (``tuning``): the model and noise chosen from the data;
- :class:`GuardOptions` (``guard``): the comparison with the per-sample estimate.

Each field is made by :func:`gfimu.option.option`, whose metadata (``unit``, ``help``) ``gfimu estimate --list-options``
prints. The flat option classes are assembled from the groups by :func:`assemble`:
:class:`gfimu.smoother.model.problem.SmootherOptions` (model, solve, batch_model, attitude, self_calibration,
batch, tuning) and the estimators of the methods 'smoother' (those and guard) and 'fixed-lag' (model, solve,
stream, tuning, guard). They keep every
option under its flat name (``-O name=value``, the presets, ``SmootherOptions(window_s=10)``), add the
group's name to each field's metadata, and give each group's values back as a frozen group dataclass
(``options.model.motion_model``, ``options.batch.window_s``); ``cls.from_groups(model, batch, ...)``
makes the flat options from group values. A method has no option of a group it does not carry: the
fixed-lag smoother has no ``window_s`` nor ``estimate_attitude``, the batch smoother no ``lag_s``.

Each declaration carries its check (:mod:`gfimu.option`: a range, a switch, one of the values of the
:class:`enum.StrEnum` below for the seven choices); the assembled classes check every value when they are made
(:func:`gfimu.option.check_declared`), and ``-O NAME=VALUE`` is read by the same check. Only the rules that tie
two options (``window_s`` and ``overlap_s``, the oscillator and the motion model) are written apart
(:class:`gfimu.smoother.model.problem.SmootherOptions`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple

from ...noise import DEFAULT_ACCEL_NOISE_STD_MPS2
from ...option import Choice, Number, Numbers, Satisfies, check_declared, option


class MotionModel(StrEnum):
    """``motion_model``: white angular jerk, or white angular snap (batch smoother only)."""
    JERK = "jerk"
    SNAP = "snap"


class Measurement(StrEnum):
    """``measurement``: the raw accelerometer readings, or the per-sample inversion (batch smoother only)."""
    ACCELEROMETER = "accelerometer"
    QUADRATIC = "quadratic"


class Initialisation(StrEnum):
    """``initialisation``: the initial states of each solve."""
    SIGN_RESOLVING = "sign-resolving"
    ML = "ml"


class RobustLoss(StrEnum):
    """``robust_loss``: the loss of the robust re-weighting."""
    HUBER = "huber"
    CAUCHY = "cauchy"


class Solver(StrEnum):
    """``solver``: the batch smoother's solver."""
    NUMPY = "numpy"
    GTSAM = "gtsam"


class Engine(StrEnum):
    """``engine``: the fixed-lag smoother's window solver."""
    NUMPY = "numpy"
    GTSAM = "gtsam"


class Guard(StrEnum):
    """``guard``: what the comparison with the per-sample estimate does (:mod:`gfimu.smoother.guard`)."""
    REPLACE = "replace"
    WARN = "warn"
    OFF = "off"


MIN_DENSITY = 1e-9
"""The smallest noise density (``..._per_sqrt_s``) given on a command line: the floor of the smoother's own tuned
densities (1e-40 made its normal equations singular)."""

POSITIVE = Number(0.0, low_open=True)
"""A number > 0 (a std, a length of time)."""
AT_LEAST_ZERO = Number(0.0)
"""A number >= 0 (0: off)."""
DENSITY = Number(0.0, low_open=True, least_given=MIN_DENSITY)
"""A noise density: > 0, and at least :data:`MIN_DENSITY` on a command line."""
COUNT = Number(1, integer=True)
"""An integer >= 1."""


def _factor_groups(value) -> bool:
    from .factor_group import FactorGroup

    return isinstance(value, (tuple, list)) and all(isinstance(g, FactorGroup) for g in value)


@dataclass(frozen=True)
class ModelOptions:
    """The model both smoothers solve: the motion model, its noise densities, the accelerometer noise, the
    gyroscope, the first state's priors and further factor groups. Noise densities are continuous-time: a
    random walk of density q has step std ``q sqrt(h)``."""

    motion_model: str = option("jerk", help=(
        "'jerk': ω̇ is a random walk (white angular jerk, state [ω, ω̇, f]); 'snap': ω̈ is a random walk (white "
        "angular snap, state [ω, ω̇, f, ω̈]), smoother for slow, smooth motion (batch smoother only)"),
        check=Choice(MotionModel))
    omega_dot_random_walk_radps2_per_sqrt_s: float = option(30.0, "rad/s²/√s", (
        "white angular jerk density ('jerk' model): how fast ω̇ may change; larger follows faster motion, "
        "smooths less"), check=DENSITY)
    specific_force_random_walk_mps2_per_sqrt_s: float = option(30.0, "m/s²/√s", (
        "random walk density of the specific force: how fast it may change"), check=DENSITY)
    default_accel_noise_std_mps2: float = option(DEFAULT_ACCEL_NOISE_STD_MPS2, "m/s²", (
        "accelerometer white-noise std when no axis of array.toml gives one (an axis without one among axes "
        "with one takes their mean)"), check=POSITIVE)
    use_gyro: bool = option(True, help="use the gyroscope when the array has one")
    initial_omega_std_radps: float = option(100.0, "rad/s", "weak prior std of the first sample's ω (zero mean)",
        check=POSITIVE)
    initial_omega_dot_std_radps2: float = option(1000.0, "rad/s²", (
        "weak prior std of the first sample's ω̇ (zero mean)"), check=POSITIVE)
    initial_specific_force_std_mps2: float = option(1000.0, "m/s²", (
        "weak prior std of the first sample's specific force (zero mean), keeping the normal equations definite"),
        check=POSITIVE)
    process_axis_factors: tuple[float, float, float] = option((1.0, 1.0, 1.0), help=(
        "factor on the jerk (or snap) density per body axis x, y, z: motion about one body axis (turntable, "
        "pendulum) is far smoother about the others"), check=Numbers(3, 0.0, low_open=True))
    process_axis_frequencies_hz: tuple[float, float, float] = option((0.0, 0.0, 0.0), "Hz", (
        "'jerk' model: natural frequency per body axis x, y, z; f > 0 makes the motion about that axis a "
        "driven oscillator ω̈ = -(2π f)² ω + white jerk (turntables, shakers, pendulums, gait), 0 the plain "
        "white jerk"), check=Numbers(3, 0.0, 1e4))
    factor_groups: tuple = option((), help=(
        "further factor groups (gfimu.smoother.model.groups.FactorGroup, from Python) added to the model of every "
        "solve; the fixed-lag smoother takes those whose rows each tie one sample (per_sample) or two "
        "consecutive samples (steps)"),
        check=Satisfies(_factor_groups, "a tuple of FactorGroup objects (gfimu.smoother.model.groups)"))


@dataclass(frozen=True)
class SolveOptions:
    """How both smoothers start and stop a solve of their model and what it gives out: the initial states, the
    Levenberg-Marquardt limits, the one-sigma uncertainties."""

    compute_sigma: bool = option(False, help=(
        "also output one-sigma marginal uncertainties of the estimates (sigma_ columns)"))
    max_iterations: int = option(30, help=(
        "largest number of Levenberg-Marquardt iterations per solve (the fixed-lag smoother: of the solves of "
        "its tuning stretch)"), check=COUNT)
    relative_tolerance: float = option(1e-10, help="stop a solve when the cost decreases by less than this fraction",
        check=AT_LEAST_ZERO)
    initialisation: str = option("sign-resolving", help=(
        "initial states: 'sign-resolving' (gfimu.smoother.solve.initialise) or 'ml' (the per-sample "
        "maximum-likelihood estimate with its sign choice; slower, more robust on real recordings with large "
        "model residuals and fast motion at low rates)"), check=Choice(Initialisation))
    init_window_s: float = option(0.4, "s", "window of the sign-resolving initialisation", check=POSITIVE)
    ml_sign_chain: bool = option(False, help=(
        "with initialisation='ml': re-choose the sign of each sample's ML ω so that consecutive samples follow "
        "the trapezoid of ML's ω̇ (dynamic programming), fixing the per-sample sign choice where a fast "
        "rotation slows through zero and reverses"))


@dataclass(frozen=True)
class BatchModelOptions:
    """The parts of the model only the batch smoother (method 'smoother') has beside the attitude
    (:class:`AttitudeOptions`) and self-calibration (:class:`SelfCalibrationOptions`): the white-snap density,
    the per-sample inversion as measurement, free flight, and the motion-dependent noise and robust losses it
    re-weights over whole solutions (the fixed-lag smoother chooses its own from the stream,
    :mod:`gfimu.smoother.stream.model_choice`)."""

    omega_ddot_random_walk_radps3_per_sqrt_s: float = option(300.0, "rad/s³/√s", (
        "white angular snap density ('snap' model): how fast ω̈ may change"), check=DENSITY)
    measurement: str = option("accelerometer", help=(
        "'accelerometer': one factor per sensor on its raw readings (any array, self-calibration possible); "
        "'quadratic': the per-sample inversion [f, ω̇, q(ω)] with its covariance (an invertible array, no "
        "self-calibration; batch smoother only)"), check=Choice(Measurement))
    free_flight: bool = option(False, help=(
        "treat the whole log as torque-free free flight (McGinnis, Perkins & King 2012): needs [body] in array.toml (batch "
        "smoother only)"))
    torque_noise_std_nm: float = option(1e-4, "N m", "std of the unmodelled torque in the Euler factor", check=POSITIVE)
    free_fall_std_mps2: float = option(0.05, "m/s²", "std of the specific force at the centre of mass in free flight",
        check=POSITIVE)
    accel_noise_slope_mps2_per_radps: float = option(0.0, "m/s² per rad/s", (
        "accelerometer noise std growing with the rotation rate, sqrt(σ² + (slope |ω|)²) per sample, "
        "re-weighted from the current ω over reweight_iterations solves (MIMU4444: about 0.047); 0 keeps the "
        "noise of array.toml (the fixed-lag smoother's model sets it itself)"), check=AT_LEAST_ZERO)
    robust_loss: str = option("huber", help=(
        "loss of the robust re-weighting, 'huber' or 'cauchy' (iteratively re-weighted least squares, one "
        "re-weighting per solve of reweight_iterations; the fixed-lag smoother's model sets it itself)"),
        check=Choice(RobustLoss))
    accel_robust_threshold: float = option(0.0, "σ", (
        "robust loss on each accelerometer axis, threshold on its whitened residual; 0 keeps the Gaussian loss "
        "(the fixed-lag smoother's model sets it itself)"), check=AT_LEAST_ZERO)
    process_robust_threshold: float = option(0.0, "σ", (
        "robust loss on each motion-model step, threshold on its whitened residual norm / sqrt(rows); 0 keeps "
        "the Gaussian loss; lets sudden jerks through unsmoothed (the fixed-lag smoother's model sets it "
        "itself)"), check=AT_LEAST_ZERO)

    @property
    def robust(self) -> bool:
        """Whether any robust re-weighting is on."""
        return self.accel_robust_threshold > 0 or self.process_robust_threshold > 0


@dataclass(frozen=True)
class AttitudeOptions:
    """The attitude in the batch smoother's state (method 'smoother'): whether it is carried, the inclinometer
    that observes its tilt, and its process noise and yaw prior."""

    use_inclinometer: bool = option(False, help=(
        "use the inclinometer's tilt angles (Lu, Tsai & Lin 2010); implies estimate_attitude (batch smoother only)"))
    estimate_attitude: bool = option(False, help=(
        "carry the attitude R_k (W←B) in the state and output orientation and gravity-free acceleration; tilt "
        "is observed through the inclinometer or the random walk of the gravity-free acceleration, yaw only "
        "through a weak prior (initial_yaw_std_rad; batch smoother only)"))
    accel_random_walk_mps2_per_sqrt_s: float = option(30.0, "m/s²/√s", (
        "with the attitude: random walk density of the gravity-free acceleration (replaces the specific-force "
        "one)"), check=DENSITY)
    attitude_random_walk_rad_per_sqrt_s: float = option(1e-3, "rad/√s", (
        "with the attitude: process noise of R_{k+1} = R_k Exp(h (ω_k + ω_{k+1}) / 2)"), check=DENSITY)
    initial_yaw_std_rad: float = option(1.0, "rad", (
        "with the attitude: prior std of the first sample's yaw (the tilt prior, 10 rad, leaves it free)"),
        check=POSITIVE)


@dataclass(frozen=True)
class SelfCalibrationOptions:
    """The batch smoother's (method 'smoother') self-calibration: constant accelerometer biases and
    scale-factor errors and the gyroscope bias estimated with the motion, and their priors."""

    self_calibrate_bias: bool = option(False, help=(
        "estimate a constant bias per accelerometer axis and the gyro bias (batch smoother only)"))
    bias_prior_std_mps2: float = option(0.1, "m/s²", "prior std of each accelerometer bias (around 0)", check=POSITIVE)
    gyro_bias_prior_std_radps: float = option(0.05, "rad/s", (
        "prior std of the gyro bias (around 0) with self_calibrate_bias"), check=POSITIVE)
    self_calibrate_scale: bool = option(False, help=(
        "estimate a constant scale-factor error per accelerometer axis (batch smoother only)"))
    scale_prior_std: float = option(0.01, help=(
        "prior std of each accelerometer scale-factor error (a fraction, around 0) with self_calibrate_scale"),
        check=POSITIVE)

    @property
    def calibrates(self) -> bool:
        """Whether any calibration variable is estimated."""
        return self.self_calibrate_bias or self.self_calibrate_scale


@dataclass(frozen=True)
class BatchOptions:
    """The batch smoother's (method 'smoother') solve windows, re-weighting, restarts and workers."""

    window_s: float | None = option(30.0, "s", (
        "solve logs longer than this in overlapping windows of at most this length, stretched by up to a "
        "quarter when that saves a short last window (None: the whole log at once)"),
        check=Number(0.0, low_open=True, none=True))
    overlap_s: float = option(2.0, "s", "overlap of consecutive windows; each half of it is taken from the nearer window",
        check=AT_LEAST_ZERO)
    reweight_iterations: int = option(3, help=(
        "solves with the noise re-weighted from the previous solution when accel_noise_slope_mps2_per_radps or a "
        "robust threshold is set"), check=COUNT)
    branch_restarts: bool = option(True, help=(
        "robust model of an inconsistent log: after each window's solve, move the short runs of samples "
        "between outlying motion-model steps to the other branches of ω (sign-flipped, mirrored through the "
        "array's plane) and keep them where the robust objective falls"))
    tune_span_s: float | None = option(10.0, "s", (
        "with tune_process_noise: choose the process noise on at most this much of each solve window, its "
        "middle (10 s of readings fix a handful of noise levels well, and the choice then costs no more as "
        "the window grows; None: the whole window)"), check=Number(0.0, low_open=True, none=True))
    workers: int = option(0, "processes", (
        "processes solving the solve windows at once (the same numbers): 0 = one per CPU, at most one per "
        "window; 1 = all in this process (attitude windows, which start from the one before, and the gtsam "
        "solver always run in this process)"), check=Number(0, integer=True))
    solver: str = option("numpy", help=(
        "batch solver: 'numpy' (vectorised banded Levenberg-Marquardt, linear in the length) or 'gtsam' (the "
        "same problem as a GTSAM graph, eliminated in time order: a cross-check)"), check=Choice(Solver))


@dataclass(frozen=True)
class StreamOptions:
    """The fixed-lag smoother's (method 'fixed-lag') lag, window engine and model updates."""

    lag_s: float = option(0.2, "s", "the delay of each estimate after its sample arrives (a live stream's output "
                          "delay): the seconds of future data behind it, less the screening's look-ahead where that is "
                          "at most half of it (28 samples and a 0.02 s block: 0.076 s at 500 Hz), else plus it",
                          check=POSITIVE)
    relinearize_threshold: float = option(0.1, "rad/s", (
        "engine 'gtsam': iSAM2 relinearises ω when its update exceeds this (ω̇ and f enter linearly)"), check=POSITIVE)
    relinearize_skip: int = option(10, help="engine 'gtsam': iSAM2 checks for relinearisation every this many updates",
        check=COUNT)
    marginalise_every_s: float | None = option(None, "s", (
        "engine 'gtsam': old states are marginalised in blocks of this length (the window holds lag_s to "
        "lag_s + twice this); None: 125 samples, at most 0.25 s"), check=Number(0.0, low_open=True, none=True))
    warmup_s: float = option(0.2, "s", "data gathered at the start of each segment for its initialisation",
        check=AT_LEAST_ZERO)
    hold_max_s: float = option(4.0, "s", (
        "engine 'numpy': the first rows of each segment are held until the data decide the sign of ω (a "
        "log-likelihood ratio of 6.9 nats between its branches), then come out re-solved; at most this long "
        "(0: no hold)"), check=AT_LEAST_ZERO)
    gap_factor: float = option(1.5, help=(
        "a step longer than this times the nominal step is a gap: the smoother restarts after it"),
        check=Number(1.0, low_open=True))
    fast_measurement: bool = option(True, help=(
        "one factor for all accelerometer axes and a preallocated trapezoid factor (the same residuals, "
        "cheaper); False: the per-sensor factors of gfimu.factors (engine 'gtsam' only)"))
    engine: str = option("numpy", help=(
        "window solver: 'numpy' (a Kalman filter carrying the window's cross-covariances) or 'gtsam' (iSAM2's "
        "IncrementalFixedLagSmoother, the reference)"), check=Choice(Engine))
    tune_window_s: float = option(3.0, "s", (
        "length of the stretch of data the model is first chosen on (the stream's one-time start-up delay)"),
        check=POSITIVE)
    retune_every_s: float = option(10.0, "s", (
        "with auto_model: choose the model again on the recent past this often (and at once when the motion "
        "outgrows it)"), check=POSITIVE)
    model_window_s: float = option(30.0, "s", "with auto_model: length of the recent past the model is chosen on",
        check=POSITIVE)
    screen_readings: bool = option(True, help=(
        "screen the readings for gross errors as they come, by the rule gfimu estimate applies to a whole log "
        "(gfimu.readings.StreamScreen): each reading waits max(28 samples, 0.2 s) plus at most 0.05 s for its "
        "decision before it reaches the smoother, which delays every estimate by as much; False: the readings "
        "reach the smoother as they come (a reading that is not finite or beyond any accelerometer's range is "
        "then skipped by gfimu live and refused by gfimu estimate)"))


@dataclass(frozen=True)
class TuningOptions:
    """The model and the noise chosen from the data, by both smoothers."""

    auto_model: bool = option(True, help=(
        "choose the model from the log (gfimu.smoother.tuning.model_choice): readings that follow the rigid-body equation up to "
        "their stated noise keep the options; larger, heavy-tailed or |ω|-growing residuals (real arrays) get "
        "the ML initialisation with its sign chain, the measured noise floor and slope, Cauchy losses and "
        "moment-estimated process noise; options set away from their defaults are kept either way (the "
        "fixed-lag smoother: on the stream's recent past, engine 'numpy')"))
    tune_process_noise: bool = option(False, help=(
        "choose the jerk/snap density per body axis and the specific-force density by maximising the marginal "
        "likelihood of the data (per solve window; the fixed-lag smoother on its first tune_window_s); on by "
        "default in the methods 'smoother' and 'fixed-lag'"))
    tune_axis_frequencies: bool = option(True, help=(
        "with tune_process_noise ('jerk' model): per body axis, try the oscillator at the dominant frequency of "
        "the estimated ω and keep it where it raises the marginal likelihood"))
    tune_motion_model: bool = option(False, help=(
        "with tune_process_noise: also choose 'jerk' or 'snap' by the same criterion (batch smoother only; off: "
        "the snap model's normal equations become stiff with small per-axis densities)"))
    tune_accel_noise: bool = option(False, help=(
        "with tune_process_noise: also scale the accelerometer noise of every axis by the same criterion (for "
        "sensors whose rigid-body residual exceeds their white noise)"))


@dataclass(frozen=True)
class GuardOptions:
    """The comparison of the smoother's answer with the per-sample estimate (:mod:`gfimu.smoother.guard`)."""

    guard: str = option("replace", help=(
        "compare the answer with the per-sample ML estimate where that is well determined: 'replace' uses the "
        "per-sample answer, its sign following the smoother's around it, over spans where the smoother fits the "
        "readings worse than its model allows, and warns; 'warn' keeps the smoother's answer and warns; 'off' "
        "skips the comparison"), check=Choice(Guard))


class ModelGroups(NamedTuple):
    """The groups of a smoother's model as they travel together from the options to the problem: the model,
    how its solves start and stop, the batch smoother's batch model, attitude and self-calibration, and the
    tuning that chooses the model's noise from the data. A problem (:class:`gfimu.smoother.model.problem.SmootherProblem`,
    the stream's :class:`gfimu.smoother.stream.array_model.ArrayModel`) is built of the first five; a choice of
    the model reads and gives the model, solve, batch model and tuning
    (:func:`gfimu.smoother.tuning.model_choice.misfit_options`, the batch smoother's
    :func:`gfimu.smoother.batch.engine.chosen_model`, the fixed-lag smoother's
    :mod:`gfimu.smoother.stream.model_choice`), the noise tuner the model and batch model
    (:meth:`gfimu.smoother.tuning.evidence.Tuning.apply`)."""

    model: ModelOptions
    solve: SolveOptions
    batch_model: BatchModelOptions
    attitude: AttitudeOptions
    self_calibration: SelfCalibrationOptions
    tuning: TuningOptions

    @classmethod
    def of(cls, options) -> ModelGroups:
        """The groups of flat ``options`` (an assembled class carrying them all, as
        :class:`gfimu.smoother.model.problem.SmootherOptions`)."""
        return cls(*(getattr(options, name) for name in cls._fields))

    @classmethod
    def defaults(cls) -> ModelGroups:
        """Every group of the model at its declared defaults."""
        return cls(*(GROUP_CLASSES[name]() for name in cls._fields))


GROUP_CLASSES: dict[str, type] = {"model": ModelOptions, "solve": SolveOptions, "batch_model": BatchModelOptions,
                                  "attitude": AttitudeOptions, "self_calibration": SelfCalibrationOptions,
                                  "batch": BatchOptions, "stream": StreamOptions, "tuning": TuningOptions,
                                  "guard": GuardOptions}
"""Group name -> its dataclass, in the order ``--list-options`` lists them."""

GROUP_METHODS = {"batch_model": ("batch-smoother", "smoother"), "attitude": ("batch-smoother", "smoother"),
                 "self_calibration": ("batch-smoother", "smoother"), "batch": ("batch-smoother", "smoother"),
                 "stream": ("fixed-lag-smoother", "fixed-lag")}
"""The groups only one smoother carries -> (what its options are called, the smoother's method)."""

GROUPS: dict[str, tuple[str, ...]] = {name: tuple(f.name for f in dataclasses.fields(cls))
                                      for name, cls in GROUP_CLASSES.items()}
"""Group -> option names."""

GROUP_OF = {name: group for group, names in GROUPS.items() for name in names}
"""Option name -> its group."""


def groups_of(cls) -> tuple[str, ...]:
    """The option groups a flat options class (or object) carries, in :data:`GROUPS` order."""
    names = {f.metadata.get("group") for f in dataclasses.fields(cls)}
    return tuple(g for g in GROUPS if g in names)


def _group_property(group: str):
    part = GROUP_CLASSES[group]

    def get(self):
        return part(**{n: getattr(self, n) for n in GROUPS[group]})

    get.__name__ = group
    get.__doc__ = f"The {group} options as a frozen :class:`{part.__name__}`."
    return property(get)


def _from_groups(cls, *parts, **changes):
    """The flat options from the group values ``parts`` (a group not given keeps its defaults), then ``changes``
    by flat name."""
    own = groups_of(cls)
    values = {}
    for part in parts:
        group = next((g for g, c in GROUP_CLASSES.items() if isinstance(part, c)), None)
        if group not in own:
            raise TypeError(f"{cls.__name__} has no option group {group or type(part).__name__!r} "
                            f"(its groups: {', '.join(own)})")
        values.update({n: getattr(part, n) for n in GROUPS[group]})
    known = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(changes) - known)
    if unknown:
        raise TypeError(f"{cls.__name__} has no option {', '.join(unknown)}")
    return cls(**{**values, **changes})


def with_groups(options, *parts):
    """The flat ``options`` with the values of the group values ``parts`` (a tuned model and batch model, say),
    its other options kept."""
    values = {}
    for part in parts:
        values.update({f.name: getattr(part, f.name) for f in dataclasses.fields(part)})
    return dataclasses.replace(options, **values)


def _checked_post_init(cls):
    """``__post_init__`` of an assembled class: every option checked by its declaration
    (:func:`gfimu.option.check_declared`; once, by the class the object is made of), then the class's own
    ``__post_init__`` (or its base's)."""
    own = cls.__dict__.get("__post_init__")

    def __post_init__(self) -> None:
        if type(self).__post_init__ is __post_init__:
            check_declared(self, getattr(self, "method", "") or "smoother")
        if own is not None:
            own(self)
        else:
            parent = super(cls, self)
            if hasattr(parent, "__post_init__"):
                parent.__post_init__()

    __post_init__.__doc__ = own.__doc__ if own is not None else _checked_post_init.__doc__
    return __post_init__


def assemble(*groups: str, **defaults):
    """Class decorator, under ``@dataclass``: the class gets the fields of the option ``groups`` (their
    defaults, types and metadata, with the group's name added to the metadata), a property per group
    returning its values (none for ``guard``, the option of that name) and ``from_groups``. ``defaults``
    changes the default of a field of these groups or of a base class; the metadata stays the declaration's.
    The class body declares no option of a group."""

    def wrap(cls):
        own = dict(cls.__dict__.get("__annotations__", {}))
        clash = sorted(n for n in own if n in GROUP_OF)
        if clash:
            raise TypeError(f"{cls.__name__} declares {', '.join(clash)}: declare an option in its group only")
        inherited = {}
        for base in reversed(cls.__mro__[1:]):
            inherited.update(getattr(base, "__dataclass_fields__", {}))
        annotations = {}
        left = dict(defaults)
        for group in groups:
            for f in dataclasses.fields(GROUP_CLASSES[group]):
                annotations[f.name] = f.type
                setattr(cls, f.name, dataclasses.field(default=left.pop(f.name, f.default),
                                                       metadata={**f.metadata, "group": group}))
        for name in list(left):
            f = inherited.get(name)
            if f is None or "group" not in f.metadata:
                raise TypeError(f"{cls.__name__}: no option {name!r} whose default could change")
            annotations[name] = f.type
            setattr(cls, name, dataclasses.field(default=left.pop(name), metadata=f.metadata))
        cls.__annotations__ = {**annotations, **own}
        for group in groups:
            if group != "guard":
                setattr(cls, group, _group_property(group))
        cls.from_groups = classmethod(_from_groups)
        cls.__post_init__ = _checked_post_init(cls)
        return cls

    return wrap
