"""Local restarts of the robust smoother's solution on the other branches of ω (gfimu.smoother.solve.restarts)."""

from dataclasses import replace

import numpy as np

from gfimu.array import mimu4444_array
from gfimu.simulate import simulate
from gfimu.smoother.solve import restarts
from gfimu.smoother.solve.banded import solve_reweighted
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.model.layout import OMEGA, OMEGA_DOT

ROBUST = SmootherOptions(robust_loss="cauchy", accel_robust_threshold=2.0, process_robust_threshold=2.0,
                         omega_dot_random_walk_radps2_per_sqrt_s=300.0, window_s=None)


def _solved(log, options, start):
    problem = SmootherProblem.of(log, options)
    return problem, solve_reweighted(problem, start, options.batch, warm=True)


def test_branches_keep_a_planar_arrays_readings():
    """ω sign-flipped (ω̇ kept) and ω mirrored through the board plane (ω̇ moved) predict the same
    readings of a planar array as ω itself (MIMU4444: sensors ±1 mm out of the plane, so nearly)."""
    array = mimu4444_array()
    log = simulate("random3d", array, rate_hz=200.0, duration_s=1.0, seed=2)
    problem = SmootherProblem.of(log, ROBUST)
    t = log.truth
    X = np.hstack([t.omega_b_radps, t.omega_dot_b_radps2, t.specific_force_b_mps2])
    rows = restarts.FrozenObjective(problem).rows
    from gfimu.factors import accelerometer

    def predict(Y):
        return accelerometer.accelerometer_prediction(Y[:, 0:3], Y[:, 3:6], Y[:, 6:9], rows)

    n = restarts.plane_normal(problem.all_positions_m)
    assert abs(abs(n[2]) - 1.0) < 1e-3
    base = predict(X)
    assert np.max(np.abs(predict(restarts.flipped(X, n)) - base)) < 1e-9
    # the out-of-plane offsets of the board (about 1 mm) leave a small misfit, against readings of
    # tens of m/s²
    assert np.max(np.abs(predict(restarts.mirrored(X, n)) - base)) < 0.05 * np.max(np.abs(base))


def test_a_short_run_on_the_sign_flipped_branch_is_restarted():
    """A 2-sample run of the solution moved to -ω at a fast rotation stays there under the robust
    Levenberg-Marquardt (a local minimum: the Cauchy loss on the two large steps at its ends barely
    pulls); the restarts find the run, move it back and lower the robust objective."""
    array = mimu4444_array()
    log = simulate("random3d", array, rate_hz=200.0, duration_s=2.0, seed=5)
    t = log.truth
    x_true = np.hstack([t.omega_b_radps, t.omega_dot_b_radps2, t.specific_force_b_mps2])
    problem, good = _solved(log, ROBUST, x_true)
    speed = np.linalg.norm(good.states[:, OMEGA], axis=1)
    k = int(np.argmax(speed[50:-50])) + 50
    bad_start = good.states.copy()
    bad_start[k:k + 2, OMEGA] *= -1.0
    problem_bad, bad = _solved(log, ROBUST, bad_start)
    # the robust solve keeps the run on the wrong branch
    assert np.all(np.sum(bad.states[k:k + 2, OMEGA] * good.states[k:k + 2, OMEGA], axis=1) < 0)
    before = restarts.FrozenObjective(problem_bad)(bad.states)
    fixed, tried, kept = restarts.branch_restarts(problem_bad, bad.states)
    after = restarts.FrozenObjective(problem_bad)(fixed)
    assert tried >= 1 and kept >= 1
    assert after < before - 1.0, (before, after)
    err_bad = np.linalg.norm(bad.states[k:k + 2, OMEGA] - good.states[k:k + 2, OMEGA], axis=1)
    err_fixed = np.linalg.norm(fixed[k:k + 2, OMEGA] - good.states[k:k + 2, OMEGA], axis=1)
    assert np.all(err_fixed < 0.05 * err_bad), (err_bad, err_fixed)
    # the right solution itself is not moved
    same, _, kept_good = restarts.branch_restarts(problem, good.states)
    assert np.max(np.abs(same[:, OMEGA] - good.states[:, OMEGA])) < 0.05 * speed.max()


def test_restarts_do_not_apply_without_a_robust_motion_model():
    log = simulate("random3d", mimu4444_array(), rate_hz=200.0, duration_s=0.5, seed=1)
    problem = SmootherProblem.of(log, replace(ROBUST, process_robust_threshold=0.0))
    X = np.zeros((len(log), 9))
    out, tried, kept = restarts.branch_restarts(problem, X)
    assert out is X and tried == kept == 0
    assert not restarts.applies(problem)
    assert OMEGA_DOT == slice(3, 6)
