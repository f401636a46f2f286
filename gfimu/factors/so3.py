"""Vectorised SO(3) helpers for the factors: Exp, Log, right Jacobians."""

from __future__ import annotations

import numpy as np

from ..rotations import matrix_from_rotation_vector, rotation_vector_from_matrix, skew

exp = matrix_from_rotation_vector
log = rotation_vector_from_matrix


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
