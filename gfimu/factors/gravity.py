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


def accel_random_walk_residual(f0, f1, rot0, rot1):
    """Random-walk step of the gravity-free acceleration ``a = f + Rᵀ g``:
    ``(f1 + R1ᵀ g) - (f0 + R0ᵀ g)`` (N, 3), Jacobians on f0, f1, r0, r1.

    With it, a smooth acceleration makes the gravity direction (tilt)
    observable from the specific force alone.
    """
    F0 = np.atleast_2d(np.asarray(f0, dtype=float))
    F1 = np.atleast_2d(np.asarray(f1, dtype=float))
    R0 = np.asarray(rot0, dtype=float).reshape(-1, 3, 3)
    R1 = np.asarray(rot1, dtype=float).reshape(-1, 3, 3)
    g0 = np.einsum("nji,j->ni", R0, GRAVITY_W_MPS2)
    g1 = np.einsum("nji,j->ni", R1, GRAVITY_W_MPS2)
    n = max(F0.shape[0], R0.shape[0])
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    return (F1 + g1) - (F0 + g0), {"f0": -eye, "f1": eye, "r0": -skew(g0), "r1": skew(g1)}


def make_accel_random_walk_factor(key_f0: int, key_f1: int, key_r0: int, key_r1: int, noise_model):
    def error(values):
        r, j = accel_random_walk_residual(vector_at(values, key_f0), vector_at(values, key_f1),
                                          rotation_at(values, key_r0), rotation_at(values, key_r1))
        return r[0], [j["f0"][0], j["f1"][0], j["r0"][0], j["r1"][0]]

    return custom_factor(noise_model, [key_f0, key_f1, key_r0, key_r1], error)
