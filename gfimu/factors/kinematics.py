"""Kinematics between consecutive samples.

- angular velocity (trapezoid, as Ho & Lin 2009's sign recovery and Li et al. 2021's
  improved Euler step): ``ω_{k+1} = ω_k + h/2 (ω̇_k + ω̇_{k+1})``;
- attitude (Li et al. 2021, eq. 10 on SO(3)): ``R_{k+1} = R_k Exp(h (ω_k + ω_{k+1}) / 2)``.

With ω̇ a random walk of density q (white angular jerk), the trapezoid
residual has variance ``q² h³ / 12`` and is independent of the ω̇ increment,
so the two factors together are the exact discrete form of that prior
(see :func:`trapezoid_sigma`).
"""

from __future__ import annotations

import numpy as np

from . import so3, custom_factor, rotation_at, vector_at


def trapezoid_sigma(omega_dot_density: float, dt_s) -> np.ndarray:
    """Std of the trapezoid residual under white angular jerk: ``q sqrt(h³/12)``."""
    return omega_dot_density * np.sqrt(np.asarray(dt_s, dtype=float) ** 3 / 12.0)


def angular_velocity_step(omega0: np.ndarray, omega1: np.ndarray, omega_dot0: np.ndarray, omega_dot1: np.ndarray,
                          dt_s: np.ndarray) -> np.ndarray:
    """The residual of :func:`angular_velocity_residual` alone, (N, 3) arrays and ``dt_s`` (N,)."""
    return omega1 - omega0 - 0.5 * dt_s[:, None] * (omega_dot0 + omega_dot1)


def angular_velocity_residual(omega0, omega1, omega_dot0, omega_dot1, dt_s):
    """``ω1 - ω0 - h/2 (ω̇0 + ω̇1)`` (N, 3) with Jacobians on w0, w1, d0, d1 (N, 3, 3)."""
    w0, w1, d0, d1 = (np.atleast_2d(np.asarray(v, dtype=float)) for v in (omega0, omega1, omega_dot0, omega_dot1))
    h = np.atleast_1d(np.asarray(dt_s, dtype=float))
    n = max(w0.shape[0], h.shape[0])
    r = angular_velocity_step(w0, w1, d0, d1, h)
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    half = -0.5 * h[:, None, None] * np.eye(3)
    half = np.broadcast_to(half, (n, 3, 3))
    return r, {"w0": -eye, "w1": eye, "d0": half, "d1": half}


def attitude_residual(rot0, rot1, omega0, omega1, dt_s):
    """``Log(Exp(φ)ᵀ R0ᵀ R1)`` with ``φ = h (ω0 + ω1) / 2``, (N, 3), and Jacobians.

    Jacobians on r0, r1 (right perturbations) and w0, w1, each (N, 3, 3).
    """
    R0 = np.asarray(rot0, dtype=float).reshape(-1, 3, 3)
    R1 = np.asarray(rot1, dtype=float).reshape(-1, 3, 3)
    w0 = np.atleast_2d(np.asarray(omega0, dtype=float))
    w1 = np.atleast_2d(np.asarray(omega1, dtype=float))
    h = np.atleast_1d(np.asarray(dt_s, dtype=float))
    phi = 0.5 * h[:, None] * (w0 + w1)
    E = so3.exp(phi)
    delta = np.swapaxes(E, -1, -2) @ np.swapaxes(R0, -1, -2) @ R1
    e = so3.log(delta)
    jl_inv = so3.left_jacobian_inverse(e)
    j_r0 = -jl_inv @ np.swapaxes(E, -1, -2)
    j_r1 = so3.right_jacobian_inverse(e)
    j_w = -0.5 * h[:, None, None] * (jl_inv @ so3.right_jacobian(phi))
    return e, {"r0": j_r0, "r1": j_r1, "w0": j_w, "w1": j_w}


def make_angular_velocity_factor(key_w0, key_w1, key_d0, key_d1, dt_s: float, noise_model):
    """CustomFactor for the trapezoid step between samples k and k+1."""

    def error(values):
        r, j = angular_velocity_residual(
            vector_at(values, key_w0), vector_at(values, key_w1), vector_at(values, key_d0), vector_at(values, key_d1), dt_s
        )
        return r[0], [j["w0"][0], j["w1"][0], j["d0"][0], j["d1"][0]]

    return custom_factor(noise_model, [key_w0, key_w1, key_d0, key_d1], error)


def make_attitude_factor(key_r0, key_r1, key_w0, key_w1, dt_s: float, noise_model):
    """CustomFactor for ``R_{k+1} = R_k Exp(h (ω_k + ω_{k+1}) / 2)`` on Rot3 keys."""

    def error(values):
        r, j = attitude_residual(
            rotation_at(values, key_r0), rotation_at(values, key_r1), vector_at(values, key_w0), vector_at(values, key_w1), dt_s
        )
        return r[0], [j["r0"][0], j["r1"][0], j["w0"][0], j["w1"][0]]

    return custom_factor(noise_model, [key_r0, key_r1, key_w0, key_w1], error)


# --- white angular snap: ω, ω̇, ω̈ with ω̈ a random walk -------------------------

def snap_process_covariance(snap_density: float, dt_s) -> np.ndarray:
    """Covariance (N, 3, 3) of one step of ``[ω, ω̇, ω̈]`` (one axis) under white snap of density q.

    ``q² [[h⁵/20, h⁴/8, h³/6], [h⁴/8, h³/3, h²/2], [h³/6, h²/2, h]]``.
    """
    h = np.atleast_1d(np.asarray(dt_s, dtype=float))[:, None, None]
    c = np.array([[1 / 20, 1 / 8, 1 / 6], [1 / 8, 1 / 3, 1 / 2], [1 / 6, 1 / 2, 1.0]])
    powers = np.array([[5, 4, 3], [4, 3, 2], [3, 2, 1]])
    return snap_density**2 * c * h**powers


def angular_motion_residual(omega0, omega1, omega_dot0, omega_dot1, omega_ddot0, omega_ddot1, dt_s):
    """Exact step of the triple integrator ``[ω, ω̇, ω̈]``, (N, 9) rows ordered (ω, ω̇, ω̈) × (x, y, z).

    ``[ω1 - ω0 - h ω̇0 - h²/2 ω̈0, ω̇1 - ω̇0 - h ω̈0, ω̈1 - ω̈0]``; Jacobians on
    w0, w1, d0, d1, j0, j1, each (N, 9, 3).
    """
    w0, w1, d0, d1, j0, j1 = (np.atleast_2d(np.asarray(v, dtype=float)) for v in
                              (omega0, omega1, omega_dot0, omega_dot1, omega_ddot0, omega_ddot1))
    h = np.atleast_1d(np.asarray(dt_s, dtype=float))[:, None]
    n = max(w0.shape[0], h.shape[0])
    r = np.concatenate([w1 - w0 - h * d0 - 0.5 * h * h * j0, d1 - d0 - h * j0, j1 - j0], axis=1)
    eye = np.eye(3)
    z = np.zeros((n, 9, 3))
    jac = {k: z.copy() for k in ("w0", "w1", "d0", "d1", "j0", "j1")}
    hh = h[:, :, None]
    jac["w0"][:, 0:3] = -eye
    jac["w1"][:, 0:3] = eye
    jac["d0"][:, 0:3] = -hh * eye
    jac["d0"][:, 3:6] = -eye
    jac["d1"][:, 3:6] = eye
    jac["j0"][:, 0:3] = -0.5 * hh * hh * eye
    jac["j0"][:, 3:6] = -hh * eye
    jac["j0"][:, 6:9] = -eye
    jac["j1"][:, 6:9] = eye
    return r, jac


def angular_motion_covariance(snap_density: float, dt_s) -> np.ndarray:
    """(N, 9, 9) covariance of :func:`angular_motion_residual`'s rows (axes independent)."""
    per_axis = snap_process_covariance(snap_density, dt_s)  # (N, 3, 3) over (ω, ω̇, ω̈)
    return np.einsum("nab,ij->naibj", per_axis, np.eye(3)).reshape(-1, 9, 9)


def make_angular_motion_factor(key_w0, key_w1, key_d0, key_d1, key_j0, key_j1, dt_s: float, noise_model):
    """CustomFactor for one white-snap step; noise model from :func:`angular_motion_covariance`."""
    keys = [key_w0, key_w1, key_d0, key_d1, key_j0, key_j1]

    def error(values):
        r, j = angular_motion_residual(*(vector_at(values, k) for k in keys), dt_s)
        return r[0], [j[n][0] for n in ("w0", "w1", "d0", "d1", "j0", "j1")]

    return custom_factor(noise_model, keys, error)
