"""Process models: random walks (ω̇, specific force or acceleration, biases) and the oscillator.

``x_{k+1} - x_k ~ N(0, q² h)`` for a random walk of density q (units of x per
√s, e.g. ``omega_dot_random_walk_radps2_per_sqrt_s``), plus a prior on a
single variable.

Oscillator: per body axis, ``ω̈ = -Ω² ω + w`` with w white angular jerk of
density q, a driven undamped oscillator of natural frequency Ω (turntables and
shakers driven sinusoidally, pendulums, gait). Its exact discrete step is
``[ω; ω̇]_{k+1} = Φ [ω; ω̇]_k + v``, ``Φ = exp(h [[0, 1], [-Ω², 0]])``,
``v ~ N(0, q² ∫₀ʰ Φ(s) e₂ e₂ᵀ Φ(s)ᵀ ds)``: a sinusoid of frequency Ω leaves no
residual at all, and Ω = 0 is the white-jerk model.
"""

from __future__ import annotations

import numpy as np

from . import custom_factor, vector_at
from . import so3
from . import rotation_at


def random_walk_sigma(density_per_sqrt_s: float, dt_s) -> np.ndarray:
    """Std of one random-walk step: ``q sqrt(h)``."""
    return density_per_sqrt_s * np.sqrt(np.asarray(dt_s, dtype=float))


def random_walk_residual(x0: np.ndarray, x1: np.ndarray):
    """``x1 - x0`` (N, m) and Jacobians ``{'x0': -I, 'x1': I}`` (N, m, m)."""
    a = np.atleast_2d(np.asarray(x0, dtype=float))
    b = np.atleast_2d(np.asarray(x1, dtype=float))
    n, m = b.shape
    eye = np.broadcast_to(np.eye(m), (n, m, m))
    return b - a, {"x0": -eye, "x1": eye}


def oscillator_transition(dt_s, natural_frequency_radps) -> np.ndarray:
    """(N, 3, 2, 2) transition of (ω, ω̇) per step and body axis: ``exp(h [[0, 1], [-Ω², 0]])``."""
    h = np.atleast_1d(np.asarray(dt_s, dtype=float))[:, None]
    om = np.asarray(natural_frequency_radps, dtype=float).reshape(1, 3)
    x = om * h
    c = np.cos(x)
    sinc = np.where(x > 1e-8, np.sin(x) / np.where(x > 0, om, 1.0), h)  # sin(Ωh)/Ω, h at Ω = 0
    phi = np.empty(h.shape[:1] + (3, 2, 2))
    phi[..., 0, 0], phi[..., 0, 1] = c, sinc
    phi[..., 1, 0], phi[..., 1, 1] = -om * om * sinc, c
    return phi


def oscillator_covariance(jerk_density: float, dt_s, natural_frequency_radps) -> np.ndarray:
    """(N, 3, 2, 2) covariance of one step of (ω, ω̇) per body axis under ``ω̈ = -Ω² ω + w``,
    w white with density q: ``q² ∫₀ʰ Φ(s) e₂ e₂ᵀ Φ(s)ᵀ ds`` (Ω = 0: white jerk,
    ``q² [[h³/3, h²/2], [h²/2, h]]``); series in Ωh below 1e-3 to avoid cancellation."""
    h = np.atleast_1d(np.asarray(dt_s, dtype=float))[:, None]
    om = np.asarray(natural_frequency_radps, dtype=float).reshape(1, 3)
    x = om * h
    small = x < 1e-3
    oms = np.where(small, 1.0, om)
    # exact forms, with their series (to second order in (Ωh)²) where Ωh is small
    q11 = np.where(small, h**3 / 3.0 * (1.0 - x * x / 5.0), (h / 2.0 - np.sin(2 * x) / (4 * oms)) / oms**2)
    q12 = np.where(small, h**2 / 2.0 * (1.0 - x * x / 3.0), np.sin(x) ** 2 / (2 * oms**2))
    q22 = np.where(small, h * (1.0 - x * x / 3.0), h / 2.0 + np.sin(2 * x) / (4 * oms))
    cov = np.empty(h.shape[:1] + (3, 2, 2))
    cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 0], cov[..., 1, 1] = q11, q12, q12, q22
    return jerk_density**2 * cov


def oscillator_residual(omega0, omega1, omega_dot0, omega_dot1, dt_s, natural_frequency_radps):
    """Exact step of the driven oscillator, residual ``[ω1; ω̇1] - Φ [ω0; ω̇0]`` per axis, rows
    ordered ``(ω_x, ω_y, ω_z, ω̇_x, ω̇_y, ω̇_z)``: (N, 6) and Jacobians on w0, w1, d0, d1 (N, 6, 3)."""
    w0, w1, d0, d1 = (np.atleast_2d(np.asarray(v, dtype=float)) for v in (omega0, omega1, omega_dot0, omega_dot1))
    phi = oscillator_transition(dt_s, natural_frequency_radps)
    n = max(w0.shape[0], phi.shape[0])
    phi = np.broadcast_to(phi, (n, 3, 2, 2))
    r = np.concatenate([w1 - phi[..., 0, 0] * w0 - phi[..., 0, 1] * d0,
                        d1 - phi[..., 1, 0] * w0 - phi[..., 1, 1] * d0], axis=1)
    eye = np.eye(3)
    top, bottom = np.zeros((n, 6, 3)), np.zeros((n, 6, 3))
    top[:, :3], bottom[:, 3:] = eye, eye
    jw0 = -np.concatenate([phi[..., 0, 0, None] * eye, phi[..., 1, 0, None] * eye], axis=1)
    jd0 = -np.concatenate([phi[..., 0, 1, None] * eye, phi[..., 1, 1, None] * eye], axis=1)
    return r, {"w0": jw0, "w1": top, "d0": jd0, "d1": bottom}


def oscillator_step_covariance(jerk_density: float, dt_s, natural_frequency_radps, axis_factors=(1.0, 1.0, 1.0)) -> np.ndarray:
    """(N, 6, 6) covariance of :func:`oscillator_residual`'s rows, the density scaled per axis."""
    per_axis = oscillator_covariance(jerk_density, dt_s, natural_frequency_radps)
    per_axis = per_axis * (np.asarray(axis_factors, dtype=float) ** 2)[None, :, None, None]
    n = per_axis.shape[0]
    cov = np.zeros((n, 6, 6))
    for i in range(3):
        idx = np.array([i, 3 + i])
        cov[:, idx[:, None], idx[None, :]] = per_axis[:, i]
    return cov


def prior_residual(x: np.ndarray, mean: np.ndarray):
    """``x - mean`` (N, m) and ``{'x': I}``."""
    a = np.atleast_2d(np.asarray(x, dtype=float))
    n, m = a.shape
    return a - np.asarray(mean, dtype=float), {"x": np.broadcast_to(np.eye(m), (n, m, m))}


def make_random_walk_factor(key0: int, key1: int, noise_model):
    """CustomFactor ``x1 - x0`` between two vector variables of equal size."""

    def error(values):
        r, j = random_walk_residual(vector_at(values, key0), vector_at(values, key1))
        return r[0], [j["x0"][0], j["x1"][0]]

    return custom_factor(noise_model, [key0, key1], error)


def make_oscillator_factor(key_w0: int, key_w1: int, key_d0: int, key_d1: int, dt_s: float,
                           natural_frequency_radps, noise_model):
    """CustomFactor of one exact oscillator step; noise model from :func:`oscillator_step_covariance`."""
    omega = np.asarray(natural_frequency_radps, dtype=float).reshape(3)
    keys = [key_w0, key_w1, key_d0, key_d1]

    def error(values):
        r, j = oscillator_residual(*(vector_at(values, k) for k in keys), dt_s, omega)
        return r[0], [j[n][0] for n in ("w0", "w1", "d0", "d1")]

    return custom_factor(noise_model, keys, error)


def make_prior_factor(key: int, mean, noise_model):
    """CustomFactor ``x - mean`` on one vector variable."""
    mu = np.asarray(mean, dtype=float).reshape(-1)

    def error(values):
        r, j = prior_residual(vector_at(values, key), mu)
        return r[0], [j["x"][0]]

    return custom_factor(noise_model, [key], error)


def attitude_prior_residual(rotation_wb, prior_wb):
    """``Log(R R̂ᵀ)`` (N, 3), the attitude error in world axes (x, y: tilt; z: yaw),
    and ``{'r': Jl⁻¹(e) R}`` for the right perturbation of R."""

    R = np.asarray(rotation_wb, dtype=float).reshape(-1, 3, 3)
    P = np.asarray(prior_wb, dtype=float).reshape(-1, 3, 3)
    e = so3.log(R @ np.swapaxes(P, -1, -2))
    return e, {"r": so3.left_jacobian_inverse(e) @ R}


def make_attitude_prior_factor(key_attitude: int, prior_wb, noise_model):
    """CustomFactor on a Rot3 variable: world-axis attitude error against ``prior_wb`` (3×3)."""

    prior = np.asarray(prior_wb, dtype=float).reshape(3, 3)

    def error(values):
        r, j = attitude_prior_residual(rotation_at(values, key_attitude), prior)
        return r[0], [j["r"][0]]

    return custom_factor(noise_model, [key_attitude], error)
