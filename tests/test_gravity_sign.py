"""Sign of a steady rotation from the rotation of gravity in the body frame."""

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.simulate import SensorErrors, simulate
from gfimu.smoother.solve.gravity_sign import gravity_sign_score, steady_rotation


def test_score_is_minus_one_for_pure_gravity_and_right_sign():
    # body spinning at a constant 3 rad/s about its z axis, tilted 30° from vertical; f = -Rᵀ g exactly
    rate, tilt = 3.0, np.radians(30.0)
    t = np.arange(0, 2.0, 0.002)
    omega = np.tile([0.0, 0.0, rate], (t.size, 1))
    g_b = 9.80665 * np.column_stack([np.sin(tilt) * np.cos(-rate * t), np.sin(tilt) * np.sin(-rate * t),
                                     np.full(t.size, -np.cos(tilt))])
    f = -g_b
    s, n = gravity_sign_score(omega, f, np.diff(t))
    assert n == t.size - 2
    assert s == pytest.approx(-1.0, abs=1e-5)
    s_flipped, _ = gravity_sign_score(-omega, f, np.diff(t))
    assert s_flipped == pytest.approx(1.0, abs=1e-5)


def test_simulated_constant_turntable_is_steady_and_its_sign_shows_in_gravity():
    log = simulate("turntable-constant", cube_array(0.025, 0.07), rate_hz=500.0, duration_s=3.0,
                   noise=SensorErrors.none(), seed=1)
    truth = log.truth
    assert steady_rotation(truth.omega_b_radps, 0.03, 200)
    s, _ = gravity_sign_score(truth.omega_b_radps, truth.specific_force_b_mps2, log.dt_s)
    assert -1.1 < s < -0.85


def test_reversal_is_not_steady():
    log = simulate("reversal", cube_array(0.025, 0.07), rate_hz=500.0, duration_s=3.0, noise=SensorErrors.none(), seed=1)
    assert not steady_rotation(log.truth.omega_b_radps, 0.03, 200)


def test_no_usable_sample():
    s, n = gravity_sign_score(np.zeros((10, 3)), np.tile([0, 0, 9.81], (10, 1)), np.full(9, 0.01))
    assert n == 0 and np.isnan(s)


@pytest.mark.parametrize("seed", [0, 2, 3])
def test_smoothers_get_the_sign_of_a_constant_rotation(seed):
    """Seeds whose lever-arm-only initialisation picked the wrong sign (ω off by 2 × 180°/s)."""
    from gfimu.methods import make_estimator

    log = simulate("turntable-constant", cube_array(0.025, 0.07), rate_hz=500.0, duration_s=3.0, seed=seed)
    for method in ("smoother", "fixed-lag"):
        est = make_estimator(method).estimate(log).motion
        err = est.omega_b_radps - log.truth.omega_b_radps
        assert np.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.05, method
