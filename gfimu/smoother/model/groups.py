"""Factor groups: the smoother's model as one list of equations, each written once for every consumer.

A group gives, for a :class:`gfimu.smoother.model.problem.SmootherProblem`,

- :meth:`FactorGroup.noise`: its noise levels from the options and the log, a typed frozen value
  (:mod:`gfimu.smoother.model.noise_levels`: :class:`AccelNoise`, :class:`MotionNoise`, ...) gathered by the
  problem into one :class:`NoiseLevels` and read back under its field (``problem.noise.accel.sigma``,
  ``problem.noise.motion.trapezoid_sigma``); re-weighted by making a new problem,
- :meth:`FactorGroup.terms`: its whitened residuals and analytic Jacobians over all samples at
  once (vectorised; the batch solver and the tuner's normal equations),
- :meth:`FactorGroup.gtsam_factors`: the same residuals as GTSAM factors (the graph path),
- :meth:`FactorGroup.log_normaliser`: ``Σ log σ`` over its rows (the tuner's evidence),

so the batch solver, the noise tuner, the bound and the GTSAM graph read one definition. The
model (:data:`BUILT_IN`, in the order the problem adds them): the accelerometer measurement (Ho &
Lin 2009, eq. 6) or the per-sample inversion ('quadratic'), the first-state prior, the specific-force
random walk or, with the attitude, the attitude kinematics (Li et al. 2021, eqs. 9-10 on SO(3)), the
random walk of the gravity-free acceleration and the attitude prior; the motion model (white jerk:
trapezoid kinematics and the ω̇ random walk, the driven oscillator, or white snap), the gyroscope
(Lu, Tsai & Lin 2010), free flight (McGinnis, Perkins & King 2012, eq. 1), the inclinometer (Lu, Tsai & Lin 2010) and the calibration
priors. Further groups are given with ``SmootherOptions.factor_groups`` and reach every consumer
without changing any of them; those whose terms are per sample (``per_sample``) or tie two
consecutive samples (``steps``) also reach the fixed-lag smoother (:mod:`gfimu.smoother.stream.fixed_lag`),
which evaluates them on each sample alone or on the two samples of each step, as it does the
built-in motion model and specific-force walk. What a group may read of the problem it is given is
:class:`gfimu.smoother.model.noise_levels.ModelView`.
"""

from __future__ import annotations

import sys

import numpy as np

from ... import noise
from ...errors import DataError, InputError
from ...factors import (
    accelerometer,
    attitude_key,
    diagonal_noise,
    euler,
    free_fall,
    gaussian_noise,
    gravity,
    gyroscope,
    inclinometer,
    kinematics,
    omega_ddot_key,
    omega_dot_key,
    omega_key,
    process,
    quadratic,
    specific_force_key,
)
from .factor_group import FactorGroup, Term  # noqa: F401  (both also importable from here)
from .layout import KINEMATIC_SIZE, OMEGA, OMEGA_DDOT, OMEGA_DOT, SPECIFIC_FORCE

def _kernels_here(group) -> bool:
    """Whether ``group`` runs its compiled kernels (:mod:`gfimu.smoother.model.kernels`): its ``compiled`` on,
    in a process that has loaded numba."""
    return group.compiled and "numba" in sys.modules


def _kernel_whitening(problem) -> np.ndarray:
    """The accelerometer whitening ``1 / σ`` as the kernels take it: (1, axes) for every sample, or (N,
    axes) per sample."""
    accel = problem.noise.accel
    return (1.0 / accel.sigma)[None, :] if accel.per_sample is None else 1.0 / accel.per_sample
from .noise_levels import (
    AccelNoise,
    AttitudeNoise,
    CalibrationNoise,
    FirstStateNoise,
    ForceWalkNoise,
    FreeFlightNoise,
    GyroNoise,
    InversionNoise,
    ModelView,
    MotionNoise,
    TiltNoise,
)


def _contiguous(a: np.ndarray) -> np.ndarray:
    """``a`` as a writable C-contiguous float array (a copy only where it is not one): the one array type
    the compiled kernels are compiled for."""
    a = np.ascontiguousarray(a, dtype=float)
    return a if a.flags.writeable else a.copy()


def unary_jacobian(problem, blocks: list[tuple[slice, np.ndarray]], rows: int, n: int) -> np.ndarray:
    """(n, rows, state size) Jacobian with the given (n, rows, 3) blocks at their state columns."""
    J = np.zeros((n, rows, problem.layout.size))
    for sl, block in blocks:
        J[:, :, sl] = block
    return J


class FirstStatePriorGroup(FactorGroup):
    """Weak zero-mean priors on the first sample's motion states ``[ω, ω̇, f(, ω̈)]`` (stds
    ``problem.noise.first_state.sigma``), keeping the normal equations definite."""

    name = "first-state prior"
    first = True
    per_sample = False

    def noise(self, problem: ModelView) -> FirstStateNoise:
        model = problem.model
        first = np.repeat([model.initial_omega_std_radps, model.initial_omega_dot_std_radps2,
                           model.initial_specific_force_std_mps2], 3)
        if problem.layout.snap:
            first = np.concatenate([first, np.full(3, 100.0 * model.initial_omega_dot_std_radps2)])
        return FirstStateNoise(first)

    def terms(self, problem, states, params):
        mk = problem.layout.motion_size
        r, _ = process.prior_residual(states[:1, :mk], np.zeros(mk))
        J = np.zeros((1, mk, problem.layout.size))
        sigma = problem.noise.first_state.sigma
        J[0, :, :mk] = np.diag(1.0 / sigma)
        return [Term("unary", r / sigma, {"x": J}, None, first=0)]

    def gtsam_factors(self, problem):
        pairs = [(omega_key(0), OMEGA), (omega_dot_key(0), OMEGA_DOT), (specific_force_key(0), SPECIFIC_FORCE)]
        if problem.layout.snap:
            pairs.append((omega_ddot_key(0), OMEGA_DDOT))
        sigma = problem.noise.first_state.sigma
        return [process.make_prior_factor(key, np.zeros(3), diagonal_noise(sigma[sl])) for key, sl in pairs]

    def log_normaliser(self, problem):
        return float(np.sum(np.log(problem.noise.first_state.sigma)))


def _columns(columns: slice) -> np.ndarray:
    """The state columns of a slice as an index array (for the diagonal entries of a block)."""
    return np.arange(columns.start, columns.stop)


def _padded(blocks: list[np.ndarray], state_size: int) -> np.ndarray:
    """Jacobian blocks over ``[ω, ω̇, f]`` with zero columns for the rest of the state."""
    return np.concatenate(blocks + [np.zeros_like(blocks[-1])] * ((state_size - KINEMATIC_SIZE) // 3), axis=2)


def _binary(problem, rows: int, pairs: list[tuple[slice, np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """(N-1, rows, state size) Jacobians of a step on samples k and k+1, blocks ``(columns, d/dx_k, d/dx_k+1)``."""
    J0 = np.zeros((problem.n - 1, rows, problem.layout.size))
    J1 = np.zeros((problem.n - 1, rows, problem.layout.size))
    for sl, j0, j1 in pairs:
        J0[:, :, sl], J1[:, :, sl] = j0, j1
    return J0, J1


class _ArrayMeasurementGroup(FactorGroup):
    """The array's measurement in the form ``batch_model.measurement`` names (``formulation``), over every
    sample, with the accelerometers' noise ``problem.noise.accel`` (array.toml, or the option
    ``default_accel_noise_std_mps2``: :func:`gfimu.noise.accel_noise_std`)."""

    formulation = ""
    measurement = True
    per_sample = False

    def applies(self, problem) -> bool:
        return problem.batch_model.measurement == self.formulation

    def noise(self, problem: ModelView) -> AccelNoise:
        return AccelNoise(noise.accel_noise_std(problem.array, problem.model.default_accel_noise_std_mps2))


class AccelerometerGroup(_ArrayMeasurementGroup):
    """The accelerometer equation of every sensor at every sample (Ho & Lin 2009, eq. 6), with the
    per-axis biases and scale-factor errors when self-calibrating. Noise: ``problem.noise.accel``
    (:class:`~gfimu.smoother.model.noise_levels.AccelNoise`: ``sigma`` from array.toml or the option
    ``default_accel_noise_std_mps2``, or ``per_sample`` when set: motion-dependent noise, robust
    re-weighting)."""

    name = "accelerometer"
    formulation = "accelerometer"

    def terms(self, problem, states, params):
        return [self.term(problem, states, params)]

    @staticmethod
    def _calibrated(problem) -> bool:
        """Whether the problem estimates per-sensor biases or scale factors (then the sensors one by one)."""
        return any(name.startswith(("bias", "scale")) for name in problem.global_blocks)

    def term(self, problem, X: np.ndarray, params: np.ndarray) -> Term:
        if not self._calibrated(problem):
            return self._term_all_axes(problem, X)
        rows = []
        jx = []
        m = problem.layout.size
        jg = np.zeros((problem.n, problem.log.array.n_axes, problem.n_global))
        for i, (d, p, cols) in enumerate(problem.sensors):
            bias = problem.global_part(params, f"bias{i}")
            scale = problem.global_part(params, f"scale{i}")
            r, j = accelerometer.accelerometer_residual(X[:, OMEGA], X[:, OMEGA_DOT], X[:, SPECIFIC_FORCE],
                                                        problem.log.accel_mps2[:, cols], d, p, bias, scale)
            rows.append(r)
            jx.append(_padded([j["w"], j["d"], j["f"]], m))
            if bias is not None:
                jg[:, cols, problem.global_blocks[f"bias{i}"][0]] = j["b"]
            if scale is not None:
                jg[:, cols, problem.global_blocks[f"scale{i}"][0]] = j["s"]
        r = np.concatenate(rows, axis=1)
        w = self._whitening(problem, r.shape)
        r = r * w
        J = np.concatenate(jx, axis=1) * w[:, :, None]
        jg *= w[:, :, None]
        return Term("unary", r, {"x": J}, jg)

    @staticmethod
    def _whitening(problem, shape) -> np.ndarray:
        return problem.noise.accel.whitening(shape)

    def _all_axes(self, problem, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple]:
        """Every axis at once, without per-sensor calibration: the whitened residual (N, axes), the
        whitening (N, axes) and the products of :func:`gfimu.factors.accelerometer.rigid_body_readings`."""
        pred, products = accelerometer.rigid_body_readings(X[:, OMEGA], X[:, OMEGA_DOT], X[:, SPECIFIC_FORCE],
                                                           problem.all_rows, problem.all_directions_b,
                                                           problem.all_positions_m)
        white = self._whitening(problem, pred.shape)
        return (pred - problem.log.accel_mps2) * white, white, products

    def _omega_jacobian(self, problem, X: np.ndarray, products, white: np.ndarray) -> np.ndarray:
        """(N, axes, 3) whitened ∂reading/∂ω of every axis: ``(rᵀω) s + (sᵀω) r - 2 (sᵀr) ω``."""
        return accelerometer.omega_jacobian(X[:, OMEGA], products, problem.all_directions_b,
                                            problem.all_positions_m) * white[:, :, None]

    def _term_all_axes(self, problem, X: np.ndarray) -> Term:
        """:meth:`term` without per-sensor calibration: every axis at once, the whitened Jacobian
        written straight into its columns (the same numbers as
        :func:`gfimu.factors.accelerometer.accelerometer_residual`)."""
        rows = problem.all_rows
        r, white, products = self._all_axes(problem, X)
        J = np.zeros(r.shape + (problem.layout.size,))
        J[:, :, OMEGA] = self._omega_jacobian(problem, X, products, white)
        J[:, :, OMEGA_DOT] = rows[:, 3:6] * white[:, :, None]
        J[:, :, SPECIFIC_FORCE] = rows[:, 0:3] * white[:, :, None]
        jg = np.zeros(r.shape + (problem.n_global,)) if problem.n_global else None
        return Term("unary", r, {"x": J}, jg)

    compiled = True
    """:meth:`accumulate`, :meth:`squared_norm` and :meth:`whitened_residual` through the compiled kernels
    (:mod:`gfimu.smoother.model.kernels`: one pass over the samples) in a process that has loaded numba
    (:mod:`gfimu.smoother.preload`: the fixed-lag smoother's, and the batch smoother's on a log large enough
    to repay numba's start); False, or without numba loaded: the numpy expressions they replace (the tests'
    oracle). The two agree to rounding."""

    def accumulate(self, problem, states, params, diag, lower, grad):
        """Without per-sensor calibration: with whitening w_i of axis i, ``J_i = w_i [∂y_i/∂ω, c_i]``
        where ``c_i`` (the structure-matrix row over ``[ω̇, f]``) is constant, so ``JᵀJ`` is the
        per-sample ω block ``Σ J_ω,iᵀ J_ω,i``, the cross block ``Σ J_ω,iᵀ w_i c_iᵀ`` (one matrix product
        over all samples) and ``Σ w_i² c_i c_iᵀ`` (constant unless the noise varies per sample)."""
        if self._calibrated(problem):
            return None
        if _kernels_here(self):
            return self._accumulate_compiled(problem, states, diag, grad)
        rows = problem.all_rows
        r, white, products = self._all_axes(problem, states)
        n, axes = r.shape
        jw = self._omega_jacobian(problem, states, products, white)  # (N, axes, 3)
        c = np.concatenate([rows[:, 3:6], rows[:, 0:3]], axis=1)  # (axes, 6) over [ω̇, f]
        linear = slice(OMEGA_DOT.start, SPECIFIC_FORCE.stop)  # (the layout keeps ω, ω̇, f side by side)
        jwt = np.swapaxes(jw, 1, 2)
        diag[:, OMEGA, OMEGA] += jwt @ jw
        if problem.noise.accel.per_sample is None:  # one whitening for every sample
            wc = white[0][:, None] * c
            cross = (np.ascontiguousarray(jwt).reshape(n * 3, axes) @ wc).reshape(n, 3, 6)
            diag[:, linear, linear] += wc.T @ wc
            grad[:, linear] += r @ wc
        else:  # Σ_a J_ω,a w_a c_aᵀ as one product of (J_ω w) with c
            jww = np.ascontiguousarray(np.swapaxes(jw * white[:, :, None], 1, 2)).reshape(n * 3, axes)
            cross = (jww @ c).reshape(n, 3, 6)
            diag[:, linear, linear] += ((white * white) @ (c[:, :, None] * c[:, None, :]).reshape(axes, 36)).reshape(n, 6, 6)
            grad[:, linear] += (r * white) @ c
        diag[:, OMEGA, linear] += cross
        diag[:, linear, OMEGA] += np.swapaxes(cross, 1, 2)
        grad[:, OMEGA] += np.einsum("nai,na->ni", jw, r)
        return 0.5 * float(np.sum(r * r)), r.size

    @staticmethod
    def _accumulate_compiled(problem, states, diag, grad) -> tuple[float, int]:
        """:meth:`accumulate` by :func:`gfimu.smoother.model.kernels.accumulate`."""
        from . import kernels

        white = _kernel_whitening(problem)
        y = _contiguous(problem.log.accel_mps2)
        sq = np.empty(y.shape[0])
        kernels.accumulate(_contiguous(states), y, _contiguous(problem.all_directions_b),
                                 _contiguous(problem.all_positions_m), _contiguous(problem.all_rows),
                                 _contiguous(white), diag, grad, sq)
        return 0.5 * float(np.sum(sq)), y.size

    def whitened_residual(self, problem, states, params) -> np.ndarray:
        """(N, axes) whitened residuals, without the Jacobians."""
        if self._calibrated(problem):
            return self.term(problem, states, params).residual
        if _kernels_here(self):
            from . import kernels

            white = _kernel_whitening(problem)
            y = _contiguous(problem.log.accel_mps2)
            out = np.empty(y.shape)
            kernels.whitened_residual(_contiguous(states), _contiguous(problem.all_directions_b),
                                            _contiguous(problem.all_positions_m), _contiguous(problem.all_rows), y,
                                            _contiguous(white), out)
            return out
        return self._all_axes(problem, states)[0]

    def squared_norm(self, problem, states, params):
        if problem.n_global:
            return super().squared_norm(problem, states, params)
        if _kernels_here(self):  # the reading accumulate linearises, by the same operations (kernels.squared_norm)
            from . import kernels

            y = _contiguous(problem.log.accel_mps2)
            sq = np.empty(y.shape[0])
            kernels.squared_norm(_contiguous(states), _contiguous(problem.all_directions_b),
                                 _contiguous(problem.all_positions_m), _contiguous(problem.all_rows), y,
                                 _contiguous(_kernel_whitening(problem)), sq)
            return float(np.sum(sq))
        r = self._all_axes(problem, states)[0]
        return float(np.sum(r * r))

    def gtsam_factors(self, problem):
        y = problem.log.accel_mps2
        accel = problem.noise.accel
        sigma = np.broadcast_to(accel.sigma, y.shape) if accel.per_sample is None else accel.per_sample
        out = []
        for k in range(problem.n):
            for i, (d, p, cols) in enumerate(problem.sensors):
                kb = problem.global_blocks[f"bias{i}"][1] if f"bias{i}" in problem.global_blocks else None
                ks = problem.global_blocks[f"scale{i}"][1] if f"scale{i}" in problem.global_blocks else None
                out.append(accelerometer.make_accelerometer_factor(
                    omega_key(k), omega_dot_key(k), specific_force_key(k), y[k, cols], d, p,
                    diagonal_noise(sigma[k, cols]), kb, ks))
        return out

    def log_normaliser(self, problem):
        accel = problem.noise.accel
        if accel.per_sample is None:
            return problem.n * float(np.sum(np.log(accel.sigma)))
        return float(np.sum(np.log(accel.per_sample)))

    def reweighted(self, problem, states: np.ndarray, params: np.ndarray, weight) -> AccelNoise:
        """The robust re-weighting's accelerometer noise at ``states``: each axis's std from
        :meth:`AccelNoise.start` divided by ``sqrt(weight(e))`` of its whitened residual e under that std."""
        accel = problem.noise.accel
        base = accel.start(problem.n)
        plain = problem.with_noise(accel=accel.with_per_sample(np.array(base)))  # whiten with the base noise
        r = self.whitened_residual(plain, states, params)
        return accel.with_per_sample(base / np.sqrt(weight(r)))


class InversionGroup(_ArrayMeasurementGroup):
    """``measurement='quadratic'``: the per-sample inversion ``[f, ω̇, q(ω)]`` (Ho & Lin 2009, eq. 7) with
    its covariance (:class:`~gfimu.smoother.model.noise_levels.InversionNoise`, ``problem.noise.inversion``)."""

    name = "per-sample inversion"
    formulation = "quadratic"

    def noise(self, problem: ModelView) -> InversionNoise:
        sigma = super().noise(problem).sigma
        x_hat, x_cov = quadratic.inversion(problem.log.array, problem.log.accel_mps2)
        return InversionNoise(sigma, x_hat=x_hat, x_cov=x_cov,
                              x_whiten=np.linalg.inv(np.linalg.cholesky(x_cov)))  # L⁻¹ with cov = L Lᵀ

    def terms(self, problem, states, params):
        X, inv = states, problem.noise.inversion
        r, j = quadratic.inversion_residual(X[:, OMEGA], X[:, OMEGA_DOT], X[:, SPECIFIC_FORCE], inv.x_hat)
        J = _padded([j["w"], j["d"], j["f"]], problem.layout.size)
        return [Term("unary", r @ inv.x_whiten.T, {"x": inv.x_whiten @ J})]

    def gtsam_factors(self, problem):
        inv = problem.noise.inversion
        return [quadratic.make_inversion_factor(omega_key(k), omega_dot_key(k), specific_force_key(k),
                                                inv.x_hat[k], gaussian_noise(inv.x_cov)) for k in range(problem.n)]

    def log_normaliser(self, problem):
        return -problem.n * float(np.sum(np.log(np.diag(problem.noise.inversion.x_whiten))))


class SpecificForceWalkGroup(FactorGroup):
    """The specific force as a random walk (``specific_force_random_walk_mps2_per_sqrt_s``;
    step std ``problem.noise.force_walk.step_sigma``), without the attitude."""

    name = "specific-force random walk"
    per_sample = False
    steps = True
    linear = True

    def applies(self, problem) -> bool:
        return not problem.layout.attitude

    def noise(self, problem: ModelView) -> ForceWalkNoise:
        return ForceWalkNoise(process.random_walk_sigma(problem.model.specific_force_random_walk_mps2_per_sqrt_s,
                                                        problem.dt_s))

    def terms(self, problem, states, params):
        X = states
        rf, _ = process.random_walk_residual(X[:-1, SPECIFIC_FORCE], X[1:, SPECIFIC_FORCE])
        wf = 1.0 / problem.noise.force_walk.step_sigma[:, None]
        Jf0, Jf1 = _binary(problem, 3, [(SPECIFIC_FORCE, -np.eye(3), np.eye(3))])
        return [Term("binary", rf * wf, {"x0": Jf0 * wf[:, :, None], "x1": Jf1 * wf[:, :, None]})]

    @staticmethod
    def _whitened_steps(problem, states: np.ndarray) -> np.ndarray:
        """(N-1, 3) the residual of :meth:`terms`, ``(f1 - f0) / σ``, without its Jacobians."""
        return (states[1:, SPECIFIC_FORCE] - states[:-1, SPECIFIC_FORCE]) * (1.0 / problem.noise.force_walk.step_sigma[:, None])

    def squared_norm(self, problem, states, params):
        r = self._whitened_steps(problem, states)
        return float(np.sum(r * r))

    def accumulate(self, problem, states, params, diag, lower, grad):
        """Per axis the step ``u (f1 - f0)`` (u = 1/σ): ``JᵀJ`` adds u² to both diagonals and -u² to
        the coupling, ``Jᵀr`` is ``∓u e``."""
        u = 1.0 / problem.noise.force_walk.step_sigma
        e = self._whitened_steps(problem, states)
        u2 = (u * u)[:, None]
        f = _columns(SPECIFIC_FORCE)
        diag[:-1, f, f] += u2
        diag[1:, f, f] += u2
        lower[:, f, f] -= u2
        ue = u[:, None] * e
        grad[:-1, f] -= ue
        grad[1:, f] += ue
        return 0.5 * float(np.sum(e * e)), e.size

    def gtsam_factors(self, problem):
        return [process.make_random_walk_factor(specific_force_key(k), specific_force_key(k + 1),
                                                diagonal_noise(np.full(3, problem.noise.force_walk.step_sigma[k])))
                for k in range(problem.n - 1)]

    def log_normaliser(self, problem):
        return 3 * float(np.sum(np.log(problem.noise.force_walk.step_sigma)))


class AttitudeGroup(FactorGroup):
    """With the attitude R_k (W←B) in the state: its kinematics ``R_{k+1} = R_k Exp(h (ω_k + ω_{k+1}) / 2)``
    (Li et al. 2021, eqs. 9-10 on SO(3)), the gravity-free acceleration ``f + Rᵀ g`` as a random walk and a
    weak prior on the first attitude (tilt free, yaw ``initial_yaw_std_rad``); their noise
    ``problem.noise.attitude`` (:class:`~gfimu.smoother.model.noise_levels.AttitudeNoise`)."""

    name = "attitude"
    per_sample = False

    def applies(self, problem) -> bool:
        return bool(problem.layout.attitude)

    def noise(self, problem: ModelView) -> AttitudeNoise:
        opt = problem.attitude
        return AttitudeNoise(prior_wb=np.eye(3), prior_sigma=np.array([10.0, 10.0, opt.initial_yaw_std_rad]),
                             step_sigma=process.random_walk_sigma(opt.attitude_random_walk_rad_per_sqrt_s, problem.dt_s),
                             accel_step_sigma=process.random_walk_sigma(opt.accel_random_walk_mps2_per_sqrt_s, problem.dt_s))

    def terms(self, problem, states, params):
        X, AT = states, problem.layout.rotation
        R = problem.rotations(X)
        out = []
        # attitude kinematics R_{k+1} = R_k Exp(h (ω_k + ω_{k+1}) / 2)
        r, j = kinematics.attitude_residual(R[:-1], R[1:], X[:-1, OMEGA], X[1:, OMEGA], problem.dt_s)
        w = 1.0 / problem.noise.attitude.step_sigma[:, None]
        J0, J1 = _binary(problem, 3, [(AT, j["r0"], j["r1"]), (OMEGA, j["w0"], j["w1"])])
        out.append(Term("binary", r * w, {"x0": J0 * w[:, :, None], "x1": J1 * w[:, :, None]}))
        # gravity-free acceleration a = f + Rᵀ g as a random walk
        r, j = gravity.accel_random_walk_residual(X[:-1, SPECIFIC_FORCE], X[1:, SPECIFIC_FORCE], R[:-1], R[1:])
        w = 1.0 / problem.noise.attitude.accel_step_sigma[:, None]
        J0, J1 = _binary(problem, 3, [(SPECIFIC_FORCE, j["f0"], j["f1"]), (AT, j["r0"], j["r1"])])
        out.append(Term("binary", r * w, {"x0": J0 * w[:, :, None], "x1": J1 * w[:, :, None]}))
        # weak prior on the first attitude (fixes yaw)
        r, j = process.attitude_prior_residual(R[:1], problem.noise.attitude.prior_wb)
        w = 1.0 / problem.noise.attitude.prior_sigma
        Jp = np.zeros((1, 3, problem.layout.size))
        Jp[:, :, AT] = j["r"] * w[:, None]
        out.append(Term("unary", r * w, {"x": Jp}, None, first=0))
        return out

    def gtsam_factors(self, problem):
        out = [process.make_attitude_prior_factor(attitude_key(0), problem.noise.attitude.prior_wb,
                                                  diagonal_noise(problem.noise.attitude.prior_sigma))]
        for k in range(problem.n - 1):
            out.append(kinematics.make_attitude_factor(attitude_key(k), attitude_key(k + 1), omega_key(k), omega_key(k + 1),
                                                       float(problem.dt_s[k]),
                                                       diagonal_noise(np.full(3, problem.noise.attitude.step_sigma[k]))))
            out.append(gravity.make_accel_random_walk_factor(specific_force_key(k), specific_force_key(k + 1), attitude_key(k),
                                                             attitude_key(k + 1),
                                                             diagonal_noise(np.full(3, problem.noise.attitude.accel_step_sigma[k]))))
        return out

    def log_normaliser(self, problem):
        return float(sum(self.log_normaliser_parts(problem)))

    def log_normaliser_parts(self, problem):
        return [3 * float(np.sum(np.log(problem.noise.attitude.step_sigma)) + np.sum(np.log(problem.noise.attitude.accel_step_sigma))),
                float(np.sum(np.log(problem.noise.attitude.prior_sigma)))]


class MotionModelGroup(FactorGroup):
    """The angular motion model, one step per pair of samples:

    - 'jerk': trapezoid kinematics ``ω_{k+1} = ω_k + h/2 (ω̇_k + ω̇_{k+1})`` and the random walk of ω̇
      (white angular jerk), stacked as one 6-row step;
    - with ``process_axis_frequencies_hz``: the exact step of the driven oscillator per axis
      (:func:`gfimu.factors.process.oscillator_residual`);
    - 'snap': the exact white-snap step of ``[ω, ω̇, ω̈]``.

    Its noise: ``problem.noise.motion`` (:class:`~gfimu.smoother.model.noise_levels.MotionNoise`).
    """

    motion = True
    compiled = True
    """:meth:`accumulate` (white jerk) through the compiled kernel (:func:`gfimu.smoother.model.kernels.white_jerk`:
    one pass over the samples); False: the numpy expressions it replaces (the tests' oracle)."""

    name = "motion model"
    per_sample = False
    steps = True
    linear = True

    def noise(self, problem: ModelView) -> MotionNoise:
        opt = problem.model
        snap_cov = snap_whiten = None
        if opt.motion_model == "snap":
            cov = kinematics.angular_motion_covariance(problem.batch_model.omega_ddot_random_walk_radps3_per_sqrt_s,
                                                       problem.dt_s)
            axis = np.tile(np.asarray(opt.process_axis_factors, dtype=float), 3)
            snap_cov = cov * axis[:, None] * axis[None, :]
            snap_whiten = np.linalg.inv(np.linalg.cholesky(cov)) / axis
        q = opt.omega_dot_random_walk_radps2_per_sqrt_s
        step_sigma = process.random_walk_sigma(q, problem.dt_s)
        axis_factors = np.asarray(opt.process_axis_factors, dtype=float)
        omega_n = 2.0 * np.pi * np.asarray(opt.process_axis_frequencies_hz, dtype=float)
        oscillator = bool(np.any(omega_n > 0))
        unit_cov = unit_whiten = None
        if oscillator:
            unit_cov = process.oscillator_step_covariance(q, problem.dt_s, omega_n, axis_factors)
            unit_whiten = np.linalg.inv(np.linalg.cholesky(unit_cov))
        return MotionNoise(kinematics.trapezoid_sigma(q, problem.dt_s), step_sigma, axis_factors, omega_n,
                           oscillator=oscillator, oscillator_unit_cov=unit_cov, oscillator_unit_whiten=unit_whiten,
                           oscillator_unit_sigma=step_sigma if oscillator else None, snap_cov=snap_cov,
                           snap_whiten=snap_whiten)

    def reweighted(self, problem, states: np.ndarray, weight) -> MotionNoise:
        """The robust re-weighting's motion-model noise at ``states``: the stds each step starts from
        (:meth:`MotionNoise.start`) divided by ``sqrt(weight(e))`` of its whitened residual norm / √rows."""
        plain = problem.noise.motion.from_start(problem.layout.snap)
        r = self.step_residual(problem.with_noise(motion=plain), states)
        return plain.weighted(weight(np.sqrt(np.mean(r**2, axis=1))), problem.layout.snap)

    def step_residual(self, problem, X: np.ndarray, noise: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """(N-1, rows) whitened residual of every step (what the robust re-weighting weighs); ``noise``:
        the (trapezoid, ω̇-step) std of the white-jerk steps to whiten with instead of the problem's."""
        W, D = OMEGA, OMEGA_DOT
        if problem.layout.snap:
            ra, _ = kinematics.angular_motion_residual(X[:-1, W], X[1:, W], X[:-1, D], X[1:, D],
                                                       X[:-1, OMEGA_DDOT], X[1:, OMEGA_DDOT], problem.dt_s)
            return np.einsum("nij,nj->ni", problem.noise.motion.snap_whiten, ra)
        if problem.noise.motion.oscillator:
            ro, _ = process.oscillator_residual(X[:-1, W], X[1:, W], X[:-1, D], X[1:, D], problem.dt_s,
                                                problem.noise.motion.natural_frequency_radps)
            return np.einsum("nij,nj->ni", problem.noise.motion.oscillator_whiten(), ro)
        rk, _ = kinematics.angular_velocity_residual(X[:-1, W], X[1:, W], X[:-1, D], X[1:, D], problem.dt_s)
        rd, _ = process.random_walk_residual(X[:-1, D], X[1:, D])
        motion = problem.noise.motion
        trapezoid, step = (motion.trapezoid_sigma, motion.omega_dot_step_sigma) if noise is None else noise
        return np.concatenate([rk / (trapezoid[:, None] * motion.axis_factors),
                               rd / (step[:, None] * motion.axis_factors)], axis=1)

    def terms(self, problem, states, params):
        X, W, D, A = states, OMEGA, OMEGA_DOT, OMEGA_DDOT
        if problem.layout.snap:
            # white snap: exact triple-integrator step of [ω, ω̇, ω̈] (9 rows, full covariance)
            ra, ja = kinematics.angular_motion_residual(X[:-1, W], X[1:, W], X[:-1, D], X[1:, D], X[:-1, A], X[1:, A],
                                                        problem.dt_s)
            J0, J1 = _binary(problem, 9, [(W, ja["w0"], ja["w1"]), (D, ja["d0"], ja["d1"]), (A, ja["j0"], ja["j1"])])
            Wn = problem.noise.motion.snap_whiten
            return [Term("binary", np.einsum("nij,nj->ni", Wn, ra), {"x0": Wn @ J0, "x1": Wn @ J1})]
        if problem.noise.motion.oscillator:
            # exact step of the driven oscillator per axis (6 rows, 2×2 blocks of covariance)
            ro, jo = process.oscillator_residual(X[:-1, W], X[1:, W], X[:-1, D], X[1:, D], problem.dt_s,
                                                 problem.noise.motion.natural_frequency_radps)
            J0, J1 = _binary(problem, 6, [(W, jo["w0"], jo["w1"]), (D, jo["d0"], jo["d1"])])
            Wn = problem.noise.motion.oscillator_whiten()
            return [Term("binary", np.einsum("nij,nj->ni", Wn, ro), {"x0": Wn @ J0, "x1": Wn @ J1})]
        # trapezoid kinematics + ω̇ random walk, stacked as one binary term (6 rows)
        rk, jk = kinematics.angular_velocity_residual(X[:-1, W], X[1:, W], X[:-1, D], X[1:, D], problem.dt_s)
        rd, _ = process.random_walk_residual(X[:-1, D], X[1:, D])
        steps, m = problem.n - 1, problem.layout.size
        J0 = np.zeros((steps, 6, m))
        J1 = np.zeros((steps, 6, m))
        J0[:, 0:3, W], J1[:, 0:3, W] = jk["w0"], jk["w1"]
        J0[:, 0:3, D], J1[:, 0:3, D] = jk["d0"], jk["d1"]
        J0[:, 3:6, D], J1[:, 3:6, D] = -np.eye(3), np.eye(3)
        wb = self._white_jerk_weights(problem)
        return [Term("binary", np.concatenate([rk, rd], axis=1) * wb, {"x0": J0 * wb[:, :, None], "x1": J1 * wb[:, :, None]})]

    @staticmethod
    def _white_jerk_weights(problem) -> np.ndarray:
        """(N-1, 6) whitening of the trapezoid and ω̇ random-walk rows."""
        motion = problem.noise.motion
        return 1.0 / np.concatenate([motion.trapezoid_sigma[:, None] * motion.axis_factors,
                                     motion.omega_dot_step_sigma[:, None] * motion.axis_factors], axis=1)

    def accumulate(self, problem, states, params, diag, lower, grad):
        """White jerk, per body axis with ``w = ω_a``, ``d = ω̇_a``, step h and row weights t (trapezoid),
        u (ω̇ random walk): rows ``e1 = t (w1 - w0 - h/2 (d0 + d1))``, ``e2 = u (d1 - d0)``, so

            J0ᵀJ0 = [[t², t²h/2], [t²h/2, t²h²/4 + u²]]     J1ᵀJ1 = [[t², -t²h/2], [-t²h/2, t²h²/4 + u²]]
            J1ᵀJ0 = [[-t², -t²h/2], [t²h/2, t²h²/4 - u²]]    (rows w1, d1; columns w0, d0)
            J0ᵀr = [-t e1, -t h/2 e1 - u e2]                 J1ᵀr = [t e1, -t h/2 e1 + u e2]

        (the same sums as :meth:`terms`' Jacobians to rounding). None for the other motion models."""
        if problem.layout.snap or problem.noise.motion.oscillator:
            return None
        W, D = OMEGA, OMEGA_DOT
        wb = self._white_jerk_weights(problem)
        if _kernels_here(self):
            from . import kernels

            e1, e2 = np.empty((problem.n - 1, 3)), np.empty((problem.n - 1, 3))
            kernels.white_jerk(_contiguous(states), _contiguous(problem.dt_s), _contiguous(wb), diag, lower, grad, e1, e2)
            return 0.5 * float(np.sum(e1 * e1) + np.sum(e2 * e2)), e1.size + e2.size
        t, u = wb[:, 0:3], wb[:, 3:6]
        h = problem.dt_s[:, None]
        e1, e2 = self._white_jerk_rows(problem, states, wb)
        t2, u2 = t * t, u * u
        t2h = 0.5 * h * t2
        t2hh = 0.5 * h * t2h
        w, d = _columns(W), _columns(D)
        diag[:-1, w, w] += t2
        diag[1:, w, w] += t2
        diag[:-1, w, d] += t2h
        diag[:-1, d, w] += t2h
        diag[1:, w, d] -= t2h
        diag[1:, d, w] -= t2h
        diag[:-1, d, d] += t2hh + u2
        diag[1:, d, d] += t2hh + u2
        lower[:, w, w] -= t2
        lower[:, w, d] -= t2h
        lower[:, d, w] += t2h
        lower[:, d, d] += t2hh - u2
        te1, the1, ue2 = t * e1, 0.5 * h * t * e1, u * e2
        grad[:-1, w] -= te1
        grad[1:, w] += te1
        grad[:-1, d] -= the1 + ue2
        grad[1:, d] += ue2 - the1
        return 0.5 * float(np.sum(e1 * e1) + np.sum(e2 * e2)), e1.size + e2.size

    @staticmethod
    def _white_jerk_rows(problem, X: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N-1, 3) each: the whitened trapezoid and ω̇ random-walk rows of :meth:`terms`, without
        their Jacobians (``weights``: :meth:`_white_jerk_weights`)."""
        W, D = OMEGA, OMEGA_DOT
        rk = kinematics.angular_velocity_step(X[:-1, W], X[1:, W], X[:-1, D], X[1:, D], problem.dt_s)
        return rk * weights[:, 0:3], (X[1:, D] - X[:-1, D]) * weights[:, 3:6]

    def squared_norm(self, problem, states, params):
        """The same residuals as :meth:`terms` (white jerk: without building its Jacobians)."""
        if problem.layout.snap or problem.noise.motion.oscillator:
            return super().squared_norm(problem, states, params)
        r = np.concatenate(self._white_jerk_rows(problem, states, self._white_jerk_weights(problem)), axis=1)
        return float(np.sum(r * r))

    def gtsam_factors(self, problem):
        out = []
        motion = problem.noise.motion
        oscillator_cov = motion.oscillator_covariance() if motion.oscillator and not problem.layout.snap else None
        for k in range(problem.n - 1):
            w0, w1, d0, d1 = omega_key(k), omega_key(k + 1), omega_dot_key(k), omega_dot_key(k + 1)
            h = float(problem.dt_s[k])
            if problem.layout.snap:
                out.append(kinematics.make_angular_motion_factor(w0, w1, d0, d1, omega_ddot_key(k), omega_ddot_key(k + 1), h,
                                                                 gaussian_noise(motion.snap_cov[k])))
            elif motion.oscillator:
                out.append(process.make_oscillator_factor(w0, w1, d0, d1, h, motion.natural_frequency_radps,
                                                          gaussian_noise(oscillator_cov[k])))
            else:
                out.append(kinematics.make_angular_velocity_factor(w0, w1, d0, d1, h, diagonal_noise(
                    motion.trapezoid_sigma[k] * motion.axis_factors)))
                out.append(process.make_random_walk_factor(d0, d1, diagonal_noise(
                    motion.omega_dot_step_sigma[k] * motion.axis_factors)))
        return out

    def log_normaliser(self, problem):
        if problem.layout.snap:
            return 0.5 * float(np.sum(np.linalg.slogdet(problem.noise.motion.snap_cov)[1]))
        if problem.noise.motion.oscillator:
            return 0.5 * float(np.sum(np.linalg.slogdet(problem.noise.motion.oscillator_covariance())[1]))
        return float(sum(self.log_normaliser_parts(problem)))

    def log_normaliser_parts(self, problem):
        if problem.layout.snap or problem.noise.motion.oscillator:
            return [self.log_normaliser(problem)]
        motion = problem.noise.motion
        return [3 * float(np.sum(np.log(motion.trapezoid_sigma)) + np.sum(np.log(motion.omega_dot_step_sigma))),
                2 * (problem.n - 1) * float(np.sum(np.log(motion.axis_factors)))]


class GyroscopeGroup(FactorGroup):
    """``ω_k + b_g - ω_meas,k`` with the gyroscope's noise (Lu, Tsai & Lin 2010), bias when self-calibrating."""

    name = "gyroscope"
    per_sample = False

    def applies(self, problem) -> bool:
        return bool(problem.use_gyro)

    def noise(self, problem: ModelView) -> GyroNoise:
        gyro = problem.log.gyro_b_radps
        if gyro is not None and not np.all(np.isfinite(gyro)):
            row = int(np.argwhere(~np.isfinite(gyro))[0, 0])
            raise DataError(f"{problem.log.source}: gyroscope reading is not finite at sample {row}")
        return GyroNoise(noise.gyro_noise_std(problem.array))

    def terms(self, problem, states, params):
        n, s = problem.n, problem.noise.gyro.sigma
        gb = problem.global_part(params, "gyro_bias")
        r, j = gyroscope.gyroscope_residual(states[:, OMEGA], problem.log.gyro_b_radps, gb)
        jg = None
        if gb is not None:
            jg = np.zeros((n, 3, problem.n_global))
            jg[:, :, problem.global_blocks["gyro_bias"][0]] = j["g"] / s
        return [Term("unary", r / s, {"x": unary_jacobian(problem, [(OMEGA, j["w"])], 3, n) / s}, jg)]

    def gtsam_factors(self, problem):
        kg = problem.global_blocks["gyro_bias"][1] if "gyro_bias" in problem.global_blocks else None
        noise = diagonal_noise(np.full(3, problem.noise.gyro.sigma))
        return [gyroscope.make_gyroscope_factor(omega_key(k), problem.log.gyro_b_radps[k], noise, kg) for k in range(problem.n)]

    def log_normaliser(self, problem):
        return 3 * problem.n * float(np.log(problem.noise.gyro.sigma))


class FreeFlightGroup(FactorGroup):
    """Free flight (McGinnis, Perkins & King 2012, eq. 1): Euler's torque-free equation ``I ω̇ + ω × I ω = 0`` (torque
    noise ``torque_noise_std_nm``) and zero specific force (``free_fall_std_mps2``), read as
    ``problem.noise.free_flight``."""

    name = "free flight"

    def applies(self, problem) -> bool:
        return bool(problem.batch_model.free_flight)

    def noise(self, problem: ModelView) -> FreeFlightNoise:
        return FreeFlightNoise(problem.batch_model.torque_noise_std_nm, problem.batch_model.free_fall_std_mps2)

    def terms(self, problem, states, params):
        n, levels = problem.n, problem.noise.free_flight
        r, j = euler.euler_residual(states[:, OMEGA], states[:, OMEGA_DOT], problem.log.array.body.principal_inertia_kgm2)
        s = levels.torque_sigma
        out = [Term("unary", r / s, {"x": unary_jacobian(problem, [(OMEGA, j["w"]), (OMEGA_DOT, j["d"])], 3, n) / s})]
        r, j = free_fall.free_fall_residual(states[:, SPECIFIC_FORCE])
        s = levels.fall_sigma
        out.append(Term("unary", r / s, {"x": unary_jacobian(problem, [(SPECIFIC_FORCE, j["f"])], 3, n) / s}))
        return out

    def gtsam_factors(self, problem):
        levels = problem.noise.free_flight
        inertia = problem.log.array.body.principal_inertia_kgm2
        torque = diagonal_noise(np.full(3, levels.torque_sigma))
        fall = diagonal_noise(np.full(3, levels.fall_sigma))
        out = []
        for k in range(problem.n):
            out.append(euler.make_euler_factor(omega_key(k), omega_dot_key(k), inertia, torque))
            out.append(free_fall.make_free_fall_factor(specific_force_key(k), fall))
        return out

    def log_normaliser(self, problem):
        levels = problem.noise.free_flight
        return 3 * problem.n * float(np.log(levels.torque_sigma) + np.log(levels.fall_sigma))


class InclinometerGroup(FactorGroup):
    """The inclinometer's two tilt angles against the attitude's direction cosines of gravity
    (Lu, Tsai & Lin 2010, eqs. 12-13), when the attitude is estimated with ``use_inclinometer``."""

    name = "inclinometer"

    def applies(self, problem) -> bool:
        return bool(problem.layout.attitude and problem.use_inclinometer)

    def noise(self, problem: ModelView) -> TiltNoise:
        if not np.all(np.isfinite(problem.log.tilt_rad)):
            row = int(np.argwhere(~np.isfinite(problem.log.tilt_rad))[0, 0])
            raise DataError(f"{problem.log.source}: inclinometer reading is not finite at sample {row}")
        return TiltNoise(noise.tilt_noise_std(problem.log.array))

    def terms(self, problem, states, params):
        s = problem.noise.tilt.sigma
        r, j = inclinometer.inclinometer_residual(problem.rotations(states), problem.log.tilt_rad)
        J = unary_jacobian(problem, [(problem.layout.rotation, j["r"])], 2, problem.n) / s
        return [Term("unary", r / s, {"x": J})]

    def gtsam_factors(self, problem):
        noise = diagonal_noise(np.full(2, problem.noise.tilt.sigma))
        return [inclinometer.make_inclinometer_factor(attitude_key(k), problem.log.tilt_rad[k], noise) for k in range(problem.n)]

    def log_normaliser(self, problem):
        return 2 * problem.n * float(np.log(problem.noise.tilt.sigma))


class CalibrationPriorGroup(FactorGroup):
    """Zero-mean priors on the calibration variables (biases, scale-factor errors, gyroscope bias),
    so that nothing in the problem is unobserved."""

    name = "calibration priors"
    per_sample = False

    def applies(self, problem) -> bool:
        return problem.n_global > 0

    def noise(self, problem: ModelView) -> CalibrationNoise:
        """Each block's prior std from the self-calibration: ``bias_prior_std_mps2`` (``bias*``), ``scale_prior_std``
        (``scale*``), ``gyro_bias_prior_std_radps`` (the gyroscope bias)."""
        opt = problem.self_calibration
        s = np.zeros(problem.n_global)
        for name, (sl, _) in problem.global_blocks.items():
            if name.startswith("bias"):
                s[sl] = opt.bias_prior_std_mps2
            elif name.startswith("scale"):
                s[sl] = opt.scale_prior_std
            else:
                s[sl] = opt.gyro_bias_prior_std_radps
        return CalibrationNoise(s)

    def terms(self, problem, states, params):
        s = problem.noise.calibration.prior_sigma
        return [Term("global", (params / s)[None], {}, np.diag(1.0 / s)[None])]

    def gtsam_factors(self, problem):
        s = problem.noise.calibration.prior_sigma
        return [process.make_prior_factor(key, np.zeros(sl.stop - sl.start), diagonal_noise(s[sl]))
                for sl, key in problem.global_blocks.values()]

    def log_normaliser(self, problem):
        return float(np.sum(np.log(problem.noise.calibration.prior_sigma)))


BUILT_IN = (AccelerometerGroup(), InversionGroup(), FirstStatePriorGroup(), SpecificForceWalkGroup(), AttitudeGroup(),
            MotionModelGroup(), GyroscopeGroup(), FreeFlightGroup(), InclinometerGroup(), CalibrationPriorGroup())
"""The model: the built-in groups, in the order the problem adds them (each where it applies)."""
