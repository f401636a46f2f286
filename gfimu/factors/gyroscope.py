"""Gyroscope (Lu, Tsai & Lin 2010): reads ω in B, plus an optional bias, ``ω + b_g``."""

from __future__ import annotations

import numpy as np

from . import custom_factor


def gyroscope_residual(omega_b_radps, gyro_b_radps, bias_radps=None):
    """``ω + b_g - ω_meas`` (N, 3) and ``{'w': I[, 'g': I]}``."""
    w = np.atleast_2d(np.asarray(omega_b_radps, dtype=float))
    m = np.atleast_2d(np.asarray(gyro_b_radps, dtype=float))
    n = max(w.shape[0], m.shape[0])
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    r = w - m
    jac = {"w": eye}
    if bias_radps is not None:
        r = r + np.asarray(bias_radps, dtype=float)
        jac["g"] = eye
    return r, jac


def make_gyroscope_factor(key_omega: int, gyro_b_radps, noise_model, key_bias: int | None = None):
    meas = np.asarray(gyro_b_radps, dtype=float).reshape(1, 3)
    keys = [key_omega] + ([key_bias] if key_bias is not None else [])

    def error(values):
        bias = values.atVector(key_bias) if key_bias is not None else None
        r, j = gyroscope_residual(values.atVector(key_omega), meas, bias)
        return r[0], [j["w"][0]] + ([j["g"][0]] if key_bias is not None else [])

    return custom_factor(noise_model, keys, error)
