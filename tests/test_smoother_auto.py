"""The smoother's model chosen from the log (gfimu.smoother.tuning.model_choice)."""

import numpy as np
import pytest

from gfimu.array import cube_array, random_array
from gfimu.estimators.ml import MLEstimator
from gfimu.simulate import simulate
from gfimu.smoother.tuning import model_choice as auto


def _with_extra_noise(log, slope, seed=1):
    wn = np.linalg.norm(log.truth.omega_b_radps, axis=1)
    rng = np.random.default_rng(seed)
    return log.replace(accel_mps2=log.accel_mps2 + rng.normal(size=log.accel_mps2.shape) * (slope * wn)[:, None])


@pytest.mark.parametrize("array", [cube_array(), random_array(8)], ids=["cube", "eight-triads"])
def test_consistent_logs_keep_the_gaussian_model(array):
    """White noise at the stated 0.07 m/s²: the check finds the readings consistent (ratio about 1,
    tail share near the Gaussian 6e-5, no slope)."""
    log = simulate("random3d", array, rate_hz=500.0, duration_s=3.0, seed=4)
    check = auto.check_model(log, MLEstimator().estimate(log).motion)
    assert check.consistent, check
    assert 0.8 < check.noise_ratio < 1.25 and check.tail_share < 0.002
    assert abs(check.noise_floor_mps2 - 0.07) < 0.01 and check.noise_slope_mps2_per_radps < 0.01


@pytest.mark.parametrize("array", [cube_array(), random_array(8)], ids=["cube", "eight-triads"])
def test_noise_growing_with_the_rate_is_measured(array):
    """Noise std sqrt(0.07² + (0.05 |ω|)²): the slope is recovered within 15 %, the floor within 25 %
    (binned by the per-sample estimate's noisy |ω|, the slowest bin reads high: measured 0.083-0.087)."""
    log = _with_extra_noise(simulate("random3d", array, rate_hz=500.0, duration_s=3.0, seed=4), 0.05)
    check = auto.check_model(log, MLEstimator().estimate(log).motion)
    assert not check.consistent and any("grows with" in r for r in check.reasons)
    assert abs(check.noise_slope_mps2_per_radps - 0.05) < 0.0075, check
    assert abs(check.noise_floor_mps2 - 0.07) < 0.0175, check


def test_noise_vs_rate_on_known_powers():
    """Residuals drawn with std sqrt(0.1² + (0.02 |ω|)²) on 15 degrees of freedom per sample (|ω| known
    exactly): σ₀ and s recovered within 5 %."""
    rng = np.random.default_rng(0)
    n, axes = 40000, 24
    omega = rng.normal(size=(n, 3)) * rng.uniform(0, 20, size=(n, 1))
    std = np.sqrt(0.1**2 + (0.02 * np.linalg.norm(omega, axis=1)) ** 2)
    # a 9-unknown fit leaves 15 of 24 dimensions: residual power is χ²_15 scaled by (15/24) σ²
    r = rng.normal(size=(n, axes - 9)) * std[:, None]
    r = np.hstack([r, np.zeros((n, 9))])
    floor, slope = auto.noise_vs_rate(r, omega, axes / (axes - 9))
    assert abs(floor - 0.1) < 0.005 and abs(slope - 0.02) < 0.001, (floor, slope)


def test_motion_densities_of_a_random_walk_that_rests_half_the_time():
    """ω̇ a random walk of density 400 rad/s²/√s during motion and still in between, plus white
    estimate noise: the density of the motion is recovered within 15 %, not diluted by the rest."""
    rng = np.random.default_rng(3)
    n, h = 20000, 0.002
    moving = (np.arange(n) // 2500) % 2 == 1
    steps = rng.normal(size=(n, 3)) * 400.0 * np.sqrt(h) * moving[:, None]
    omega_dot = np.cumsum(steps, axis=0)
    force = np.cumsum(rng.normal(size=(n, 3)) * 30.0 * np.sqrt(h) * moving[:, None], axis=0)
    v_jerk, v_force = np.full((n, 3), 0.5**2), np.full((n, 3), 0.01**2)
    states = np.hstack([np.zeros((n, 3)), omega_dot + rng.normal(size=(n, 3)) * 0.5,
                        force + rng.normal(size=(n, 3)) * 0.01])
    q_jerk, q_force = auto.motion_densities(states, np.full(n - 1, h), v_jerk, v_force)
    np.testing.assert_allclose(q_jerk, 400.0, rtol=0.15)
    np.testing.assert_allclose(q_force, 30.0, rtol=0.15)


def test_misfit_options_and_describe():
    check = auto.ModelCheck(False, 100, 5.0, 0.1, 0.2, 0.03, 20.0, 0.05, ("x",))
    from gfimu.smoother.model.problem import SmootherOptions

    chosen = auto.misfit_options(SmootherOptions().model_groups, check)
    model, solve, batch_model, tuning = chosen.model, chosen.solve, chosen.batch_model, chosen.tuning
    assert solve.initialisation == "ml" and solve.ml_sign_chain and batch_model.robust and not tuning.tune_process_noise
    assert batch_model.accel_noise_slope_mps2_per_radps == 0.03 and model.default_accel_noise_std_mps2 == 0.2
    assert "disagree" in check.describe() and "0.03" in check.describe()


def test_local_density_factors_rest_and_motion():
    """ω̇ resting, then a random walk of the motion density: factor 1 in the motion, the noise's
    level (about σ√2 / (q √h) per axis) at rest, a ramp of one period between."""
    rng = np.random.default_rng(2)
    n, h, q = 4000, 0.002, 400.0
    moving = np.arange(n) >= 2000
    omega_dot = np.cumsum(rng.normal(size=(n, 3)) * q * np.sqrt(h) * moving[:, None], axis=0)
    sigma = 0.5
    states = np.hstack([np.zeros((n, 3)), omega_dot + rng.normal(size=(n, 3)) * sigma, np.zeros((n, 3))])
    f = auto.local_density_factors(states, np.full(n - 1, h), np.full((n, 3), sigma**2), q, period_s=0.5)
    rest_level = sigma * np.sqrt(2.0) / (q * np.sqrt(h))
    assert np.all(f <= 1.0)
    np.testing.assert_allclose(np.median(f[:1500]), rest_level, rtol=0.1)
    assert np.median(f[2500:]) > 0.85


def test_residual_only_cost_equals_the_cost_of_the_terms():
    """The cost evaluated from the residuals alone equals half the squared whitened residuals of every
    factor (with constant and with motion-dependent accelerometer noise)."""
    from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem

    log = simulate("random3d", cube_array(), rate_hz=500.0, duration_s=1.0, seed=2)
    problem = SmootherProblem.of(log, SmootherOptions())
    states = np.random.default_rng(0).normal(size=(len(log), 9))
    params = np.zeros(0)

    def from_terms():
        return 0.5 * sum(float(np.sum(t.residual**2)) for t in problem.terms(states, params))

    np.testing.assert_allclose(problem.cost(states, params), from_terms(), rtol=1e-12)
    problem = problem.with_noise(accel=problem.noise.accel.motion_dependent(states[:, 0:3], 0.03))
    np.testing.assert_allclose(problem.cost(states, params), from_terms(), rtol=1e-12)


@pytest.mark.slow
def test_noise_chosen_on_the_middle_of_the_window_keeps_the_accuracy():
    """40 s of random motion at 500 Hz (two solve windows): the process noise chosen on the middle
    10 s of each window gives the ω RMSE of the choice on the whole window within 10 %."""
    from gfimu.smoother.batch.engine import BatchSmootherEstimator

    log = simulate("random3d", cube_array(0.025), rate_hz=500.0, duration_s=40.0, seed=3)

    def rmse(motion):
        return float(np.sqrt(np.mean(np.sum((motion.omega_b_radps - log.truth.omega_b_radps) ** 2, axis=1))))

    span = rmse(BatchSmootherEstimator().estimate(log).motion)
    whole = rmse(BatchSmootherEstimator(tune_span_s=None).estimate(log).motion)
    assert span < 1.1 * whole, (span, whole)


def test_motion_density_of_a_stretch_shorter_than_the_motion_period():
    """A stretch shorter than MOTION_PERIOD_S (0.3 s at 20 kHz, as the stream's cut first stretch is): the
    density of a random walk of ω̇ of known density is found from its steps, as on a long stretch."""
    from gfimu.smoother.tuning.model_choice import MOTION_PERIOD_S, motion_densities

    rate, n, q = 20000.0, 6000, 300.0
    assert n / rate < MOTION_PERIOD_S
    rng = np.random.default_rng(2)
    h = np.full(n - 1, 1.0 / rate)
    X = np.zeros((n, 9))
    X[:, 3:6] = np.cumsum(rng.normal(0.0, q * np.sqrt(1.0 / rate), (n, 3)), axis=0)
    noise = np.full((n, 3), 1e-12)
    jerk, _, found = motion_densities(X, h, noise, noise, with_motion=True)
    assert found
    # the robust scale of n Gaussian steps: relative spread about 1.2 / sqrt(n) per axis
    np.testing.assert_allclose(jerk, q, rtol=8 * 1.2 / np.sqrt(n))
