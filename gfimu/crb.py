"""Cramér–Rao bound for rigid-body motion from an accelerometer array.

Skog, Nilsson, Händel & Nehorai, "Inertial sensor arrays, maximum likelihood,
and Cramér–Rao bound", IEEE TSP 2016. Per sample the readings are

    y = S [f, ω̇, q(ω)] + e,        e ~ N(0, Σ),  Σ = diag(σ_i²)

(Ho & Lin 2009's linear model, :func:`gfimu.rigid_body.structure_matrix`), plus
optionally a gyro ``y_g = ω + e_g`` with ``e_g ~ N(0, σ_g² I)``. With
θ = (f, ω̇, ω) the Fisher information is

    J(ω) = Dᵀ Σ⁻¹ D,   D = ∂h/∂θ = [S_f, S_ω̇, S_q ∂q/∂ω]   (n × 9)

(+ σ_g⁻² on the ω block with a gyro). It depends on ω only, not on f or ω̇,
because the model is linear in those. The bound on the covariance of any
unbiased estimator is ``J⁻¹``.

At ω = 0 the accelerometer-only model loses ω entirely (∂q/∂ω = 0) and J is
singular. There the bound is returned through the pseudo-inverse of J with
``inf`` on the variances (and covariances) of every parameter that has a
component in J's null space, and ``singular`` is set for that sample; the
observable parameters (f, ω̇) keep their finite bound. Pure maths, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import rigid_body
from .array import ArrayModelError, SensorArray
from .errors import InputError
from .motion import Motion

PARAMETERS = ("f_x", "f_y", "f_z", "dw_x", "dw_y", "dw_z", "w_x", "w_y", "w_z")
"""Order of θ in the 9 × 9 covariance: specific force, ω̇, ω."""

SLICE_SPECIFIC_FORCE = slice(0, 3)
SLICE_OMEGA_DOT = slice(3, 6)
SLICE_OMEGA = slice(6, 9)


@dataclass(frozen=True)
class CRBResult:
    """Per-sample Cramér–Rao bound.

    ``covariance`` is (N, 9, 9) in the order :data:`PARAMETERS`;
    ``singular`` (N,) marks samples whose Fisher information is singular
    (unobservable parameters have infinite variance there).
    """

    covariance: np.ndarray
    singular: np.ndarray

    @property
    def sigma_specific_force(self) -> np.ndarray:
        """(N, 3) bound on the std of f, m/s²."""
        return self._sigma(SLICE_SPECIFIC_FORCE)

    @property
    def sigma_omega_dot(self) -> np.ndarray:
        """(N, 3) bound on the std of ω̇, rad/s²."""
        return self._sigma(SLICE_OMEGA_DOT)

    @property
    def sigma_omega(self) -> np.ndarray:
        """(N, 3) bound on the std of ω, rad/s."""
        return self._sigma(SLICE_OMEGA)

    def _sigma(self, block: slice) -> np.ndarray:
        d = np.diagonal(self.covariance, axis1=1, axis2=2)[:, block]
        return np.sqrt(d)

    def _rmse_bound(self, block: slice) -> float:
        d = np.diagonal(self.covariance, axis1=1, axis2=2)[:, block]
        return float(np.sqrt(np.mean(np.sum(d, axis=1))))

    def rmse_bound_omega(self) -> float:
        """sqrt(mean over samples of trace Cov(ω)), rad/s: the lowest RMSE of |ω̂ - ω|."""
        return self._rmse_bound(SLICE_OMEGA)

    def rmse_bound_omega_dot(self) -> float:
        """sqrt(mean trace Cov(ω̇)), rad/s²."""
        return self._rmse_bound(SLICE_OMEGA_DOT)

    def rmse_bound_specific_force(self) -> float:
        """sqrt(mean trace Cov(f)), m/s²."""
        return self._rmse_bound(SLICE_SPECIFIC_FORCE)


def axis_noise_std(array: SensorArray, noise_std_mps2=None) -> np.ndarray:
    """(n_axes,) accelerometer noise std: ``noise_std_mps2`` (scalar or per axis) or the array's."""
    if noise_std_mps2 is None:
        sigma = array.noise_std_per_axis_mps2
        missing = [c for c, s in zip(array.accel_columns, sigma) if not np.isfinite(s)]
        if missing:
            raise ArrayModelError(
                f"array {array.name!r}: no noise_std_mps2 for axes {missing}; give it in array.toml or as noise_std_mps2"
            )
    else:
        sigma = np.broadcast_to(np.asarray(noise_std_mps2, dtype=float), (array.n_axes,)).copy()
    if np.any(~np.isfinite(sigma)) or np.any(sigma <= 0):
        raise ArrayModelError(f"array {array.name!r}: accelerometer noise std must be finite and > 0, got {sigma.tolist()}")
    return sigma


def fisher_information(
    structure_matrix: np.ndarray,
    axis_noise_std_mps2: np.ndarray,
    omega_b_radps: np.ndarray,
    gyro_noise_std_radps: float | None = None,
) -> np.ndarray:
    """Fisher information J(ω) (N, 9, 9) of θ = (f, ω̇, ω) for one sample per row of ω."""
    S = np.asarray(structure_matrix, dtype=float)
    w = np.asarray(omega_b_radps, dtype=float).reshape(-1, 3)
    inv_var = 1.0 / np.asarray(axis_noise_std_mps2, dtype=float) ** 2
    n = w.shape[0]
    lin = S[:, :6]
    Sq = S[:, 6:]
    Dq = rigid_body.quadratic_terms_jacobian(w)  # (N, 6, 3)
    Dw = np.einsum("aj,njk->nak", Sq, Dq)  # (N, n_axes, 3)
    J = np.empty((n, 9, 9))
    J[:, :6, :6] = (lin.T * inv_var) @ lin
    cross = np.einsum("ai,a,nak->nik", lin, inv_var, Dw)
    J[:, :6, 6:] = cross
    J[:, 6:, :6] = np.swapaxes(cross, 1, 2)
    J[:, 6:, 6:] = np.einsum("naj,a,nak->njk", Dw, inv_var, Dw)
    if gyro_noise_std_radps is not None:
        if not (np.isfinite(gyro_noise_std_radps) and gyro_noise_std_radps > 0):
            raise InputError(f"gyro_noise_std_radps must be finite and > 0, got {gyro_noise_std_radps}")
        J[:, 6:, 6:] += np.eye(3) / gyro_noise_std_radps**2
    return J


def invert_information(J: np.ndarray, rcond: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of each (9, 9) information matrix; ``inf`` on unobservable parameters.

    Returns ``(covariance, singular)``. A sample is singular when an
    eigenvalue of J is below ``rcond`` times the largest; every parameter with
    a component above 1e-6 in such an eigenvector gets infinite variance (and
    its row and column of the covariance are set to ``inf``).
    """
    J = 0.5 * (J + np.swapaxes(J, 1, 2))
    # Scale to unit diagonal first so that rcond is unit-free.
    d = np.sqrt(np.clip(np.diagonal(J, axis1=1, axis2=2), 0.0, None))
    d_safe = np.where(d > 0, d, 1.0)
    Js = J / d_safe[:, :, None] / d_safe[:, None, :]
    vals, vecs = np.linalg.eigh(Js)
    top = np.maximum(vals[:, -1:], np.finfo(float).tiny)
    null = vals <= rcond * top
    inv_vals = np.where(null, 0.0, 1.0 / np.where(null, 1.0, vals))
    cov_s = np.einsum("nik,nk,njk->nij", vecs, inv_vals, vecs)
    cov = cov_s / d_safe[:, :, None] / d_safe[:, None, :]
    singular = np.any(null, axis=1)
    if np.any(singular):
        weight = np.einsum("nik,nk->ni", vecs**2, null.astype(float))
        lost = (weight > 1e-12) | (d == 0)
        lost &= singular[:, None]
        cov = np.where(lost[:, :, None] | lost[:, None, :], np.inf, cov)
    return cov, singular


def crb_per_sample(
    array: SensorArray,
    omega_b_radps,
    noise_std_mps2=None,
    gyro_noise_std_radps: float | None = None,
    gyro: bool = False,
) -> CRBResult:
    """Cramér–Rao bound on (f, ω̇, ω) at each angular velocity in ``omega_b_radps`` (N, 3).

    ``noise_std_mps2``: accelerometer noise std (scalar or per axis); default
    the array's. A gyro enters when ``gyro_noise_std_radps`` is given, or when
    ``gyro=True`` (then with the array's gyro noise).
    """
    w = np.asarray(omega_b_radps, dtype=float)
    if w.ndim == 1:
        w = w[None, :]
    if w.ndim != 2 or w.shape[1] != 3 or not np.all(np.isfinite(w)):
        raise InputError(f"omega_b_radps must be finite with shape (N, 3), got shape {np.shape(omega_b_radps)}")
    sigma = axis_noise_std(array, noise_std_mps2)
    if gyro and gyro_noise_std_radps is None:
        if array.gyroscope is None or array.gyroscope.noise_std_radps is None:
            raise ArrayModelError(f"array {array.name!r} has no gyroscope noise_std_radps; pass gyro_noise_std_radps")
        gyro_noise_std_radps = array.gyroscope.noise_std_radps
    J = fisher_information(array.structure_matrix(), sigma, w, gyro_noise_std_radps)
    cov, singular = invert_information(J)
    return CRBResult(cov, singular)


def crb_for_motion(array: SensorArray, motion: Motion, **options) -> CRBResult:
    """:func:`crb_per_sample` along a motion's ω (the bound does not depend on f or ω̇)."""
    if motion.omega_b_radps is None:
        raise InputError("the motion has no omega_b_radps to evaluate the bound at")
    return crb_per_sample(array, motion.omega_b_radps, **options)
