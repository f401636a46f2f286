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

from dataclasses import dataclass, field, fields, replace

import gtsam
import numpy as np

from ..array import SensorArray
from ..factors import GRAVITY_W_MPS2, _so3
from ..log import Log
from ..motion import Motion
from ..progress import progress as progress_bar
from ..rotations import quaternion_from_matrix
from .banded import (  # noqa: F401  (the banded core, also importable from here)
    Factorisation,
    NormalEquations,
    SolveResult,
    add_normal_equations,
    factor_blocks,
    factorise,
    marginal_covariances,
    normal_equations,
    solve,
    solve_step,
    to_lower_banded,
)
from .graph import STATE_SIZE, SmootherOptions, SmootherProblem, options_reason
from .initialise import initial_attitude, initial_estimate, initial_states
from .result import SmootherResult
from .tuning import InitialStates, Tuning, make_problem, tuned_problem

SOLVERS = ("numpy", "gtsam")
"""Solvers of the batch smoother: the vectorised banded Levenberg-Marquardt (default: linear in the
length with a small constant, marginal σ included) and the same problem as a GTSAM graph, linearised,
eliminated in time order and retracted here (a cross-check, slower by the Python factor callbacks)."""


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


def solve_problem(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None,
                  compute_sigma: bool = False, solver: str = "numpy") -> SolveResult:
    """Solve ``problem`` from ``states`` with the banded numpy solver or GTSAM (:data:`SOLVERS`)."""
    if solver == "numpy":
        return solve(problem, states, params, compute_sigma=compute_sigma)
    if solver != "gtsam":
        raise ValueError(f"unknown solver {solver!r}; choose one of: {', '.join(SOLVERS)}")
    X, P, iterations, converged = gtsam_levenberg_marquardt(problem, states, params, int(problem.options.max_iterations),
                                                     problem.options.relative_tolerance)
    ne = normal_equations(problem, X, P)
    result = SolveResult(X, P, ne.cost, iterations, converged)
    if compute_sigma:
        result.covariance, result.param_covariance = marginal_covariances(ne, factorise(ne, 0.0))
    return result


def smooth(log: Log, options: SmootherOptions, progress: bool = False, initial: InitialStates | None = None,
           solver: str = "numpy") -> SmootherResult:
    """The batch smoother on a whole log: overlapping solve windows, each with its process noise chosen
    from the data when ``options.tune_process_noise``.

    ``initial``: how each window's initial states are made (default
    :func:`gfimu.smoother.initialise.initial_estimate`); ``solver``: one of :data:`SOLVERS`."""
    opt = options
    reason = options_reason(log.array, opt, attitude_supported=True)
    if reason:
        raise ValueError(f"{log.source}: {reason}")
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of: {', '.join(SOLVERS)}")
    n = len(log)
    if n < 2:
        raise ValueError(f"{log.source}: the smoother needs at least 2 samples, got {n}")
    attitude = opt.estimate_attitude or opt.use_inclinometer
    M = (12 if opt.motion_model == "snap" else STATE_SIZE) + (3 if attitude else 0)
    states = np.zeros((n, M))
    sd = np.zeros((n, M)) if opt.compute_sigma else None
    windows = window_slices(n, log.rate_hz, opt.window_s, opt.overlap_s)
    calibration = []
    tunings: list[Tuning] = []
    notes = []
    iterations, cost = 0, 0.0
    previous = None  # (solve slice, attitudes) of the window before
    for w, (solve_sl, keep_log, keep_win) in enumerate(progress_bar(windows, total=len(windows), desc="smoother",
                                                                    enable=progress and len(windows) > 1)):
        part = log.select(solve_sl)
        if attitude:
            res, problem = _solve_with_attitude(part, opt, previous, solve_sl, tunings, initial, solver)
            previous = (solve_sl, problem.rotations(res.states))
            iterations += res.iterations
        else:
            problem, x0 = tuned_problem(part, opt, tunings, initial)
            res = solve_problem(problem, x0, None, opt.compute_sigma, solver)
            iterations += res.iterations
            slope = opt.accel_noise_slope_mps2_per_radps > 0 and opt.measurement == "accelerometer"
            if slope or opt.robust:
                for _ in range(int(opt.reweight_iterations) - 1):  # re-weight from the new estimate
                    if slope:
                        problem.set_motion_dependent_noise(res.states[:, 0:3], opt.accel_noise_slope_mps2_per_radps)
                    if opt.robust:
                        problem.set_robust_weights(res.states, res.params)
                    res = solve_problem(problem, res.states, None, opt.compute_sigma, solver)
                    iterations += res.iterations
        if not res.converged:
            notes.append(f"solve window {w + 1} of {len(windows)} (samples {solve_sl.start}..{solve_sl.stop - 1}) "
                         f"stopped after {res.iterations} iterations without converging")
        cost += float(res.cost)
        m = min(M, res.states.shape[1])
        states[keep_log, :m] = res.states[keep_win, :m]
        if sd is not None:
            sd[keep_log, :m] = np.sqrt(np.einsum("nii->ni", res.covariance))[keep_win, :m]
        calibration.append({name: res.params[sl] for name, (sl, _) in problem.global_blocks.items()})
    sigma = {}
    if sd is not None:
        sigma = {"omega_b_radps": sd[:, 0:3], "omega_dot_b_radps2": sd[:, 3:6], "specific_force_b_mps2": sd[:, 6:9]}
    extra = {}
    if attitude:
        R = _so3.exp(states[:, M - 3:])
        extra["quaternion_wb"] = quaternion_from_matrix(R)
        extra["accel_b_mps2"] = states[:, 6:9] + np.einsum("nji,j->ni", R, GRAVITY_W_MPS2)
    motion = Motion(log.timestamps_ns, omega_b_radps=states[:, 0:3], omega_dot_b_radps2=states[:, 3:6],
                    specific_force_b_mps2=states[:, 6:9], sigma=sigma, **extra)
    return SmootherResult(motion, tuple(tunings), tuple(calibration), iterations, cost, len(windows), tuple(notes))


def _solve_with_attitude(part: Log, opt: SmootherOptions, previous, solve_sl: slice, tunings: list,
                         initial: InitialStates | None, solver: str):
    """Two stages: the smoother without attitude, then the attitude propagated from its ω
    (starting from the previous window's attitude, which also anchors the yaw) and the full solve."""
    base = replace(opt, estimate_attitude=False, use_inclinometer=False, compute_sigma=False)
    t = None
    if opt.tune_process_noise:  # the process noise of ω, ω̇ chosen without the attitude, kept with it
        before = len(tunings)
        problem0, x0 = tuned_problem(part, replace(base, tune_motion_model=False), tunings, initial)
        first = solve_problem(problem0, x0, None, False, solver)
        t = tunings[-1] if len(tunings) > before else None
        opt = replace(opt, omega_dot_random_walk_radps2_per_sqrt_s=problem0.options.omega_dot_random_walk_radps2_per_sqrt_s,
                      process_axis_factors=problem0.options.process_axis_factors,
                      process_axis_frequencies_hz=problem0.options.process_axis_frequencies_hz)
    else:
        first = solve_problem(SmootherProblem(part, base), (initial or initial_states)(part, base), None, False, solver)
    start = None
    if previous is not None:
        prev_sl, prev_R = previous
        start = prev_R[solve_sl.start - prev_sl.start]
    R = initial_attitude(part, first.states[:, 0:3], first.states[:, 6:9], start, opt.use_inclinometer)
    problem = make_problem(part, opt, t.accel_noise_scale) if t is not None else SmootherProblem(part, opt)
    problem.attitude_prior_wb = R[0]
    x0 = np.hstack([first.states, _so3.log(R)])
    return solve_problem(problem, x0, first.params if first.params.size else None, opt.compute_sigma, solver), problem


@dataclass(frozen=True)
class BatchSmootherEstimator(SmootherOptions):
    """Factor-graph smoother over the whole log (method "smoother").

    Options: see :class:`gfimu.smoother.graph.SmootherOptions`. Returns ω, ω̇
    and the specific force at the body origin for every sample, with
    one-sigma marginal uncertainties when ``compute_sigma``; :meth:`result`
    returns everything the run produced (:class:`SmootherResult`).

    Unlike :class:`SmootherOptions`, ``tune_process_noise`` is on by default: the
    jerk density per body axis and the specific-force density are chosen per solve
    window by the marginal likelihood of the data (:mod:`gfimu.smoother.tuning`);
    ``tune_process_noise=False`` uses the fixed densities.
    """

    tune_process_noise: bool = True
    solver: str = field(default="numpy", metadata={"unit": "", "help": "batch solver: 'numpy' (vectorised banded "
                                                   "Levenberg-Marquardt, default) or 'gtsam' (the same problem as a GTSAM graph)"})
    _runs: list = field(default_factory=list, init=False, repr=False, compare=False)
    """The results of :meth:`estimate` (only the newest is kept), behind :attr:`last_tuning`."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {self.solver!r}")

    def options(self) -> SmootherOptions:
        return SmootherOptions(**{f.name: getattr(self, f.name) for f in fields(SmootherOptions)})

    def applicable(self, array: SensorArray) -> str | None:
        return options_reason(array, self.options(), attitude_supported=True)

    def result(self, log: Log, progress: bool = False, initial: InitialStates | None = None) -> SmootherResult:
        """The smoother on ``log`` (:func:`smooth`), with everything it produced."""
        return smooth(log, self.options(), progress=progress, initial=initial, solver=self.solver)

    def estimate(self, log: Log, progress: bool = False) -> Motion:
        res = self.result(log, progress)
        self._runs[:] = [res]
        return res.motion

    @property
    def last_tuning(self) -> list:
        """The tunings of the newest :meth:`estimate` (kept for existing callers; :meth:`result` returns them)."""
        return list(self._runs[-1].tunings) if self._runs else []

    @property
    def last_calibration(self) -> list[dict]:
        """The calibration estimates of the newest :meth:`estimate` (see :attr:`SmootherResult.calibration`)."""
        return list(self._runs[-1].calibration) if self._runs else []


def _hessian_diagonal(linear: gtsam.GaussianFactorGraph, dims: dict[int, int]) -> dict[int, np.ndarray]:
    """Diagonal of JᵀJ of a linearised graph, per key (the scale of Marquardt's damping)."""
    out = {key: np.zeros(d) for key, d in dims.items()}
    for i in range(linear.size()):
        factor = linear.at(i)
        A, _ = factor.jacobian()
        col = np.sum(A * A, axis=0)
        start = 0
        for key in factor.keys():
            d = dims[key]
            out[key] += col[start:start + d]
            start += d
    return out


def gtsam_levenberg_marquardt(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None,
                              iterations: int = 10, tolerance: float = 1e-12) -> tuple[np.ndarray, np.ndarray, int, bool]:
    """The graph path: :meth:`SmootherProblem.gtsam_graph`, solved by the same Levenberg-Marquardt
    schedule as :func:`gfimu.smoother.banded.solve`, driven here on a Python-owned Values: linearise,
    eliminate with the states in time order (then the calibration variables), retract. The time
    ordering keeps the elimination a chain, linear in the length. Each iteration first tries the
    undamped Gauss-Newton step; Marquardt damping ``λ (diag(JᵀJ) + 10⁻⁹)`` is switched on and raised
    tenfold only while a step fails to lower the cost. Returns the states, the calibration variables,
    the iterations and whether it converged (relative decrease below ``tolerance``)."""
    graph = problem.gtsam_graph()
    P = np.zeros(problem.n_global) if params is None else np.asarray(params, dtype=float)
    values = problem.gtsam_values(states, P)
    ordering = problem.gtsam_ordering()
    dims = problem.gtsam_key_dims()
    cost = graph.error(values)
    lam, it, converged = 0.0, 0, False
    for it in range(1, iterations + 1):
        linear = graph.linearize(values)
        diag = None
        while True:
            system = linear
            if lam > 0.0:
                diag = diag or _hessian_diagonal(linear, dims)
                system = linear.clone()
                for key, d in diag.items():
                    system.add(gtsam.JacobianFactor(key, np.diag(np.sqrt(lam * (d + 1e-9))), np.zeros(d.size),
                                                    gtsam.noiseModel.Unit.Create(d.size)))
            try:
                delta = system.eliminateSequential(ordering).optimize()
            except RuntimeError:  # numerically indefinite: damp more
                if lam > 1e10:
                    raise
                lam = 1e-6 if lam == 0.0 else lam * 10.0
                continue
            trial = values.retract(delta)
            new_cost = graph.error(trial)
            if new_cost <= cost or lam > 1e10:
                break
            lam = 1e-6 if lam == 0.0 else lam * 10.0
        if new_cost > cost:
            converged = True
            break
        decrease = cost - new_cost
        values, cost = trial, new_cost
        lam = 0.0 if lam < 1e-8 else lam / 10.0
        step = max((float(np.max(np.abs(delta.at(key)))) for key in dims), default=0.0)
        if decrease <= tolerance * max(cost, 1e-300) or step < 1e-12:
            converged = True
            break
    X, P = problem.from_gtsam_values(values)
    return X, P, it, converged


gtsam_gauss_newton = gtsam_levenberg_marquardt
"""The former name of :func:`gtsam_levenberg_marquardt` (which takes the plain Gauss-Newton step whenever it lowers the cost)."""


def solve_with_gtsam(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None,
                     iterations: int = 10, tolerance: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """States and calibration variables from :func:`gtsam_gauss_newton`."""
    X, P, _, _ = gtsam_levenberg_marquardt(problem, states, params, iterations, tolerance)
    return X, P
