"""Batch smoother (method "smoother"): the whole log at once, linear in its length.

The factors of :class:`gfimu.smoother.graph.SmootherProblem` are evaluated
vectorised over all samples; their Gauss-Newton normal equations are
block-tridiagonal in the per-sample states (plus a dense border for the
calibration variables), solved by a banded Cholesky factorisation and a
Schur complement on the border, inside Levenberg-Marquardt iterations. The
marginal covariances come from the same factor by a backward block recursion
(selected inversion), also linear in the length. Long logs are solved in
overlapping windows.

Per window, the process noise (jerk density per body axis, specific-force
density; optionally the accelerometer noise scale and the motion model) is
chosen by maximising the marginal likelihood of the readings
(:mod:`gfimu.smoother.tuning`, on by default here); with
``accel_noise_slope_mps2_per_radps`` the accelerometer noise grows with |ω|
and is re-weighted from each solution (iteratively re-weighted least squares).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded

from ..array import SensorArray
from ..log import Log
from ..motion import Motion
from .graph import STATE_SIZE, SmootherOptions, SmootherProblem, options_reason


@dataclass
class NormalEquations:
    """Gauss-Newton system ``H δ = -g`` with H = [[A, C], [Cᵀ, B]], A block-tridiagonal.

    ``diag`` (N, 9, 9) and ``lower`` (N-1, 9, 9) are A's blocks (``lower[k]``
    = A[k+1, k]); ``coupling`` (N, 9, G) = C; ``border`` (G, G) = B.
    """

    diag: np.ndarray
    lower: np.ndarray
    grad: np.ndarray
    coupling: np.ndarray
    border: np.ndarray
    grad_global: np.ndarray
    cost: float
    rows: int | None = None
    """Number of whitened residual rows."""


def normal_equations(problem: SmootherProblem, states: np.ndarray, params: np.ndarray, terms=None) -> NormalEquations:
    """Accumulate JᵀJ and Jᵀr of all factors (or of ``terms``), vectorised."""
    n, G, M = problem.n, problem.n_global, problem.state_size
    diag = np.zeros((n, M, M))
    lower = np.zeros((n - 1, M, M))
    grad = np.zeros((n, M))
    coupling = np.zeros((n, M, G))
    border = np.zeros((G, G))
    grad_g = np.zeros(G)
    cost = 0.0
    rows = 0
    for t in (problem.terms(states, params) if terms is None else terms):
        r = t.residual
        cost += 0.5 * float(np.sum(r * r))
        rows += r.size
        if t.kind == "unary":
            J = t.jac["x"]
            k0, k1 = t.first, t.first + r.shape[0]
            JT = np.swapaxes(J, 1, 2)
            diag[k0:k1] += JT @ J
            grad[k0:k1] += np.einsum("nij,nj->ni", JT, r)
            if t.jac_global is not None:
                Jg = t.jac_global
                coupling[k0:k1] += JT @ Jg
                border += np.einsum("nri,nrj->ij", Jg, Jg)
                grad_g += np.einsum("nri,nr->i", Jg, r)
        elif t.kind == "binary":
            J0, J1 = t.jac["x0"], t.jac["x1"]
            J0T, J1T = np.swapaxes(J0, 1, 2), np.swapaxes(J1, 1, 2)
            diag[:-1] += J0T @ J0
            diag[1:] += J1T @ J1
            lower += J1T @ J0
            grad[:-1] += np.einsum("nij,nj->ni", J0T, r)
            grad[1:] += np.einsum("nij,nj->ni", J1T, r)
        else:
            Jg = t.jac_global
            border += np.einsum("nri,nrj->ij", Jg, Jg)
            grad_g += np.einsum("nri,nr->i", Jg, r)
    return NormalEquations(diag, lower, grad, coupling, border, grad_g, cost, rows)


def add_normal_equations(a: NormalEquations, b: NormalEquations) -> NormalEquations:
    """Normal equations of the union of two sets of factors on the same states."""
    return NormalEquations(a.diag + b.diag, a.lower + b.lower, a.grad + b.grad, a.coupling + b.coupling, a.border + b.border,
                           a.grad_global + b.grad_global, a.cost + b.cost, (a.rows or 0) + (b.rows or 0))


def to_lower_banded(diag: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """LAPACK lower band storage (2m, N m) of a block-tridiagonal symmetric matrix."""
    n, m, _ = diag.shape
    ab = np.zeros((2 * m, n * m))
    for c in range(m):
        for d in range(2 * m):
            row = c + d
            if row < m:
                ab[d, c::m] = diag[:, row, c]
            elif row < 2 * m:
                ab[d, c::m][: n - 1] = lower[:, row - m, c]
    return ab


def factor_blocks(cb: np.ndarray, n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Blocks L[k, k] (N, m, m) and L[k+1, k] (N-1, m, m) of a lower band Cholesky factor."""
    Lkk = np.zeros((n, m, m))
    Lnext = np.zeros((n - 1, m, m))
    for c in range(m):
        for d in range(2 * m):
            row = c + d
            if row < m:
                Lkk[:, row, c] = cb[d, c::m]
            elif row < 2 * m:
                Lnext[:, row - m, c] = cb[d, c::m][: n - 1]
    return Lkk, Lnext


@dataclass
class Factorisation:
    """Banded Cholesky factor of the Jacobi-scaled ``S A S`` (``scale`` = diag of S), plus the border."""

    cb: np.ndarray
    scale: np.ndarray  # (N m,)
    Y: np.ndarray | None  # A⁻¹ C, (N m, G)
    schur: np.ndarray | None  # B - Cᵀ A⁻¹ C

    def solve(self, b: np.ndarray) -> np.ndarray:
        """A⁻¹ b for b (N m,) or (N m, k)."""
        s = self.scale if b.ndim == 1 else self.scale[:, None]
        return s * cho_solve_banded((self.cb, True), s * b, check_finite=False)


def factorise(ne: NormalEquations, damping: float = 0.0) -> Factorisation:
    """Factor A (+ Marquardt damping) after symmetric Jacobi scaling, which keeps the
    factorisation accurate when the states have very different scales (e.g. ω̈)."""
    n, M = ne.diag.shape[:2]
    diag = ne.diag
    if damping:
        diag = diag + damping * (np.einsum("nii->ni", ne.diag)[:, :, None] * np.eye(M) + 1e-9 * np.eye(M))
    d = np.einsum("nii->ni", diag)
    if np.any(~(d > 0)):
        k, i = np.argwhere(~(d > 0))[0]
        raise np.linalg.LinAlgError(f"normal equations not positive definite: state {i} of sample {k} is unobserved")
    sc = 1.0 / np.sqrt(d)
    diag_s = diag * sc[:, :, None] * sc[:, None, :]
    lower_s = ne.lower * sc[1:, :, None] * sc[:-1, None, :]
    cb = cholesky_banded(to_lower_banded(diag_s, lower_s), lower=True, check_finite=False)
    fac = Factorisation(cb, sc.reshape(-1), None, None)
    if ne.border.size:
        C = ne.coupling.reshape(n * M, -1)
        Y = fac.solve(C)
        border = ne.border + (damping * (np.diag(np.diag(ne.border)) + 1e-9 * np.eye(len(ne.border))) if damping else 0.0)
        fac.Y, fac.schur = Y, border - C.T @ Y
    return fac


def solve_step(ne: NormalEquations, fac: Factorisation) -> tuple[np.ndarray, np.ndarray]:
    """Newton step (δx (N, m), δp (G,)) of the (damped) normal equations."""
    n, M = ne.diag.shape[:2]
    gx = ne.grad.reshape(-1)
    ax = fac.solve(gx)
    if fac.Y is None:
        return -ax.reshape(n, M), np.zeros(0)
    C = ne.coupling.reshape(n * M, -1)
    dp = np.linalg.solve(fac.schur, -ne.grad_global + C.T @ ax)
    dx = -ax - fac.Y @ dp
    return dx.reshape(n, M), dp


def marginal_covariances(ne: NormalEquations, fac: Factorisation) -> tuple[np.ndarray, np.ndarray | None]:
    """Diagonal blocks of H⁻¹ for the states (N, m, m) and the border (G, G).

    Backward recursion on the block-bidiagonal Cholesky factor L of the
    scaled A (A_s⁻¹ = L⁻ᵀ L⁻¹): ``Σ_k = P_k + M_kᵀ Σ_{k+1} M_k`` with
    ``P_k = L_kk⁻ᵀ L_kk⁻¹`` and ``M_k = L_{k+1,k} L_kk⁻¹``; unscaled by S; then
    the Schur correction ``Y_k S⁻¹ Y_kᵀ`` of the calibration variables.
    """
    n, M = ne.diag.shape[:2]
    Lkk, Lnext = factor_blocks(fac.cb, n, M)
    Linv = np.linalg.inv(Lkk)
    P = np.swapaxes(Linv, 1, 2) @ Linv
    Mk = Lnext @ Linv[:-1]
    MkT = np.swapaxes(Mk, 1, 2)
    sigma = np.empty((n, M, M))
    sigma[-1] = P[-1]
    for k in range(n - 2, -1, -1):
        sigma[k] = P[k] + MkT[k] @ sigma[k + 1] @ Mk[k]
    sc = fac.scale.reshape(n, M)
    sigma *= sc[:, :, None] * sc[:, None, :]
    if fac.Y is None:
        return sigma, None
    s_inv = np.linalg.inv(fac.schur)
    Yk = fac.Y.reshape(n, M, -1)
    sigma += Yk @ s_inv @ np.swapaxes(Yk, 1, 2)
    return sigma, s_inv


REWEIGHTED_TOLERANCE = 0.01
"""Re-weighted solves stop when an iteration lowers the cost by less than this fraction of the
cost's statistical spread at the solution, ``sqrt(R / 2)`` for R whitened rows (the std of half a
χ² with R degrees of freedom): further iterations move the estimate by far less than its noise."""


@dataclass
class SolveResult:
    states: np.ndarray
    params: np.ndarray
    cost: float
    iterations: int
    converged: bool
    covariance: np.ndarray | None = None
    param_covariance: np.ndarray | None = None


def solve(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None,
          compute_sigma: bool = False, method: str = "lm", reweight=None,
          max_iterations: int | None = None) -> SolveResult:
    """Levenberg-Marquardt (or plain Gauss-Newton) on the banded normal equations.

    Each iteration first tries the undamped Gauss-Newton step (the problem is
    close to linear near a good initial point); Marquardt damping
    ``λ diag(H)`` is switched on, and raised tenfold, only while a step fails
    to lower the cost, and lowered again after each success.

    ``reweight(states, params)``, when given, re-weights the factors (motion-dependent noise,
    robust losses) at the current estimate before every iteration: iteratively re-weighted
    least squares with the Levenberg-Marquardt safeguard, each step accepted when it lowers the
    cost under the weights it was computed with. It stops when an iteration lowers that cost by
    less than ``relative_tolerance`` of it, or, re-weighting, by less than
    :data:`REWEIGHTED_TOLERANCE` of its statistical spread (or after ``max_iterations``, default
    the options').
    """
    opt = problem.options
    X = np.array(states, dtype=float)
    P = np.zeros(problem.n_global) if params is None else np.array(params, dtype=float)
    if reweight is not None:
        reweight(X, P)
    ne = normal_equations(problem, X, P)
    lam = 0.0
    converged = False
    it = 0
    limit = int(opt.max_iterations if max_iterations is None else max_iterations)
    for it in range(1, limit + 1):
        while True:
            try:
                fac = factorise(ne, lam)
            except np.linalg.LinAlgError:  # numerically indefinite (very stiff process noise): damp more
                if lam > 1e10:
                    raise
                lam = 1e-6 if lam == 0.0 else lam * 10.0
                continue
            dx, dp = solve_step(ne, fac)
            Xn, Pn = problem.retract(X, dx), P + dp
            new_cost = problem.cost(Xn, Pn)
            if method != "lm" or new_cost <= ne.cost or lam > 1e10:
                break
            lam = 1e-6 if lam == 0.0 else lam * 10.0
        decrease = ne.cost - new_cost
        if method == "lm" and new_cost > ne.cost:
            converged = True
            break
        X, P = Xn, Pn
        lam = 0.0 if lam < 1e-8 else lam / 10.0
        if reweight is not None:
            reweight(X, P)
        ne = normal_equations(problem, X, P)
        enough = opt.relative_tolerance * max(new_cost, 1e-300)
        if reweight is not None:  # the weights move with every step: stop within the cost's own spread
            enough = max(enough, REWEIGHTED_TOLERANCE * np.sqrt(0.5 * (ne.rows or 1)))
        if decrease <= enough or np.max(np.abs(dx)) < 1e-12:
            converged = True
            break
    result = SolveResult(X, P, ne.cost, it, converged)
    if compute_sigma:
        cov, pcov = marginal_covariances(ne, factorise(ne, 0.0))
        result.covariance, result.param_covariance = cov, pcov
    return result


def reweighting(problem: SmootherProblem, options: SmootherOptions):
    """The re-weighting callback of :func:`solve` for the motion-dependent accelerometer noise and
    the robust losses of ``options``, or None when neither is on."""
    slope = options.accel_noise_slope_mps2_per_radps > 0 and options.measurement == "accelerometer"
    if not (slope or options.robust):
        return None

    def reweight(states: np.ndarray, params: np.ndarray) -> None:
        if slope:
            problem.set_motion_dependent_noise(states[:, 0:3], options.accel_noise_slope_mps2_per_radps)
        if options.robust:
            problem.set_robust_weights(states, params)

    return reweight


def solve_reweighted(problem: SmootherProblem, states: np.ndarray, options: SmootherOptions,
                     params: np.ndarray | None = None, compute_sigma: bool | None = None,
                     warm: bool = False) -> SolveResult:
    """Solve with the motion-dependent noise and robust losses of ``options``: first
    ``reweight_iterations - 1`` iterations under the plain noise (a start for the weights), then
    iteratively re-weighted Levenberg-Marquardt to convergence (:func:`solve`)."""
    sigma = options.compute_sigma if compute_sigma is None else compute_sigma
    reweight = reweighting(problem, options)
    if reweight is None:
        return solve(problem, states, params, compute_sigma=sigma)
    if warm:  # ``states`` is already a re-weighted solution
        return solve(problem, states, params, compute_sigma=sigma, reweight=reweight)
    first = solve(problem, states, params, max_iterations=max(1, int(options.reweight_iterations) - 1))
    return solve(problem, first.states, first.params if first.params.size else None,
                 compute_sigma=sigma, reweight=reweight)


def window_slices(n: int, rate_hz: float, window_s: float | None, overlap_s: float) -> list[tuple[slice, slice, slice]]:
    """(solve slice, keep slice in the log, keep slice within the window) of overlapping windows."""
    if window_s is None:
        return [(slice(0, n), slice(0, n), slice(0, n))]
    w = max(int(round(window_s * rate_hz)), 4)
    o = max(int(round(overlap_s * rate_hz)), 2)
    if n <= w:
        return [(slice(0, n), slice(0, n), slice(0, n))]
    out = []
    start = 0
    keep_from = 0
    while True:
        stop = min(start + w, n)
        if stop == n:
            out.append((slice(start, n), slice(keep_from, n), slice(keep_from - start, n - start)))
            break
        keep_to = stop - o // 2
        out.append((slice(start, stop), slice(keep_from, keep_to), slice(keep_from - start, keep_to - start)))
        keep_from = keep_to
        start = stop - o
    return out


CHECK_SAMPLES = 5000
"""The model check (:func:`gfimu.smoother.auto.check_model`) reads at most about this many samples,
evenly spread over the log (120,000 residuals of an 8-triad array)."""


@dataclass(frozen=True)
class BatchSmootherEstimator(SmootherOptions):
    """Factor-graph smoother over the whole log (method "smoother").

    Options: see :class:`gfimu.smoother.graph.SmootherOptions`. Returns ω, ω̇
    and the specific force at the body origin for every sample, with
    one-sigma marginal uncertainties when ``compute_sigma``. Calibration
    estimates of the last solve are kept in :attr:`last_calibration`.

    Unlike :class:`SmootherOptions`, ``tune_process_noise`` is on by default: the
    jerk density per body axis and the specific-force density are chosen per solve
    window by the marginal likelihood of the data (:mod:`gfimu.smoother.tuning`;
    the choice is kept in :attr:`last_tuning`); ``tune_process_noise=False`` uses
    the fixed densities.
    """

    tune_process_noise: bool = True
    tune_span_s: float | None = 10.0
    """With ``tune_process_noise``: choose the process noise on at most this much of each solve
    window, its middle [s] (the evidence of 10 s of readings fixes a handful of noise levels well;
    the cost of the choice then stops growing with the window); None: on the whole window."""
    auto_model: bool = True
    """Choose the model from the log (:mod:`gfimu.smoother.auto`): logs whose readings follow the
    rigid-body equation up to the stated white noise keep the options as they are; logs whose
    residual is larger, heavy-tailed or grows with |ω| (real arrays) get the ML initialisation with
    its sign chain, the measured noise floor and slope, Cauchy losses and moment-estimated process
    noise. Options set to other than their defaults are kept either way; False: the options as given."""

    def options(self) -> SmootherOptions:
        return SmootherOptions(**{f.name: getattr(self, f.name) for f in fields(SmootherOptions)})

    def applicable(self, array: SensorArray) -> str | None:
        return options_reason(array, self.options(), attitude_supported=True)

    def estimate(self, log: Log, progress: bool = False) -> Motion:
        from ..progress import progress as progress_bar

        opt = self.options()
        reason = options_reason(log.array, opt, attitude_supported=True)
        if reason:
            raise ValueError(f"{log.source}: {reason}")
        n = len(log)
        if n < 2:
            raise ValueError(f"{log.source}: the smoother needs at least 2 samples, got {n}")
        attitude = opt.estimate_attitude or opt.use_inclinometer
        M = (12 if opt.motion_model == "snap" else STATE_SIZE) + (3 if attitude else 0)
        states = np.zeros((n, M))
        sd = np.zeros((n, M)) if opt.compute_sigma else None
        windows = window_slices(n, log.rate_hz, opt.window_s, opt.overlap_s)
        calibration = []
        tunings = []
        opt, auto = self._auto_model(log, opt, attitude)
        object.__setattr__(self, "_last_model_check", auto[0] if auto else None)
        previous = None  # (solve slice, attitudes) of the window before
        for solve_sl, keep_log, keep_win in progress_bar(windows, total=len(windows), desc="smoother", enable=progress and len(windows) > 1):
            part = log.select(solve_sl)
            if attitude:
                res, problem = self._solve_with_attitude(part, opt, previous, solve_sl, tunings)
                previous = (solve_sl, problem.rotations(res.states))
            else:
                if auto is not None and not auto[0].consistent:
                    problem, x0 = self._moment_problem(part, opt, auto, solve_sl, tunings)
                    res = solve_reweighted(problem, x0, problem.options)
                else:
                    problem, x0 = self._tuned_problem(part, opt, tunings, self.tune_span_s)
                    res = solve_reweighted(problem, x0, opt)
            m = min(M, res.states.shape[1])
            states[keep_log, :m] = res.states[keep_win, :m]
            if sd is not None:
                sd[keep_log, :m] = np.sqrt(np.einsum("nii->ni", res.covariance))[keep_win, :m]
            calibration.append({name: res.params[sl] for name, (sl, _) in problem.global_blocks.items()})
        object.__setattr__(self, "_last_calibration", calibration)
        object.__setattr__(self, "_last_tuning", tunings)
        sigma = {}
        if sd is not None:
            sigma = {"omega_b_radps": sd[:, 0:3], "omega_dot_b_radps2": sd[:, 3:6], "specific_force_b_mps2": sd[:, 6:9]}
        extra = {}
        if attitude:
            from ..factors import GRAVITY_W_MPS2, _so3
            from ..rotations import quaternion_from_matrix

            R = _so3.exp(states[:, M - 3:])
            extra["quaternion_wb"] = quaternion_from_matrix(R)
            extra["accel_b_mps2"] = states[:, 6:9] + np.einsum("nji,j->ni", R, GRAVITY_W_MPS2)
        return Motion(log.timestamps_ns, omega_b_radps=states[:, 0:3], omega_dot_b_radps2=states[:, 3:6],
                      specific_force_b_mps2=states[:, 6:9], sigma=sigma, **extra)

    def _auto_model(self, log: Log, opt: SmootherOptions, attitude: bool):
        """(options, (ModelCheck, ML motion, noise densities) or None) of :mod:`gfimu.smoother.auto`."""
        from dataclasses import replace

        from ..estimators.ml import MLEstimator
        from .auto import check_model, estimate_noise_variances, misfit_options, motion_densities, with_densities

        if (not self.auto_model or attitude or opt.free_flight or opt.measurement != "accelerometer"
                or opt.self_calibrate_bias or opt.self_calibrate_scale):
            return opt, None
        ml = MLEstimator()
        if ml.applicable(log.array) is not None or not np.all(np.isfinite(log.accel_mps2)):
            return opt, None
        step = max(1, len(log) // CHECK_SAMPLES)
        sample = log if step == 1 else log.select(slice(0, None, step))
        motion = ml.estimate(sample)
        check = check_model(sample, motion)
        if check.consistent:
            return opt, (check, None)
        if step > 1:
            motion = ml.estimate(log)
        chosen = misfit_options(opt, check)
        defaults = {f.name: f.default for f in fields(SmootherOptions)}
        keep = {name: getattr(opt, name) for name in defaults
                if name != "tune_process_noise" and getattr(opt, name) != defaults[name]
                and getattr(chosen, name) != getattr(opt, name)}
        if self.tune_process_noise:  # the process noise of the log's motion (else the fixed densities)
            x = np.hstack([motion.omega_b_radps, motion.omega_dot_b_radps2, motion.specific_force_b_mps2])
            chosen = with_densities(chosen, *motion_densities(x, log.dt_s, *estimate_noise_variances(
                log.array, check, motion.omega_b_radps)))
        chosen = replace(chosen, **keep)
        return chosen, (check, motion)

    def _moment_problem(self, part: Log, opt: SmootherOptions, auto, solve_sl: slice, tunings: list):
        """Problem and initial states of one window of an inconsistent log: ML initialisation with its
        sign chain, the measured noise floor and slope, the process densities chosen for the log, and
        the jerk density lowered where the body rests (:func:`gfimu.smoother.auto.local_density_factors`)."""
        from .auto import estimate_noise_variances, local_density_factors
        from .initialise import sign_chain
        from .tuning import Tuning, make_problem

        check, motion = auto
        omega = motion.omega_b_radps[solve_sl]
        omega_dot = motion.omega_dot_b_radps2[solve_sl]
        if opt.ml_sign_chain:
            omega = omega * sign_chain(omega, omega_dot, part.dt_s)[:, None]
        x0 = np.hstack([omega, omega_dot, motion.specific_force_b_mps2[solve_sl]])
        scale = 1.0
        if np.isfinite(check.stated_noise_mps2) and check.stated_noise_mps2 > 0:
            scale = check.noise_floor_mps2 / check.stated_noise_mps2
        tunings.append(Tuning("jerk", opt.omega_dot_random_walk_radps2_per_sqrt_s, scale, float("nan"), 0,
                              tuple(opt.process_axis_factors), opt.specific_force_random_walk_mps2_per_sqrt_s))
        problem = make_problem(part, opt, scale, x0[:, 0:3])
        factors = local_density_factors(x0, part.dt_s, estimate_noise_variances(part.array, check, omega)[0],
                                        opt.omega_dot_random_walk_radps2_per_sqrt_s)
        problem.trapezoid_sigma = problem.trapezoid_sigma * factors
        problem.omega_dot_step_sigma = problem.omega_dot_step_sigma * factors
        return problem, x0

    @property
    def last_model_check(self):
        """The :class:`gfimu.smoother.auto.ModelCheck` of the last :meth:`estimate` (None when not run)."""
        return getattr(self, "_last_model_check", None)

    @staticmethod
    def _tuned_problem(part: Log, opt: SmootherOptions, tunings: list, span_s: float | None = None):
        """Problem and initial states of one window, with the process noise chosen from the data
        (:func:`gfimu.smoother.tuning.tune`) when ``tune_process_noise``; the choice is appended to ``tunings``."""
        from dataclasses import replace

        from .tuning import make_problem, tune

        x0 = BatchSmootherEstimator._initial_states(part, opt)
        if not opt.tune_process_noise:
            return make_problem(part, opt, 1.0, x0[:, 0:3]), x0
        models = ("jerk", "snap") if opt.tune_motion_model else None
        solved: list = []
        span = slice(0, len(part))
        if span_s is not None and part.times_s[-1] - part.times_s[0] > span_s:
            width = max(int(round(span_s * part.rate_hz)), 4)
            start = (len(part) - width) // 2
            span = slice(start, start + width)
        tuning, tuned = tune(part.select(span), opt, x0[span], models=models, accel_noise=opt.tune_accel_noise,
                             states_out=solved)
        tunings.append(tuning)
        if tuned.motion_model != opt.motion_model:
            x0 = BatchSmootherEstimator._initial_states(part, tuned)
        elif any(f > 0 for f in tuning.axis_frequencies_hz):
            if span == slice(0, len(part)):
                x0 = solved[0]  # the stiff oscillator model starts from the tuner's solution
            else:  # ... or from the white-jerk solution of the whole window with the chosen densities
                plain = replace(tuned, process_axis_frequencies_hz=(0.0, 0.0, 0.0))
                x0 = solve(make_problem(part, plain, tuning.accel_noise_scale, x0[:, 0:3]), x0).states
        return make_problem(part, tuned, tuning.accel_noise_scale, x0[:, 0:3]), x0

    @staticmethod
    def _initial_states(part: Log, opt: SmootherOptions) -> np.ndarray:
        """Initial states: the sign-resolving initialisation or the per-sample ML estimate."""
        from .initialise import initial_states

        if opt.initialisation != "ml" or opt.free_flight:
            return initial_states(part, opt)
        from ..estimators.ml import MLEstimator

        m = MLEstimator().estimate(part)
        omega = m.omega_b_radps
        if opt.ml_sign_chain:
            from .initialise import sign_chain

            omega = omega * sign_chain(omega, m.omega_dot_b_radps2, part.dt_s)[:, None]
        x = np.hstack([omega, m.omega_dot_b_radps2, m.specific_force_b_mps2])
        if opt.motion_model == "snap":
            x = np.hstack([x, np.gradient(m.omega_dot_b_radps2, part.times_s, axis=0)])
        return x

    @staticmethod
    def _solve_with_attitude(part: Log, opt: SmootherOptions, previous, solve_sl: slice, tunings: list | None = None):
        """Two stages: the smoother without attitude, then the attitude propagated from its ω
        (starting from the previous window's attitude, which also anchors the yaw) and the full solve."""
        from dataclasses import replace

        from ..factors import _so3
        from .initialise import initial_attitude, initial_states

        base = replace(opt, estimate_attitude=False, use_inclinometer=False, compute_sigma=False)
        if opt.tune_process_noise:  # the process noise of ω, ω̇ chosen without the attitude, kept with it
            problem0, x0 = BatchSmootherEstimator._tuned_problem(part, replace(base, tune_motion_model=False),
                                                                 [] if tunings is None else tunings)
            first = solve(problem0, x0)
            t = tunings[-1] if tunings else None
            opt = replace(opt, omega_dot_random_walk_radps2_per_sqrt_s=problem0.options.omega_dot_random_walk_radps2_per_sqrt_s,
                          process_axis_factors=problem0.options.process_axis_factors,
                          process_axis_frequencies_hz=problem0.options.process_axis_frequencies_hz)
        else:
            t = None
            first = solve(SmootherProblem(part, base), initial_states(part, base))
        start = None
        if previous is not None:
            prev_sl, prev_R = previous
            start = prev_R[solve_sl.start - prev_sl.start]
        R = initial_attitude(part, first.states[:, 0:3], first.states[:, 6:9], start, opt.use_inclinometer)
        if t is not None:
            from .tuning import make_problem

            problem = make_problem(part, opt, t.accel_noise_scale)
        else:
            problem = SmootherProblem(part, opt)
        problem.attitude_prior_wb = R[0]
        x0 = np.hstack([first.states, _so3.log(R)])
        return solve(problem, x0, first.params if first.params.size else None, compute_sigma=opt.compute_sigma), problem

    @property
    def last_tuning(self) -> list:
        """Per solve window: the process noise chosen from the data (:class:`gfimu.smoother.tuning.Tuning`),
        from the last :meth:`estimate` with ``tune_process_noise``."""
        return getattr(self, "_last_tuning", [])

    @property
    def last_calibration(self) -> list[dict]:
        """Per window: calibration variable name -> estimate, from the last :meth:`estimate`."""
        return getattr(self, "_last_calibration", [])


def solve_with_gtsam(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None,
                     iterations: int = 10, tolerance: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """The graph path: the same problem as a GTSAM graph of CustomFactors, Gauss-Newton
    driven here (linearize -> GaussianFactorGraph.optimize -> retract) on a
    Python-owned Values. Quadratic in length through GTSAM's Python callbacks;
    meant for verification on small logs.
    """
    graph = problem.gtsam_graph()
    P = np.zeros(problem.n_global) if params is None else params
    values = problem.gtsam_values(states, P)
    error = graph.error(values)
    for _ in range(iterations):
        delta = graph.linearize(values).optimize()
        values = values.retract(delta)
        new_error = graph.error(values)
        if error - new_error <= tolerance * max(new_error, 1e-300):
            break
        error = new_error
    return problem.from_gtsam_values(values)
