"""The fixed-lag window's branches decided again before the oldest state leaves (WindowFilter.settle):
an interior run of states moved onto another branch of the readings' ambiguity, the decision that
moves it back with the lag's data on both sides, and the cases where nothing is decided."""

from __future__ import annotations

import numpy as np
import pytest

from gfimu.array import mimu4444_array
from gfimu.simulate import simulate
from gfimu.smoother.stream.window_filter import (
    OUTLYING_STEP2,
    SETTLE_FALSE_ALARM,
    WindowFilter,
)
from gfimu.smoother.stream.array_model import ArrayModel
from gfimu.smoother.model.problem import SmootherOptions
from gfimu.smoother.solve.restarts import branch

RATE_HZ = 62.5


def _stream(seed: int = 1, gyro: bool = False):
    """Hand-like motion seen by the MIMU4444 board (nearly planar: ±1 mm out of its plane) at its rate."""
    array = mimu4444_array(0.05, with_gyroscope=gyro)
    return simulate("random3d", array, rate_hz=RATE_HZ, duration_s=2.0, seed=seed, omega_rms_radps=6.0,
                    max_frequency_hz=2.0)


def _window(log, n: int, gyro: bool = False) -> WindowFilter:
    """A window of the first ``n`` samples, solved state by state as the stream solves them."""
    filt = WindowFilter(ArrayModel(log.array, SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=200.0).model_groups),
                        capacity=256, branches=True)
    g = log.gyro_b_radps if gyro else None
    start = np.r_[log.truth.omega_b_radps[0], np.zeros(6)]
    filt.begin(0, int(log.timestamps_ns[0]), log.accel_mps2[0], None if g is None else g[0], start=start)
    for k in range(1, n):
        h = (log.timestamps_ns[k] - log.timestamps_ns[k - 1]) * 1e-9
        filt.advance(k, h, int(log.timestamps_ns[k]), log.accel_mps2[k], None if g is None else g[k])
    return filt


def test_the_outlying_step_is_the_chi2_quantile():
    from scipy.stats import chi2

    assert OUTLYING_STEP2 == pytest.approx(chi2.ppf(1.0 - SETTLE_FALSE_ALARM, 6), rel=1e-9)


def test_moving_an_interior_run_leaves_the_rest_of_the_window():
    log = _stream()
    filt = _window(log, 40)
    filt._flush()  # the lazily updated old states brought up to date, as a move does first
    mean = np.array([filt.mean(k) for k in range(40)])
    cross = filt._cross[filt._lo:filt._hi].copy()
    P = filt._P.copy()
    filt.move_branch(20, 3, 24)
    moved = np.array([filt.mean(k) for k in range(40)])
    w, dw = branch(3, mean[20:24, 0:3], mean[20:24, 3:6], filt._normal)
    np.testing.assert_allclose(moved[20:24, 0:3], w)
    np.testing.assert_allclose(moved[20:24, 3:6], dw)
    np.testing.assert_allclose(moved[:20], mean[:20])
    np.testing.assert_allclose(moved[24:], mean[24:])
    np.testing.assert_allclose(filt._P, P)  # the newest state did not move
    np.testing.assert_allclose(filt._cross[filt._lo + 24:filt._hi], cross[24:])
    filt.move_branch(20, 3, 24)
    np.testing.assert_allclose(np.array([filt.mean(k) for k in range(40)]), mean, atol=1e-9)
    np.testing.assert_allclose(filt._cross[filt._lo:filt._hi], cross, atol=1e-9)


@pytest.mark.parametrize("kind", [1, 2, 3])
def test_a_run_on_another_branch_goes_back_when_its_first_state_leaves(kind):
    log = _stream()
    truth = log.truth.omega_b_radps
    filt = _window(log, 70)
    before = np.array([filt.mean(k)[0:3] for k in range(70)])
    # a run of four states where branch `kind` is far from the truth (ω well away from the plane for a mirror)
    apart = np.linalg.norm(branch(kind, truth, np.zeros_like(truth), filt._normal)[0] - truth, axis=1) > 3.0
    a = next(k for k in range(20, 50) if apart[k:k + 4].all())
    filt.move_branch(a, kind, a + 4)
    for _ in range(a - 1):  # the states before the run leave the window; its first follows the oldest
        assert filt.settle(lambda i: log.accel_mps2[filt._base + filt._lo + i]) == 0
        filt.drop_oldest()
    assert np.linalg.norm(filt.mean(a)[0:3] - truth[a]) > 3.0  # on the other branch
    assert filt.settle(lambda i: log.accel_mps2[a - 1 + i]) == 4
    assert filt.n_settled == 1
    after = np.array([filt.mean(k)[0:3] for k in range(a, a + 4)])
    # back on the branch of the truth, as close to it as the filter had the run before the move
    err_before = np.linalg.norm(before[a:a + 4] - truth[a:a + 4], axis=1)
    err_after = np.linalg.norm(after - truth[a:a + 4], axis=1)
    assert np.all(err_after < err_before + 0.05), (err_after, err_before)
    # the states after the run and the few re-solved with it are where they were
    np.testing.assert_allclose(np.array([filt.mean(k)[0:3] for k in range(a + 10, 70)]), before[a + 10:70], atol=1e-9)


def test_a_consistent_window_is_left_alone():
    log = _stream(seed=2)
    filt = _window(log, 100)
    before = np.array([filt.mean(k) for k in range(100)])
    for k in range(60):
        assert filt.settle(lambda i, k=k: log.accel_mps2[k + i]) == 0
        filt.drop_oldest()
    assert filt.n_settled == 0
    np.testing.assert_allclose(np.array([filt.mean(k) for k in range(60, 100)]), before[60:], atol=1e-9)


def test_nothing_is_decided_with_a_gyroscope():
    log = _stream(gyro=True)
    filt = _window(log, 60, gyro=True)
    filt.move_branch(30, 1, 34)
    for _ in range(29):
        filt.drop_oldest()
    assert filt.settle(lambda i: log.accel_mps2[29 + i]) == 0
    assert np.linalg.norm(filt.mean(30)[0:3] + log.truth.omega_b_radps[30]) < 1.0  # still flipped


def test_a_window_filtered_with_an_outgrown_model_is_solved_again_with_the_new_one():
    from dataclasses import replace

    from gfimu.array import cube_array
    from gfimu.smoother.stream.fixed_lag import FixedLagSmoother
    from gfimu.smoother.model.option_groups import ModelGroups
    from gfimu.smoother.stream.model_choice import StreamModel

    log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=200, duration_s=3.0, seed=5, omega_rms_radps=4.0)
    slow = SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=0.5)  # far below the motion's
    sm = FixedLagSmoother(log.array, slow.model_groups, lag_s=1.0, rate_hz=200, hold_max_s=0.0)  # rows come out at the lag
    for k in range(400):
        sm.push(log.timestamps_ns[k], log.accel_mps2[k])
    ks = [k for k, _ in sm._segment.window]
    truth = log.truth.omega_b_radps

    def window_error():
        return np.sqrt(np.mean([np.sum((sm._segment.engine.mean(k)[0:3] - truth[k]) ** 2) for k in ks]))

    before = window_error()
    fast = replace(slow, omega_dot_random_walk_radps2_per_sqrt_s=30.0)
    sm._use(StreamModel(ModelGroups.of(fast), 1.0, None, None, int(log.timestamps_ns[399]), 400))
    sm._replay_window()
    after = window_error()
    assert [k for k, _ in sm._segment.window] == ks  # the same states, none emitted
    assert after < 0.5 * before, (before, after)
    # and the stream goes on from the solved window
    upd = sm.push(log.timestamps_ns[400], log.accel_mps2[400])
    assert len(upd.smoothed) == 1 and upd.smoothed[0].timestamp_ns == log.timestamps_ns[ks[0]]
