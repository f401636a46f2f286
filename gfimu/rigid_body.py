"""Rigid-body acceleration field (Ho & Lin 2009, eqs. 1-7).

A point at lever arm r on a rigid body has acceleration
``a_p = a_o + ω̇ × r + ω × (ω × r)``; an accelerometer there reads the specific
force ``f_p = f + ω̇ × r + ω × (ω × r)`` with ``f = a_o - g`` (all in B).
Writing ``ω × (ω × r) = (ω ωᵀ - |ω|² I) r`` makes the reading linear in the
twelve unknowns ``x = [f, ω̇, q(ω)]`` with the six quadratic terms of Ho & Lin 2009,
eq. 2, ordered ``q = [ωx²+ωy², ωx²+ωz², ωy²+ωz², ωxωy, ωxωz, ωyωz]``.
"""

from __future__ import annotations

import numpy as np

N_UNKNOWNS = 12
QUADRATIC_NAMES = ("wx2+wy2", "wx2+wz2", "wy2+wz2", "wxwy", "wxwz", "wywz")


def quadratic_terms(omega_b: np.ndarray) -> np.ndarray:
    """The six quadratic terms q(ω) of Ho & Lin 2009, eq. 2; (..., 3) -> (..., 6)."""
    w = np.asarray(omega_b, dtype=float)
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    return np.stack([x * x + y * y, x * x + z * z, y * y + z * z, x * y, x * z, y * z], axis=-1)


def quadratic_terms_jacobian(omega_b: np.ndarray) -> np.ndarray:
    """d q / d ω, (..., 3) -> (..., 6, 3) (the one Jacobian of :func:`quadratic_terms`)."""
    w = np.asarray(omega_b, dtype=float)
    out = np.zeros(w.shape[:-1] + (6, 3))
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    out[..., 0, 0] = out[..., 1, 0] = 2 * x
    out[..., 0, 1] = out[..., 2, 1] = 2 * y
    out[..., 1, 2] = out[..., 2, 2] = 2 * z
    out[..., 3, 0], out[..., 3, 1] = y, x
    out[..., 4, 0], out[..., 4, 2] = z, x
    out[..., 5, 1], out[..., 5, 2] = z, y
    return out


def centripetal_matrix(position_m: np.ndarray) -> np.ndarray:
    """Matrix C(r), (..., 3) -> (..., 3, 6), with ``ω × (ω × r) = C(r) q(ω)``."""
    r = np.asarray(position_m, dtype=float)
    rx, ry, rz = r[..., 0], r[..., 1], r[..., 2]
    zero = np.zeros_like(rx)
    rows = [
        [zero, zero, -rx, ry, rz, zero],
        [zero, -ry, zero, rx, zero, rz],
        [-rz, zero, zero, zero, rx, ry],
    ]
    return np.stack([np.stack(r_, axis=-1) for r_ in rows], axis=-2)


def structure_matrix(directions_b: np.ndarray, positions_m: np.ndarray) -> np.ndarray:
    """Structure matrix S (n × 12) of Ho & Lin 2009, eq. 6, for n single-axis sensors.

    Row j maps ``x = [f, ω̇, q(ω)]`` to the reading along unit direction ``s_j``
    (in B) of a sensor at ``r_j``: ``s_jᵀ f + (r_j × s_j)ᵀ ω̇ + s_jᵀ C(r_j) q``.
    """
    s = np.asarray(directions_b, dtype=float).reshape(-1, 3)
    r = np.asarray(positions_m, dtype=float).reshape(-1, 3)
    if s.shape != r.shape:
        raise ValueError(f"directions {s.shape} and positions {r.shape} differ in shape")
    quad = np.einsum("ni,nij->nj", s, centripetal_matrix(r))
    return np.hstack([s, np.cross(r, s), quad])


def point_specific_force(
    specific_force_b: np.ndarray,
    omega_dot_b: np.ndarray,
    omega_b: np.ndarray,
    position_m: np.ndarray,
) -> np.ndarray:
    """Specific force at lever arm r: ``f + ω̇ × r + ω × (ω × r)``, broadcasting."""
    f = np.asarray(specific_force_b, dtype=float)
    dw = np.asarray(omega_dot_b, dtype=float)
    w = np.asarray(omega_b, dtype=float)
    r = np.asarray(position_m, dtype=float)
    return f + np.cross(dw, r) + np.cross(w, np.cross(w, r))


def omega_from_quadratic_terms(q: np.ndarray) -> np.ndarray:
    """Magnitudes |ωx|, |ωy|, |ωz| from q (Ho & Lin 2009, §IV); (..., 6) -> (..., 3).

    ``ωx² = (q1 + q2 - q3) / 2`` etc.; negative values (noise) are clipped to 0.
    The signs are not observable from q alone.
    """
    q = np.asarray(q, dtype=float)
    sq = 0.5 * np.stack(
        [q[..., 0] + q[..., 1] - q[..., 2], q[..., 0] - q[..., 1] + q[..., 2], -q[..., 0] + q[..., 1] + q[..., 2]],
        axis=-1,
    )
    return np.sqrt(np.clip(sq, 0.0, None))
