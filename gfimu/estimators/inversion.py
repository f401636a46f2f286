"""Direct inversion of the structure matrix (Ho & Lin 2009, eq. 7).

Every sample is solved on its own: ``x = [f, ω̇, q(ω)] = S⁺ a`` (a weighted
least-squares solution when the array has more than twelve axes or unequal
noise). ω is recovered from q(ω) up to one global sign, which is carried
from sample to sample by continuity; this is the papers' gyro-free baseline,
and it loses the sign whenever ω passes near zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..option import option
from ..array import SensorArray
from ..errors import DataError, InputError
from ..log import Log
from ..motion import Motion
from ..rigid_body import omega_from_quadratic_terms
from ._common import (PerSampleEstimator, check_finite, continuity_signs, omega_from_quadratic_terms_signed,
                      weighted_least_squares)


def inversion_matrix(array: SensorArray) -> tuple[np.ndarray, np.ndarray]:
    """Solve matrix A (12, n_axes) with ``x = A a``, and the covariance of x (12, 12).

    When every axis has a positive ``noise_std_mps2``, A is the weighted
    least-squares solution ``(SᵀΣ⁻¹S)⁻¹SᵀΣ⁻¹`` with ``Σ = diag(σ²)`` and the
    covariance is ``(SᵀΣ⁻¹S)⁻¹``. Otherwise axes are weighted equally
    (``A = S⁺``) and the covariance is ``A Σ Aᵀ``: NaN where the array gives no
    noise level. Raises :class:`~gfimu.array.ArrayModelError` (via
    ``array.check_invertible``) when S cannot be inverted.
    """
    array.check_invertible()
    return weighted_least_squares(array.structure_matrix(), array.noise_std_per_axis_mps2)


def invert(array: SensorArray, accel_mps2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample inversion (Ho & Lin 2009, eq. 7): readings (N, n_axes) -> x (N, 12), cov (12, 12).

    ``accel_mps2`` holds each axis's reading in its sensor's own frame, in the
    order of ``array.accel_columns``; x = [f (m/s²), ω̇ (rad/s²), q(ω)
    ((rad/s)²)], the same covariance applying to every sample.
    """
    a = np.asarray(accel_mps2, dtype=float)
    single = a.ndim == 1
    a2 = a.reshape(1, -1) if single else a
    if a2.ndim != 2 or a2.shape[1] != array.n_axes:
        raise InputError(
            f"accel_mps2 has shape {a.shape}; array {array.name!r} has {array.n_axes} accelerometer axes "
            f"({', '.join(array.accel_columns)})"
        )
    check_finite(a2, "accel_mps2", array.accel_columns)
    A, cov = inversion_matrix(array)
    x = a2 @ A.T
    return (x[0] if single else x), cov


def omega_sigma_from_quadratic(omega_abs: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """One-sigma of |ωk| from the covariance of q (first-order, softened at zero).

    ``ωx² = (q1 + q2 - q3)/2`` etc. give var(ωk²); then
    ``σ(|ωk|) ≈ σ(ωk²) / (2|ωk| + sqrt(σ(ωk²)))``, which is the linearised value
    for large |ωk| and ``sqrt(σ(ωk²))`` at zero, where the linearisation fails.
    """
    L = 0.5 * np.array([[1, 1, -1, 0, 0, 0], [1, -1, 1, 0, 0, 0], [-1, 1, 1, 0, 0, 0]], dtype=float)
    var_sq = np.einsum("ij,jk,ik->i", L, cov[6:, 6:], L)
    s_sq = np.sqrt(np.clip(var_sq, 0.0, None))
    return s_sq[None, :] / (2.0 * np.abs(omega_abs) + np.sqrt(s_sq)[None, :] + 1e-300)


def sigma_from_inversion(cov: np.ndarray, n: int) -> dict[str, np.ndarray]:
    """One-sigma of f and ω̇ for n samples from the inversion covariance ({} when unknown)."""
    if not np.all(np.isfinite(cov)):
        return {}
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return {"specific_force_b_mps2": np.tile(sd[0:3], (n, 1)), "omega_dot_b_radps2": np.tile(sd[3:6], (n, 1))}


def check_log_for_inversion(log: Log) -> None:
    if len(log) == 0:
        raise DataError(f"{log.source}: log has no samples")


@dataclass
class InversionEstimator(PerSampleEstimator):
    """Ho & Lin 2009, eq. 7 applied sample by sample; ω by magnitudes and cross-term signs.

    ω: magnitudes from the quadratic sums, relative signs from the cross terms
    (largest component positive, see
    :func:`gfimu.estimators._common.omega_from_quadratic_terms_signed`), and the
    remaining global sign chosen at each sample as the one of ``±ω`` nearer to
    the previous sample's estimate (first sample of each gap-free segment:
    largest component positive). When |ω| passes near zero this continuity is
    lost and the sign may flip: the baseline behaviour the sign-tracking
    methods ('integration', 'imm') improve on. Options: ``gfimu estimate --method inversion --list-options``.
    """

    method = "inversion"

    compute_sigma: bool = option(False, help=(
        "also output one-sigma uncertainties of f, ω̇ (from the inversion covariance) and ω "
        "(omega_sigma_from_quadratic) when the array gives its noise levels"))

    def applicable(self, array: SensorArray) -> str | None:
        return array.inversion_reason()

    def estimate_motion(self, log: Log, progress: bool = False) -> Motion:
        check_log_for_inversion(log)
        x, cov = invert(log.array, log.accel_mps2)
        q = x[:, 6:]
        omega = np.empty((len(log), 3))
        for seg in log.segments():
            v = omega_from_quadratic_terms_signed(q[seg])
            omega[seg] = continuity_signs(v)[:, None] * v
        sigma = sigma_from_inversion(cov, len(log)) if self.compute_sigma else {}
        if sigma:
            sigma["omega_b_radps"] = omega_sigma_from_quadratic(omega_from_quadratic_terms(q), cov)
        return Motion(
            log.timestamps_ns,
            omega_b_radps=omega,
            omega_dot_b_radps2=x[:, 3:6],
            specific_force_b_mps2=x[:, 0:3],
            sigma=sigma,
        )
