"""Structure-matrix inversion (Ho & Lin 2009, eq. 7): exact recovery, covariance, signs."""

import numpy as np
import pytest

from gfimu.array import Accelerometer, ArrayModelError, SensorArray, cube_array, mimu4444_array
from gfimu.methods import make_estimator
from gfimu.estimators._common import continuity_signs, omega_from_quadratic_terms_signed
from gfimu.estimators.inversion import invert, inversion_matrix
from gfimu.rigid_body import quadratic_terms
from gfimu.rotations import matrix_from_rotation_vector

from test_estimators_classic import analytic_log, sines


def test_invert_recovers_state_exactly_on_rotated_sensors():
    rng = np.random.default_rng(0)
    accs = [Accelerometer(f"s{i}", rng.uniform(-0.05, 0.05, 3), matrix_from_rotation_vector(rng.normal(size=3)),
                          noise_std_mps2=0.05 * (i + 1)) for i in range(5)]
    arr = SensorArray(tuple(accs))
    f, dw, w = rng.normal(size=(3, 50, 3)) * np.array([3.0, 20.0, 6.0])[:, None, None]
    x, cov = invert(arr, arr.predict_readings(f, dw, w))
    np.testing.assert_allclose(x, np.hstack([f, dw, quadratic_terms(w)]), rtol=1e-9, atol=1e-9)
    assert cov.shape == (12, 12) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_inversion_covariance_matches_monte_carlo():
    """Weighted least squares with unequal noise: sample covariance of x vs (SᵀΣ⁻¹S)⁻¹."""
    base = cube_array(0.05)
    stds = [0.03, 0.07, 0.05, 0.1]
    arr = base.with_accelerometers(
        [Accelerometer(a.name, a.position_m, noise_std_mps2=s) for a, s in zip(base.accelerometers, stds)])
    truth = arr.predict_readings([0.3, -0.2, 9.8], [5.0, -3.0, 2.0], [2.0, -1.0, 3.0])
    rng = np.random.default_rng(11)
    n = 40000
    noisy = truth + rng.standard_normal((n, arr.n_axes)) * arr.noise_std_per_axis_mps2
    x, cov = invert(arr, noisy)
    sample = np.cov(x.T)
    np.testing.assert_allclose(np.diag(sample), np.diag(cov), rtol=0.04)
    corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    sample_corr = sample / np.sqrt(np.outer(np.diag(sample), np.diag(sample)))
    np.testing.assert_allclose(sample_corr, corr, atol=0.03)
    # the weighted solution beats the unweighted one on the noisy sensors' worst axis
    S = arr.structure_matrix()
    A_plain = np.linalg.pinv(S)
    cov_plain = (A_plain * arr.noise_std_per_axis_mps2**2) @ A_plain.T
    assert np.all(np.diag(cov) <= np.diag(cov_plain) * (1 + 1e-12))


def test_cube_covariance_closed_form():
    """Cube at half edge l, equal noise σ: var(f_i) = σ²/4 (the four sensors averaged)."""
    arr = cube_array(0.05, noise_std_mps2=0.07)
    _, cov = inversion_matrix(arr)
    np.testing.assert_allclose(np.diag(cov)[:3], 0.07**2 / 4, rtol=1e-12)


def test_unknown_noise_gives_nan_covariance_and_no_sigma():
    arr = cube_array(noise_std_mps2=None)
    _, cov = inversion_matrix(arr)
    assert np.all(np.isnan(cov))
    log = analytic_log(arr, sines(), duration_s=0.1)
    est = make_estimator("inversion", compute_sigma=True).estimate(log).motion
    assert est.sigma == {}


def test_sigma_output_matches_covariance():
    arr = cube_array(noise_std_mps2=0.07)
    log = analytic_log(arr, sines(offset=(5, 5, 5)), duration_s=0.1)
    est = make_estimator("inversion", compute_sigma=True).estimate(log).motion
    _, cov = inversion_matrix(arr)
    np.testing.assert_allclose(est.sigma["omega_dot_b_radps2"][0], np.sqrt(np.diag(cov)[3:6]))
    # far from zero the ω sigma is the linearised σ(ω²)/(2|ω|) (up to the softening term)
    w = np.abs(log.truth.omega_b_radps[0])
    L = 0.5 * np.array([[1, 1, -1], [1, -1, 1], [-1, 1, 1]])
    s_sq = np.sqrt(np.diag(L @ cov[6:9, 6:9] @ L.T))
    np.testing.assert_allclose(est.sigma["omega_b_radps"][0], s_sq / (2 * w), rtol=0.2)


def test_errors_name_the_cause():
    with pytest.raises(ArrayModelError, match="coplanar"):
        invert(SensorArray(tuple(Accelerometer(f"a{i}", [np.cos(t), np.sin(t), 0.0]) for i, t in enumerate([0, 1, 2, 3]))),
               np.zeros((2, 12)))
    with pytest.raises(ValueError, match="has shape"):
        invert(cube_array(), np.zeros((2, 11)))
    assert make_estimator("inversion").applicable(mimu4444_array()) is None  # nearly planar, still invertible


def test_relative_signs_from_cross_terms():
    rng = np.random.default_rng(5)
    w = rng.normal(size=(1000, 3)) * 3
    v = omega_from_quadratic_terms_signed(quadratic_terms(w))
    sign = np.sign(w[np.arange(1000), np.argmax(np.abs(w), axis=1)])
    np.testing.assert_allclose(v, sign[:, None] * w, atol=1e-9)


def test_continuity_signs_follow_the_previous_sample():
    v = np.array([[1.0, 0, 0], [-1.0, 0.1, 0], [0.9, 0, 0], [0.9, 0, 0]])
    s = continuity_signs(v)
    np.testing.assert_array_equal(s, [1, -1, 1, 1])
    signed = s[:, None] * v  # (1,0,0), (1,-0.1,0), (0.9,0,0), (0.9,0,0): no jumps
    assert np.abs(np.diff(signed, axis=0)).max() < 0.2


def test_inversion_estimator_noise_free():
    log = analytic_log(cube_array(noise_std_mps2=None), sines(offset=(0.5, 0, 0)), duration_s=3.0)
    est = make_estimator("inversion").estimate(log).motion
    truth = log.truth
    w0 = truth.omega_b_radps[0]
    s = np.sign(w0[np.argmax(np.abs(w0))])  # the first sample's global sign is +, on the largest component
    np.testing.assert_allclose(est.omega_b_radps, s * truth.omega_b_radps, atol=1e-9)
    np.testing.assert_allclose(est.omega_dot_b_radps2, truth.omega_dot_b_radps2, atol=1e-10)
    np.testing.assert_allclose(est.specific_force_b_mps2, truth.specific_force_b_mps2, atol=1e-12)
    assert est.accel_b_mps2 is None and est.quaternion_wb is None
