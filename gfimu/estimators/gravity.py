"""Gravity compensation and orientation (Lu, Tsai & Lin 2010, eqs. 12-13 and Li et al. 2021, eqs. 9-10).

Accelerometers read the specific force ``f = a − g``; the acceleration of
the body origin is ``a = f + g_B`` with ``g_B = R_wbᵀ (0, 0, −9.80665)``.
Gravity in B comes either from a two-axis inclinometer (Lu, Tsai & Lin 2010: the
direction cosines of the body axes with the vertical) or from an attitude
propagated with ω (Li et al. 2021: improved-Euler quaternion update), driven by
a gyroscope or by the accelerometer-derived ω.

Yaw convention: the heading about the vertical is not observable from
gravity. Every attitude built from a vertical direction has zero yaw: the
body x axis, projected on the horizontal plane, points along world x
(``R_wb = R_y(pitch) R_x(roll)``). Propagated attitudes start with this
convention at the first sample of each gap-free segment.
"""

from __future__ import annotations

import numpy as np

from ..errors import DataError, InputError
from ..log import Log
from ..motion import Motion
from ..rotations import matrix_from_quaternion, quaternion_multiply

STANDARD_GRAVITY_MPS2 = 9.80665
GRAVITY_W_MPS2 = np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2])

# coefficient of ω_{N-1} × ω_N in the vector part of the quaternion increment
# (Li et al. 2021, eq. 10). The text prints r²/8; the second-order Magnus expansion
# for ω varying linearly over the step gives r²/24, which is used here. The
# term is O(r³) either way, so the update is second order in r with both.
CONING_COEFFICIENT = 1.0 / 24.0


def up_b_from_tilt(tilt_rad: np.ndarray) -> np.ndarray:
    """Unit upward vertical in B from inclinometer tilts (Lu, Tsai & Lin 2010, Fig. 2), (N, 2) -> (N, 3).

    ``tilt_x`` (``tilt_y``) is the angle between the body x (y) axis and the
    upward vertical, so the up vector's body components are the direction
    cosines ``(cos θx, cos θy, cos θz)`` with ``cos θz = +sqrt(1 − cos²θx −
    cos²θy)``: the body z axis is assumed to point upward (θz < 90°), the
    inclinometer's own convention. Tilts with ``cos²θx + cos²θy > 1`` are
    impossible and raise ValueError naming the sample.
    """
    t = np.asarray(tilt_rad, dtype=float)
    if t.ndim != 2 or t.shape[1] != 2:
        raise InputError(f"tilt_rad must have shape (N, 2), got {t.shape}")
    bad = ~np.all(np.isfinite(t), axis=1)
    if bad.any():
        raise DataError(f"tilt_rad: non-finite value at sample {int(np.argmax(bad))}")
    cx, cy = np.cos(t[:, 0]), np.cos(t[:, 1])
    rest = 1.0 - cx**2 - cy**2
    if np.any(rest < -1e-9):
        k = int(np.argmax(rest < -1e-9))
        raise DataError(
            f"tilt_rad: sample {k} has tilt_x = {t[k, 0]:.6g} rad, tilt_y = {t[k, 1]:.6g} rad, "
            "whose direction cosines exceed 1 (cos²θx + cos²θy > 1)"
        )
    return np.column_stack([cx, cy, np.sqrt(np.clip(rest, 0.0, None))])


def gravity_b_from_tilt(tilt_rad: np.ndarray) -> np.ndarray:
    """Gravity in B, ``−g (cos θx, cos θy, cos θz)`` (Lu, Tsai & Lin 2010, eq. 12), (N, 2) -> (N, 3) m/s²."""
    return -STANDARD_GRAVITY_MPS2 * up_b_from_tilt(tilt_rad)


def quaternion_from_up_b(up_b: np.ndarray) -> np.ndarray:
    """Attitude q_wb (N, 4) with zero yaw that maps the body vector ``up_b`` to world +z.

    ``R_wb = R_y(pitch) R_x(roll)``: its third row is ``up_b``, so
    ``pitch = −asin(u_x)`` and ``roll = atan2(u_y, u_z)``.
    """
    u = np.atleast_2d(np.asarray(up_b, dtype=float))
    norm = np.linalg.norm(u, axis=1, keepdims=True)
    if np.any(norm == 0) or not np.all(np.isfinite(u)):
        raise DataError("quaternion_from_up_b: the vertical direction is zero or not finite")
    u = u / norm
    pitch = -np.arcsin(np.clip(u[:, 0], -1.0, 1.0))
    roll = np.arctan2(u[:, 1], u[:, 2])
    zeros = np.zeros_like(pitch)
    qy = np.column_stack([np.cos(pitch / 2), zeros, np.sin(pitch / 2), zeros])
    qx = np.column_stack([np.cos(roll / 2), np.sin(roll / 2), zeros, zeros])
    return quaternion_multiply(qy, qx)


def improved_euler_increments(omega_b_radps: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """Quaternion increments Δq_N (N-1, 4) of Li et al. 2021, eq. 10, from body rates at consecutive samples.

    ``Δq = [1 − r²/8 ω_{N-1}·ω_N,  r/4 (ω_{N-1} + ω_N) + c r² ω_{N-1} × ω_N]``,
    normalised, with r the step and c = :data:`CONING_COEFFICIENT`; the update
    is ``q_N = q_{N-1} ⊗ Δq_N`` (Li et al. 2021's ``Φ⁺_{N-1}`` multiplication, for
    scalar-first quaternions and ω in B).
    """
    w = np.asarray(omega_b_radps, dtype=float)
    r = np.asarray(dt_s, dtype=float)[:, None]
    w0, w1 = w[:-1], w[1:]
    vec = r / 4.0 * (w0 + w1) + CONING_COEFFICIENT * r**2 * np.cross(w0, w1)
    scal = 1.0 - r[:, 0] ** 2 / 8.0 * np.einsum("ij,ij->i", w0, w1)
    dq = np.column_stack([scal, vec])
    return dq / np.linalg.norm(dq, axis=1, keepdims=True)


def propagate_quaternion(q0_wb: np.ndarray, omega_b_radps: np.ndarray, timestamps_ns: np.ndarray) -> np.ndarray:
    """Attitudes q_wb (N, 4) from q0 at the first sample and body rates (N, 3) (Li et al. 2021, eq. 10).

    The chain ``q_N = q_{N-1} ⊗ Δq_N`` is a product of increments, evaluated as
    a vectorised prefix product (log₂ N passes) instead of a Python loop.
    """
    w = np.asarray(omega_b_radps, dtype=float)
    t = np.asarray(timestamps_ns, dtype=np.int64)
    if w.ndim != 2 or w.shape[1] != 3 or len(w) != len(t):
        raise InputError(f"propagate_quaternion: omega {w.shape} and timestamps {t.shape} do not match")
    if not np.all(np.isfinite(w)):
        raise DataError(f"propagate_quaternion: non-finite ω at sample {int(np.argmax(~np.all(np.isfinite(w), axis=1)))}")
    q0 = np.asarray(q0_wb, dtype=float).reshape(4)
    q0 = q0 / np.linalg.norm(q0)
    n = len(w)
    out = np.empty((n, 4))
    if n == 0:
        return out
    prefix = np.vstack([[1.0, 0.0, 0.0, 0.0], improved_euler_increments(w, np.diff(t) * 1e-9)])
    step = 1
    while step < n:
        prefix[step:] = quaternion_multiply(prefix[:-step], prefix[step:])
        prefix[step:] /= np.linalg.norm(prefix[step:], axis=1, keepdims=True)
        step *= 2
    out[:] = quaternion_multiply(q0[None, :], prefix)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _initial_up_b(log: Log, motion: Motion, seg: slice, window_s: float | None) -> np.ndarray:
    """Upward vertical in B at a segment's start: mean over its first ``window_s`` seconds.

    ``None``: the first sample alone from an inclinometer (valid in motion), the
    first 0.05 s of specific force otherwise (the body must be still).
    """
    if window_s is None:
        window_s = 0.0 if log.tilt_rad is not None else 0.05
    if not (np.isfinite(window_s) and window_s >= 0):
        raise InputError(f"add_orientation: initial_window_s must be >= 0, got {window_s!r}")
    t = log.timestamps_ns[seg]
    k = max(1, int(np.searchsorted(t, t[0] + int(round(window_s * 1e9)), side="right")))
    if log.tilt_rad is not None:
        up = up_b_from_tilt(log.tilt_rad[seg][:k]).mean(axis=0)
    else:
        up = motion.specific_force_b_mps2[seg][:k].mean(axis=0)  # at rest f = −g: points up
    if not np.linalg.norm(up) > 0:
        raise DataError(f"{log.source}: cannot find the vertical at sample {seg.start} (zero specific force)")
    return up / np.linalg.norm(up)


def add_orientation(log: Log, motion: Motion, source: str = "inclinometer",
                    initial_window_s: float | None = None) -> Motion:
    """Add gravity-free acceleration ``accel_b_mps2`` and attitude ``quaternion_wb`` to an estimate.

    ``source``:

    - ``"inclinometer"``: gravity in B from the tilt angles at every sample
      (Lu, Tsai & Lin 2010, eqs. 12-13); the attitude has roll and pitch from the tilts
      and zero yaw (heading is not observable from an inclinometer).
    - ``"gyro"`` / ``"estimate"``: the attitude is propagated with the
      gyroscope readings / the estimate's ω by the improved Euler update of
      Li et al. 2021 (eq. 10), restarting at each gap-free segment from an initial
      attitude with zero yaw whose vertical is the mean over the segment's
      first ``initial_window_s`` seconds of the inclinometer (if the log has
      one) or of the estimated specific force (the body must then be still).
      Default: the inclinometer's first sample alone (it is valid in
      motion), or 0.05 s of specific force (averaging its noise).

    In all cases ``a = f + g_B`` with f the estimate's specific force.
    """
    if motion.specific_force_b_mps2 is None:
        raise InputError("add_orientation: the estimate has no specific force (f) to remove gravity from")
    if len(motion) != len(log) or not np.array_equal(motion.timestamps_ns, log.timestamps_ns):
        raise InputError("add_orientation: the estimate's timestamps differ from the log's")
    f = motion.specific_force_b_mps2
    if source == "inclinometer":
        if log.tilt_rad is None:
            raise InputError(f"{log.source}: orientation source 'inclinometer' needs tilt_x, tilt_y columns")
        up = up_b_from_tilt(log.tilt_rad)
        return motion.replace(accel_b_mps2=f - STANDARD_GRAVITY_MPS2 * up, quaternion_wb=quaternion_from_up_b(up))
    if source == "gyro":
        if log.gyro_b_radps is None:
            raise InputError(f"{log.source}: orientation source 'gyro' needs gyroscope columns w_x, w_y, w_z")
        omega = log.gyro_b_radps
    elif source == "estimate":
        if motion.omega_b_radps is None:
            raise InputError("add_orientation: orientation source 'estimate' needs an estimate with ω")
        omega = motion.omega_b_radps
    else:
        raise InputError(f"add_orientation: source must be 'inclinometer', 'gyro' or 'estimate', got {source!r}")
    quat = np.empty((len(log), 4))
    for seg in log.segments():
        q0 = quaternion_from_up_b(_initial_up_b(log, motion, seg, initial_window_s))[0]
        quat[seg] = propagate_quaternion(q0, omega[seg], log.timestamps_ns[seg])
    gravity_b = np.einsum("nji,j->ni", matrix_from_quaternion(quat), GRAVITY_W_MPS2)
    return motion.replace(accel_b_mps2=f + gravity_b, quaternion_wb=quat)
