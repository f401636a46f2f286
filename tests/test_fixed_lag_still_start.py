"""A segment whose first samples show the body at rest starts from ω = 0 (gfimu.smoother.solve.initialise.still_start,
FixedLagSmoother._still_start); one that starts moving is untouched."""

from unittest import mock

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.simulate import simulate
from gfimu.smoother.solve.initialise import STILL_Z, still_start
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator, FixedLagSmoother

SIGMA = 0.07


def _rest_readings(array, n, rng, omega=np.zeros(3), omega_dot=np.zeros(3), f=np.array([0.0, 0.0, 9.81])):
    S = array.structure_matrix()
    from gfimu.rigid_body import quadratic_terms

    z = np.concatenate([f, omega_dot, quadratic_terms(omega[None])[0]])
    y = np.tile(S @ z, (n, 1))
    return y + (rng.standard_normal(y.shape) * SIGMA if rng is not None else 0.0)


def test_noise_free_rest_gives_the_integrated_omega_dot_noise_as_the_prior_std():
    """Constant readings of a body at rest: still, with σ = σ_ω̇ T / √N, σ_ω̇ the RMS over the axes of the
    per-sample std of the fitted ω̇ (from (SᵀΣ⁻¹S)⁻¹), exactly."""
    array = cube_array(0.05, noise_std_mps2=SIGMA)
    S = array.structure_matrix()
    n, rate = 100, 500.0
    t = np.arange(n) / rate
    y = _rest_readings(array, n, None)
    sigma = np.full(S.shape[0], SIGMA)
    got = still_start(t, y, S, sigma)
    cov = np.linalg.inv((S / SIGMA).T @ (S / SIGMA))
    want = np.sqrt(np.mean(np.diag(cov)[3:6])) * t[-1] / np.sqrt(n)
    assert got == pytest.approx(want, rel=1e-12)
    # the cube: (SᵀS)⁻¹'s ω̇ diagonal is 1 / (8 r²) = 50 m⁻² at r = 5 cm, so σ_ω̇ = 0.07 √50
    assert got == pytest.approx(SIGMA * np.sqrt(50.0) * 0.198 / 10.0, rel=1e-9)


def test_white_noise_at_rest_is_still_and_rotation_or_turning_gravity_is_not():
    """At the stated noise a body at rest passes both χ² tests; a constant rotation of 0.7 rad/s (ω_z² =
    0.49 rad²/s², 7 times the std of its mean over 100 samples, 0.07 √100 / √100) fails the mean test;
    gravity turning at 0.2 rad/s (f_x drifts by 0.39 m/s² over 0.2 s: about 1000 above the variation's
    dof of 1188, against a margin of 3 √(2 · 1188) = 146) fails the variation test."""
    array = cube_array(0.05, noise_std_mps2=SIGMA)
    S = array.structure_matrix()
    sigma = np.full(S.shape[0], SIGMA)
    n = 100
    t = np.arange(n) / 500.0
    rng = np.random.default_rng(3)
    y = _rest_readings(array, n, rng)
    assert still_start(t, y, S, sigma) is not None
    y = _rest_readings(array, n, rng, omega=np.array([0.0, 0.0, 0.7]))
    assert still_start(t, y, S, sigma) is None
    angle = 0.2 * t
    f = 9.81 * np.column_stack([np.sin(angle), np.zeros(n), np.cos(angle)])
    y = np.vstack([_rest_readings(array, 1, None, f=fk)[0] for fk in f]) + rng.standard_normal((n, S.shape[0])) * SIGMA
    assert still_start(t, y, S, sigma) is None
    # readings twice as noisy as stated: χ² of the variation at 4 dof-units, far above dof + 3 √(2 dof)
    y = _rest_readings(array, n, rng)
    assert still_start(t, y + rng.standard_normal(y.shape) * SIGMA * np.sqrt(3.0), S, sigma) is None
    assert STILL_Z == 3.0


def test_no_test_without_a_full_rank_array_or_two_samples():
    array = cube_array(0.05, noise_std_mps2=SIGMA)
    S = array.structure_matrix()
    y = _rest_readings(array, 2, None)
    sigma = np.full(S.shape[0], SIGMA)
    assert still_start(np.zeros(1), y[:1], S, sigma) is None
    assert still_start(np.arange(2.0), y[:, :6], S[:6], sigma[:6]) is None


def _omega(log, still: bool):
    """The fixed-lag smoother's ω over ``log``, with the still start (``still``) or without it."""
    if still:
        return FixedLagEstimator().estimate(log).motion.omega_b_radps
    with mock.patch.object(FixedLagSmoother, "_still_start", lambda self, *args: None):
        return FixedLagEstimator().estimate(log).motion.omega_b_radps


def _rmse(est, truth):
    return float(np.sqrt(np.mean(np.sum((est - truth) ** 2, axis=1))))


@pytest.mark.slow
def test_a_log_that_starts_at_rest_starts_from_omega_zero_and_gains():
    """The real EuRoC V1_01_easy motion (at rest for its first second, then |ω| below 0.6 rad/s) through a
    10 cm cube at 0.07 m/s², 250 Hz, 8 s: the readings see ω only through q(ω) ~ |ω|², near the noise,
    so ω comes from integrating ω̇ from the start. Judged still from the data, the start prior ω = 0
    takes the ω RMSE (of the norm) down by more than 30 % (measured 0.146 to 0.092 rad/s), below imm's
    (0.124), which assumes the body at rest."""
    log = simulate("euroc", array=cube_array(0.05, noise_std_mps2=SIGMA), rate_hz=250.0, duration_s=8.0, seed=0)
    truth = log.truth.omega_b_radps
    sm = FixedLagEstimator().smoother(log.array, 250.0)
    for i in range(len(log)):
        sm.push(log.timestamps_ns[i], log.accel_mps2[i])
    sm.flush()
    assert len(sm.still_starts) == 1 and 0.0 < sm.still_starts[0] < 0.05
    before, after = _rmse(_omega(log, False), truth), _rmse(_omega(log, True), truth)
    from gfimu.methods import make_estimator

    imm = _rmse(make_estimator("imm").estimate_motion(log).omega_b_radps, truth)
    assert after < 0.7 * before
    assert after < imm


def test_a_log_that_starts_moving_is_unchanged():
    """Hand-held motion from the first sample (random3d, 200 Hz, 4 s): no still start, the same rows as
    with the still start switched off."""
    log = simulate("random3d", array=cube_array(0.05, noise_std_mps2=SIGMA), rate_hz=200.0, duration_s=4.0, seed=2)
    sm = FixedLagEstimator().smoother(log.array, 200.0)
    for i in range(len(log)):
        sm.push(log.timestamps_ns[i], log.accel_mps2[i])
    sm.flush()
    assert sm.still_starts == []
    np.testing.assert_array_equal(_omega(log, True), _omega(log, False))
