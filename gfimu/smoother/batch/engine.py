"""Batch smoother (method "smoother"): the whole log at once, linear in its length.

The factors of :class:`gfimu.smoother.model.problem.SmootherProblem` are evaluated
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
(:mod:`gfimu.smoother.tuning.evidence`, on by default here); with
``accel_noise_slope_mps2_per_radps`` the accelerometer noise grows with |ω|
and is re-weighted from each solution (iteratively re-weighted least squares).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ...array import SensorArray
from ...errors import DataError, InputError
from ...estimate import Estimate, Report, options_of
from ...estimators.ml import MLEstimator
from ...factors import GRAVITY_W_MPS2, so3 as _so3
from ...log import Log
from ...parallel import check_workers, fork_workers, forked_map
from ...motion import Motion
from ...progress import progress as progress_bar
from ...rotations import quaternion_from_matrix
from ..tuning.model_choice import CHECK_SAMPLES, check_model, chosen_options, estimate_noise_variances, local_density_factors
from ..solve.banded import (  # noqa: F401  (the banded core, also importable from here)
    REWEIGHTED_TOLERANCE,
    Factorisation,
    NormalEquations,
    SolveResult,
    add_normal_equations,
    factor_blocks,
    factorise,
    marginal_covariances,
    normal_equations,
    reweighting,
    solve,
    solve_reweighted,
    solve_step,
    to_lower_banded,
)
from ..model.problem import SmootherOptions, SmootherProblem, options_reason
from ..model.option_groups import BatchOptions, ModelGroups, assemble
from ..solve.initialise import initial_attitude, initial_states, sign_chain
from ..model.layout import OMEGA, SPECIFIC_FORCE, StateLayout
from ..solve.restarts import branch_restarts
from ..result import SmootherEstimator, unguarded
from .. import preload
from ..solve.sigma_scale import calibrated_sigma
from ..tuning.evidence import InitialStates, Tuning, make_problem, tuned_problem

SOLVERS = ("numpy", "gtsam")
"""Solvers of the batch smoother: the vectorised banded Levenberg-Marquardt (default: linear in the
length with a small constant, marginal σ included) and the same problem as a GTSAM graph, linearised,
eliminated in time order and retracted here (a cross-check, slower by the Python factor callbacks)."""


ALIGN_CUTS = 20
"""A window whose start has the other sign of ω than the window before is turned to that sign up to one of
this many cuts (the lowest local minima of |ω| past the overlap, and the window's end), the one of least cost."""
ALIGN_MIN_GAIN = 5.0
"""... and the turned solution is kept only when its cost (a negative log-likelihood) is lower by this much: the
readings at least e⁵ ≈ 150 times likelier (a window whose overlap rests, where ω is noise and either sign fits
as well, keeps its own)."""
WINDOW_STRETCH = 1.25
"""Solve windows may be up to this factor longer than ``window_s`` when that saves a window: a log a
little longer than a whole number of windows is cut into equal windows instead of leaving a short
last one (whose few seconds tell the noise levels poorly and still cost a whole tuning)."""


def window_slices(n: int, rate_hz: float, window_s: float | None, overlap_s: float) -> list[tuple[slice, slice, slice]]:
    """(solve slice, keep slice in the log, keep slice within the window) of overlapping windows.

    The log is cut into the fewest windows of at most ``window_s`` (stretched by up to
    :data:`WINDOW_STRETCH`) that overlap by ``overlap_s``, all of one length (within a sample);
    each keeps its samples up to the middle of its overlap with the next."""
    if window_s is None:
        return [(slice(0, n), slice(0, n), slice(0, n))]
    w = max(int(round(window_s * rate_hz)), 4)
    o = max(int(round(overlap_s * rate_hz)), 2)
    if n <= w:
        return [(slice(0, n), slice(0, n), slice(0, n))]
    k = int(np.ceil((n - o) / (w - o)))
    if k > 1 and (n - o) / (k - 1) + o <= WINDOW_STRETCH * w:
        k -= 1
    if k == 1:
        return [(slice(0, n), slice(0, n), slice(0, n))]
    starts = [int(round(i * (n - o) / k)) for i in range(k)]
    stops = starts[1:] + [n - o]
    stops = [s + o for s in stops]
    out = []
    keep_from = 0
    for i, (start, stop) in enumerate(zip(starts, stops)):
        keep_to = n if i == k - 1 else stop - o // 2
        out.append((slice(start, stop), slice(keep_from, keep_to), slice(keep_from - start, keep_to - start)))
        keep_from = keep_to
    return out





def solve_problem(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None,
                  compute_sigma: bool = False, solver: str = "numpy", reweight=None,
                  max_iterations: int | None = None) -> SolveResult:
    """:func:`gfimu.smoother.solve.banded.solve` with the banded numpy solver or the GTSAM graph (:data:`SOLVERS`)."""
    if solver == "numpy":
        return solve(problem, states, params, compute_sigma=compute_sigma, reweight=reweight, max_iterations=max_iterations)
    if solver != "gtsam":
        raise InputError(f"unknown solver {solver!r}; choose one of: {', '.join(SOLVERS)}")
    limit = int(problem.solve.max_iterations if max_iterations is None else max_iterations)
    X, P, iterations, converged, problem = gtsam_levenberg_marquardt(problem, states, params, limit,
                                                                     problem.solve.relative_tolerance, reweight)
    ne = normal_equations(problem, X, P)
    result = SolveResult(X, P, ne.cost, iterations, converged, problem=problem)
    if compute_sigma:
        result.covariance, result.param_covariance = marginal_covariances(ne, factorise(ne, 0.0))
    return result


def solve_window(problem: SmootherProblem, states: np.ndarray, batch: BatchOptions, params: np.ndarray | None = None,
                 compute_sigma: bool | None = None, solver: str = "numpy") -> SolveResult:
    """:func:`gfimu.smoother.solve.banded.solve_reweighted` (motion-dependent noise and robust losses of the
    problem's batch model, ``batch.reweight_iterations``) with either solver."""
    if solver == "numpy":
        return solve_reweighted(problem, states, batch, params, compute_sigma)
    sigma = problem.solve.compute_sigma if compute_sigma is None else compute_sigma
    reweight = reweighting(problem.batch_model)
    if reweight is None:
        return solve_problem(problem, states, params, sigma, solver)
    first = solve_problem(problem, states, params, False, solver, max_iterations=max(1, int(batch.reweight_iterations) - 1))
    return solve_problem(problem, first.states, first.params if first.params.size else None, sigma, solver, reweight)


def smooth(log: Log, groups: ModelGroups, batch: BatchOptions, progress: bool = False,
           initial: InitialStates | None = None, per_sample: bool = False) -> Estimate:
    """The batch smoother on a whole log: the model of the option ``groups`` solved in the overlapping
    solve windows of ``batch`` (their length and overlap, the solver, the restarts, the re-weighting, the
    tuning span and the worker processes), the model chosen from the log and the process noise from each
    window's data as ``groups.tuning`` asks.

    ``initial``: how each window's initial states are made (default
    :func:`gfimu.smoother.solve.initialise.initial_estimate`). The report (method "smoother", the options of
    all its groups) carries the noise tuned and the calibration per window, the solver's iterations and cost,
    the model check and, when the check made it, the per-sample estimate; no guard. ``per_sample``: the
    per-sample estimate of the whole log is wanted after the run (the guard's), so the model check makes it
    whether it needs it or not, started beside its own estimate of a subsample (:func:`chosen_model`)."""
    # the options whole, as the report gives them
    options = SmootherOptions.from_groups(*groups, batch)
    _check_smoothable(log, groups, batch.solver)
    preload.wait()  # (the kernels' loading begun while the log was read is over before anything is forked)
    layout = StateLayout.of(groups.model, groups.attitude)
    attitude = layout.attitude
    windows = window_slices(len(log), log.rate_hz, batch.window_s, batch.overlap_s)
    timings = {}
    t0 = time.perf_counter()
    chosen, auto = groups, None
    if groups.tuning.auto_model:
        chosen, auto = chosen_model(log, chosen, attitude, per_sample)
        timings["model check"] = time.perf_counter() - t0
    if auto is not None and auto[0].constant:  # nothing to smooth: the per-sample answer, said so
        motion = auto[1] if auto[1] is not None else MLEstimator().estimate_motion(log)
        note = f"{log.source}: {auto[0].describe()}; the per-sample estimate is returned"
        return Estimate(motion, Report.of("smoother", options, timings=timings, warnings=(note,), model_check=auto[0],
                                          iterations=0, cost=0.0, windows=0, per_sample=motion))
    t0 = time.perf_counter()
    if attitude:  # each window starts from the attitude of the one before: in turn
        outcomes = _attitude_windows(log, chosen, windows, initial, batch.solver, progress)
    else:
        context = _WindowContext(log, chosen, batch, auto, initial, windows)
        outcomes = _run_windows(context, window_workers(batch.workers, len(windows), batch.solver), progress)
        _align_signs(context, outcomes)
    timings["solve windows"] = time.perf_counter() - t0
    joined = _Joined.of(log, layout, chosen, windows, outcomes)
    return Estimate(joined.motion(log, layout), Report.of(
        "smoother", options, timings=timings, warnings=joined.notes, model_check=auto[0] if auto else None,
        tunings=joined.tunings, calibration=joined.calibration, iterations=joined.iterations, cost=joined.cost,
        windows=len(windows), per_sample=auto[1] if auto else None))


def _check_smoothable(log: Log, groups: ModelGroups, solver: str) -> None:
    """An :class:`InputError` when the model of the option ``groups`` does not fit the log's array or ``solver``
    is unknown, a :class:`DataError` when the log has fewer than 2 samples."""
    reason = options_reason(log.array, groups, attitude_supported=True)
    if reason:
        raise InputError(f"{log.source}: {reason}")
    if solver not in SOLVERS:
        raise InputError(f"unknown solver {solver!r}; choose one of: {', '.join(SOLVERS)}")
    n = len(log)
    if n < 2:
        raise DataError(f"{log.source}: the smoother needs at least 2 samples, got {n}")


@dataclass
class _Joined:
    """The solve windows' outcomes joined over the whole log: the kept states and σ (None without
    ``compute_sigma``), and what the report says of them (tunings, calibration, iterations, cost, notes)."""

    states: np.ndarray
    sd: np.ndarray | None
    calibration: list
    tunings: list
    notes: list
    iterations: int
    cost: float

    @classmethod
    def of(cls, log: Log, layout: StateLayout, groups: ModelGroups, windows: list,
           outcomes: list[_WindowOutcome]) -> _Joined:
        """Each window's kept rows in place, in window order; σ scaled by the readings' misfit where
        :func:`_calibrates_sigma`."""
        n, M = len(log), layout.size
        out = cls(np.zeros((n, M)), np.zeros((n, M)) if groups.solve.compute_sigma else None, [], [], [], 0, 0.0)
        for w, ((solve_sl, keep_log, keep_win), res) in enumerate(zip(windows, outcomes)):
            out.tunings.extend(res.tunings)
            out.iterations += res.iterations
            if not res.converged:
                out.notes.append(f"solve window {w + 1} of {len(windows)} (samples {solve_sl.start}..{solve_sl.stop - 1}) "
                                 f"stopped after {res.iterations} iterations without converging")
            out.cost += res.cost
            m = min(M, res.states.shape[1])
            out.states[keep_log, :m] = res.states[:, :m]
            if out.sd is not None:
                out.sd[keep_log, :m] = res.sd[:, :m]
            out.calibration.append(res.calibration)
        if (out.sd is not None and outcomes and all(res.noise is not None for res in outcomes)
                and _calibrates_sigma(log, groups)):
            noise_std = np.vstack([res.noise for res in outcomes])
            process = None
            if (len(log) > 2 and all(res.process is not None for res in outcomes)
                    and all(np.array_equal(res.process[1], outcomes[0].process[1]) for res in outcomes)):
                process = (np.vstack([res.process[0] for res in outcomes])[:-1], outcomes[0].process[1], log.dt_s)
            batch_model = groups.batch_model
            out.sd = calibrated_sigma(log.array, log.accel_mps2, out.states, out.sd, noise_std,
                                      (batch_model.robust_loss, batch_model.accel_robust_threshold)
                                      if batch_model.accel_robust_threshold > 0 else None, process=process,
                                      dt_s=log.dt_s)
        return out

    def motion(self, log: Log, layout: StateLayout) -> Motion:
        """The :class:`Motion` of the joined states (with the attitude's quaternion and the gravity-free
        acceleration when the states hold the attitude) and σ."""
        states = self.states
        sigma = {} if self.sd is None else layout.quantities(self.sd)
        extra = {}
        if layout.attitude:
            R = _so3.exp(states[:, layout.rotation])
            extra["quaternion_wb"] = quaternion_from_matrix(R)
            extra["accel_b_mps2"] = states[:, layout.specific_force] + np.einsum("nji,j->ni", R, GRAVITY_W_MPS2)
        return Motion(log.timestamps_ns, sigma=sigma, **layout.quantities(states), **extra)


@dataclass
class _WindowOutcome:
    """What one solve window gives the whole log: its states (those it keeps, and σ), calibration, choices."""

    solved: np.ndarray
    """The states of the whole solve window (its overlaps with its neighbours included)."""
    keep: slice
    """The rows of :attr:`solved` the log keeps."""
    sd: np.ndarray | None
    calibration: dict
    tunings: list
    iterations: int
    cost: float
    converged: bool
    noise: np.ndarray | None = None
    """The accelerometer noise std the solution assumed on the kept rows before any robust weight (N, axes)."""
    process: tuple | None = None
    """(jerk density (N, 3) of the step from each kept row to the next (the last row of the solve window: the step
    into it) per body axis, the driven oscillator's Ω (3,)) as the solution assumed them, or None (σ not computed,
    or white snap)."""

    @property
    def states(self) -> np.ndarray:
        """The kept states."""
        return self.solved[self.keep]

    @classmethod
    def of(cls, res: SolveResult, problem: SmootherProblem, keep_win: slice, tunings: list) -> _WindowOutcome:
        sd = None if res.covariance is None else np.sqrt(np.einsum("nii->ni", res.covariance))[keep_win]
        solved = res.problem or problem
        noise = None if sd is None else np.array(solved.noise.accel.start(solved.n))[keep_win]
        return cls(res.states, keep_win, sd, {name: res.params[sl] for name, (sl, _) in problem.global_blocks.items()},
                   tunings, res.iterations, float(res.cost), bool(res.converged), noise,
                   None if sd is None else _process_densities(res.problem or problem, keep_win))


def _process_densities(problem: SmootherProblem, keep: slice) -> tuple | None:
    """:attr:`_WindowOutcome.process` of the rows ``keep`` of ``problem``'s solution."""
    motion = problem.noise.motion
    if motion.snap_cov is not None or problem.n < 2:
        return None
    rows = np.minimum(np.arange(problem.n)[keep], problem.n - 2)
    density = np.asarray(motion.omega_dot_step_sigma, dtype=float) / np.sqrt(problem.dt_s)  # q times any local factor
    return density[rows, None] * np.asarray(motion.axis_factors, dtype=float), np.asarray(motion.natural_frequency_radps,
                                                                                            dtype=float)


@dataclass
class _WindowContext:
    """Everything a window without attitude needs, shared by the windows (and by the worker
    processes, which inherit it when they start)."""

    log: Log
    groups: ModelGroups
    batch: BatchOptions
    auto: tuple | None
    initial: InitialStates | None
    windows: list

    def solve(self, w: int) -> _WindowOutcome:
        solve_sl, _, keep_win = self.windows[w]
        part = self.log.select(solve_sl)
        batch, tunings = self.batch, []
        if self.auto is not None and not self.auto[0].consistent:
            problem, x0 = moment_problem(part, self.groups, self.auto, solve_sl, tunings)
            res = solve_window(problem, x0, batch, solver=batch.solver)
            if batch.branch_restarts:
                res = _restarted(problem, res)
        else:
            problem, x0 = self._tuned(part, tunings)
            res = solve_window(problem, x0, batch, solver=batch.solver)
        return _WindowOutcome.of(res, problem, keep_win, tunings)

    def _tuned(self, part: Log, tunings: list):
        """:func:`gfimu.smoother.tuning.evidence.tuned_problem` of a window ``part``."""
        return tuned_problem(part, self.groups, tunings, self.initial, self.batch.tune_span_s)

    def aligned(self, w: int, outcome: _WindowOutcome, earlier_omega_b_radps: np.ndarray) -> _WindowOutcome | None:
        """Window ``w`` solved again with the sign of ω the window before found over their overlap
        (``earlier_omega_b_radps``, the overlap's first rows of this window), when its own solution has the
        other sign there: its solution turned to that sign up to the cut (a local minimum of |ω| past the
        overlap, or the window's end) of least cost, re-solved; the outcome when its cost is lower than
        ``outcome``'s by :data:`ALIGN_MIN_GAIN`, else None. Windows of the Gaussian model without calibration
        variables only (the robust model has its restarts)."""
        if self.auto is not None and not self.auto[0].consistent:
            return None
        solve_sl, _, keep_win = self.windows[w]
        part = self.log.select(solve_sl)
        tunings: list = []
        problem, _ = self._tuned(part, tunings)
        if problem.n_global:  # calibration variables: their values are not kept to compare costs at
            return None
        X = outcome.solved
        start = earlier_omega_b_radps.shape[0]
        cuts = _low_speed_cuts(X[:, OMEGA], start) + [len(X)]
        best, best_cost = None, np.inf
        for cut in cuts:
            Y = X.copy()
            Y[:cut, OMEGA] *= -1.0
            c = problem.cost(Y, None)
            if c < best_cost:
                best, best_cost = Y, c
        res = solve_window(problem, best, self.batch, solver=self.batch.solver)
        agrees = np.sum(res.states[:start, OMEGA] * earlier_omega_b_radps) > 0
        if not (agrees and res.cost < outcome.cost - ALIGN_MIN_GAIN):
            return None
        return _WindowOutcome.of(res, problem, keep_win, tunings)


def window_workers(workers: int, windows: int, solver: str = "numpy") -> int:
    """Processes to solve ``windows`` windows with: ``workers`` (0: one per CPU this process may run
    on), at most one per window, forked so that they inherit the log (:func:`gfimu.parallel.fork_workers`:
    1 in a daemonic process such as a Dask worker); 1 with the GTSAM solver."""
    check_workers(workers)
    return 1 if solver != "numpy" else fork_workers(workers, windows)


def _run_windows(context: _WindowContext, workers: int, progress: bool) -> list[_WindowOutcome]:
    """Every window of ``context``, in this process or spread over ``workers`` forked processes (each
    window's numbers are the same either way: the windows do not depend on one another). An error
    in a window, or an interruption, stops the other workers at once."""
    total = len(context.windows)
    bar = progress_bar(range(total), total=total, desc="smoother", enable=progress and total > 1)
    out: list = [None] * total
    done = iter(bar)
    for w, outcome in forked_map(context.solve, range(total), workers, ordered=False):
        out[w] = outcome
        next(done, None)
    return out


def _low_speed_cuts(omega_b_radps: np.ndarray, first: int = 1) -> list[int]:
    """The :data:`ALIGN_CUTS` lowest local minima of |ω| from row ``first`` on (the rows where ω may change
    sign at least cost), in time order."""
    speed = np.linalg.norm(omega_b_radps, axis=1)
    if len(speed) < first + 3:
        return []
    inner = speed[first:-1]
    minima = np.nonzero((inner <= speed[first - 1:-2]) & (inner < speed[first + 1:]))[0] + first
    return sorted(minima[np.argsort(speed[minima])[:ALIGN_CUTS]].tolist())


def _align_signs(context: _WindowContext, outcomes: list[_WindowOutcome]) -> list[int]:
    """Each window, in turn, whose ω over its overlap with the window before has the other sign than that
    window's (a window's start has no past of its own to set the sign by, the one before has) solved again
    with that sign (:meth:`_WindowContext.aligned`) and kept where its cost falls; their indices."""
    aligned = []
    for w in range(1, len(outcomes)):
        before, here = context.windows[w - 1][0], context.windows[w][0]
        overlap = before.stop - here.start
        if overlap < 2:
            continue
        earlier = outcomes[w - 1].solved[here.start - before.start:, OMEGA]
        if np.sum(earlier * outcomes[w].solved[:overlap, OMEGA]) >= 0:
            continue
        better = context.aligned(w, outcomes[w], earlier)
        if better is not None:
            better.iterations += outcomes[w].iterations
            outcomes[w] = better
            aligned.append(w)
    return aligned


def _attitude_windows(log: Log, groups: ModelGroups, windows: list, initial: InitialStates | None, solver: str,
                      progress: bool) -> list[_WindowOutcome]:
    out = []
    previous = None  # (solve slice, attitudes) of the window before
    for solve_sl, _, keep_win in progress_bar(windows, total=len(windows), desc="smoother",
                                              enable=progress and len(windows) > 1):
        tunings: list = []
        res, problem = _solve_with_attitude(log.select(solve_sl), groups, previous, solve_sl, tunings, initial, solver)
        previous = (solve_sl, problem.rotations(res.states))
        out.append(_WindowOutcome.of(res, problem, keep_win, tunings))
    return out


def _calibrates_sigma(log: Log, groups: ModelGroups) -> bool:
    """Whether σ is scaled by the readings' misfit (:mod:`gfimu.smoother.solve.sigma_scale`): the accelerometers
    alone, as they are (no gyroscope, inclinometer or calibration variables the residual would leave out)."""
    attitude = groups.attitude
    return (groups.batch_model.measurement == "accelerometer" and not groups.self_calibration.calibrates
            and not (groups.model.use_gyro and log.array.gyroscope is not None and log.gyro_b_radps is not None)
            and not (attitude.estimate_attitude and attitude.use_inclinometer and log.array.inclinometer is not None))


def chosen_model(log: Log, given: ModelGroups, attitude: bool, per_sample: bool = False):
    """(the option groups of the model chosen from those ``given``, (ModelCheck, ML motion or None) or None) of
    :mod:`gfimu.smoother.tuning.model_choice`; the ML motion is the whole log's (:class:`MLEstimator` with its
    defaults) where the check computed it, else None.

    ``per_sample``: the whole log's ML motion is wanted anyway (by the guard after the smoother): it is made
    whatever the check finds, its blocks started in worker processes while this one estimates the subsample
    the check reads (the same numbers as one after the other)."""
    batch_model = given.batch_model
    if (attitude or batch_model.free_flight or batch_model.measurement != "accelerometer"
            or given.self_calibration.calibrates):
        return given, None
    ml = MLEstimator()
    if ml.applicable(log.array) is not None or not np.all(np.isfinite(log.accel_mps2)):
        return given, None
    step = max(1, len(log) // CHECK_SAMPLES)
    sample = log if step == 1 else log.select(slice(0, None, step))
    whole = ml.started(log) if per_sample and step > 1 else None
    try:
        motion = ml.estimate_motion(sample)
        check = check_model(sample, motion)
        if check.consistent:  # the ML motion of the whole log is kept for the guard (it would compute it again)
            motion = motion if step == 1 else whole.motion() if whole is not None else None
        elif step > 1:
            motion = whole.motion() if whole is not None else ml.estimate_motion(log)
    finally:
        if whole is not None:
            whole.close()
    return chosen_options(given, check, log, motion), (check, motion)


def _restarted(problem: SmootherProblem, res: SolveResult) -> SolveResult:
    """``res`` with the local restarts of :func:`gfimu.smoother.solve.restarts.branch_restarts`: short runs
    on another branch of ω kept where the robust objective falls; the cost is the re-weighted cost at
    the result."""
    problem = res.problem or problem
    states, tried, kept = branch_restarts(problem, res.states)
    if not kept:
        return res
    reweight = reweighting(problem.batch_model)
    if reweight is not None:
        problem = reweight(problem, states, res.params)
    out = replace(res, states=states, cost=problem.cost(states, res.params), problem=problem)
    if res.covariance is not None:
        ne = normal_equations(problem, states, res.params)
        out.covariance, out.param_covariance = marginal_covariances(ne, factorise(ne, 0.0))
    return out


def moment_problem(part: Log, groups: ModelGroups, auto, solve_sl: slice, tunings: list):
    """Problem and initial states of one window of an inconsistent log: ML initialisation with its
    sign chain, the measured noise floor and slope, the process densities chosen for the log, and
    the jerk density lowered where the body rests (:func:`gfimu.smoother.tuning.model_choice.local_density_factors`)."""
    check, motion = auto
    model = groups.model
    omega = motion.omega_b_radps[solve_sl]
    omega_dot = motion.omega_dot_b_radps2[solve_sl]
    if groups.solve.ml_sign_chain:
        omega = omega * sign_chain(omega, omega_dot, part.dt_s)[:, None]
    x0 = np.hstack([omega, omega_dot, motion.specific_force_b_mps2[solve_sl]])
    scale = 1.0
    if np.isfinite(check.stated_noise_mps2) and check.stated_noise_mps2 > 0:
        scale = check.noise_floor_mps2 / check.stated_noise_mps2
    tunings.append(Tuning("jerk", model.omega_dot_random_walk_radps2_per_sqrt_s, scale, float("nan"), 0,
                          tuple(model.process_axis_factors), model.specific_force_random_walk_mps2_per_sqrt_s))
    problem = make_problem(part, groups, scale, x0[:, OMEGA])
    factors = local_density_factors(x0, part.dt_s, estimate_noise_variances(part.array, check, omega)[0],
                                    model.omega_dot_random_walk_radps2_per_sqrt_s)
    return problem.with_noise(motion=problem.noise.motion.scaled_steps(factors)), x0


def _solve_with_attitude(part: Log, groups: ModelGroups, previous, solve_sl: slice, tunings: list,
                         initial: InitialStates | None, solver: str):
    """Two stages: the smoother without attitude, then the attitude propagated from its ω
    (starting from the previous window's attitude, which also anchors the yaw) and the full solve."""
    base = groups._replace(solve=replace(groups.solve, compute_sigma=False),
                           attitude=replace(groups.attitude, estimate_attitude=False, use_inclinometer=False))
    t = None
    if groups.tuning.tune_process_noise:  # the process noise of ω, ω̇ chosen without the attitude, kept with it
        before = len(tunings)
        problem0, x0 = tuned_problem(part, base._replace(tuning=replace(groups.tuning, tune_motion_model=False)), tunings,
                                     initial)
        first = solve_problem(problem0, x0, None, False, solver)
        t = tunings[-1] if len(tunings) > before else None
        groups = groups._replace(model=replace(
            groups.model, omega_dot_random_walk_radps2_per_sqrt_s=problem0.model.omega_dot_random_walk_radps2_per_sqrt_s,
            process_axis_factors=problem0.model.process_axis_factors,
            process_axis_frequencies_hz=problem0.model.process_axis_frequencies_hz))
    else:
        first = solve_problem(SmootherProblem(part, base), (initial or initial_states)(part, base), None, False, solver)
    start = None
    if previous is not None:
        prev_sl, prev_R = previous
        start = prev_R[solve_sl.start - prev_sl.start]
    R = initial_attitude(part, first.states[:, OMEGA], first.states[:, SPECIFIC_FORCE], start,
                         groups.attitude.use_inclinometer)
    problem = (make_problem(part, groups, t.accel_noise_scale) if t is not None else SmootherProblem(part, groups))
    problem = problem.with_noise(attitude=problem.noise.attitude.with_prior(R[0]))
    x0 = np.hstack([first.states, _so3.log(R)])
    return solve_problem(problem, x0, first.params if first.params.size else None, groups.solve.compute_sigma,
                         solver), problem


PRELOAD_MIN_BYTES = 8_000_000
"""The batch smoother's compiled kernels are loaded for a log whose readings' file holds at least this many
bytes (about 400,000 readings, 18 bytes each in imu.csv): there they save more than numba's start costs
(on a MIMU4444 recording of 39,301 samples of 24 axes, 18 MB, about 1 s of CPU for 0.35 s)."""


@dataclass(frozen=True)
@assemble(tune_process_noise=True)
class BatchSmootherEstimator(SmootherEstimator, SmootherOptions):
    """Factor-graph smoother over the whole log (method "smoother").

    Options: those of :class:`gfimu.smoother.model.problem.SmootherOptions` (its groups) and
    ``guard`` (:mod:`gfimu.smoother.model.option_groups`; no fixed-lag option). Returns ω, ω̇
    and the specific force at the body origin for every sample, with
    one-sigma marginal uncertainties when ``compute_sigma``; the report of :meth:`estimate`
    carries everything the run produced (:class:`~gfimu.estimate.Report`).

    Unlike :class:`SmootherOptions`, ``tune_process_noise`` is on by default: the
    jerk density per body axis and the specific-force density are chosen per solve
    window by the marginal likelihood of the data (:mod:`gfimu.smoother.tuning.evidence`);
    ``tune_process_noise=False`` uses the fixed densities.
    """

    method = "smoother"

    def applicable(self, array: SensorArray) -> str | None:
        return options_reason(array, self.model_groups, attitude_supported=True)

    def preload(self, size_bytes: int | None = None) -> None:
        """Begin loading the compiled kernels of the solve in the background (:mod:`gfimu.smoother.preload`),
        while the log is read and screened: for a log of ``size_bytes`` (its readings' file; None: unknown) of
        at least :data:`PRELOAD_MIN_BYTES`. A smaller log is solved by the numpy expressions: numba's start
        (about 0.35 s of CPU and 100 MB) costs it more than the kernels save."""
        if size_bytes is not None and size_bytes < PRELOAD_MIN_BYTES:
            return
        from ..preload import start

        start("batch")

    def result(self, log: Log, progress: bool = False, initial: InitialStates | None = None) -> Estimate:
        """The smoother on ``log`` (:func:`smooth`) before the guard, its report with this estimator's
        options (:meth:`estimate` is the entry: the run, then the guard)."""
        groups = self.model_groups
        run = smooth(log, groups, self.batch, progress=progress, initial=initial,
                     per_sample=self.guard != "off" and unguarded(log, groups.model, groups.attitude,
                                                                  groups.self_calibration) is None)
        return Estimate(run.motion, replace(run.report, options=options_of(self)))


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
                              iterations: int = 10, tolerance: float = 1e-12,
                              reweight=None) -> tuple[np.ndarray, np.ndarray, int, bool]:
    """The graph path: :meth:`SmootherProblem.gtsam_graph`, solved by the Levenberg-Marquardt schedule
    of :func:`gfimu.smoother.solve.banded.solve`, driven here on a Python-owned Values: linearise, eliminate
    with the states in time order (then the calibration variables), retract. The time ordering keeps
    the elimination a chain, linear in the length. Each iteration first tries the undamped
    Gauss-Newton step; Marquardt damping ``λ (diag(JᵀJ) + 10⁻⁹)`` is switched on and raised tenfold
    only while a step fails to lower the cost. ``reweight(problem, states, params)`` re-weights the
    problem before every iteration (the graph is rebuilt with the new noise). Returns the states, the
    calibration variables, the iterations, whether it converged and the problem as last re-weighted."""
    import gtsam  # only this path needs it (imported here: it is slow to import)

    P = np.zeros(problem.n_global) if params is None else np.asarray(params, dtype=float)
    X = np.array(states, dtype=float)
    if reweight is not None:
        problem = reweight(problem, X, P)
    graph = problem.gtsam_graph()
    values = problem.gtsam_values(X, P)
    ordering = problem.gtsam_ordering()
    dims = problem.gtsam_key_dims()
    rows = sum(graph.at(i).dim() for i in range(graph.size()))
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
        enough = tolerance * max(new_cost, 1e-300)
        if reweight is not None:  # new weights at the new estimate: rebuild the graph with them
            X, P = problem.from_gtsam_values(values)
            problem = reweight(problem, X, P)
            graph = problem.gtsam_graph()
            cost = graph.error(values)
            enough = max(enough, REWEIGHTED_TOLERANCE * np.sqrt(0.5 * rows))
        step = max((float(np.max(np.abs(delta.at(key)))) for key in dims), default=0.0)
        if decrease <= enough or step < 1e-12:
            converged = True
            break
    X, P = problem.from_gtsam_values(values)
    return X, P, it, converged, problem


gtsam_gauss_newton = gtsam_levenberg_marquardt
"""The former name of :func:`gtsam_levenberg_marquardt` (which takes the plain Gauss-Newton step whenever it lowers the cost)."""


def solve_with_gtsam(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None,
                     iterations: int = 10, tolerance: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """States and calibration variables from :func:`gtsam_levenberg_marquardt`."""
    X, P = gtsam_levenberg_marquardt(problem, states, params, iterations, tolerance)[:2]
    return X, P
