"""Euler's torque-free equation (McGinnis, Perkins & King 2012, eq. 1): ``I ω̇ + ω × (I ω) = 0``.

With I the principal inertia (diagonal in B). The residual is the torque
[N m] that the state would need; a free-flight segment gives it a small
standard deviation (unmodelled torque, e.g. air drag).
"""

from __future__ import annotations

import numpy as np

from ..rotations import skew
from . import custom_factor, vector_at


def euler_residual(omega_b_radps, omega_dot_b_radps2, principal_inertia_kgm2):
    """``I ω̇ + ω × I ω`` (N, 3) and ``{'w': (N, 3, 3), 'd': (N, 3, 3)}``."""
    w = np.atleast_2d(np.asarray(omega_b_radps, dtype=float))
    dw = np.atleast_2d(np.asarray(omega_dot_b_radps2, dtype=float))
    inertia = np.asarray(principal_inertia_kgm2, dtype=float).reshape(3)
    iw = w * inertia
    r = dw * inertia + np.cross(w, iw)
    jw = skew(w) * inertia - skew(iw)
    jd = np.broadcast_to(np.diag(inertia), (w.shape[0], 3, 3))
    return r, {"w": jw, "d": jd}


def make_euler_factor(key_omega: int, key_omega_dot: int, principal_inertia_kgm2, noise_model):
    """CustomFactor on (ω_k, ω̇_k) for torque-free rotation."""
    inertia = np.asarray(principal_inertia_kgm2, dtype=float).reshape(3)

    def error(values):
        r, j = euler_residual(vector_at(values, key_omega), vector_at(values, key_omega_dot), inertia)
        return r[0], [j["w"][0], j["d"][0]]

    return custom_factor(noise_model, [key_omega, key_omega_dot], error)
