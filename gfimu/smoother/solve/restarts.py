"""Local restarts of the batch smoother's robust solution on the other branches of ω.

Accelerometers see ω through its quadratic terms, ``q(ω) = q(-ω)``, and a nearly planar array
also confuses ω with its mirror image through the array's plane (the out-of-plane readings see
ω_x ω_n, ω_y ω_n only mixed with ω̇; see docs/rigid-body-residual.md). Where the readings alone
cannot tell the branches apart, the motion model does. But with the robust (Cauchy) loss on the
motion-model steps of the robust model (:mod:`gfimu.smoother.tuning.model_choice`), a short run of samples on
another branch costs only the logarithm of the two large steps at its ends: Levenberg-Marquardt,
a local method, keeps such a run once it has it (a local minimum of the smoother's objective).

:func:`branch_restarts` searches for them after the re-weighted solve, in the smoother's own
objective only: each short run of samples between two motion-model steps beyond the robust
threshold (the solution's outlying steps, at most :data:`RUN_SAMPLES` apart) is moved to each
other branch (ω sign-flipped, ω mirrored through the array's best-fit plane with ω̇ moved so that
a planar array's readings stay fitted), re-solved locally, and kept only when the robust
objective :func:`objective` of the whole window falls. The noise is the solve's final one (its
motion-dependent part frozen at the solution), so the objective is one function for every
candidate.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...factors import accelerometer
from ..model.problem import SmootherProblem, robust_loss
from ..model.groups import AccelerometerGroup, FactorGroup, MotionModelGroup, Term
from ..model.layout import OMEGA, OMEGA_DOT, SPECIFIC_FORCE

RUN_SAMPLES = 6
"""Longest run of samples between two outlying motion-model steps that is tried on another branch."""
OUTLYING = 2.0
"""A motion-model step bounds a run when its whitened norm exceeds this many robust thresholds: the
Cauchy weight is then below 1/5, the motion model has let the step go (milder steps are the
loss's ordinary down-weighting, and trying every run between them costs far more time)."""
MAX_RUNS_PER_SAMPLE = 0.02
"""At most this many runs per sample of the window are tried (and 10 more): the runs between outlying
steps are the solution's rare misfits; a window with far more of them is one the robust model does not
fit, where trying them all would cost minutes (30 ms each) for nothing."""
MARGIN_SAMPLES = 8
"""Samples on each side of a run re-solved with it (the rest of the window stays where it is)."""


def applies(problem: SmootherProblem) -> bool:
    """Whether the restarts apply: the accelerometer equation with a robust loss on the white-jerk
    motion model's steps, no attitude, no calibration variables."""
    opt = problem.batch_model
    return (opt.measurement == "accelerometer" and opt.process_robust_threshold > 0 and not problem.snap
            and not problem.layout.attitude and not problem.noise.motion.oscillator and problem.n_global == 0
            and problem.n > 2 * MARGIN_SAMPLES + RUN_SAMPLES)


class FrozenObjective:
    """The robust objective of a solved problem with its noise as the re-weighting left it: the
    accelerometer noise at the solution's |ω| (un-reweighted), the motion-model steps' base noise
    (:meth:`AccelNoise.start`, :meth:`MotionNoise.start` of the problem's noise levels)."""

    def __init__(self, problem: SmootherProblem):
        self.problem = problem
        trapezoid, omega_dot_step, _ = problem.noise.motion.start()
        self.accel_sigma = np.array(problem.noise.accel.start(problem.n))
        self.trapezoid_sigma, self.omega_dot_step_sigma = np.array(trapezoid), np.array(omega_dot_step)
        self.rows = problem.all_rows

    def step_norms(self, X: np.ndarray) -> tuple[np.ndarray, int]:
        """(N-1,) whitened step residual norms / √rows under the base noise, and the rows per step."""
        e = self.problem.group(MotionModelGroup).step_residual(self.problem, X,
                                                               (self.trapezoid_sigma, self.omega_dot_step_sigma))
        return np.sqrt(np.mean(e * e, axis=1)), e.shape[1]

    def __call__(self, X: np.ndarray) -> float:
        """J: Σ ρ over the accelerometer axes, Σ rows · ρ over the motion-model steps (on the step's
        norm / √rows, as the re-weighting), ½ Σ of the other whitened rows squared."""
        p, opt = self.problem, self.problem.batch_model
        r = (accelerometer.accelerometer_prediction(X[:, OMEGA], X[:, OMEGA_DOT], X[:, SPECIFIC_FORCE], self.rows)
             - p.log.accel_mps2) / self.accel_sigma
        total = float(np.sum(robust_loss(r * r, opt.accel_robust_threshold, opt.robust_loss)))
        e, rows = self.step_norms(X)
        total += rows * float(np.sum(robust_loss(e * e, opt.process_robust_threshold, opt.robust_loss)))
        params = np.zeros(0)
        for g in p.groups:
            if isinstance(g, (AccelerometerGroup, MotionModelGroup)):
                continue
            total += 0.5 * g.squared_norm(p, X, params)
        return total


class _HeldStates(FactorGroup):
    """Whole states of some samples held at given values (the ends of a local re-solve)."""

    name = "held states"
    per_sample = False

    def __init__(self, index, values, sigma: float = 1e-6):
        self.index, self.values, self.sigma = list(index), np.asarray(values), sigma

    def terms(self, problem, states, params):
        m = problem.state_size
        J = np.eye(m)[None] / self.sigma
        return [Term("unary", ((states[i] - v) / self.sigma)[None], {"x": J}, first=int(i))
                for i, v in zip(self.index, self.values)]

    def log_normaliser(self, problem):
        return 0.0


def plane_normal(positions_m: np.ndarray) -> np.ndarray:
    """Unit normal of the best-fit plane through the accelerometer positions (smallest principal direction)."""
    p = np.asarray(positions_m, dtype=float)
    return np.linalg.svd(p - p.mean(axis=0))[2][-1]


def branch(kind: int, omega: np.ndarray, omega_dot: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ω, ω̇) (each (3,) or (N, 3)) on branch ``kind`` of the readings' ambiguity: bit 1 flips ω
    (q(ω) = q(-ω)), bit 2 mirrors ω through the plane of unit normal ``normal`` with ω̇ moved so that a
    planar array's readings stay fitted sample by sample, ``ω' = ω - 2 (ω·n) n``,
    ``ω̇' = ω̇ - 2 (ω·n) (n × ω)``; the four form a group (``a ^ b``)."""
    w, dw = omega, omega_dot
    if kind & 2:
        n = normal
        wn = (w @ n)[..., None] if w.ndim > 1 else float(w @ n)
        n_x_w = np.stack([n[1] * w[..., 2] - n[2] * w[..., 1], n[2] * w[..., 0] - n[0] * w[..., 2],
                          n[0] * w[..., 1] - n[1] * w[..., 0]], axis=-1)
        w, dw = w - 2.0 * wn * n, dw - 2.0 * wn * n_x_w
    if kind & 1:
        w = -w
    return w, dw


def _on_branch(kind: int, X: np.ndarray, normal: np.ndarray) -> np.ndarray:
    out = X.copy()
    out[:, OMEGA], out[:, OMEGA_DOT] = branch(kind, X[:, OMEGA], X[:, OMEGA_DOT], normal)
    return out


def flipped(X: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """ω turned to -ω, ω̇ kept (the quadratic terms do not see the sign of ω)."""
    return _on_branch(1, X, normal)


def mirrored(X: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """ω mirrored through the plane of unit normal n, ω̇ moved so that a planar array's readings stay
    fitted sample by sample (:func:`branch`)."""
    return _on_branch(2, X, normal)


BRANCHES = (flipped, mirrored)


def outlier_runs(objective: FrozenObjective, X: np.ndarray, longest: int = RUN_SAMPLES) -> list[tuple[int, int]]:
    """Runs [a, b) of samples between two motion-model steps beyond :data:`OUTLYING` robust
    thresholds, at most ``longest`` samples long, shortest first."""
    e, _ = objective.step_norms(X)
    steps = np.nonzero(e > OUTLYING * objective.problem.batch_model.process_robust_threshold)[0]
    runs = []
    for i, k1 in enumerate(steps):
        for k2 in steps[i + 1:]:
            if k2 - k1 > longest:
                break
            runs.append((int(k1) + 1, int(k2) + 1))
    return sorted(runs, key=lambda r: (r[1] - r[0], r[0]))


def local_resolve(objective: FrozenObjective, X: np.ndarray, a: int, b: int, margin: int = MARGIN_SAMPLES,
                  max_iterations: int = 10) -> np.ndarray:
    """X with samples [a - margin, b + margin) re-solved under the frozen noise (robust re-weighting
    only), the two samples at each inner end of that stretch held."""
    from .banded import reweighting, solve

    p = objective.problem
    lo, hi = max(a - margin, 0), min(b + margin, p.n)
    held = [i for i in (lo, lo + 1) if lo > 0] + [i for i in (hi - 2, hi - 1) if hi < p.n]
    model = replace(p.model, factor_groups=tuple(p.model.factor_groups) + (_HeldStates([i - lo for i in held], X[held]),))
    sub = SmootherProblem(p.log.select(slice(lo, hi)), p.options._replace(model=model))
    sub = sub.with_noise(accel=sub.noise.accel.with_base(objective.accel_sigma[lo:hi]),
                         motion=sub.noise.motion.with_steps(objective.trapezoid_sigma[lo:hi - 1],
                                                            objective.omega_dot_step_sigma[lo:hi - 1]))
    reweight = reweighting(replace(p.batch_model, accel_noise_slope_mps2_per_radps=0.0))
    Y = X.copy()
    Y[lo:hi] = solve(sub, X[lo:hi], reweight=reweight, max_iterations=max_iterations).states
    return Y


def branch_restarts(problem: SmootherProblem, states: np.ndarray) -> tuple[np.ndarray, int, int]:
    """(states, restarts tried, restarts kept): the solution ``states`` of ``problem`` (after its
    re-weighted solve) with the short runs between outlying motion-model steps moved to another
    branch wherever that lowers the robust objective (module docstring). ``states`` unchanged when
    the restarts do not apply (:func:`applies`)."""
    if not applies(problem):
        return states, 0, 0
    objective = FrozenObjective(problem)
    normal = plane_normal(problem.all_positions_m)
    X = np.array(states, dtype=float)
    best = objective(X)
    tried = kept = 0
    runs = outlier_runs(objective, X)
    for a, b in runs[:int(MAX_RUNS_PER_SAMPLE * problem.n) + 10]:
        current = X
        for branch in BRANCHES:
            start = current.copy()
            start[a:b] = branch(current[a:b], normal)
            tried += 1
            Y = local_resolve(objective, start, a, b)
            c = objective(Y)
            if c < best:
                X, best = Y, c
        kept += X is not current
    return X, tried, kept
