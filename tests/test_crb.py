"""Cramér–Rao bound of the rigid-body model (Skog et al. 2016)."""

import numpy as np
import pytest

from gfimu import array as layouts
from gfimu.array import ArrayModelError, cube_array, mimu4444_array, single_triad
from gfimu.crb import PARAMETERS, crb_per_sample, fisher_information


def random_array(seed=0, n=5, noise=0.05):
    return layouts.random_array(n, half_extent_m=0.05, noise_std_mps2=noise, seed=seed, name="random")


def test_parameter_order():
    assert PARAMETERS[:3] == ("f_x", "f_y", "f_z") and PARAMETERS[6:] == ("w_x", "w_y", "w_z")


def test_centred_single_triad_bounds_specific_force_only():
    res = crb_per_sample(single_triad(noise_std_mps2=0.07), [[1.0, 2.0, 3.0]])
    np.testing.assert_allclose(res.covariance[0, :3, :3], 0.07**2 * np.eye(3), rtol=1e-12)
    assert res.singular[0]
    assert np.all(np.isinf(res.sigma_omega)) and np.all(np.isinf(res.sigma_omega_dot))


def test_cube_at_rest_matches_closed_form():
    """At ω = 0: Cov f = σ²/4 I and Cov ω̇ = σ²/(8 h²) I for four triads on alternate corners."""
    h, sigma = 0.05, 0.07
    res = crb_per_sample(cube_array(h, noise_std_mps2=sigma), np.zeros((1, 3)))
    assert res.singular[0]
    np.testing.assert_allclose(res.covariance[0, :3, :3], sigma**2 / 4 * np.eye(3), rtol=1e-10, atol=1e-18)
    np.testing.assert_allclose(res.covariance[0, 3:6, 3:6], sigma**2 / (8 * h**2) * np.eye(3), rtol=1e-10, atol=1e-15)
    assert np.all(np.isinf(res.sigma_omega))
    assert res.rmse_bound_omega() == np.inf
    assert res.rmse_bound_specific_force() == pytest.approx(np.sqrt(3 * sigma**2 / 4), rel=1e-10)


def test_gyro_fixes_the_bound_at_rest():
    """With a gyro and ω = 0 the accelerometers carry no ω information: Cov ω = σ_g² I."""
    res = crb_per_sample(cube_array(), np.zeros((1, 3)), gyro_noise_std_radps=0.01)
    assert not res.singular[0]
    np.testing.assert_allclose(res.covariance[0, 6:, 6:], 1e-4 * np.eye(3), rtol=1e-9, atol=1e-16)
    # and a gyro never hurts
    w = np.array([[2.0, -1.0, 3.0]])
    assert np.all(crb_per_sample(cube_array(), w, gyro_noise_std_radps=0.01).sigma_omega < crb_per_sample(cube_array(), w).sigma_omega)


def test_information_matches_numerical_jacobian_of_the_model():
    arr = random_array(seed=3)
    rng = np.random.default_rng(4)
    w = rng.normal(size=3) * 3
    f, dw = rng.normal(size=3), rng.normal(size=3)
    theta = np.concatenate([f, dw, w])

    def h(th):
        return arr.predict_readings(th[:3], th[3:6], th[6:])

    eps = 1e-6
    D = np.column_stack([(h(theta + eps * e) - h(theta - eps * e)) / (2 * eps) for e in np.eye(9)])
    sigma = arr.noise_std_per_axis_mps2
    J_num = D.T @ (D / sigma[:, None] ** 2)
    J = fisher_information(arr.structure_matrix(), sigma, w[None])[0]
    np.testing.assert_allclose(J, J_num, rtol=1e-7, atol=1e-6)


def test_bound_scales_with_noise_variance():
    arr = random_array(seed=5)
    w = np.random.default_rng(6).normal(size=(4, 3)) * 4
    c1 = crb_per_sample(arr, w, noise_std_mps2=0.01).covariance
    c3 = crb_per_sample(arr, w, noise_std_mps2=0.03).covariance
    np.testing.assert_allclose(c3, 9 * c1, rtol=1e-8)


def test_omega_bound_falls_as_one_over_rate():
    """Far from ω = 0 the ω information grows as |ω|² (∂q/∂ω is linear in ω)."""
    arr = cube_array()
    d = np.array([0.3, -0.5, 0.8])
    s = crb_per_sample(arr, np.array([2 * d, 20 * d])).sigma_omega
    np.testing.assert_allclose(s[1], s[0] / 10, rtol=1e-9)


def test_mimu4444_specific_force_bound():
    """Eight triads with identity rotation: f is the mean reading, Cov f = σ²/8 I at ω = 0."""
    res = crb_per_sample(mimu4444_array(noise_std_mps2=0.05), np.zeros((1, 3)))
    np.testing.assert_allclose(res.covariance[0, :3, :3], 0.05**2 / 8 * np.eye(3), rtol=1e-9, atol=1e-15)


def test_missing_noise_is_an_error():
    with pytest.raises(ArrayModelError, match="noise_std_mps2"):
        crb_per_sample(cube_array(noise_std_mps2=None), [[1.0, 0.0, 0.0]])
    with pytest.raises(ArrayModelError, match="gyroscope"):
        crb_per_sample(cube_array(), [[1.0, 0.0, 0.0]], gyro=True)
    with pytest.raises(ValueError, match="shape"):
        crb_per_sample(cube_array(), np.zeros((2, 2)))


def test_bound_along_a_motion():
    from gfimu.crb import crb_for_motion
    from gfimu.motion import Motion

    w = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [4.0, -1.0, 0.5]])
    res = crb_for_motion(cube_array(), Motion(np.arange(3), omega_b_radps=w))
    np.testing.assert_array_equal(res.singular, [True, False, False])
    np.testing.assert_allclose(res.covariance[1:], crb_per_sample(cube_array(), w[1:]).covariance)
    # the trajectory average includes the unobservable sample at rest
    assert res.rmse_bound_omega() == np.inf and np.isfinite(res.rmse_bound_omega_dot())
    with pytest.raises(ValueError, match="omega"):
        crb_for_motion(cube_array(), Motion(np.arange(3)))
