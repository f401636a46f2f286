"""ω from the quadratic terms with the sign of the integrated ω̇ (Ho & Lin 2009 §IV; Lin et al. 2011 §3.1).

Both estimators first invert every sample (Ho & Lin 2009, eq. 7) for f, ω̇ and
q(ω). Then, sample by sample within each gap-free segment:

- ``PureIntegrationEstimator`` (Lin et al. 2011, eq. 8, "integration method"):
  ``ω_j = ω_{j-1} + h/2 (ω̇_{j-1} + ω̇_j)``. Drifts without bound.
- ``IntegrationEstimator`` (Ho & Lin 2009, eqs. 9-10; Lin et al. 2011, eqs. 8-11,
  "quadratic method"): the prediction ``ω_int,j`` of eq. 8 from the previous
  *estimate* selects one of the eight candidates ``(±|ωx|, ±|ωy|, ±|ωz|)`` whose
  magnitudes come from the quadratic sums a, b, c (eq. 10), by the least L2
  distance to ``ω_int,j`` (eq. 11). As the candidates differ only in
  component signs, the L2 minimiser takes each component's sign from
  ``ω_int,j`` (a zero prediction counts as positive); :func:`select_candidate`
  evaluates the eight candidates explicitly and the estimator uses the
  equivalent per-component rule in a tight scalar loop.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Union

import numpy as np

from ..option import option
from ..array import SensorArray
from ..log import Log
from ..motion import Motion
from ..progress import progress as progress_bar
from ..rigid_body import omega_from_quadratic_terms
from ._common import PerSampleEstimator, resolve_initial_omega, trapezoid_increments, validate_initial_omega
from .inversion import check_log_for_inversion, invert, sigma_from_inversion

SIGN_CANDIDATES = np.array(list(itertools.product((1.0, -1.0), repeat=3)))  # (8, 3)

InitialOmega = Union[str, tuple[float, float, float]]


def select_candidate(omega_abs: np.ndarray, omega_int: np.ndarray) -> np.ndarray:
    """Lin et al. 2011, eq. 11: the candidate ``s ⊙ |ω|`` (8 sign patterns) nearest to ω_int.

    Vectorised over leading axes: (..., 3), (..., 3) -> (..., 3). Ties go to
    the first pattern in ``SIGN_CANDIDATES`` (positive signs first).
    """
    omega_abs = np.asarray(omega_abs, dtype=float)
    omega_int = np.asarray(omega_int, dtype=float)
    cands = SIGN_CANDIDATES * omega_abs[..., None, :]
    dist = np.sum((cands - omega_int[..., None, :]) ** 2, axis=-1)
    best = np.argmin(dist, axis=-1)
    return np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]


def sign_tracking_loop(mag: list[float], inc: list[float], w0: float, alpha=None, beta=None) -> list[float]:
    """Scalar recursion of one axis (the components decouple).

    ``p = ω_{j-1} + inc_{j-1}`` (the trapezoid prediction) and
    ``ω_j = α_j p + β_j sign(p) |ω_j|`` — with α = 0, β = 1 the quadratic
    method of Lin et al. 2011, eqs. 10-11, otherwise the soft-switched mixture of the
    IMM (:mod:`gfimu.estimators.imm`). ``mag``, ``alpha`` and ``beta`` hold the
    values at samples 0..n-1; ``w0`` is the prediction for sample 0.
    """
    n = len(mag)
    out = [0.0] * n
    p = w0
    if alpha is None:
        for j in range(n):
            w = mag[j] if p >= 0.0 else -mag[j]
            out[j] = w
            if j < n - 1:
                p = w + inc[j]
        return out
    for j in range(n):
        m = mag[j] if p >= 0.0 else -mag[j]
        w = alpha[j] * p + beta[j] * m
        out[j] = w
        if j < n - 1:
            p = w + inc[j]
    return out


@dataclass
class _IntegratingEstimator(PerSampleEstimator):
    """Options shared by the two integrating methods."""

    initial_omega: InitialOmega = option("zero", help=(
        "ω at the start of each gap-free segment: 'zero' (body at rest, Ho & Lin 2009 footnote 3; the first sample "
        "then takes positive signs), 'quadratic' (magnitudes from the first sample's quadratic sums, relative "
        "signs from its cross terms, largest component positive) or three numbers in rad/s (first segment; "
        "later segments use 'quadratic')"))
    compute_sigma: bool = option(False, help="one-sigma of f and ω̇ from the inversion (ω has none)")

    def __post_init__(self) -> None:
        validate_initial_omega(self.initial_omega)

    def applicable(self, array: SensorArray) -> str | None:
        return array.inversion_reason()


@dataclass
class PureIntegrationEstimator(_IntegratingEstimator):
    """Trapezoid integration of the inverted ω̇ (Lin et al. 2011, eq. 8); f and ω̇ by inversion.

    Options (``initial_omega``, ``compute_sigma``): ``gfimu estimate --method pure-integration --list-options``.
    """

    method = "pure-integration"

    def estimate_motion(self, log: Log, progress: bool = False) -> Motion:
        check_log_for_inversion(log)
        x, cov = invert(log.array, log.accel_mps2)
        omega = np.empty((len(log), 3))
        segs = log.segments()
        for k, seg in enumerate(progress_bar(segs, total=len(segs), desc="pure-integration", enable=progress)):
            w0 = resolve_initial_omega(self.initial_omega, x[seg][:1, 6:], k == 0)
            inc = trapezoid_increments(x[seg, 3:6], log.timestamps_ns[seg])
            omega[seg] = w0 + np.vstack([np.zeros((1, 3)), np.cumsum(inc, axis=0)])
        return Motion(log.timestamps_ns, omega_b_radps=omega, omega_dot_b_radps2=x[:, 3:6],
                      specific_force_b_mps2=x[:, 0:3],
                      sigma=sigma_from_inversion(cov, len(log)) if self.compute_sigma else {})


@dataclass
class IntegrationEstimator(_IntegratingEstimator):
    """Quadratic-term magnitudes with the sign of the integrated prediction (Ho & Lin 2009; Lin et al. 2011).

    f and ω̇ come from the inversion; |ω| per axis from the quadratic sums
    (``ωx² = (a + b - c)/2`` …, clipped at zero); the sign of each component
    from the trapezoid prediction ``ω_{j-1} + h/2 (ω̇_{j-1} + ω̇_j)``. At the
    first sample of each gap-free segment the prediction is ``initial_omega``
    (options: ``gfimu estimate --method integration --list-options``).
    """

    method = "integration"

    def estimate_motion(self, log: Log, progress: bool = False) -> Motion:
        check_log_for_inversion(log)
        x, cov = invert(log.array, log.accel_mps2)
        mag = omega_from_quadratic_terms(x[:, 6:])
        omega = np.empty((len(log), 3))
        segs = log.segments()
        for k, seg in enumerate(progress_bar(segs, total=len(segs), desc="integration", enable=progress)):
            w0 = resolve_initial_omega(self.initial_omega, x[seg][:1, 6:], k == 0)
            inc = trapezoid_increments(x[seg, 3:6], log.timestamps_ns[seg])
            for axis in range(3):
                omega[seg, axis] = sign_tracking_loop(mag[seg, axis].tolist(), inc[:, axis].tolist(), float(w0[axis]))
        return Motion(log.timestamps_ns, omega_b_radps=omega, omega_dot_b_radps2=x[:, 3:6],
                      specific_force_b_mps2=x[:, 0:3],
                      sigma=sigma_from_inversion(cov, len(log)) if self.compute_sigma else {})
