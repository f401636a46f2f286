"""Gravity: specific force, gravity-free acceleration and attitude,
``f = a - Rᵀ g`` with g = (0, 0, -9.80665) m/s² in W and R = R_wb.
"""

from __future__ import annotations

import numpy as np

from ..rotations import skew
from . import GRAVITY_W_MPS2, custom_factor, rotation_at, vector_at


def gravity_residual(specific_force_b_mps2, accel_b_mps2, rotation_wb):
    """``f - a + Rᵀ g`` (N, 3) and Jacobians on f, a, r (right perturbation)."""
    f = np.atleast_2d(np.asarray(specific_force_b_mps2, dtype=float))
    a = np.atleast_2d(np.asarray(accel_b_mps2, dtype=float))
    R = np.asarray(rotation_wb, dtype=float).reshape(-1, 3, 3)
    g_b = np.einsum("nji,j->ni", R, GRAVITY_W_MPS2)
    n = max(f.shape[0], R.shape[0])
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    return f - a + g_b, {"f": eye, "a": -eye, "r": skew(g_b)}


def make_gravity_factor(key_specific_force: int, key_accel: int, key_attitude: int, noise_model):
    def error(values):
        r, j = gravity_residual(vector_at(values, key_specific_force), vector_at(values, key_accel), rotation_at(values, key_attitude))
        return r[0], [j["f"][0], j["a"][0], j["r"][0]]

    return custom_factor(noise_model, [key_specific_force, key_accel, key_attitude], error)
