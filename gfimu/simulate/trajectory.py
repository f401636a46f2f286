"""Exact rigid-body trajectories: attitude from ω, gravity, smooth signals.

Pure maths. A trajectory is sampled as :class:`BodyKinematics`: ω, ω̇ (its
exact derivative), the gravity-free acceleration of the body origin in B, and
the attitude W←B, which is the integral of ω (analytic where the motion
allows, otherwise :func:`integrate_attitude`, a fourth-order Magnus scheme
with sub-steps small enough to be exact to ~1e-12 rad).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .. import rotations
from ..errors import DataError

GRAVITY_W_MPS2 = np.array([0.0, 0.0, -9.80665])
"""Gravity in the world frame W (z up), as in the log format."""


@dataclass(frozen=True)
class BodyKinematics:
    """Sampled motion of the body origin, all in B (quaternion W←B, scalar first)."""

    times_s: np.ndarray
    omega_b_radps: np.ndarray
    omega_dot_b_radps2: np.ndarray
    accel_b_mps2: np.ndarray
    quaternion_wb: np.ndarray
    position_w_m: np.ndarray | None = None  # origin in W, when the scenario defines it

    @property
    def gravity_b_mps2(self) -> np.ndarray:
        """Gravity expressed in B, ``Rᵀ g``, (N, 3)."""
        return gravity_in_body(self.quaternion_wb)

    @property
    def specific_force_b_mps2(self) -> np.ndarray:
        """``f = a − Rᵀ g`` in B (what an accelerometer at the origin reads)."""
        return self.accel_b_mps2 - self.gravity_b_mps2


def gravity_in_body(quaternion_wb: np.ndarray) -> np.ndarray:
    """``Rᵀ g`` for each attitude, (N, 4) -> (N, 3)."""
    r = rotations.matrix_from_quaternion(quaternion_wb)
    return np.einsum("nji,j->ni", r, GRAVITY_W_MPS2)


def tilt_angles_rad(quaternion_wb: np.ndarray) -> np.ndarray:
    """Inclinometer angles (tilt_x, tilt_y) of the log format, (N, 2).

    The angle between body x (y) and the upward vertical: ``cos tilt_x`` is
    the z component in W of the body x axis, ``R[2, 0]`` (Lu, Tsai & Lin 2010, eq. 12).
    """
    r = rotations.matrix_from_quaternion(quaternion_wb)
    return np.arccos(np.clip(r[:, 2, :2], -1.0, 1.0))


def quaternion_axis_angle(axis: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    """Unit quaternions of rotations by ``angle_rad`` (N,) about the fixed unit ``axis``."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    half = 0.5 * np.asarray(angle_rad, dtype=float)[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def level_quaternion_from_specific_force(specific_force_b_mps2: np.ndarray) -> np.ndarray:
    """Attitude W←B with zero heading whose ``Rᵀ (0, 0, 1)`` is along ``f`` (body at rest).

    The smallest rotation taking the measured "up" direction in B onto the
    world z axis.
    """
    f = np.asarray(specific_force_b_mps2, dtype=float).reshape(3)
    norm = np.linalg.norm(f)
    if not np.isfinite(norm) or norm < 1e-6:
        raise DataError(f"cannot level on a specific force of {f.tolist()} m/s² (no gravity direction)")
    up_b = f / norm
    ez = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up_b, ez)
    s, c = np.linalg.norm(axis), float(np.dot(up_b, ez))
    if s < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0]) if c > 0 else np.array([0.0, 1.0, 0.0, 0.0])
    return quaternion_axis_angle(axis / s, np.arctan2(s, c))


def sum_of_sines(times_s, amplitude, frequency_hz, phase_rad, order: int = 0) -> np.ndarray:
    """``Σ_k A_k sin(2π f_k t + φ_k)`` per column and its derivatives.

    ``amplitude``, ``frequency_hz``, ``phase_rad`` are (K, D) arrays (K
    components for each of D columns); ``order`` 0, 1 or 2 selects the value,
    first or second time derivative. Returns (N, D).
    """
    t = np.asarray(times_s, dtype=float)[:, None, None]
    a = np.asarray(amplitude, dtype=float)
    w = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float)
    arg = w * t + np.asarray(phase_rad, dtype=float)
    if order == 0:
        terms = a * np.sin(arg)
    elif order == 1:
        terms = a * w * np.cos(arg)
    elif order == 2:
        terms = -a * w * w * np.sin(arg)
    else:
        raise ValueError(f"order must be 0, 1 or 2, got {order}")
    return terms.sum(axis=1)


def _quaternion_scan(q: np.ndarray) -> np.ndarray:
    """Running products ``q_0 ⊗ q_1 ⊗ … ⊗ q_k`` of (M, 4) quaternions (parallel prefix)."""
    out = q.copy()
    d = 1
    while d < out.shape[0]:
        out[d:] = rotations.quaternion_multiply(out[:-d], out[d:])
        d *= 2
    return out


def integrate_attitude(
    omega_fn: Callable[[np.ndarray], np.ndarray],
    times_s: np.ndarray,
    quaternion0_wb: np.ndarray,
    max_angle_step_rad: float = 2e-3,
    omega_samples: np.ndarray | None = None,
) -> np.ndarray:
    """Attitudes W←B at ``times_s`` from ``q̇ = ½ q ⊗ (0, ω(t))``, ω in B.

    Fourth-order Magnus step with two Gauss–Legendre nodes ``t±`` (Li et al. 2021
    uses the improved Euler step instead; this one is exact to round-off at
    the step sizes used): ``q ← q ⊗ exp(h/2 (ω₋ + ω₊) + √3/12 h² ω₋ × ω₊)``.
    Each sample interval is split into sub-steps so that no sub-step turns
    more than ``max_angle_step_rad``. ``omega_fn`` must accept an array of
    times and return (M, 3).
    """
    t = np.asarray(times_s, dtype=float).reshape(-1)
    q0 = np.asarray(quaternion0_wb, dtype=float).reshape(4)
    q0 = q0 / np.linalg.norm(q0)
    n = t.size
    if n == 0:
        return np.zeros((0, 4))
    if n == 1:
        return q0[None, :].copy()
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise ValueError("integrate_attitude: times must be strictly increasing")
    w = np.asarray(omega_fn(t) if omega_samples is None else omega_samples, dtype=float)
    peak = float(np.max(np.linalg.norm(w, axis=1))) * 1.5 + 1e-12
    n_sub = int(np.clip(np.ceil(peak * float(dt.max()) / max_angle_step_rad), 1, 10_000))
    # sub-step starts, (n-1, n_sub)
    h = dt / n_sub
    starts = t[:-1, None] + h[:, None] * np.arange(n_sub)[None, :]
    c = np.sqrt(3.0) / 6.0
    t_minus = (starts + (0.5 - c) * h[:, None]).reshape(-1)
    t_plus = (starts + (0.5 + c) * h[:, None]).reshape(-1)
    w_minus = np.asarray(omega_fn(t_minus), dtype=float)
    w_plus = np.asarray(omega_fn(t_plus), dtype=float)
    hh = np.repeat(h, n_sub)[:, None]
    phi = 0.5 * hh * (w_minus + w_plus) + (np.sqrt(3.0) / 12.0) * hh * hh * np.cross(w_minus, w_plus)
    dq = rotations.quaternion_from_rotation_vector(phi).reshape(n - 1, n_sub, 4)
    step = dq[:, 0, :]
    for j in range(1, n_sub):
        step = rotations.quaternion_multiply(step, dq[:, j, :])
    chain = np.concatenate([q0[None, :], step], axis=0)
    q = _quaternion_scan(chain)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q
