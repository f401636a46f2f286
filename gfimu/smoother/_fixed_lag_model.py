"""Factors and initial values of the fixed-lag smoother.

The same model as the batch smoother (:mod:`gfimu.smoother.graph`), with the
key conventions of :mod:`gfimu.factors`: variables ``w``/``d``/``f`` of sample
k hold ω [rad/s], ω̇ [rad/s²] and f [m/s²] in B.

- accelerometer equation of every sensor (paper 000, eq. 6):
  :func:`gfimu.factors.accelerometer.make_accelerometer_factor`, or, with
  ``fast_measurement``, one factor for all axes computing the same residual
  and Jacobian with the structure matrix (``S [f, ω̇, q(ω)] - y``);
- trapezoid ``ω_{k+1} = ω_k + h/2 (ω̇_k + ω̇_{k+1})``:
  :func:`gfimu.factors.kinematics.make_angular_velocity_factor` (or the same
  residual with preallocated Jacobians with ``fast_measurement``);
- random walks of ω̇ and f (``x_{k+1} - x_k``, the residual of
  :mod:`gfimu.factors.process`) and priors as gtsam's own
  ``BetweenFactorVector`` / ``PriorFactorVector``, evaluated without Python;
- gyroscope on ω (residual ``ω - ω_meas``) as a ``PriorFactorVector``;
- with ``process_axis_frequencies_hz`` set, the exact oscillator step of
  (ω, ω̇) (:func:`gfimu.factors.process.oscillator_residual`) in place of the
  trapezoid and the ω̇ random walk;
- the factor groups given in ``SmootherOptions.factor_groups``
  (:mod:`gfimu.smoother.groups`, those ``per_sample``), each evaluated on each
  sample alone (:class:`SampleProblem`) from the same vectorised residual and
  Jacobian the batch smoother uses (:meth:`ArrayModel.sample_terms`).

The process noise follows the options exactly as the batch smoother's
:class:`~gfimu.smoother.graph.SmootherProblem` does: the trapezoid and ω̇
random-walk stds are scaled per body axis by ``process_axis_factors``; the
accelerometer noise std of every axis can be scaled by ``accel_noise_scale``
(the factor chosen by :func:`gfimu.smoother.tuning.tune` with ``tune_accel_noise``).
"""

from __future__ import annotations

import numpy as np

from .. import noise, rigid_body
from ..array import SensorArray
from ..errors import InputError
from ..factors import accelerometer, kinematics, process
from ..log import Log
from .graph import SmootherOptions
from .layout import KINEMATIC_SIZE, OMEGA, OMEGA_DOT, SPECIFIC_FORCE, StateLayout


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


class SampleProblem:
    """One sample of a stream seen as a problem of one sample, what a factor group is evaluated on
    (the attributes of :class:`gfimu.smoother.graph.SmootherProblem` a per-sample group reads: its
    one-sample ``log``, ``options``, ``n``, ``layout``, ``state_size``, no calibration variables)."""

    def __init__(self, array: SensorArray, options: SmootherOptions, t_ns: int, y: np.ndarray, gyro=None) -> None:
        self.log = Log(array, np.array([t_ns], dtype=np.int64), np.asarray(y, dtype=float)[None],
                       gyro_b_radps=None if gyro is None else np.asarray(gyro, dtype=float)[None], source="fixed-lag stream")
        self.options = options
        self.n = 1
        self.dt_s = np.zeros(0)
        self.layout = StateLayout()
        self.state_size = self.layout.size
        self.snap = self.attitude = False
        self.n_global = 0
        self.global_blocks: dict = {}

    def global_part(self, params: np.ndarray, name: str) -> None:
        return None


class ArrayModel:
    """Precomputed geometry and noise models of one array under ``SmootherOptions``."""

    def __init__(self, array: SensorArray, options: SmootherOptions, fast_measurement: bool = True,
                 accel_noise_scale: float = 1.0) -> None:
        if not (np.isfinite(accel_noise_scale) and accel_noise_scale > 0):
            raise InputError(f"accel_noise_scale must be a positive number, got {accel_noise_scale!r}")
        self.array = array
        self.options = options
        self.fast_measurement = bool(fast_measurement)
        self.accel_noise_scale = float(accel_noise_scale)
        S = array.structure_matrix()
        self.S_lin = np.ascontiguousarray(S[:, :6])  # [f, ω̇] columns
        self.S_q = np.ascontiguousarray(S[:, 6:])
        self.S_f = np.ascontiguousarray(S[:, :3])
        self.S_dw = np.ascontiguousarray(S[:, 3:6])
        sigma = noise.accel_noise_std(array, options.default_accel_noise_std_mps2)
        sigma = sigma * self.accel_noise_scale
        self.accel_sigma_mps2 = sigma
        self._geometry = accelerometer.array_geometry(array)  # (directions, positions, column slice)
        self._gtsam_noise: dict = {}
        wL = self.S_lin / sigma[:, None]
        self.pinv_lin_w = np.linalg.pinv(wL, rcond=1e-10) / sigma[None, :]  # [f, ω̇] given q(ω)
        self.linear_part_observable = np.linalg.matrix_rank(wL) == 6
        self._zero3 = np.zeros(3)
        self._eye3 = np.eye(3)
        self._noise_cache: dict = {}
        self.axis_factors = np.asarray(options.process_axis_factors, dtype=float)
        self.natural_frequency_radps = 2.0 * np.pi * np.asarray(options.process_axis_frequencies_hz, dtype=float)
        self.oscillator = bool(np.any(self.natural_frequency_radps > 0))
        self.gyro_sigma_radps = float(noise.gyro_noise_std(array))  # as the batch smoother
        self.groups = tuple(options.factor_groups)
        # the robust model of an inconsistent log (gfimu.smoother.auto): the noise grows with |ω| and
        # each axis may be weighted by the robust loss of its whitened residual (the stream's model
        # leaves that off: see gfimu.smoother.stream_model)
        self.accel_noise_slope_mps2_per_radps = float(options.accel_noise_slope_mps2_per_radps)
        self.accel_robust_threshold = float(options.accel_robust_threshold) if options.measurement == "accelerometer" else 0.0
        self.robust_loss = options.robust_loss
        self.process_robust_threshold = float(options.process_robust_threshold)

    def sample_terms(self, t_ns: int, y: np.ndarray, gyro=None):
        """The factor groups of the options at one sample: None when none applies there, else a function
        ``x -> (r, J)`` of the state ``[ω, ω̇, f]`` giving their whitened residual rows (R,) and Jacobian
        (R, 9), from each group's :meth:`~gfimu.smoother.groups.FactorGroup.terms` on that sample alone."""
        if not self.groups:
            return None
        view = SampleProblem(self.array, self.options, t_ns, y, gyro)
        groups = [g for g in self.groups if g.applies(view)]
        if not groups:
            return None
        for group in groups:
            group.setup(view)
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

    # --- gtsam noise models (built on first use) --------------------------------------
    @property
    def accel_noise(self):
        if "accel" not in self._gtsam_noise:
            self._gtsam_noise["accel"] = gtsam.noiseModel.Diagonal.Sigmas(self.accel_sigma_mps2)
        return self._gtsam_noise["accel"]

    @property
    def sensors(self) -> list:
        """(directions, positions, column slice, gtsam noise model) of every accelerometer."""
        if "sensors" not in self._gtsam_noise:
            self._gtsam_noise["sensors"] = [(d, p, cols, gtsam.noiseModel.Diagonal.Sigmas(self.accel_sigma_mps2[cols]))
                                            for d, p, cols in self._geometry]
        return self._gtsam_noise["sensors"]

    @property
    def gyro_noise(self):
        if "gyro" not in self._gtsam_noise:
            self._gtsam_noise["gyro"] = gtsam.noiseModel.Isotropic.Sigma(3, self.gyro_sigma_radps)
        return self._gtsam_noise["gyro"]

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
        """All axes at once: ``S_f f + S_ω̇ ω̇ + S_q q(ω) - y`` (paper 000, eq. 6)."""
        S_q, S_f, S_dw = self.S_q, self.S_f, self.S_dw

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

    def _fast_trapezoid_factor(self, w0: int, w1: int, d0: int, d1: int, h: float, noise) -> gtsam.CustomFactor:
        """``ω1 - ω0 - h/2 (ω̇0 + ω̇1)`` with its constant Jacobians, without per-call allocation."""
        half_h = 0.5 * h
        jd = -half_h * self._eye3

        def residual(values):
            return values.atVector(w1) - values.atVector(w0) - half_h * (values.atVector(d0) + values.atVector(d1))

        return _linear_factor(noise, [w0, w1, d0, d1], residual, (-self._eye3, self._eye3, jd, jd))

    def _fast_oscillator_factor(self, w0: int, w1: int, d0: int, d1: int, h: float, noise) -> gtsam.CustomFactor:
        """Exact oscillator step ``[ω1; ω̇1] - Φ [ω0; ω̇0]`` (:func:`gfimu.factors.process.oscillator_residual`)
        with its constant Jacobians."""
        phi = process.oscillator_transition(h, self.natural_frequency_radps)[0]
        a, b, c, d = phi[:, 0, 0], phi[:, 0, 1], phi[:, 1, 0], phi[:, 1, 1]
        top = np.vstack([self._eye3, np.zeros((3, 3))])
        bottom = np.vstack([np.zeros((3, 3)), self._eye3])
        jw0 = -np.vstack([np.diag(a), np.diag(c)])
        jd0 = -np.vstack([np.diag(b), np.diag(d)])

        def residual(values):
            x0, y0 = values.atVector(w0), values.atVector(d0)
            return np.concatenate([values.atVector(w1) - a * x0 - b * y0, values.atVector(d1) - c * x0 - d * y0])

        return _linear_factor(noise, [w0, w1, d0, d1], residual, (jw0, top, jd0, bottom))

    def _process_noises(self, h: float):
        key = round(h * 1e9)
        cached = self._noise_cache.get(key)
        if cached is None:
            o = self.options
            q_dw = o.omega_dot_random_walk_radps2_per_sqrt_s
            axis = self.axis_factors  # per body axis, as SmootherProblem
            cached = (
                gtsam.noiseModel.Diagonal.Sigmas(float(kinematics.trapezoid_sigma(q_dw, h)) * axis),
                gtsam.noiseModel.Diagonal.Sigmas(float(process.random_walk_sigma(q_dw, h)) * axis),
                gtsam.noiseModel.Isotropic.Sigma(
                    3, float(process.random_walk_sigma(o.specific_force_random_walk_mps2_per_sqrt_s, h))),
                gtsam.noiseModel.Gaussian.Covariance(
                    process.oscillator_step_covariance(q_dw, h, self.natural_frequency_radps, axis)[0])
                if self.oscillator else None,
            )
            if len(self._noise_cache) > 64:  # irregular timestamps: keep the cache bounded
                self._noise_cache.clear()
            self._noise_cache[key] = cached
        return cached

    def add_process(self, graph: gtsam.NonlinearFactorGraph, k0: int, k1: int, h: float) -> None:
        w0, d0, f0 = keys(k0)
        w1, d1, f1 = keys(k1)
        int_noise, dw_noise, f_noise, osc_noise = self._process_noises(h)
        if self.oscillator:
            if self.fast_measurement:
                graph.add(self._fast_oscillator_factor(w0, w1, d0, d1, h, osc_noise))
            else:
                graph.add(process.make_oscillator_factor(w0, w1, d0, d1, h, self.natural_frequency_radps, osc_noise))
            graph.add(gtsam.BetweenFactorVector(f0, f1, self._zero3, f_noise))
            return
        if self.fast_measurement:
            graph.add(self._fast_trapezoid_factor(w0, w1, d0, d1, h, int_noise))
        else:
            graph.add(kinematics.make_angular_velocity_factor(w0, w1, d0, d1, h, int_noise))
        graph.add(gtsam.BetweenFactorVector(d0, d1, self._zero3, dw_noise))
        graph.add(gtsam.BetweenFactorVector(f0, f1, self._zero3, f_noise))

    def add_priors(self, graph: gtsam.NonlinearFactorGraph, k: int) -> None:
        """Weak zero-mean priors on the first state of a segment, as the batch smoother."""
        o = self.options
        kw, kd, kf = keys(k)
        for key, std in ((kw, o.initial_omega_std_radps), (kd, o.initial_omega_dot_std_radps2),
                         (kf, o.initial_specific_force_std_mps2)):
            graph.add(gtsam.PriorFactorVector(key, self._zero3, gtsam.noiseModel.Isotropic.Sigma(3, float(std))))

    # --- initial values ---------------------------------------------------------
    def predict(self, omega, omega_dot, f, h: float, y: np.ndarray):
        """Initial value of a new state: ω by one step of ω̇, then [f, ω̇] from y given q(ω)."""
        w = omega + h * omega_dot
        if not self.linear_part_observable:
            return w, omega_dot, f
        x6 = self.pinv_lin_w @ (y - self.S_q @ rigid_body.quadratic_terms(w))
        return w, x6[3:], x6[:3]
