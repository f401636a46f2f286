"""Gyro-aided inversion and the best-layout gain matrix of Lu, Tsai & Lin 2010 (eqs. 8-9)."""

import numpy as np
import pytest

from gfimu.array import ArrayModelError, Gyroscope, SensorArray, cube_array, paper001_array, single_triad
from gfimu.methods import make_estimator
from gfimu.estimators.gyro_aided import gyro_aided_matrices, gyro_aided_solve, paper001_gain_matrix

from test_estimators_classic import analytic_log, sines

# Lu, Tsai & Lin 2010, eq. 9 as printed, m = 0.5, n = 0.25
PRINTED_G = np.array([
    [0.5, 0, 0, 0.5, 0, 0],
    [0, 0.5, 0, 0, 0.5, 0],
    [0, 0, 0.5, 0, 0, 0.5],
    [0.25, 0.25, 0.25, -0.25, -0.25, -0.25],
    [-0.25, -0.25, 0.25, 0.25, 0.25, -0.25],
    [0.25, -0.25, 0.25, -0.25, 0.25, -0.25],
])
PRINTED_P = np.array([
    [0, 0, 1, 0, 0, 0],
    [0, 1, 0, 0, 0, 0],
    [-1, 0, 0, 0, 0, 0],
    [0, 0, 0, -1, -1, 0],
    [0, 0, 0, 1, 0, 1],
    [0, 0, 0, 0, -1, 1],
], dtype=float)


def test_gain_matrix_reproduces_printed_eq9():
    G, P = paper001_gain_matrix(0.5, 0.25)
    np.testing.assert_array_equal(G, PRINTED_G)
    # G @ W through BLAS: entries of order 1 summed from 6 products, G's condition number 2: 8·6·ε·cond
    np.testing.assert_allclose(P, PRINTED_P, atol=8 * 6 * np.finfo(float).eps * np.linalg.cond(G))


def test_paper001_array_has_the_printed_gain_matrix():
    A, W, _ = gyro_aided_matrices(paper001_array(noise_std_mps2=0.07))
    np.testing.assert_allclose(A, PRINTED_G, atol=1e-12)
    np.testing.assert_allclose(A @ W, PRINTED_P, atol=1e-12)
    # n scales with the inverse lever arm; m stays 1/2
    A, _, _ = gyro_aided_matrices(paper001_array(lever_arm_m=0.02))
    np.testing.assert_allclose(A[3:], PRINTED_G[3:] / 0.02, rtol=1e-12)
    np.testing.assert_allclose(A[:3], PRINTED_G[:3], atol=1e-12)
    with pytest.raises(ValueError, match="must be 0.5"):
        paper001_gain_matrix(0.4, 0.25)
    with pytest.raises(ArrayModelError, match="must be 0.5"):
        paper001_array(m_m=0.3)


def test_eq10_angular_acceleration_is_free_of_gravity():
    """Eqs. 10-11: the ω̇ rows sum to zero per sensing direction, so a uniform field cancels."""
    for direction in range(3):
        assert np.allclose(PRINTED_G[3:, direction] + PRINTED_G[3:, direction + 3], 0.0)


@pytest.mark.parametrize("make_array", [
    lambda: paper001_array(lever_arm_m=0.03),
    lambda: SensorArray(cube_array(noise_std_mps2=0.05).accelerometers, "cube+gyro", gyroscope=Gyroscope(0.01)),
])
def test_gyro_aided_noise_free_recovery(make_array):
    arr = make_array()
    log = analytic_log(arr, sines(amp=(8.0, 6.0, 9.0), offset=(2, -3, 1)), duration_s=1.0, gyro=True)
    est = make_estimator("gyro-aided").estimate(log).motion
    np.testing.assert_allclose(est.omega_b_radps, log.truth.omega_b_radps, atol=0)
    np.testing.assert_allclose(est.omega_dot_b_radps2, log.truth.omega_dot_b_radps2, atol=1e-9)
    np.testing.assert_allclose(est.specific_force_b_mps2, log.truth.specific_force_b_mps2, atol=1e-11)


def test_gyro_aided_noise_scaling_and_sigma():
    arr = paper001_array(lever_arm_m=0.03, noise_std_mps2=0.07)
    log = analytic_log(arr, sines(offset=(1, 1, 1)), duration_s=4.0, gyro=True)
    truth = log.truth
    rng = np.random.default_rng(2)
    rms = []
    for sd in (0.02, 0.04):
        noisy = log.replace(accel_mps2=log.accel_mps2 + sd * rng.standard_normal(log.accel_mps2.shape))
        x = gyro_aided_solve(arr, noisy.accel_mps2, noisy.gyro_b_radps)
        rms.append(np.sqrt(np.mean((x[:, 3:] - truth.omega_dot_b_radps2) ** 2, axis=0)))
    np.testing.assert_allclose(rms[1] / rms[0], 2.0, rtol=0.1)


def test_gyro_aided_sigma_closed_form_and_monte_carlo():
    L, sd_a, sd_g = 0.03, 0.07, 0.01
    arr = paper001_array(lever_arm_m=L, noise_std_mps2=sd_a)
    # at rest: eq. 9 gives σ(f) = m σ √2 = σ/√2 and σ(ω̇) = n σ √6 with n = 1/(4L)
    still = analytic_log(arr, lambda t: (np.zeros((t.size, 3)), np.zeros((t.size, 3))), duration_s=0.02, gyro=True)
    est = make_estimator("gyro-aided", compute_sigma=True).estimate(still).motion
    np.testing.assert_allclose(est.sigma["specific_force_b_mps2"], sd_a / np.sqrt(2), rtol=1e-12)
    np.testing.assert_allclose(est.sigma["omega_dot_b_radps2"], np.sqrt(6) * sd_a / (4 * L), rtol=1e-12)
    np.testing.assert_allclose(est.sigma["omega_b_radps"], sd_g)
    # spinning: gyro noise enters through W q(ω_m); first-order sigma vs Monte Carlo
    w = np.array([[6.0, -4.0, 5.0]])
    readings = arr.predict_readings([[0.2, 0.1, 9.8]], [[3.0, 1.0, -2.0]], w)
    rng = np.random.default_rng(8)
    n = 20000
    gyro = w + sd_g * rng.standard_normal((n, 3))
    x = gyro_aided_solve(arr, readings + sd_a * rng.standard_normal((n, 6)), gyro)
    one = still.replace(timestamps_ns=still.timestamps_ns[:1], accel_mps2=readings, gyro_b_radps=w, truth=None)
    sig = make_estimator("gyro-aided", compute_sigma=True).estimate(one).motion.sigma
    np.testing.assert_allclose(x.std(axis=0)[:3], sig["specific_force_b_mps2"][0], rtol=0.05)
    np.testing.assert_allclose(x.std(axis=0)[3:], sig["omega_dot_b_radps2"][0], rtol=0.05)


def test_gyro_aided_applicability():
    est = make_estimator("gyro-aided")
    assert "no gyroscope" in est.applicable(cube_array())
    assert "at least 6" in est.applicable(SensorArray(single_triad().accelerometers, gyroscope=Gyroscope()))
    assert est.applicable(paper001_array()) is None
