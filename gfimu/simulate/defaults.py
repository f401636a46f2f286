"""The defaults of a simulated log, in one place: ``gfimu simulate``, ``gfimu demo`` and the
scenarios of :data:`gfimu.simulate.SCENARIOS` that do not set their own take them from here.

With nothing set, ``gfimu simulate random3d`` and the first log of ``gfimu demo`` are the same
log (same array, noise, rate, duration and seed, so the same readings).
"""

from __future__ import annotations

CUBE_HALF_EDGE_M = 0.05
"""Half edge of the default array, four triads on alternate corners of a cube [m] (a 10 cm cube)."""

ACCEL_NOISE_STD_MPS2 = 0.07
"""White accelerometer noise per axis of the default array [m/s²]."""

RATE_HZ = 500.0
"""Sample rate [Hz] of the synthetic motions (random3d, reversal) and of the demo."""

DURATION_S = 10.0
"""Length [s] of the synthetic motions (random3d, reversal) and of each demo log."""

SEED = 0
"""Seed of the motion and of the noise."""


def default_cube(half_edge_m: float | None = None):
    """The default array: :func:`gfimu.array.cube_array` with the default size and noise."""
    from ..array import cube_array

    return cube_array(CUBE_HALF_EDGE_M if half_edge_m is None else half_edge_m, noise_std_mps2=ACCEL_NOISE_STD_MPS2)
