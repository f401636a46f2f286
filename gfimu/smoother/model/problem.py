"""Smoother options and the smoothing problem built from a log.

State of sample k: ``x_k = [ω_k, ω̇_k, f_k]`` (9 numbers, body frame B; the
'snap' motion model appends ω̈_k), plus
global calibration variables when self-calibration is on (per-axis
accelerometer bias and scale-factor error, gyroscope bias).

The model is the list of factor groups of :mod:`gfimu.smoother.model.groups` that apply to the options
(:data:`gfimu.smoother.model.groups.BUILT_IN`, then ``SmootherOptions.factor_groups``): the accelerometer
equation of every sensor (Ho & Lin 2009, eq. 6) or the per-sample inversion; the motion model
(trapezoid kinematics and the ω̇ random walk, i.e. white angular jerk of density
``omega_dot_random_walk_radps2_per_sqrt_s``, or per body axis the driven oscillator
``ω̈ = -Ω² ω + white jerk``, or with ``motion_model='snap'`` the exact white-snap step of
[ω, ω̇, ω̈]); the random walk of the specific force, or with the attitude its kinematics and the
random walk of the gravity-free acceleration; the gyroscope, free flight (McGinnis, Perkins & King 2012, eq. 1), the
inclinometer; weak priors on the first state and priors on the calibration variables so that
nothing in the graph is unobserved. Each group gives its noise levels when the problem is built
(:class:`gfimu.smoother.model.noise_levels.NoiseLevels`, ``problem.noise``).

:class:`SmootherProblem` assembles the groups: their terms vectorised over the samples (the fast
path), and the same problem as a GTSAM ``NonlinearFactorGraph`` of their factors (the graph path).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from ...array import SensorArray
from ...errors import DataError, InputError
from ...factors import (
    so3 as _so3,
    accelerometer,
    attitude_key,
    bias_key,
    gyro_bias_key,
    omega_ddot_key,
    omega_dot_key,
    omega_key,
    scale_key,
    specific_force_key,
)
from ...log import Log
from .parts import delegated
from .groups import BUILT_IN, FactorGroup, Term  # noqa: F401  (Term: also importable from here)
from .noise_levels import NoiseLevels
from .option_groups import ModelGroups, ModelOptions, MotionModel, SelfCalibrationOptions, assemble
from .layout import KINEMATIC_SIZE, OMEGA, OMEGA_DDOT, OMEGA_DOT, SPECIFIC_FORCE, StateLayout

STATE_SIZE = KINEMATIC_SIZE
"""State size of the default white-jerk model; white snap appends ω̈ (12); see :mod:`gfimu.smoother.model.layout`."""
W, D, F, A = OMEGA, OMEGA_DOT, SPECIFIC_FORCE, OMEGA_DDOT


@dataclass(frozen=True)
@assemble("model", "solve", "batch_model", "attitude", "self_calibration", "batch", "tuning")
class SmootherOptions:
    """Options of the batch smoother's problem and solves: the groups ``model``, ``solve``, ``batch_model``,
    ``attitude``, ``self_calibration``, ``batch`` and ``tuning`` of :mod:`gfimu.smoother.model.option_groups`,
    where each option is declared with its unit, default and help (``options.model``, ``options.batch``, ...:
    the groups' values; :meth:`model_groups`: those of the model together). Defaults suit
    100 Hz-1 kHz logs. The fixed-lag smoother takes the groups of its model (its estimator's
    :attr:`~gfimu.smoother.result.SmootherEstimator.model_groups`: those it does not carry at their defaults)."""

    def __post_init__(self) -> None:
        """The rules that tie two options (each option's own range is checked by its declaration,
        :mod:`gfimu.smoother.model.option_groups`)."""
        if self.window_s is not None and not (self.window_s > 2 * self.overlap_s > 0):
            raise InputError(f"smoother option window_s ({self.window_s}) must exceed twice overlap_s ({self.overlap_s}) > 0")
        check_oscillators(self)

    @property
    def robust(self) -> bool:
        """Whether any robust re-weighting is on."""
        return self.batch_model.robust

    @property
    def model_groups(self) -> ModelGroups:
        """The groups of the model together (:class:`~gfimu.smoother.model.option_groups.ModelGroups`)."""
        return ModelGroups.of(self)


def check_oscillators(model: ModelOptions) -> None:
    """An :class:`InputError` when the ``model`` (option group) asks for the driven oscillator
    (``process_axis_frequencies_hz``) on another motion model than white jerk."""
    frequencies = np.asarray(model.process_axis_frequencies_hz, dtype=float)
    if np.any(frequencies > 0) and model.motion_model != MotionModel.JERK:
        raise InputError("smoother option process_axis_frequencies_hz needs motion_model='jerk'")


def options_reason(array: SensorArray, groups: ModelGroups, attitude_supported: bool = False) -> str | None:
    """Why the smoother cannot solve the model of ``groups`` (its model, batch model, attitude and
    self-calibration) on ``array`` (None if it can).

    ``attitude_supported``: the caller carries the attitude state (the batch
    smoother does); otherwise ``use_inclinometer`` and ``estimate_attitude``
    are refused.
    """
    model, batch_model, attitude = groups.model, groups.batch_model, groups.attitude
    if (attitude.use_inclinometer or attitude.estimate_attitude) and not attitude_supported:
        return "use_inclinometer / estimate_attitude need the attitude state, which this smoother does not carry"
    if attitude.use_inclinometer and array.inclinometer is None:
        return f"use_inclinometer: array {array.name!r} has no inclinometer"
    if (attitude.use_inclinometer or attitude.estimate_attitude) and batch_model.free_flight:
        return "estimate_attitude is not available in free flight (the specific force carries no gravity)"
    if batch_model.measurement == "quadratic":
        if groups.self_calibration.calibrates or batch_model.free_flight:
            return "measurement='quadratic' works on the per-sample inversion: no self-calibration or free flight"
        try:
            array.check_invertible()
        except ValueError as exc:
            return f"measurement='quadratic' needs the per-sample inversion: {exc}"
    if batch_model.free_flight:
        if array.body is None:
            return f"free_flight needs the body's principal inertia ([body] in array.toml); array {array.name!r} has none"
        return None
    gyro_used = array.gyroscope is not None and model.use_gyro
    if not gyro_used and len(array.accelerometers) > 1 and float(np.ptp(array.axis_positions_m, axis=0).max()) < 1e-6:
        return (f"the accelerometers of array {array.name!r} all sit at one point (position_m spans less than "
                "1 µm): the rotation is not sensed; check position_m in array.toml (metres, in the body frame)")
    if array.n_axes < 6 and not gyro_used:
        return (f"array {array.name!r} has {array.n_axes} accelerometer axes; without free flight or a gyroscope "
                "ω cannot be observed (use free_flight=True with the body's inertia)")
    if not gyro_used:
        return array.geometry_reason(several_solutions=True)
    return None


def robust_weight(e: np.ndarray, c: float, loss: str) -> np.ndarray:
    """IRLS weight ``ρ'(e) / e`` of whitened residuals ``e`` under the robust loss (:func:`robust_loss`)
    of threshold ``c`` > 0: Cauchy ``1 / (1 + e²/c²)``, Huber ``min(1, c/|e|)``."""
    e = np.abs(e)
    if loss == "cauchy":
        return 1.0 / (1.0 + (e / c) ** 2)
    return np.where(e <= c, 1.0, c / np.maximum(e, 1e-300))


def robust_loss(e2: np.ndarray, c: float, loss: str) -> np.ndarray:
    """ρ of squared whitened residuals ``e²``, the loss whose IRLS weight is :func:`robust_weight`:
    Cauchy ``c²/2 log(1 + e²/c²)``, Huber ``e²/2`` within c and ``c|e| - c²/2`` beyond; ``e²/2``
    when c is 0 (no robust loss)."""
    if c <= 0:
        return 0.5 * e2
    if loss == "cauchy":
        return 0.5 * c * c * np.log1p(e2 / (c * c))
    e = np.sqrt(e2)
    return np.where(e <= c, 0.5 * e2, c * e - 0.5 * c * c)


@dataclass(frozen=True)
class AxisGeometry:
    """Where the array's accelerometer axes point and sit: per accelerometer (directions (k, 3), positions
    (k, 3), column slice) and every axis at once (one vectorised evaluation when no per-sensor calibration)."""

    sensors: list
    """(directions, positions, column slice) of each accelerometer (:func:`gfimu.factors.accelerometer.array_geometry`)."""
    directions_b: np.ndarray
    """(axes, 3) sensing direction of every axis in the body frame."""
    positions_m: np.ndarray
    """(axes, 3) position of every axis [m]."""
    rows: np.ndarray
    """(axes, 12) each axis's row of the structure matrix."""

    @classmethod
    def of(cls, array: SensorArray) -> AxisGeometry:
        """The geometry of ``array``'s accelerometers, in the order of its columns."""
        sensors = accelerometer.array_geometry(array)
        directions = np.concatenate([d for d, _, _ in sensors])
        positions = np.concatenate([p for _, p, _ in sensors])
        return cls(sensors, directions, positions, accelerometer.axis_rows(directions, positions))


@dataclass(frozen=True)
class CalibrationBlocks:
    """The calibration variables, one vector beside the states: each block's name (``bias0``, ``scale0``,
    ..., ``gyro_bias``) -> (slice of the vector, GTSAM key), and the vector's ``size``."""

    blocks: dict
    size: int

    @classmethod
    def of(cls, sensors: list, calibration: SelfCalibrationOptions, use_gyro: bool) -> CalibrationBlocks:
        """Per-axis accelerometer biases, then scale-factor errors, then the gyroscope bias, as the
        self-calibration ``calibration`` asks."""
        blocks = {}
        g = 0
        if calibration.self_calibrate_bias:
            for i, (_, _, cols) in enumerate(sensors):
                size = cols.stop - cols.start
                blocks[f"bias{i}"] = (slice(g, g + size), bias_key(i))
                g += size
        if calibration.self_calibrate_scale:
            for i, (_, _, cols) in enumerate(sensors):
                size = cols.stop - cols.start
                blocks[f"scale{i}"] = (slice(g, g + size), scale_key(i))
                g += size
        if use_gyro and calibration.self_calibrate_bias:
            blocks["gyro_bias"] = (slice(g, g + 3), gyro_bias_key())
            g += 3
        return cls(blocks, g)


@dataclass(eq=False)
class SmootherProblem:
    """The smoothing problem of one contiguous log (fast path and graph path): the log, the option groups it is
    built from (:attr:`options`, a :class:`~gfimu.smoother.model.option_groups.ModelGroups`, read by their names:
    :attr:`model`, :attr:`solve`, :attr:`batch_model`, :attr:`attitude`, :attr:`self_calibration`; :meth:`of`
    takes them from flat options),
    the model's groups and their noise levels (:attr:`noise`, a frozen
    :class:`~gfimu.smoother.model.noise_levels.NoiseLevels`: ``problem.noise.accel.sigma``, ...). What its
    groups read of it is :class:`~gfimu.smoother.model.noise_levels.ModelView`.

    Besides them it holds the samples (``n``, ``dt_s``), the axes' :attr:`geometry` (:class:`AxisGeometry`;
    ``sensors``, ``all_directions_b``, ``all_positions_m``, ``all_rows`` read it), the calibration variables
    (:attr:`calibration`, :class:`CalibrationBlocks`; ``global_blocks``, ``n_global``), the state
    :attr:`layout` (the solvers' ``state_size``, ``snap``, ``AT`` read it; a group reads the
    layout itself) and which of the gyroscope and the inclinometer the model uses.

    Frozen once built: nothing sets an attribute on it afterwards. A re-weighting returns a new problem
    around new noise levels (:meth:`with_noise`, given the new value of a level, made by that level's own
    methods: ``problem.with_noise(accel=problem.noise.accel.motion_dependent(omega, slope))``; the robust
    re-weighting: :func:`gfimu.smoother.solve.banded.robust_reweighted`), sharing the rest. Its methods name
    no group's noise levels: the groups and the re-weightings do."""

    log: Log
    options: ModelGroups = field(default_factory=ModelGroups.defaults)

    def __post_init__(self) -> None:
        if not isinstance(self.options, ModelGroups):
            raise TypeError("SmootherProblem(log, groups) takes the option groups of the model (ModelGroups); "
                            "SmootherProblem.of(log, options) takes flat options")
        reason = options_reason(self.log.array, self.options, attitude_supported=True)
        if reason:
            raise InputError(reason)
        arr = self.log.array
        model = self.model
        self.n = len(self.log)
        if self.n < 2:
            raise DataError(f"{self.log.source}: the smoother needs at least 2 samples, got {self.n}")
        self.dt_s = self.log.dt_s
        bad = ~np.isfinite(self.log.accel_mps2)
        if np.any(bad):
            row, col = np.argwhere(bad)[0]
            raise DataError(f"{self.log.source}: accelerometer reading {arr.accel_columns[col]} is not finite at sample {row} "
                            f"({int(bad.sum())} such values); the smoother needs finite readings")
        self.geometry = AxisGeometry.of(arr)
        self.use_gyro = arr.gyroscope is not None and model.use_gyro and self.log.gyro_b_radps is not None
        self.calibration = CalibrationBlocks.of(self.geometry.sensors, self.self_calibration, self.use_gyro)
        self.layout = StateLayout.of(model, self.attitude)
        self.use_inclinometer = bool(self.attitude.use_inclinometer and self.log.tilt_rad is not None)
        if self.attitude.use_inclinometer and self.log.tilt_rad is None:
            raise InputError(f"{self.log.source}: use_inclinometer but the log has no tilt_x, tilt_y columns")
        # the model: every group that applies, the measurement first, then those placed first
        # (the first-state prior), then the rest in order; each gives its own noise levels
        groups = [g for g in BUILT_IN + tuple(model.factor_groups) if g.applies(self)]
        self.groups = tuple(sorted(groups, key=lambda g: 0 if g.measurement else 1 if g.first else 2))
        self.noise = NoiseLevels.gather(self.groups, self)
        object.__setattr__(self, "_built", True)

    @classmethod
    def of(cls, log: Log, options) -> SmootherProblem:
        """The problem of ``log`` under the model's groups of the flat ``options`` (a :class:`SmootherOptions`,
        or any options carrying those groups)."""
        return cls(log, ModelGroups.of(options))

    # --- the option groups, by their names -----------------------------------
    model = delegated("options", "model", "The model (:class:`~gfimu.smoother.model.option_groups.ModelOptions`).")
    solve = delegated("options", "solve", "How its solves start and stop (:class:`~gfimu.smoother.model.option_groups.SolveOptions`).")
    batch_model = delegated("options", "batch_model",
                            "The batch model (:class:`~gfimu.smoother.model.option_groups.BatchModelOptions`).")
    attitude = delegated("options", "attitude", "The attitude (:class:`~gfimu.smoother.model.option_groups.AttitudeOptions`).")
    self_calibration = delegated("options", "self_calibration", (
        "The self-calibration (:class:`~gfimu.smoother.model.option_groups.SelfCalibrationOptions`)."))

    # --- the parts' values, by the names the groups read -------------------
    sensors = delegated("geometry", "sensors", "(directions, positions, column slice) of each accelerometer.")
    all_directions_b = delegated("geometry", "directions_b", "(axes, 3) sensing direction of every axis in the body frame.")
    all_positions_m = delegated("geometry", "positions_m", "(axes, 3) position of every axis [m].")
    all_rows = delegated("geometry", "rows", "(axes, 12) every axis's row of the structure matrix.")
    global_blocks = delegated("calibration", "blocks", "name -> (slice of the calibration vector, GTSAM key).")
    n_global = delegated("calibration", "size", "Size of the calibration vector.")
    # the layout's values by the solvers' short names (a factor group reads them as ``problem.layout``, :class:`ModelView`)
    snap = delegated("layout", "snap", "Whether the state carries the snap (white snap motion model).")
    state_size = delegated("layout", "size", "Values per sample's state.")

    @property
    def AT(self) -> slice:
        """Columns of the attitude's rotation vector in the state (problems with the attitude only)."""
        if not self.layout.attitude:
            raise AttributeError("'SmootherProblem' object has no attribute 'AT' (no attitude in the state)")
        return self.layout.rotation

    def __setattr__(self, name: str, value) -> None:
        if self.__dict__.get("_built"):
            raise AttributeError(f"a SmootherProblem is frozen once built (setting {name!r}): "
                                 "make a new one with with_noise(...)")
        object.__setattr__(self, name, value)

    @property
    def array(self):
        """The log's sensor array."""
        return self.log.array

    def with_noise(self, **changes) -> SmootherProblem:
        """The same problem with these fields of its noise levels changed (:meth:`NoiseLevels.replace`:
        ``problem.with_noise(accel=problem.noise.accel.scaled(2.0))``)."""
        new = copy.copy(self)
        object.__setattr__(new, "noise", self.noise.replace(**changes))
        return new

    # --- calibration variables -------------------------------------------
    def global_part(self, params: np.ndarray, name: str) -> np.ndarray | None:
        block = self.global_blocks.get(name)
        return None if block is None else params[block[0]]

    def group(self, kind: type) -> FactorGroup:
        """The model's group of class ``kind`` (KeyError if it does not apply to this problem)."""
        for g in self.groups:
            if isinstance(g, kind):
                return g
        raise KeyError(f"the problem has no {kind.__name__}")

    # --- vectorised factors (fast path) -----------------------------------
    def terms(self, states: np.ndarray, params: np.ndarray) -> list[Term]:
        """All factors, whitened, at ``states`` (N, state size) and ``params`` (G,): the groups' terms in order."""
        return [t for group in self.groups for t in group.terms(self, states, params)]

    def process_terms(self, X: np.ndarray, params: np.ndarray) -> list[Term]:
        """Every factor but the measurement's (process, priors, gyroscope, free flight, attitude), whitened."""
        return [t for group in self.groups if not group.measurement for t in group.terms(self, X, params)]

    def rotations(self, states: np.ndarray) -> np.ndarray:
        """Attitudes R_k (N, 3, 3) from the rotation-vector columns of the state."""
        return _so3.exp(states[:, self.AT])

    def retract(self, states: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """``x ⊕ δ``: vector parts added, attitude ``R ← R Exp(δ)`` (right perturbation)."""
        out = states + delta
        if self.layout.attitude:
            out[:, self.AT] = _so3.log(self.rotations(states) @ _so3.exp(delta[:, self.AT]))
        return out

    def cost(self, states: np.ndarray, params: np.ndarray) -> float:
        """Half the sum of squared whitened residuals (GTSAM's graph error)."""
        if self.batch_model.measurement == "quadratic" or self.n_global:
            return 0.5 * sum(float(np.sum(t.residual**2)) for t in self.terms(states, params))
        measured = sum(g.squared_norm(self, states, params) for g in self.groups if g.measurement)
        return 0.5 * (measured + sum(g.squared_norm(self, states, params) for g in self.groups if not g.measurement))

    def log_normaliser(self) -> float:
        """``Σ log σ`` over every row of the model (the Gaussian normaliser of the evidence)."""
        # summed with the groups placed first ahead of the measurement, part by part: the noise tuner's
        # choices can turn on the last bit of this sum (a stiff oscillator axis of a reversal log does)
        ordered = sorted(self.groups, key=lambda g: 0 if g.first else 1)
        total = 0.0
        for group in ordered:
            for part in group.log_normaliser_parts(self):
                total += part
        return total

    # --- the same problem as a GTSAM graph (graph path) -----------------------
    def gtsam_graph(self) -> gtsam.NonlinearFactorGraph:
        """NonlinearFactorGraph of CustomFactors equal to :meth:`terms`."""
        import gtsam

        graph = gtsam.NonlinearFactorGraph()
        for group in self.groups:
            for factor in group.gtsam_factors(self):
                graph.add(factor)
        return graph

    def gtsam_values(self, states: np.ndarray, params: np.ndarray) -> gtsam.Values:
        import gtsam

        values = gtsam.Values()
        for k in range(self.n):
            values.insert(omega_key(k), np.array(states[k, W]))
            values.insert(omega_dot_key(k), np.array(states[k, D]))
            values.insert(specific_force_key(k), np.array(states[k, F]))
            if self.snap:
                values.insert(omega_ddot_key(k), np.array(states[k, A]))
            if self.layout.attitude:
                values.insert(attitude_key(k), gtsam.Rot3(_so3.exp(states[k, self.AT])))
        for name, (sl, key) in self.global_blocks.items():
            values.insert(key, np.array(params[sl]))
        return values

    def gtsam_ordering(self) -> gtsam.Ordering:
        """Elimination order of :meth:`gtsam_graph`: the states sample by sample, then the calibration
        variables (a chain with a border: fill-in stays within neighbouring samples and the border)."""
        import gtsam

        ordering = gtsam.Ordering()
        for k in range(self.n):
            for key in (omega_key(k), omega_dot_key(k), specific_force_key(k)):
                ordering.push_back(key)
            if self.snap:
                ordering.push_back(omega_ddot_key(k))
            if self.layout.attitude:
                ordering.push_back(attitude_key(k))
        for name, (sl, key) in self.global_blocks.items():
            ordering.push_back(key)
        return ordering

    def gtsam_key_dims(self) -> dict[int, int]:
        """Tangent dimension of every variable of :meth:`gtsam_graph`, by key."""
        dims = {}
        for k in range(self.n):
            for key in (omega_key(k), omega_dot_key(k), specific_force_key(k)):
                dims[key] = 3
            if self.snap:
                dims[omega_ddot_key(k)] = 3
            if self.layout.attitude:
                dims[attitude_key(k)] = 3
        for name, (sl, key) in self.global_blocks.items():
            dims[key] = sl.stop - sl.start
        return dims

    def from_gtsam_values(self, values: gtsam.Values) -> tuple[np.ndarray, np.ndarray]:
        states = np.zeros((self.n, self.state_size))
        for k in range(self.n):
            states[k, W] = values.atVector(omega_key(k))
            states[k, D] = values.atVector(omega_dot_key(k))
            states[k, F] = values.atVector(specific_force_key(k))
            if self.snap:
                states[k, A] = values.atVector(omega_ddot_key(k))
            if self.layout.attitude:
                states[k, self.AT] = _so3.log(values.atRot3(attitude_key(k)).matrix())
        params = np.zeros(self.n_global)
        for name, (sl, key) in self.global_blocks.items():
            params[sl] = values.atVector(key)
        return states, params
