"""The smoother's own bound: marginal covariances of its graph linearised at the truth.

For the smoother's model (measurement noise, white angular jerk, random-walk
specific force, calibration priors) the Gauss-Newton information matrix at
the true states, ``H = Jᵀ J`` of the whitened factors, is the Bayesian
information of the window; the diagonal blocks of ``H⁻¹`` bound the mean
squared error of any estimator under that model (Bayesian Cramér-Rao bound,
computed with the smoother's own banded selected inversion). The ratio
``RMSE / RMS(bound)`` is the smoother's efficiency: 1 is the best possible;
below 1 means the true motion is smoother than the process model assumes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...factors import so3 as _so3
from ...log import Log
from ...motion import Motion
from ...rotations import matrix_from_quaternion
from ..solve.banded import factorise, marginal_covariances, normal_equations
from .engine import window_slices
from ..model.option_groups import BatchOptions, ModelGroups
from ..model.problem import SmootherProblem
from ..model.layout import OMEGA_DOT, QUANTITIES

QUANTITY_SLICES = QUANTITIES


def truth_states(truth: Motion) -> np.ndarray:
    """``[ω, ω̇, f]`` (N, 9) from a truth Motion (all three must be present)."""
    missing = [q for q in QUANTITY_SLICES if getattr(truth, q) is None]
    if missing:
        raise InputError(f"the bound needs truth of {missing}")
    return np.hstack([getattr(truth, q) for q in QUANTITY_SLICES])


def smoother_bound(log: Log, groups: ModelGroups | None = None, batch: BatchOptions | None = None,
                   truth: Motion | None = None, true_params: np.ndarray | None = None,
                   window_models: list[ModelGroups] | None = None) -> Motion:
    """One-sigma bound (as ``Motion`` with the bound in place of values and in ``sigma``) of every state of the
    batch smoother of the option groups of the model ``groups`` in the solve windows of ``batch`` (defaults:
    the groups' declared ones), at the truth.

    ``window_models``: the option groups of the model of each solve window, e.g. with the process noise that
    the batch smoother chose from the data (``[t.apply(groups) for t in estimate.report.tunings]``).
    """
    groups = groups or ModelGroups.defaults()
    batch = batch or BatchOptions()
    truth = truth or log.truth
    if truth is None:
        raise InputError(f"{log.source}: the bound needs the truth (log.truth or truth=)")
    states = truth_states(truth)
    if groups.model.motion_model == "snap":  # ω̈ of the truth by central differences
        states = np.hstack([states, np.gradient(states[:, OMEGA_DOT], log.times_s, axis=0)])
    if groups.attitude.estimate_attitude or groups.attitude.use_inclinometer:
        if truth.quaternion_wb is None:
            raise InputError("the bound with attitude needs the true quaternion_wb")
        states = np.hstack([states, _so3.log(matrix_from_quaternion(truth.quaternion_wb))])
    n = len(log)
    sd = np.zeros((n, states.shape[1]))
    windows = window_slices(n, log.rate_hz, batch.window_s, batch.overlap_s)
    if window_models is not None and len(window_models) != len(windows):
        raise InputError(f"window_models has {len(window_models)} entries for {len(windows)} solve windows")
    for i, (solve_sl, keep_log, keep_win) in enumerate(windows):
        part = log.select(solve_sl)
        problem = SmootherProblem(part, groups if window_models is None else window_models[i])
        if problem.layout.attitude:
            problem = problem.with_noise(attitude=problem.noise.attitude.with_prior(_so3.exp(states[solve_sl.start, -3:])))
        params = np.zeros(problem.n_global) if true_params is None else true_params
        ne = normal_equations(problem, states[solve_sl], params)
        cov, _ = marginal_covariances(ne, factorise(ne, 0.0))
        sd[keep_log] = np.sqrt(np.einsum("nii->ni", cov))[keep_win]
    sigma = {q: sd[:, sl] for q, sl in QUANTITY_SLICES.items()}
    return Motion(log.timestamps_ns, sigma=sigma, **sigma)


@dataclass(frozen=True)
class Efficiency:
    """RMSE of the error vector's norm, RMS of the bound's norm, and their ratio, per quantity."""

    rmse: dict
    bound: dict

    @property
    def ratio(self) -> dict:
        return {q: self.rmse[q] / self.bound[q] for q in self.rmse}

    def to_markdown(self) -> str:
        lines = ["| quantity | RMSE | bound | RMSE / bound |", "|---|---|---|---|"]
        for q in self.rmse:
            lines.append(f"| {q} | {self.rmse[q]:.4g} | {self.bound[q]:.4g} | {self.ratio[q]:.3f} |")
        return "\n".join(lines)


def efficiency(estimate: Motion, truth: Motion, bound: Motion, skip: int = 0) -> Efficiency:
    """RMSE / bound per quantity, leaving out ``skip`` samples at each end."""
    sl = slice(skip, len(truth) - skip)
    rmse, rms_bound = {}, {}
    for q in QUANTITY_SLICES:
        est, tru, bnd = getattr(estimate, q), getattr(truth, q), bound.sigma.get(q)
        if est is None or tru is None or bnd is None:
            continue
        rmse[q] = float(np.sqrt(np.mean(np.sum((est[sl] - tru[sl]) ** 2, axis=1))))
        rms_bound[q] = float(np.sqrt(np.mean(np.sum(bnd[sl] ** 2, axis=1))))
    return Efficiency(rmse, rms_bound)
