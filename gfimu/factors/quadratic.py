"""Quadratic ω terms against their per-sample inversion (Ho & Lin 2009, eq. 2; Lin et al. 2011).

The papers invert the structure matrix per sample, ``x̂ = S⁺ y``, and read
ω from the six quadratic terms ``q(ω) = [ωx²+ωy², ωx²+ωz², ωy²+ωz², ωxωy,
ωxωz, ωyωz]``. As a factor: residual ``q(ω_k) - q̂_k`` with the 6×6 block of
the inversion's covariance ``σ² (SᵀWS)⁻¹``.
"""

from __future__ import annotations

import numpy as np

from .. import rigid_body
from ..array import SensorArray
from ..estimators.inversion import invert
from . import custom_factor, vector_at


def inversion(array: SensorArray, accel_mps2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample weighted least squares ``x = [f, ω̇, q]`` (N, 12) and its covariance (12, 12)
    (:func:`gfimu.estimators.inversion.invert`)."""
    return invert(array, accel_mps2)


def quadratic_residual(omega_b_radps: np.ndarray, q_measured: np.ndarray):
    """``q(ω) - q̂`` (N, 6) and ``{'w': dq/dω (N, 6, 3)}``."""
    w = np.atleast_2d(np.asarray(omega_b_radps, dtype=float))
    return rigid_body.quadratic_terms(w) - np.atleast_2d(q_measured), {"w": rigid_body.quadratic_terms_jacobian(w)}


def make_quadratic_factor(key_omega: int, q_measured, noise_model):
    """CustomFactor on ω_k against measured quadratic terms (6,)."""
    qm = np.asarray(q_measured, dtype=float).reshape(1, 6)

    def error(values):
        r, j = quadratic_residual(vector_at(values, key_omega), qm)
        return r[0], [j["w"][0]]

    return custom_factor(noise_model, [key_omega], error)


def inversion_residual(omega_b_radps, omega_dot_b_radps2, specific_force_b_mps2, x_measured):
    """All twelve unknowns against the per-sample inversion ``x̂ = [f̂, ω̇̂, q̂]`` (Ho & Lin 2009, eq. 7).

    Residual ``[f - f̂, ω̇ - ω̇̂, q(ω) - q̂]`` (N, 12); Jacobians on 'w', 'd', 'f'
    (N, 12, 3). With the inversion's full covariance this carries the same
    information as the accelerometer factors of a 12-axis array.
    """
    w = np.atleast_2d(np.asarray(omega_b_radps, dtype=float))
    dw = np.atleast_2d(np.asarray(omega_dot_b_radps2, dtype=float))
    f = np.atleast_2d(np.asarray(specific_force_b_mps2, dtype=float))
    x = np.atleast_2d(np.asarray(x_measured, dtype=float))
    rq, jq = quadratic_residual(w, x[:, 6:12])
    n = rq.shape[0]
    r = np.concatenate([f - x[:, 0:3], dw - x[:, 3:6], rq], axis=1)
    jw = np.zeros((n, 12, 3))
    jw[:, 6:12] = jq["w"]
    jd = np.zeros((n, 12, 3))
    jd[:, 3:6] = np.eye(3)
    jf = np.zeros((n, 12, 3))
    jf[:, 0:3] = np.eye(3)
    return r, {"w": jw, "d": jd, "f": jf}


def make_inversion_factor(key_omega: int, key_omega_dot: int, key_specific_force: int, x_measured, noise_model):
    """CustomFactor on (ω_k, ω̇_k, f_k) against the per-sample inversion x̂_k (12,)."""
    xm = np.asarray(x_measured, dtype=float).reshape(1, 12)

    def error(values):
        r, j = inversion_residual(vector_at(values, key_omega), vector_at(values, key_omega_dot),
                                  vector_at(values, key_specific_force), xm)
        return r[0], [j["w"][0], j["d"][0], j["f"][0]]

    return custom_factor(noise_model, [key_omega, key_omega_dot, key_specific_force], error)
