"""Core geometry and rigid-body model (Ho & Lin 2009, eqs. 1-7)."""

import numpy as np
import pytest

from gfimu import rigid_body
from gfimu.array import Accelerometer, ArrayModelError, SensorArray, cube_array, mimu4444_array, single_triad
from gfimu.rotations import matrix_from_rotation_vector


def random_rotation(rng):
    return matrix_from_rotation_vector(rng.normal(size=3))


def test_structure_matrix_reproduces_rigid_body_equation():
    rng = np.random.default_rng(1)
    accs = [Accelerometer(f"s{i}", rng.uniform(-0.05, 0.05, 3), random_rotation(rng)) for i in range(5)]
    arr = SensorArray(tuple(accs))
    f, dw, w = rng.normal(size=(3, 3)) * [[3], [10], [5]]
    predicted = arr.predict_readings(f, dw, w)
    direct = np.concatenate(
        [a.rotation_body_sensor.T @ rigid_body.point_specific_force(f, dw, w, a.position_m) for a in accs]
    )
    np.testing.assert_allclose(predicted, direct, rtol=1e-12, atol=1e-12)


def test_quadratic_terms_jacobian_matches_finite_differences():
    rng = np.random.default_rng(2)
    w = rng.normal(size=3)
    J = rigid_body.quadratic_terms_jacobian(w)
    eps = 1e-6
    num = np.column_stack(
        [(rigid_body.quadratic_terms(w + eps * e) - rigid_body.quadratic_terms(w - eps * e)) / (2 * eps) for e in np.eye(3)]
    )
    np.testing.assert_allclose(J, num, atol=1e-8)


def test_omega_magnitudes_from_quadratic_terms():
    w = np.array([0.3, -2.0, 1.5])
    np.testing.assert_allclose(rigid_body.omega_from_quadratic_terms(rigid_body.quadratic_terms(w)), np.abs(w), atol=1e-12)


@pytest.mark.parametrize("half_edge, expected", [(1.0, np.sqrt(2)), (10.0, 10 * np.sqrt(2)), (0.1, 10.0)])
def test_cube_condition_number_paper000(half_edge, expected):
    assert cube_array(half_edge).condition_number() == pytest.approx(expected, rel=1e-12)


def test_determinant_identity_paper000():
    """|det S| = |2 det R|³ with R the edges from sensor 1 to sensors 2-4 (Ho & Lin 2009)."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        pos = rng.normal(size=(4, 3))
        arr = SensorArray(tuple(Accelerometer(f"a{i}", p) for i, p in enumerate(pos)))
        R = (pos[1:] - pos[0]).T
        assert abs(np.linalg.det(arr.structure_matrix())) == pytest.approx(abs(2 * np.linalg.det(R)) ** 3, rel=1e-9)


def test_inversion_errors_name_the_cause():
    with pytest.raises(ArrayModelError, match="needs at least 12"):
        single_triad().check_invertible()
    flat = SensorArray(tuple(Accelerometer(f"a{i}", [np.cos(t), np.sin(t), 0.0]) for i, t in enumerate([0, 1, 2, 3])))
    with pytest.raises(ArrayModelError, match="coplanar"):
        flat.check_invertible()


def test_mimu4444_is_nearly_planar():
    sv = np.linalg.svd(mimu4444_array().structure_matrix(), compute_uv=False)
    assert sv.shape == (12,)
    assert sv[-1] == pytest.approx(0.002828, rel=1e-3)


def test_bad_accelerometer_definitions():
    with pytest.raises(ArrayModelError, match="not a rotation"):
        Accelerometer("a", [0, 0, 0], np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ArrayModelError, match="axes"):
        Accelerometer("a", [0, 0, 0], axes=("x", "x"))
    with pytest.raises(ArrayModelError, match="unique"):
        SensorArray((Accelerometer("a", [0, 0, 0]), Accelerometer("a", [1, 0, 0])))


def test_rotation_vector_round_trip_including_near_pi():
    from gfimu.rotations import matrix_from_rotation_vector, rotation_vector_from_matrix

    rng = np.random.default_rng(5)
    axes = rng.normal(size=(50, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([rng.uniform(0, np.pi - 1e-3, 40), np.pi - np.logspace(-9, -5, 10)])
    phi = axes * angles[:, None]
    back = rotation_vector_from_matrix(matrix_from_rotation_vector(phi))
    R, R_back = matrix_from_rotation_vector(phi), matrix_from_rotation_vector(back)
    np.testing.assert_allclose(R_back[:40], R[:40], atol=1e-9)
    np.testing.assert_allclose(back[:40], phi[:40], atol=1e-9)
    # within 1e-4 rad of π (the quaternion route)
    np.testing.assert_allclose(R_back[40:], R[40:], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(back[40:], axis=1), angles[40:], atol=1e-9)
    np.testing.assert_allclose(rotation_vector_from_matrix(np.eye(3)), np.zeros(3), atol=0)


def test_noise_policy_resolves_a_missing_std_one_way():
    """gfimu.noise: a missing accelerometer std takes the stated axes' mean, else the default."""
    import dataclasses

    from gfimu import noise
    from gfimu.array import cube_array

    arr = cube_array(noise_std_mps2=0.04)
    np.testing.assert_array_equal(noise.accel_noise_std(arr), np.full(arr.n_axes, 0.04))
    accs = list(arr.accelerometers)
    accs[1] = dataclasses.replace(accs[1], noise_std_mps2=None)
    accs[2] = dataclasses.replace(accs[2], noise_std_mps2=0.1)
    part = dataclasses.replace(arr, accelerometers=tuple(accs))
    sigma = noise.accel_noise_std(part)
    mean = (0.04 * 6 + 0.1 * 3) / 9
    np.testing.assert_allclose(sigma[3:6], mean)
    assert noise.missing_accel_axes(part) == list(part.accel_columns[3:6])
    none = cube_array(noise_std_mps2=None)
    np.testing.assert_array_equal(noise.accel_noise_std(none, 0.3), np.full(none.n_axes, 0.3))
    assert noise.gyro_noise_std(none) == noise.DEFAULT_GYRO_NOISE_STD_RADPS
