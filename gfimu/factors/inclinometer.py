"""Inclinometer (Lu, Tsai & Lin 2010, direction cosines of gravity).

``tilt_x`` is the angle between the body x axis and the upward vertical, so
``cos(tilt_x) = (Rᵀ e_z)_x`` (log format: a still accelerometer aligned with
B reads g cos(tilt_x) on x); likewise for y. Residual: predicted minus
measured angles [rad].
"""

from __future__ import annotations

import numpy as np

from ..rotations import skew
from . import custom_factor, rotation_at

_MIN_SIN = 1e-6


def inclinometer_residual(rotation_wb, tilt_rad):
    """``acos((Rᵀ e_z)_{x,y}) - tilt`` (N, 2) and ``{'r': (N, 2, 3)}``."""
    R = np.asarray(rotation_wb, dtype=float).reshape(-1, 3, 3)
    tilt = np.atleast_2d(np.asarray(tilt_rad, dtype=float))
    up_b = R[:, 2, :]  # Rᵀ e_z
    c = np.clip(up_b[:, :2], -1.0, 1.0)
    predicted = np.arccos(c)
    s = np.maximum(np.sqrt(1.0 - c * c), _MIN_SIN)
    # d(up_b)/dδ = skew(up_b) for R <- R Exp(δ).
    d_up = skew(up_b)[:, :2, :]
    return predicted - tilt, {"r": -d_up / s[:, :, None]}


def make_inclinometer_factor(key_attitude: int, tilt_rad, noise_model):
    tilt = np.asarray(tilt_rad, dtype=float).reshape(1, 2)

    def error(values):
        r, j = inclinometer_residual(rotation_at(values, key_attitude), tilt)
        return r[0], [j["r"][0]]

    return custom_factor(noise_model, [key_attitude], error)
