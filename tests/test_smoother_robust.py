"""Robust (Huber / Cauchy IRLS) re-weighting of the batch smoother: weights, outlier rejection, defaults."""

import numpy as np
import pytest

from gfimu.smoother.batch.engine import BatchSmootherEstimator
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.solve.banded import robust_reweighted

from test_smoother_batch_tuning import CUBE, omega_rmse, process_model_log


def test_huber_and_cauchy_weights_of_accelerometer_axes():
    """With states at the truth of a noise-free log plus one corrupted reading, only that axis is
    down-weighted, by the Huber weight c/|e| or the Cauchy weight 1/(1 + (e/c)²) of its whitened error."""
    log = process_model_log([30.0, 30.0, 30.0], 30.0, duration_s=0.2)
    t = log.truth
    y = CUBE.predict_readings(t.specific_force_b_mps2, t.omega_dot_b_radps2, t.omega_b_radps)
    y[7, 4] += 0.7  # 10 sigma
    log = log.replace(accel_mps2=y)
    states = np.hstack([t.omega_b_radps, t.omega_dot_b_radps2, t.specific_force_b_mps2])
    for loss, expected in (("huber", 2.0 / 10.0), ("cauchy", 1.0 / (1.0 + 25.0))):
        p = SmootherProblem.of(log, SmootherOptions(robust_loss=loss, accel_robust_threshold=2.0))
        p = robust_reweighted(p, states)
        ratio = (p.noise.accel.sigma[None, :] / p.noise.accel.per_sample) ** 2  # = weight
        assert ratio[7, 4] == pytest.approx(expected, rel=1e-9)
        ratio[7, 4] = 1.0
        assert np.allclose(ratio, 1.0, atol=1e-12)
        p = robust_reweighted(p, states)  # idempotent: weights come from the base noise
        assert (p.noise.accel.sigma[4] / p.noise.accel.per_sample[7, 4]) ** 2 == pytest.approx(expected, rel=1e-9)


def test_process_weights_follow_the_step_residual():
    """A jump of ω between two samples (a sudden jerk) gets the Huber weight of its whitened step
    residual; the other steps keep weight 1, and the original sigmas are restored before re-weighting."""
    log = process_model_log([30.0, 30.0, 30.0], 30.0, duration_s=0.2)
    t = log.truth
    states = np.hstack([t.omega_b_radps, t.omega_dot_b_radps2, t.specific_force_b_mps2])
    p = SmootherProblem.of(log, SmootherOptions(process_robust_threshold=3.0))
    s0 = p.noise.motion.trapezoid_sigma.copy()
    states[20:, 0] += 50.0 * s0[19]  # ω_x jumps between samples 19 and 20
    p = robust_reweighted(p, states)
    w = (s0 / p.noise.motion.trapezoid_sigma) ** 2
    big = np.abs(w - 1.0) > 1e-12
    assert np.nonzero(big)[0].tolist() == [19]
    # the jump dominates its step: whitened rms over the 6 rows ≈ 50 / sqrt(6)
    assert w[19] == pytest.approx(3.0 / (50.0 / np.sqrt(6.0)), rel=0.05)
    assert np.allclose((s0 / p.noise.motion.trapezoid_sigma) ** 2, (p.noise.motion.start()[1] / p.noise.motion.omega_dot_step_sigma) ** 2)
    p = robust_reweighted(p, np.hstack([t.omega_b_radps, t.omega_dot_b_radps2, t.specific_force_b_mps2]))
    assert np.all((s0 / p.noise.motion.trapezoid_sigma) ** 2 > 0.99)


def test_robust_accelerometer_loss_rejects_gross_outliers():
    """Simulated cube log with 1 % of the readings hit by 30σ spikes: the Huber-weighted smoother
    is much closer to the truth than the Gaussian one, and the default options are not robust."""
    log = process_model_log([300.0, 300.0, 300.0], 30.0, duration_s=2.0, seed=3)
    rng = np.random.default_rng(5)
    y = log.accel_mps2.copy()
    hit = rng.random(y.shape) < 0.01
    y[hit] += rng.choice([-1.0, 1.0], size=int(hit.sum())) * 30 * 0.07
    log = log.replace(accel_mps2=y)
    common = dict(tune_process_noise=False, omega_dot_random_walk_radps2_per_sqrt_s=300.0,
                  specific_force_random_walk_mps2_per_sqrt_s=30.0, window_s=None)
    gauss = omega_rmse(BatchSmootherEstimator(**common, auto_model=False).estimate(log).motion, log.truth)
    robust = omega_rmse(BatchSmootherEstimator(**common, auto_model=False, accel_robust_threshold=2.0,
                                               reweight_iterations=4).estimate(log).motion, log.truth)
    print(f"ω RMSE Gaussian {gauss:.4f}, Huber {robust:.4f} rad/s")
    assert robust < 0.8 * gauss, (robust, gauss)
    assert not SmootherOptions().robust and not BatchSmootherEstimator().robust
    # the default model check sees the spikes (heavy tails) and switches the robust losses on itself
    est = BatchSmootherEstimator(**common).estimate(log)
    chosen = omega_rmse(est.motion, log.truth)
    check = est.report.model_check
    assert not check.consistent and check.tail_share > 0.006
    assert chosen < 0.8 * gauss, (chosen, gauss)


def test_robust_options_are_checked():
    with pytest.raises(ValueError, match="robust_loss"):
        SmootherOptions(robust_loss="tukey")
    with pytest.raises(ValueError, match="process_robust_threshold"):
        SmootherOptions(process_robust_threshold=-1.0)


def test_sign_chain_recovers_a_reversal_through_zero():
    """ω slowing through zero and reversing at 62.5 Hz, given as per-sample estimates whose sign was
    chosen to bounce back (ω·e > 0 always) and with random flips, plus noise of 1 rad/s on ω and
    50 rad/s² on ω̇: the dynamic programme returns the true signs everywhere |ω| > 2 rad/s."""
    from gfimu.smoother.solve.initialise import sign_chain

    rng = np.random.default_rng(7)
    h = 0.016
    t = np.arange(300) * h
    axis = np.array([0.6, -0.48, 0.64])
    omega = (40.0 * np.cos(2.5 * t))[:, None] * axis + np.array([0.0, 3.0, 0.0]) * np.sin(7 * t)[:, None]
    omega_dot = np.gradient(omega, t, axis=0)
    bounced = omega * np.sign(omega @ axis)[:, None]
    flips = np.where(rng.random(len(t)) < 0.2, -1.0, 1.0)
    given = bounced * flips[:, None] + rng.normal(size=omega.shape)
    s = sign_chain(given, omega_dot + 50.0 * rng.normal(size=omega.shape), np.full(len(t) - 1, h))
    fixed = given * s[:, None]
    big = np.linalg.norm(omega, axis=1) > 2.0
    assert np.all(np.sum(fixed[big] * omega[big], axis=1) > 0)
    assert np.mean(np.sum(given[big] * omega[big], axis=1) > 0) < 0.7  # the input was far off
    assert sign_chain(np.zeros((1, 3)), np.zeros((1, 3)), np.zeros(0)).tolist() == [1.0]


def test_sign_chain_choices_are_numpys_argmin():
    """The sign chain's recursion on plain floats makes the choices of the two-state recursion written with
    numpy (argmin: the first of equal costs, a NaN before a number): the same signs on random sequences, on
    sequences with NaN and infinite ω, and on ties (ω constant, ω̇ zero), robust or not."""
    from gfimu.smoother.solve.initialise import _scale_of_steps, _step_costs, sign_chain

    def with_numpy(omega, omega_dot, dt, scale):
        step = _step_costs(omega, omega_dot, dt)
        scale = _scale_of_steps(step) if scale == "data" else scale
        if scale is not None:
            step = scale**2 * np.log1p(step / scale**2)
        cost, back = np.zeros(2), np.zeros((len(omega) - 1, 2), dtype=np.int8)
        for k in range(len(omega) - 1):
            total = cost[:, None] + step[k]
            back[k] = np.argmin(total, axis=0)
            cost = total[back[k], [0, 1]]
        state, out = int(np.argmin(cost)), [0] * len(omega)
        out[-1] = state
        for k in range(len(omega) - 2, -1, -1):
            state = int(back[k, state])
            out[k] = state
        return np.where(np.array(out) == 0, 1.0, -1.0)

    rng = np.random.default_rng(11)
    for trial in range(60):
        n = int(rng.integers(2, 120))
        omega = rng.normal(size=(n, 3)) * [1e-3, 1.0, 100.0][trial % 3]
        omega_dot = rng.normal(size=(n, 3)) * [0.0, 1.0, 100.0][trial % 3]
        if trial % 4 == 1:
            omega[rng.integers(0, n, 3)] = [np.nan, np.inf, -np.inf][trial % 3]
        if trial % 5 == 2:
            omega[:], omega_dot[:] = 1.0, 0.0
        for scale in ("data", None, 0.5):
            with np.errstate(invalid="ignore", over="ignore"):
                np.testing.assert_array_equal(sign_chain(omega, omega_dot, np.full(n - 1, 0.01), scale),
                                              with_numpy(omega, omega_dot, np.full(n - 1, 0.01), scale))


def test_a_problem_is_frozen_and_reweighting_makes_a_new_one():
    """Nothing is set on a problem once built: a re-weighting returns a new problem whose noise levels
    differ where the weights say, the original keeps its own, and the levels' arrays are read-only."""
    log = process_model_log([30.0, 30.0, 30.0], 30.0, duration_s=0.2)
    t = log.truth
    states = np.hstack([t.omega_b_radps, t.omega_dot_b_radps2, t.specific_force_b_mps2])
    states[20:, 0] += 1.0  # one outlying step
    p = SmootherProblem.of(log, SmootherOptions(process_robust_threshold=3.0))
    before = p.noise.motion.trapezoid_sigma.copy()
    q = robust_reweighted(p, states)
    assert q is not p and q.log is p.log and q.groups is p.groups
    np.testing.assert_array_equal(p.noise.motion.trapezoid_sigma, before)
    assert q.noise.motion.trapezoid_sigma[19] > 2 * before[19] and np.array_equal(np.delete(q.noise.motion.trapezoid_sigma, 19), np.delete(before, 19))
    with pytest.raises(AttributeError, match="frozen"):
        p.noise = q.noise
    with pytest.raises(AttributeError):
        p.noise.motion.trapezoid_sigma = before
    with pytest.raises(AttributeError, match="frozen"):
        p.new_attribute = 1
    with pytest.raises(ValueError):
        p.noise.motion.trapezoid_sigma[0] = 1.0  # read-only
    assert p.with_noise(accel=p.noise.accel.scaled(2.0)).noise.accel.sigma[0] == 2 * p.noise.accel.sigma[0]
