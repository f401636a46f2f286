"""Rotation helpers (pure maths, vectorised): one SO(3) exponential and logarithm, on scipy's ``Rotation``.

Quaternions are scalar first, ``[w, x, y, z]``; ``quaternion_wb`` rotates a
body vector into the world frame, as in the log format.
"""

from __future__ import annotations

import numpy as np


def _rotation():
    """scipy's ``Rotation``, imported on first use (it pulls in much of scipy.spatial: a tenth of a
    second of start-up that the commands which never turn a rotation need not pay)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix: ``skew(a) @ b == cross(a, b)``. Works on (..., 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def _rowwise(fn, x: np.ndarray, inner: int, out_shape: tuple[int, ...]) -> np.ndarray:
    """``fn`` on the rows of ``x`` (..., *inner dims) that are finite and not all zero; NaN elsewhere."""
    x = np.asarray(x, dtype=float)
    lead = x.shape[: x.ndim - inner]
    flat = x.reshape((-1,) + x.shape[x.ndim - inner:])
    axes = tuple(range(1, flat.ndim))
    ok = np.all(np.isfinite(flat), axis=axes) & np.any(flat != 0, axis=axes)
    out = np.full((flat.shape[0],) + out_shape, np.nan)
    if np.any(ok):
        out[ok] = fn(flat[ok])
    return out.reshape(lead + out_shape)


def matrix_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (..., 3, 3) from quaternion(s) (..., 4), scalar first, normalised first."""
    return _rowwise(lambda v: _rotation().from_quat(v, scalar_first=True).as_matrix(), q, 1, (3, 3))


def quaternion_from_matrix(m: np.ndarray) -> np.ndarray:
    """Unit quaternion(s) (..., 4), scalar first and w >= 0, from rotation matrices (..., 3, 3)."""
    return _rowwise(lambda r: _rotation().from_matrix(r).as_quat(canonical=True, scalar_first=True), m, 2, (4,))


def matrix_from_rotation_vector(phi: np.ndarray) -> np.ndarray:
    """SO(3) exponential map, (..., 3) -> (..., 3, 3); accurate to rounding at every angle."""
    phi = np.asarray(phi, dtype=float)
    flat = phi.reshape(-1, 3)
    ok = np.all(np.isfinite(flat), axis=1)
    out = np.full((flat.shape[0], 3, 3), np.nan)
    if np.any(ok):
        out[ok] = _rotation().from_rotvec(flat[ok]).as_matrix()
    return out.reshape(phi.shape[:-1] + (3, 3))


def rotation_vector_from_matrix(m: np.ndarray) -> np.ndarray:
    """SO(3) logarithm, (..., 3, 3) -> (..., 3), angle in [0, π].

    ``θ = atan2(|v|/2, (tr R - 1)/2)`` with ``v`` the axial vector of ``R - Rᵀ`` (no ``arccos``, so
    no loss near 0); where ``cos θ < -0.9`` the axial vector vanishes and the axis comes from the
    quaternion of the symmetric part (scipy's ``Rotation``), which stays exact at and near π."""
    m = np.asarray(m, dtype=float)
    v = np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], axis=-1)
    c = 0.5 * (np.trace(m, axis1=-2, axis2=-1) - 1.0)
    s = 0.5 * np.linalg.norm(v, axis=-1)
    angle = np.arctan2(s, c)
    small = s < 1e-8
    scale = np.where(small, 0.5 + angle**2 / 12.0, angle / (2.0 * np.where(small, 1.0, s)))
    out = v * scale[..., None]
    near_pi = c < -0.9
    if np.any(near_pi):
        out[near_pi] = _rowwise(lambda r: _rotation().from_matrix(r).as_rotvec(), m[near_pi], 2, (3,))
    return out


def rotation_vector_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Rotation vector (..., 3) of quaternions (..., 4), scalar first; angle in [0, π]."""
    return _rowwise(lambda v: _rotation().from_quat(v, scalar_first=True).as_rotvec(), q, 1, (3,))


def quaternion_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ⊗ q, scalar first, broadcasting over leading axes."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def quaternion_from_rotation_vector(phi: np.ndarray) -> np.ndarray:
    """Unit quaternion (..., 4), scalar first, of the rotation vector phi (..., 3)."""
    phi = np.asarray(phi, dtype=float)
    flat = phi.reshape(-1, 3)
    ok = np.all(np.isfinite(flat), axis=1)
    out = np.full((flat.shape[0], 4), np.nan)
    if np.any(ok):
        out[ok] = _rotation().from_rotvec(flat[ok]).as_quat(scalar_first=True)
    return out.reshape(phi.shape[:-1] + (4,))
