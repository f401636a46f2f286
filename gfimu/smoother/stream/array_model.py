"""The fixed-lag smoother's model: the batch smoother's factor groups, streamed.

The key conventions of :mod:`gfimu.factors`: variables ``w``/``d``/``f`` of sample k hold ω [rad/s],
ω̇ [rad/s²] and f [m/s²] in B. What each window engine adds per sample:

- the step from the newest state to the new one (:meth:`ArrayModel.step`, a :class:`Step`): the
  terms of the groups that tie consecutive samples (``FactorGroup.steps``: the motion model, white
  jerk or driven oscillator, and the specific-force random walk of
  :mod:`gfimu.smoother.model.groups`, and such groups given in ``ModelOptions.factor_groups``),
  evaluated by their own vectorised residual and Jacobian on the two samples (:class:`StreamView`)
  with their own noise levels; the gtsam engine adds the rows as one factor
  (:meth:`ArrayModel.add_process`), the numpy engine predicts with the transition they define;
- the accelerometer equation of every sensor (Ho & Lin 2009, eq. 6), with the structure matrix
  (``S [f, ω̇, q(ω)] - y``; :func:`gfimu.factors.accelerometer.make_accelerometer_factor` per sensor
  without ``fast_measurement``), the gyroscope on ω, and the per-sample groups given in the options
  (``FactorGroup.per_sample``), each evaluated on the sample alone (:meth:`ArrayModel.sample_terms`);
- weak priors on the first state of a segment (the first-state prior group's stds).

The accelerometer noise std of every axis can be scaled by ``accel_noise_scale`` (the factor chosen
by :func:`gfimu.smoother.tuning.evidence.tune` with ``tune_accel_noise``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from types import MappingProxyType
from typing import ClassVar, Mapping

import numpy as np

from ... import rigid_body
from ...array import SensorArray
from ...errors import InputError
from ...factors import accelerometer
from ...log import Log
from ..model.parts import delegated
from ..model.groups import BUILT_IN, AccelerometerGroup, FirstStatePriorGroup, GyroscopeGroup
from ..model.noise_levels import NoiseLevels
from ..model.option_groups import ModelGroups
from ..model.layout import KINEMATIC_SIZE, OMEGA, OMEGA_DOT, SPECIFIC_FORCE, StateLayout


class _LazyGtsam:
    """The ``gtsam`` module, imported on first use (the numpy engine and ``gfimu --help`` never need it)."""

    def __getattr__(self, name: str):
        import gtsam as module

        return getattr(module, name)


gtsam = _LazyGtsam()

_W, _D, _F = (ord(c) << 56 for c in "wdf")  # gtsam.Symbol layout: character in the top byte


def keys(k: int) -> tuple[int, int, int]:
    """gtsam keys of ω, ω̇ and f of sample k (``gtsam.symbol('w', k)`` etc.)."""
    return _W | k, _D | k, _F | k


def insert_state(values: gtsam.Values, k: int, omega, omega_dot, f) -> None:
    kw, kd, kf = keys(k)
    values.insert(kw, np.asarray(omega, dtype=float))
    values.insert(kd, np.asarray(omega_dot, dtype=float))
    values.insert(kf, np.asarray(f, dtype=float))


def _linear_factor(noise_model, factor_keys: list[int], residual, jacobians: tuple) -> gtsam.CustomFactor:
    """A factor whose residual ``residual(values)`` is linear in its keys' vectors: the Jacobians, one per
    key, are the constants given, handed to GTSAM as they are (no per-call allocation)."""

    def error(this, values, out):
        r = residual(values)
        if out is not None:
            for i, J in enumerate(jacobians):
                out[i] = J
        return r

    return gtsam.CustomFactor(noise_model, factor_keys, error)


@dataclass(frozen=True, eq=False)
class StreamView:
    """Samples of a stream seen as a problem of one sample (a per-sample group's terms) or of the two
    samples of a step (a step group's terms): a :class:`gfimu.smoother.model.noise_levels.ModelView`, as the
    batch smoother's :class:`gfimu.smoother.model.problem.SmootherProblem` is, and nothing else. It holds the
    array, the model's option groups, the step lengths, the samples (their :attr:`log`, made when a group asks
    for it) and the noise levels that the groups' own :meth:`~gfimu.smoother.model.factor_group.FactorGroup.noise`
    give on it (:meth:`with_levels`); the stream's model is fixed (white jerk or the driven oscillator: the state
    ``[ω, ω̇, f]``, no attitude, no calibration variables; the gyroscope is the window engines' own)."""

    array: SensorArray
    options: ModelGroups
    """The option groups of the model (:class:`~gfimu.smoother.model.option_groups.ModelGroups`), read by their names."""
    dt_s: np.ndarray
    """(n - 1,) step lengths [s]: none for a view of one sample, one for a step."""
    samples: tuple
    """(timestamps [ns] (n,), accelerometer readings or None, gyroscope readings or None) of the samples."""
    noise: NoiseLevels = NoiseLevels()

    layout: ClassVar[StateLayout] = StateLayout()
    use_gyro: ClassVar[bool] = False
    use_inclinometer: ClassVar[bool] = False
    n_global: ClassVar[int] = 0
    global_blocks: ClassVar[Mapping] = MappingProxyType({})

    model = delegated("options", "model", "The model (:class:`~gfimu.smoother.model.option_groups.ModelOptions`).")
    batch_model = delegated("options", "batch_model", "The batch model (:class:`BatchModelOptions`).")
    attitude = delegated("options", "attitude", "The attitude (:class:`AttitudeOptions`; never on in a stream).")
    self_calibration = delegated("options", "self_calibration", (
        "The self-calibration (:class:`SelfCalibrationOptions`; never on in a stream)."))

    @classmethod
    def of(cls, array: SensorArray, options: ModelGroups, timestamps_ns, accel=None,
           gyro=None, dt_s: np.ndarray | None = None) -> StreamView:
        """The view of the samples at ``timestamps_ns`` (one or two) with these readings (None: zeros, no
        gyroscope); ``dt_s``: their step length (default: from the timestamps)."""
        timestamps_ns = np.asarray(timestamps_ns, dtype=np.int64)
        dt_s = np.diff(timestamps_ns) * 1e-9 if dt_s is None else np.asarray(dt_s, dtype=float)
        return cls(array, options, dt_s, (timestamps_ns, accel, gyro))

    @property
    def n(self) -> int:
        """Samples in the view (1 or 2)."""
        return len(self.dt_s) + 1

    @cached_property
    def log(self) -> Log:
        """The view's samples as a log (made when a group asks for it)."""
        timestamps_ns, accel, gyro = self.samples
        n, m = self.n, len(self.array.accel_columns)
        accel = np.zeros((n, m)) if accel is None else np.asarray(accel, dtype=float).reshape(n, -1)
        gyro = None if gyro is None else np.asarray(gyro, dtype=float).reshape(n, 3)
        return Log(self.array, timestamps_ns, accel, gyro_b_radps=gyro, source="fixed-lag stream")

    def with_levels(self, groups) -> StreamView:
        """The view with the noise levels of ``groups`` (:meth:`NoiseLevels.gather` on this view)."""
        return replace(self, noise=NoiseLevels.gather(groups, self))

    def global_part(self, params: np.ndarray, name: str) -> None:
        return None


@dataclass(frozen=True)
class Step:
    """The process from one sample's state x0 = [ω, ω̇, f] to the next one's, x1, as the step groups give it.

    Their whitened rows, ``r(x0, x1) ≈ r0 + J0 x0 + J1 x1`` (exact for linear groups, else their
    linearisation at the newest state and its prediction), are the factor between the two states
    (the gtsam engine adds them as they are). Minimising them over x1 for a given x0 is the
    transition the numpy engine predicts with: with ``J1 = [Q1 Q2] [R1; 0]`` (QR),
    ``x1 = F x0 + c + n``, ``F = -R1⁻¹ Q1ᵀ J0``, ``c = -R1⁻¹ Q1ᵀ r0``, ``n ~ N(0, Q)``,
    ``Q = R1⁻¹ R1⁻ᵀ``; the rows that x1 cannot absorb, ``Q2ᵀ (r0 + J0 x0)``, are a measurement of x0
    alone (``H0 x0 = z0``, unit noise; none for the built-in motion model and specific-force walk,
    whose J1 is square). For the white jerk this is ``F = [[I, h I], [0, I]]``,
    ``Q = [[σ_int² + h²/4 σ_ω̇², h/2 σ_ω̇²], [h/2 σ_ω̇², σ_ω̇²]]`` per axis; for the oscillator
    Φ and its covariance (``tests/test_fixed_lag.py`` checks both)."""

    J0: np.ndarray
    J1: np.ndarray
    r0: np.ndarray
    F: np.ndarray
    FT: np.ndarray
    Q: np.ndarray
    c: np.ndarray | None
    H0: np.ndarray | None
    z0: np.ndarray | None

    @classmethod
    def of(cls, J0: np.ndarray, J1: np.ndarray, r0: np.ndarray) -> Step:
        rows, size = J1.shape
        if rows < size:
            raise InputError(f"the step groups give {rows} rows on the next state's {size} values: the fixed-lag "
                             "smoother cannot predict it")
        if rows == size:  # no rows left for x0 alone: R1⁻¹ Q1ᵀ = J1⁻¹
            try:
                M = np.linalg.inv(J1)
            except np.linalg.LinAlgError:
                M = np.full((size, size), np.nan)
            if np.all(np.isfinite(M)):
                Q = M @ M.T
                F = -M @ J0
                return cls(J0, J1, r0, F, np.ascontiguousarray(F.T), 0.5 * (Q + Q.T),
                           None if not np.any(r0) else -M @ r0, None, None)
        Qf, Rf = np.linalg.qr(J1, mode="complete")
        R1, Q1, Q2 = Rf[:size], Qf[:, :size], Qf[:, size:]
        if not np.all(np.isfinite(R1)) or np.min(np.abs(np.diagonal(R1))) <= 1e-12 * max(np.max(np.abs(R1)), 1e-300):
            raise InputError("the step groups leave part of the next state undetermined: the fixed-lag smoother "
                             "cannot predict it")
        R1_inv = np.linalg.inv(R1)
        F = -R1_inv @ (Q1.T @ J0)
        Q = R1_inv @ R1_inv.T
        Q = 0.5 * (Q + Q.T)
        c = None if not np.any(r0) else -R1_inv @ (Q1.T @ r0)
        H0 = z0 = None
        if rows > size:
            H0, z0 = Q2.T @ J0, -(Q2.T @ r0)
            if not np.any(H0) and not np.any(z0):
                H0 = z0 = None
        return cls(J0, J1, r0, F, np.ascontiguousarray(F.T), Q, c, H0, z0)


_ZERO3 = np.zeros(3)

STEP_CACHE_SIZE = 64
"""Step lengths whose built-in steps a model keeps (:meth:`ArrayModel.step`): a recording's clock jitters
over a score of them; beyond this many (irregular timestamps) the cache starts again."""


@dataclass(frozen=True, eq=False, slots=True)
class Structure:
    """The array's geometry as the readings see it: the structure matrix ``S = [S_f, S_ω̇, S_q]`` (Ho & Lin
    2009, eq. 6) by blocks, the weighted pseudo-inverse of its linear part, and every sensor's
    (directions, positions, column slice)."""

    S_lin: np.ndarray  # [f, ω̇] columns
    S_q: np.ndarray
    S_f: np.ndarray
    S_dw: np.ndarray
    pinv_lin_w: np.ndarray  # [f, ω̇] given q(ω), weighted by the accelerometers' noise
    linear_part_observable: bool
    geometry: list  # (directions, positions, column slice) of every accelerometer


@dataclass(frozen=True, eq=False, slots=True)
class Noise:
    """The noise levels of the batch smoother's accelerometer, gyroscope and first-state prior groups on the
    array (the accelerometers' scaled by ``accel_noise_scale``)."""

    accel_sigma_mps2: np.ndarray
    mean_accel_var_mps2: float
    gyro_sigma_radps: float
    first_sigma: np.ndarray


@dataclass(eq=False, slots=True)
class Robust:
    """The robust model of an inconsistent log (:mod:`gfimu.smoother.tuning.model_choice`): the accelerometer
    noise's growth with |ω|, the robust loss's thresholds (0: off) and its name (settable: a window engine
    takes the values it is given, :meth:`WindowFilter.set_model`)."""

    accel_noise_slope_mps2_per_radps: float
    accel_robust_threshold: float
    robust_loss: str
    process_robust_threshold: float


@dataclass(frozen=True, eq=False, slots=True)
class FactorSets:
    """The factor groups by what they tie: one sample (``per_sample``, the options' own) or consecutive
    samples (``steps``, built-in and given; ``fixed_steps`` the built-in linear ones, cached per step
    length, ``other_steps`` the rest, evaluated at every step)."""

    per_sample: tuple
    steps: tuple
    fixed_steps: tuple
    other_steps: tuple


class Caches:
    """What :class:`ArrayModel` builds on first use: the gtsam noise models (``gtsam_noise``, by name) and the
    built-in step rows per step length in ns (``steps``)."""

    __slots__ = ("gtsam_noise", "steps")

    def __init__(self) -> None:
        self.gtsam_noise: dict = {}
        self.steps: dict = {}


class ArrayModel:
    """Precomputed geometry and noise models of one array under the option groups of the model ``options``
    (:class:`~gfimu.smoother.model.option_groups.ModelGroups`: its ``model``, and its ``batch_model``, the robust
    model's noise slope, thresholds and loss, and the measurement).

    Besides ``array``, ``options`` (and its ``model`` and ``batch_model``), ``fast_measurement`` and
    ``accel_noise_scale``, what it holds is in
    four parts (their fields also readable as attributes of the model, e.g. ``model.S_q``):

    - :attr:`structure` (:class:`Structure`): the structure matrix's blocks ``S_lin``, ``S_q``, ``S_f``,
      ``S_dw``, the weighted pseudo-inverse ``pinv_lin_w`` of the linear part and whether that part is
      observable, every sensor's geometry;
    - :attr:`noise` (:class:`Noise`): the accelerometers' stds per axis and their mean variance, the
      gyroscope's std, the first-state prior's stds;
    - :attr:`robust` (:class:`Robust`): the motion-dependent noise slope, the robust thresholds of the
      accelerometers and of the process, the loss;
    - :attr:`factor_sets` (:class:`FactorSets`): the per-sample and the step groups;

    and :attr:`caches` (:class:`Caches`): the gtsam noise models and the step rows per step length."""

    def __init__(self, array: SensorArray, options: ModelGroups, fast_measurement: bool = True,
                 accel_noise_scale: float = 1.0) -> None:
        if not isinstance(options, ModelGroups):
            raise TypeError("ArrayModel(array, options, ...) takes the option groups of the model (ModelGroups)")
        if not (np.isfinite(accel_noise_scale) and accel_noise_scale > 0):
            raise InputError(f"accel_noise_scale must be a positive number, got {accel_noise_scale!r}")
        self.array = array
        self.options = options
        """The option groups of the model, what the factor groups read (:class:`StreamView`)."""
        model, batch_model = options.model, options.batch_model
        self.model = model
        self.batch_model = batch_model
        self.fast_measurement = bool(fast_measurement)
        self.accel_noise_scale = float(accel_noise_scale)
        S = array.structure_matrix()
        S_lin = np.ascontiguousarray(S[:, :6])
        # the accelerometer, gyroscope and first-state noise of the batch smoother's groups, on a view of the array
        levels = StreamView.of(array, self.options, [0]).with_levels((AccelerometerGroup(), FirstStatePriorGroup(),
                                                              GyroscopeGroup())).noise
        sigma = levels.accel.scaled(self.accel_noise_scale).sigma
        wL = S_lin / sigma[:, None]
        self.structure = Structure(S_lin, np.ascontiguousarray(S[:, 6:]), np.ascontiguousarray(S[:, :3]),
                                   np.ascontiguousarray(S[:, 3:6]), np.linalg.pinv(wL, rcond=1e-10) / sigma[None, :],
                                   np.linalg.matrix_rank(wL) == 6, accelerometer.array_geometry(array))
        self.noise = Noise(sigma, float(np.mean(sigma ** 2)), levels.gyro.sigma, levels.first_state.sigma)
        step_groups = tuple(g for g in BUILT_IN + tuple(model.factor_groups) if g.steps)
        fixed_steps = tuple(g for g in step_groups if g.linear and g in BUILT_IN)
        self.factor_sets = FactorSets(tuple(g for g in model.factor_groups if g.per_sample), step_groups,
                                      fixed_steps, tuple(g for g in step_groups if g not in fixed_steps))
        # the robust model of an inconsistent log (gfimu.smoother.tuning.model_choice): the noise grows with |ω| and
        # each axis may be weighted by the robust loss of its whitened residual (the stream's model
        # leaves that off: see gfimu.smoother.stream.model_choice)
        self.robust = Robust(float(batch_model.accel_noise_slope_mps2_per_radps),
                             float(batch_model.accel_robust_threshold) if batch_model.measurement == "accelerometer" else 0.0,
                             batch_model.robust_loss, float(batch_model.process_robust_threshold))
        self.caches = Caches()

    S_lin = delegated("structure", "S_lin", "The structure matrix's [f, ω̇] columns.")
    S_q = delegated("structure", "S_q", "The structure matrix's q(ω) columns.")
    S_f = delegated("structure", "S_f", "The structure matrix's f columns.")
    S_dw = delegated("structure", "S_dw", "The structure matrix's ω̇ columns.")
    pinv_lin_w = delegated("structure", "pinv_lin_w", "[f, ω̇] given q(ω): the weighted pseudo-inverse of S_lin.")
    linear_part_observable = delegated("structure", "linear_part_observable", "Whether S_lin has rank 6.")
    _geometry = delegated("structure", "geometry", "(directions, positions, column slice) of every accelerometer.")
    accel_sigma_mps2 = delegated(
        "noise", "accel_sigma_mps2",
        """The accelerometers' std per axis: :attr:`NoiseLevels.accel` (the option ``default_accel_noise_std_mps2``
        where array.toml gives none) times ``accel_noise_scale``.""")
    mean_accel_var_mps2 = delegated("noise", "mean_accel_var_mps2", "The mean over the axes of their variances [(m/s²)²].")
    gyro_sigma_radps = delegated("noise", "gyro_sigma_radps", "The batch smoother's GyroscopeGroup's std.")
    first_sigma = delegated(
        "noise", "first_sigma",
        "The first-state prior's stds, as the batch smoother's :class:`~gfimu.smoother.model.groups.FirstStatePriorGroup`.")
    accel_noise_slope_mps2_per_radps = delegated("robust", "accel_noise_slope_mps2_per_radps",
                                                 "The accelerometer noise's growth with |ω|.", True)
    accel_robust_threshold = delegated("robust", "accel_robust_threshold",
                                       "The accelerometers' robust threshold (0: off; only with the accelerometer measurement).",
                                       True)
    robust_loss = delegated("robust", "robust_loss", "The robust loss's name.", True)
    process_robust_threshold = delegated("robust", "process_robust_threshold", "The process's robust threshold (0: off).",
                                         True)
    groups = delegated("factor_sets", "per_sample", "The per-sample groups of the options (:meth:`sample_terms`).")
    step_groups = delegated(
        "factor_sets", "steps",
        """The groups that tie consecutive samples, built-in (motion model, specific-force walk) and given
        (:meth:`step`).""")
    _step_cache = delegated("caches", "steps", "The built-in step rows per step length in ns (:meth:`step`).")

    def sample_terms(self, t_ns: int, y: np.ndarray, gyro=None):
        """The per-sample factor groups of the options at one sample: None when none applies there, else a
        function ``x -> (r, J)`` of the state ``[ω, ω̇, f]`` giving their whitened residual rows (R,) and
        Jacobian (R, 9), from each group's :meth:`~gfimu.smoother.model.groups.FactorGroup.terms` on that sample
        alone."""
        per_sample = self.factor_sets.per_sample
        if not per_sample:
            return None
        view = StreamView.of(self.array, self.options, [t_ns], y, gyro)
        groups = [g for g in per_sample if g.applies(view)]
        if not groups:
            return None
        view = view.with_levels(groups)
        none = np.zeros(0)

        def terms(x: np.ndarray):
            rows, jacs = [], []
            for group in groups:
                for t in group.terms(view, np.asarray(x, dtype=float).reshape(1, KINEMATIC_SIZE), none):
                    if t.kind != "unary" or t.jac_global is not None or t.residual.shape[0] > 1:
                        raise InputError(f"factor group {group.name!r}: the fixed-lag smoother streams only terms of one "
                                         "sample's state (unary, no calibration variables)")
                    if t.residual.shape[0]:
                        rows.append(t.residual[0])
                        jacs.append(t.jac["x"][0])
            if not rows:
                return np.zeros(0), np.zeros((0, KINEMATIC_SIZE))
            return np.concatenate(rows), np.vstack(jacs)

        return terms

    def _fixed_step(self, h: float) -> dict:
        """The built-in step groups' rows over one step of ``h`` seconds and the :class:`Step` they make
        (:meth:`step`'s cache entry)."""
        groups = self.factor_sets.fixed_steps
        view = StreamView.of(self.array, self.options, [0, round(h * 1e9)], dt_s=np.array([h])).with_levels(groups)
        zero = np.zeros(KINEMATIC_SIZE)
        rows = self._step_rows(groups, view, zero, zero)
        return {"rows": rows, 1.0: Step.of(*rows[:3])}

    def prepare_steps(self, keys_ns) -> None:
        """The built-in steps of the step lengths ``keys_ns`` [ns] (those another model of the stream met:
        :meth:`step`'s cache keys) made at once, in one view of as many steps: each step's rows are the
        groups' elementwise terms of its own length, the numbers :meth:`step` makes for it alone (a model is
        chosen again every few seconds, and a recording's jittered clock gives a score of step lengths,
        each of which cost the groups' whole machinery, about 0.4 ms, when first met)."""
        cache = self.caches.steps
        keys = [int(k) for k in keys_ns if int(k) > 0 and int(k) not in cache][:STEP_CACHE_SIZE - len(cache)]
        if len(keys) < 2:
            return
        groups = self.factor_sets.fixed_steps
        dt_s = np.array(keys, dtype=np.int64) * 1e-9  # (each h as step() gets it: (t1 - t0) * 1e-9)
        view = StreamView.of(self.array, self.options, np.concatenate([[0], np.cumsum(keys)]),
                             dt_s=dt_s).with_levels(groups)
        X = np.zeros((len(keys) + 1, KINEMATIC_SIZE))
        per_group = []
        for group in groups:
            terms = list(group.terms(view, X, np.zeros(0)))
            if any(t.kind != "binary" or t.jac_global is not None or t.residual.shape[0] != len(keys) for t in terms):
                return  # (rows not one set per step: each step made when first met, by step())
            per_group.append((group, terms))
        for i, key in enumerate(keys):
            rows = self._step_rows(groups, view, X[0], X[1], terms=per_group, step=i)
            cache[key] = {"rows": rows, 1.0: Step.of(*rows[:3])}

    @staticmethod
    def _step_rows(groups, view: StreamView, x0: np.ndarray, x1: np.ndarray, motion_factor: float = 1.0,
                   terms=None, step: int = 0):
        """(J0, J1, r0, motion) of ``groups``' terms on the two-sample ``view`` linearised at (x0, x1): rows
        ``r0 + J0 x0 + J1 x1``, the motion model's rows (``motion``, a mask) divided by ``motion_factor``
        (its stds times it, as :meth:`gfimu.smoother.model.noise_levels.MotionNoise.scaled_steps` in the batch smoother).
        ``terms``: each group's terms on ``view`` made already ((group, terms) pairs; the view then may hold
        several steps, each term binary), of which the rows of step ``step``."""
        X = np.vstack([x0, x1])
        J0s, J1s, rs, motion = [], [], [], []
        if terms is None:
            terms = [(group, group.terms(view, X, np.zeros(0))) for group in groups]
        for group, group_terms in terms:
            scale = 1.0 / motion_factor if group.motion else 1.0
            for t in group_terms:
                if t.jac_global is not None:
                    raise InputError(f"factor group {group.name!r}: the fixed-lag smoother streams no calibration variables")
                if t.kind == "binary":
                    r, J0, J1 = t.residual[step], t.jac["x0"][step], t.jac["x1"][step]
                elif t.kind == "unary":  # rows on one of the two states
                    r, J = t.residual.reshape(-1), t.jac["x"].reshape(-1, KINEMATIC_SIZE)
                    if t.residual.shape[0] == 0:
                        continue
                    on_first = t.first == 0 and t.residual.shape[0] == 1
                    J0, J1 = (J, np.zeros_like(J)) if on_first else (np.zeros_like(J), J)
                else:
                    raise InputError(f"factor group {group.name!r}: the fixed-lag smoother streams only terms of one "
                                     "sample or of two consecutive samples")
                J0s.append(J0 * scale)
                J1s.append(J1 * scale)
                rs.append((r - J0 @ x0 - J1 @ x1) * scale)
                motion.append(np.full(len(r), group.motion))
        if not rs:
            return np.zeros((0, KINEMATIC_SIZE)), np.zeros((0, KINEMATIC_SIZE)), np.zeros(0), np.zeros(0, dtype=bool)
        return np.vstack(J0s), np.vstack(J1s), np.concatenate(rs), np.concatenate(motion)

    def step(self, h: float, motion_factor: float = 1.0, t_ns: tuple[int, int] | None = None, readings=None,
             x0: np.ndarray | None = None, rows: bool = True) -> Step:
        """The process over one step of ``h`` seconds (:class:`Step`) from the step groups' own terms on the
        two samples (:class:`StreamView`): the built-in linear ones (white jerk or driven oscillator,
        specific-force random walk) kept per step length; the others (given in the options) evaluated
        on the samples at ``t_ns`` (their timestamps) with ``readings`` ((accel0, gyro0), (accel1, gyro1)),
        linearised at the newest state ``x0`` and its prediction. ``motion_factor``: the local motion
        density's factor on the motion model's stds (:func:`gfimu.smoother.tuning.model_choice.local_density_factors`).
        ``rows`` False: a step for the numpy engine, which predicts with F, Q and c alone: the rows ``J0, J1,
        r0`` of a step scaled by ``motion_factor`` are then not made (None)."""
        key = round(h * 1e9)
        cache = self.caches.steps
        fixed = cache.get(key)
        sets = self.factor_sets
        if fixed is None:
            fixed = self._fixed_step(h)
            if len(cache) > STEP_CACHE_SIZE:  # irregular timestamps: keep the cache bounded
                cache.clear()
            cache[key] = fixed
        others = None
        if sets.other_steps and t_ns is not None:
            (a0, g0), (a1, g1) = readings if readings is not None else ((None, None), (None, None))
            view = StreamView.of(self.array, self.options, list(t_ns),
                              None if a0 is None else np.vstack([a0, a1]),
                              None if g0 is None or g1 is None else np.vstack([g0, g1]), dt_s=np.array([h]))
            groups = [g for g in sets.other_steps if g.applies(view)]
            if groups:
                view = view.with_levels(groups)
                x0 = np.zeros(KINEMATIC_SIZE) if x0 is None else np.asarray(x0, dtype=float)
                base = fixed[1.0] if motion_factor == 1.0 else Step.of(*self._scaled(fixed["rows"], motion_factor))
                x1 = base.F @ x0 + (0.0 if base.c is None else base.c)
                others = self._step_rows(groups, view, x0, x1, motion_factor)[:3]
        if others is None:
            unit = fixed[1.0]
            if motion_factor == 1.0:
                return unit
            J1 = fixed["rows"][1]
            if unit.H0 is None and J1.shape[0] == J1.shape[1]:  # square J1: F stays, Q = J1⁻¹ diag(1/s²) J1⁻ᵀ
                M = fixed.get("J1_inv")
                if M is None:
                    M = fixed["J1_inv"] = np.linalg.inv(J1)
                from .kernels import scaled_process_noise

                Q = scaled_process_noise(M, np.where(fixed["rows"][3], motion_factor * motion_factor, 1.0))
                J0, J1, r0 = self._scaled(fixed["rows"], motion_factor) if rows else (None, None, None)
                return Step(J0, J1, r0, unit.F, unit.FT, Q, unit.c, None, None)
            return Step.of(*self._scaled(fixed["rows"], motion_factor))
        J0, J1, r0 = self._scaled(fixed["rows"], motion_factor)
        return Step.of(np.vstack([J0, others[0]]), np.vstack([J1, others[1]]), np.concatenate([r0, others[2]]))

    def step_parts(self, h: float):
        """``(F, Q, M, motion)`` of the built-in step over ``h`` seconds as :meth:`step` scales it: the transition,
        the process noise at a motion factor of 1, ``M = J1⁻¹`` and the rows of the motion model (``Q`` at factor
        s is ``M diag(s² on those rows, 1 elsewhere) Mᵀ``); None where a step is not made so (other step groups, rows
        on the newest state alone, an offset, a J1 that is not square). :mod:`gfimu.smoother.stream.block` takes its
        steps from here."""
        if self.factor_sets.other_steps:
            return None
        unit = self.step(h, rows=False)
        fixed = self.caches.steps.get(round(h * 1e9))
        J1 = fixed["rows"][1]
        if unit.H0 is not None or unit.c is not None or J1.shape[0] != J1.shape[1]:
            return None
        M = fixed.get("J1_inv")
        if M is None:
            M = fixed["J1_inv"] = np.linalg.inv(J1)
        return unit.F, unit.Q, M, np.asarray(fixed["rows"][3], dtype=bool)

    @staticmethod
    def _scaled(rows, motion_factor: float):
        """(J0, J1, r0) of the built-in step rows, the motion model's divided by ``motion_factor``."""
        J0, J1, r0, motion = rows
        if motion_factor == 1.0:
            return J0, J1, r0
        scale = np.where(motion, 1.0 / motion_factor, 1.0)
        return J0 * scale[:, None], J1 * scale[:, None], r0 * scale

    # --- gtsam noise models (built on first use) --------------------------------------
    @property
    def accel_noise(self):
        cache = self.caches.gtsam_noise
        if "accel" not in cache:
            cache["accel"] = gtsam.noiseModel.Diagonal.Sigmas(self.noise.accel_sigma_mps2)
        return cache["accel"]

    @property
    def sensors(self) -> list:
        """(directions, positions, column slice, gtsam noise model) of every accelerometer."""
        cache, sigma = self.caches.gtsam_noise, self.noise.accel_sigma_mps2
        if "sensors" not in cache:
            cache["sensors"] = [(d, p, cols, gtsam.noiseModel.Diagonal.Sigmas(sigma[cols]))
                                for d, p, cols in self.structure.geometry]
        return cache["sensors"]

    @property
    def gyro_noise(self):
        cache = self.caches.gtsam_noise
        if "gyro" not in cache:
            cache["gyro"] = gtsam.noiseModel.Isotropic.Sigma(3, self.noise.gyro_sigma_radps)
        return cache["gyro"]

    # --- factors ----------------------------------------------------------------
    def add_measurement(self, graph: gtsam.NonlinearFactorGraph, k: int, y: np.ndarray, gyro=None, extra=None) -> None:
        """The readings of sample k (and ``extra``, :meth:`sample_terms` of the sample, when given)."""
        kw, kd, kf = keys(k)
        if extra is not None:
            rows = extra(np.zeros(KINEMATIC_SIZE))[0].size
            if rows:
                graph.add(self._group_factor(kw, kd, kf, rows, extra))
        y = np.array(y, dtype=float)
        if self.fast_measurement:
            graph.add(self._fast_accelerometer_factor(kw, kd, kf, y))
        else:
            for d, p, cols, noise in self.sensors:
                graph.add(accelerometer.make_accelerometer_factor(kw, kd, kf, y[cols], d, p, noise))
        if gyro is not None:
            graph.add(gtsam.PriorFactorVector(kw, np.asarray(gyro, dtype=float), self.gyro_noise))

    def _group_factor(self, kw: int, kd: int, kf: int, rows: int, extra) -> gtsam.CustomFactor:
        """The factor groups' whitened rows at one sample as one factor (unit noise)."""

        def error(this, values, jacobians):
            r, J = extra(np.concatenate([values.atVector(kw), values.atVector(kd), values.atVector(kf)]))
            if jacobians is not None:
                jacobians[0] = J[:, OMEGA]
                jacobians[1] = J[:, OMEGA_DOT]
                jacobians[2] = J[:, SPECIFIC_FORCE]
            return r

        return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(rows), [kw, kd, kf], error)

    def _fast_accelerometer_factor(self, kw: int, kd: int, kf: int, y: np.ndarray) -> gtsam.CustomFactor:
        """All axes at once: ``S_f f + S_ω̇ ω̇ + S_q q(ω) - y`` (Ho & Lin 2009, eq. 6)."""
        structure = self.structure
        S_q, S_f, S_dw = structure.S_q, structure.S_f, structure.S_dw

        def error(this, values, jacobians):
            w = values.atVector(kw)
            x, yy, z = w
            q = np.array([x * x + yy * yy, x * x + z * z, yy * yy + z * z, x * yy, x * z, yy * z])
            r = S_f @ values.atVector(kf) + S_dw @ values.atVector(kd) + S_q @ q - y
            if jacobians is not None:
                jacobians[0] = S_q @ rigid_body.quadratic_terms_jacobian(w)
                jacobians[1] = S_dw
                jacobians[2] = S_f
            return r

        return gtsam.CustomFactor(self.accel_noise, [kw, kd, kf], error)

    def add_process(self, graph: gtsam.NonlinearFactorGraph, k0: int, k1: int, step: Step | float) -> None:
        """The step groups' rows between samples k0 and k1 (a :class:`Step`, or a step length in seconds:
        :meth:`step` of the built-in groups) as one factor on their ω, ω̇, f: ``r0 + J0 x0 + J1 x1``,
        whitened (unit noise), its Jacobians the step's constants."""
        if not isinstance(step, Step):
            step = self.step(float(step))
        k0_keys, k1_keys = keys(k0), keys(k1)
        J0, J1, r0 = step.J0, step.J1, step.r0
        jacobians = tuple(np.ascontiguousarray(J[:, sl]) for J in (J0, J1) for sl in (OMEGA, OMEGA_DOT, SPECIFIC_FORCE))
        factor_keys = list(k0_keys) + list(k1_keys)

        def residual(values):
            x0 = np.concatenate([values.atVector(k) for k in k0_keys])
            x1 = np.concatenate([values.atVector(k) for k in k1_keys])
            return r0 + J0 @ x0 + J1 @ x1

        graph.add(_linear_factor(gtsam.noiseModel.Unit.Create(len(r0)), factor_keys, residual, jacobians))

    def add_priors(self, graph: gtsam.NonlinearFactorGraph, k: int) -> None:
        """Weak zero-mean priors on the first state of a segment (:attr:`first_sigma`, the batch smoother's
        first-state prior)."""
        first_sigma = self.noise.first_sigma
        for key, sl in zip(keys(k), (OMEGA, OMEGA_DOT, SPECIFIC_FORCE)):
            graph.add(gtsam.PriorFactorVector(key, _ZERO3, gtsam.noiseModel.Diagonal.Sigmas(first_sigma[sl])))

    # --- initial values ---------------------------------------------------------
    def predict(self, omega, omega_dot, f, h: float, y: np.ndarray):
        """Initial value of a new state: ω by one step of ω̇, then [f, ω̇] from y given q(ω)."""
        w = omega + h * omega_dot
        structure = self.structure
        if not structure.linear_part_observable:
            return w, omega_dot, f
        x6 = structure.pinv_lin_w @ (y - structure.S_q @ rigid_body.quadratic_terms(w))
        return w, x6[3:], x6[:3]

    def predict_step(self, step: Step, x0: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Initial value of the state one ``step`` after ``x0``: ω by the step's transition, then [f, ω̇]
        from y given q(ω)."""
        x = step.F @ x0 if step.c is None else step.F @ x0 + step.c
        structure = self.structure
        if not structure.linear_part_observable:
            return x
        x6 = structure.pinv_lin_w @ (y - structure.S_q @ rigid_body.quadratic_terms(x[OMEGA]))
        return np.concatenate([x[OMEGA], x6[3:], x6[:3]])
