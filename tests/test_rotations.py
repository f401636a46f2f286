"""The one SO(3) exponential and logarithm (gfimu.rotations): exact at and near π and near 0."""

from __future__ import annotations

import numpy as np
import pytest

from gfimu import rotations
from gfimu.evaluation import attitude_error


def unit_axes(n: int, seed: int = 0) -> np.ndarray:
    a = np.random.default_rng(seed).normal(size=(n, 3))
    return a / np.linalg.norm(a, axis=1, keepdims=True)


def rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    """R = cos θ I + sin θ [u]× + (1 - cos θ) u uᵀ, written out independently of the module."""
    u = axis
    K = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    return np.cos(angle) * np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * np.outer(u, u)


@pytest.mark.parametrize("angle", [np.pi, np.pi - 1e-12, np.pi - 1e-9, np.pi - 1e-6, np.pi - 1e-3])
def test_log_at_and_near_pi_is_accurate_to_1e_12(angle):
    axes = unit_axes(200)
    R = np.stack([rodrigues(u, angle) for u in axes])
    phi = rotations.rotation_vector_from_matrix(R)
    err = np.linalg.norm(phi - axes * angle, axis=1)
    if angle == np.pi:  # the axis of a half turn has no sign
        err = np.minimum(err, np.linalg.norm(phi + axes * angle, axis=1))
    assert np.max(err) < 1e-12
    np.testing.assert_allclose(rotations.matrix_from_rotation_vector(phi), R, atol=1e-14)


def test_half_turn_built_without_trigonometry():
    """R = 2 u uᵀ - I is exactly a half turn about u."""
    for u in unit_axes(50, seed=3):
        phi = rotations.rotation_vector_from_matrix(2.0 * np.outer(u, u) - np.eye(3))
        assert abs(np.linalg.norm(phi) - np.pi) < 1e-12
        assert np.linalg.norm(np.cross(phi, u)) < 1e-12


@pytest.mark.parametrize("angle", [0.0, 1e-14, 1e-10, 1e-7, 1e-4, 0.5, 2.0])
def test_exp_log_round_trip_near_zero_and_inside(angle):
    axes = unit_axes(200, seed=1)
    R = rotations.matrix_from_rotation_vector(axes * angle)
    # two evaluations of I + sin θ K + (1 − cos θ) K², entries of order 1 summed from a few products: each side
    # rounds a handful of times, so they agree to a few ε (16 ε), whatever the BLAS kernel
    np.testing.assert_allclose(R, np.stack([rodrigues(u, angle) for u in axes]), atol=16 * np.finfo(float).eps)
    phi = rotations.rotation_vector_from_matrix(R)
    assert np.max(np.linalg.norm(phi - axes * angle, axis=1)) < 1e-12 * max(angle, 1e-3)


def test_quaternions_round_trip_with_non_negative_scalar():
    axes = unit_axes(300, seed=2)
    angles = np.random.default_rng(2).uniform(0, np.pi, 300)
    q = rotations.quaternion_from_rotation_vector(axes * angles[:, None])
    R = rotations.matrix_from_quaternion(q)
    q2 = rotations.quaternion_from_matrix(R)
    assert np.all(q2[:, 0] >= 0)
    np.testing.assert_allclose(q2, q * np.sign(q[:, :1]), atol=1e-14)
    np.testing.assert_allclose(rotations.rotation_vector_from_quaternion(q), axes * angles[:, None], atol=1e-12)


def test_non_finite_rows_give_nan_rows():
    R = np.stack([np.eye(3), np.full((3, 3), np.nan)])
    phi = rotations.rotation_vector_from_matrix(R)
    assert np.all(phi[0] == 0) and np.all(np.isnan(phi[1]))
    assert np.all(np.isnan(rotations.quaternion_from_matrix(R)[1]))


def test_attitude_error_uses_the_same_logarithm_near_pi():
    u = np.array([0.0, 0.6, 0.8])
    q_true = np.array([[1.0, 0.0, 0.0, 0.0]])
    q_est = rotations.quaternion_from_rotation_vector((np.pi - 1e-9) * u)[None]
    np.testing.assert_allclose(attitude_error(q_est, q_true)[0], (np.pi - 1e-9) * u, atol=1e-12)
