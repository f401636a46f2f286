"""Process models: random walks (ω̇, specific force or acceleration, biases).

``x_{k+1} - x_k ~ N(0, q² h)`` for a random walk of density q (units of x per
√s, e.g. ``omega_dot_random_walk_radps2_per_sqrt_s``), plus a prior on a
single variable.
"""

from __future__ import annotations

import numpy as np

from . import custom_factor, vector_at


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
    from . import _so3

    R = np.asarray(rotation_wb, dtype=float).reshape(-1, 3, 3)
    P = np.asarray(prior_wb, dtype=float).reshape(-1, 3, 3)
    e = _so3.log(R @ np.swapaxes(P, -1, -2))
    return e, {"r": _so3.left_jacobian_inverse(e) @ R}


def make_attitude_prior_factor(key_attitude: int, prior_wb, noise_model):
    """CustomFactor on a Rot3 variable: world-axis attitude error against ``prior_wb`` (3×3)."""
    from . import rotation_at

    prior = np.asarray(prior_wb, dtype=float).reshape(3, 3)

    def error(values):
        r, j = attitude_prior_residual(rotation_at(values, key_attitude), prior)
        return r[0], [j["r"][0]]

    return custom_factor(noise_model, [key_attitude], error)
