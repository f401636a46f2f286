"""The noise policy: one rule for a sensor noise std that array.toml does not give.

Estimators that need weights (the smoothers, the per-sample maximum-likelihood fit) resolve a
missing std here, the same way everywhere:

- an accelerometer axis without ``noise_std_mps2`` takes the mean std of the axes that state one;
  when none does, the caller's default (the smoother's ``default_accel_noise_std_mps2``,
  :data:`DEFAULT_ACCEL_NOISE_STD_MPS2` otherwise);
- a gyroscope without ``noise_std_radps``: :data:`DEFAULT_GYRO_NOISE_STD_RADPS`;
- an inclinometer without ``noise_std_rad``: :data:`DEFAULT_TILT_NOISE_STD_RAD`.

Estimators that only report a one-sigma (inversion, gyro-aided, free flight) do not invent one:
they leave it out where the array states no noise. The smoothers' noise tuner rescales the
accelerometer noise from the data when asked (``tune_accel_noise``), and the model check
(:mod:`gfimu.smoother.tuning.model_choice`) measures it, so a default only has to be of the right order.
"""

from __future__ import annotations

import numpy as np

DEFAULT_ACCEL_NOISE_STD_MPS2 = 0.07
"""Accelerometer white-noise std [m/s²] when no axis of the array states one (a MEMS accelerometer's order)."""
DEFAULT_GYRO_NOISE_STD_RADPS = 0.01
"""Gyroscope white-noise std [rad/s] when the array states none."""
DEFAULT_TILT_NOISE_STD_RAD = 0.002
"""Inclinometer white-noise std [rad] when the array states none."""


def stated(value) -> bool:
    """Whether a std is given: a finite number > 0."""
    return value is not None and bool(np.isfinite(value)) and value > 0


def accel_noise_std(array, default_mps2: float = DEFAULT_ACCEL_NOISE_STD_MPS2) -> np.ndarray:
    """(n_axes,) accelerometer noise std [m/s²] with the missing ones resolved (module docstring)."""
    sigma = np.asarray(array.noise_std_per_axis_mps2, dtype=float)
    known = np.isfinite(sigma) & (sigma > 0)
    if np.all(known):
        return sigma
    fill = float(np.mean(sigma[known])) if np.any(known) else float(default_mps2)
    return np.where(known, sigma, fill)


def missing_accel_axes(array) -> list[str]:
    """Columns of the accelerometer axes whose array.toml gives no noise std."""
    sigma = np.asarray(array.noise_std_per_axis_mps2, dtype=float)
    return [c for c, s in zip(array.accel_columns, sigma) if not stated(s)]


def gyro_noise_std(array, default_radps: float = DEFAULT_GYRO_NOISE_STD_RADPS) -> float:
    """Gyroscope noise std [rad/s] of ``array`` (which has a gyroscope), or the default."""
    s = array.gyroscope.noise_std_radps if array.gyroscope is not None else None
    return float(s) if stated(s) else float(default_radps)


def tilt_noise_std(array, default_rad: float = DEFAULT_TILT_NOISE_STD_RAD) -> float:
    """Inclinometer noise std [rad] of ``array``, or the default."""
    s = array.inclinometer.noise_std_rad if array.inclinometer is not None else None
    return float(s) if stated(s) else float(default_rad)
