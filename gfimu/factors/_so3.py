"""Vectorised SO(3) helpers for the factors: Exp, Log, right Jacobians."""

from __future__ import annotations

import numpy as np

from ..rotations import matrix_from_rotation_vector, skew

exp = matrix_from_rotation_vector


def log(m: np.ndarray) -> np.ndarray:
    """SO(3) logarithm, (..., 3, 3) -> (..., 3), vectorised, angle in [0, π]."""
    m = np.asarray(m, dtype=float)
    tr = np.clip((np.trace(m, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(tr)
    v = np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], axis=-1)
    s = np.sin(angle)
    small = angle < 1e-6
    scale = np.where(small, 0.5 + angle**2 / 12.0, angle / (2.0 * np.where(small, 1.0, s)))
    out = v * scale[..., None]
    near_pi = angle > np.pi - 1e-4
    if np.any(near_pi):
        # Around π the antisymmetric part vanishes: take the axis from R + I.
        idx = np.nonzero(near_pi)
        for k in zip(*idx) if m.ndim > 2 else [()]:
            r = m[k]
            b = (r + np.eye(3)) / 2.0
            col = int(np.argmax(np.diag(b)))
            axis = b[:, col] / np.sqrt(max(b[col, col], 1e-300))
            axis /= np.linalg.norm(axis)
            vk = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
            if axis @ vk < 0:
                axis = -axis
            out[k] = axis * angle[k]
    return out


def right_jacobian(phi: np.ndarray) -> np.ndarray:
    """Right Jacobian Jr(φ) of SO(3): Exp(φ + δ) ≈ Exp(φ) Exp(Jr(φ) δ)."""
    phi = np.asarray(phi, dtype=float)
    a = np.linalg.norm(phi, axis=-1)[..., None, None]
    k = skew(phi)
    small = a < 1e-5
    sa = np.where(small, 1.0, a)
    c1 = np.where(small, 0.5 - a**2 / 24.0, (1.0 - np.cos(sa)) / sa**2)
    c2 = np.where(small, 1.0 / 6.0 - a**2 / 120.0, (sa - np.sin(sa)) / sa**3)
    return np.eye(3) - c1 * k + c2 * (k @ k)


def right_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """Inverse right Jacobian: Log(Exp(φ) Exp(δ)) ≈ φ + Jr⁻¹(φ) δ."""
    phi = np.asarray(phi, dtype=float)
    a = np.linalg.norm(phi, axis=-1)[..., None, None]
    k = skew(phi)
    small = a < 1e-5
    sa = np.where(small, 1.0, a)
    c = np.where(small, 1.0 / 12.0 + a**2 / 720.0, 1.0 / sa**2 - (1.0 + np.cos(sa)) / (2.0 * sa * np.sin(sa)))
    return np.eye(3) + 0.5 * k + c * (k @ k)


def left_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """Inverse left Jacobian: Log(Exp(δ) Exp(φ)) ≈ φ + Jl⁻¹(φ) δ; Jl(φ) = Jr(-φ)."""
    return right_jacobian_inverse(-np.asarray(phi, dtype=float))
