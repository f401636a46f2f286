"""σ of a gain common to every accelerometer axis, read off the log's stretches of gravity alone
(gfimu.smoother.solve.sigma_scale: gravity_steps, gravity_windows, common_gain_variance, common_gain_sd)."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gfimu.array import cube_array
from gfimu.io.units import STANDARD_GRAVITY_MPS2 as G0
from gfimu.rigid_body import quadratic_terms
from gfimu.smoother.solve import sigma_scale as ss

ARRAY = cube_array(0.05, 0.01)


def turning(n, h, omega_b, f_w):
    """States (n, 9) of a body turning at the constant rate ``omega_b`` (body axes) about a fixed axis while its
    specific force is the constant world vector ``f_w``: f_b(t) = R(t)ᵀ f_w, R(t) = exp(t [ω]×)."""
    t = np.arange(n) * h
    R = Rotation.from_rotvec(t[:, None] * np.asarray(omega_b)[None, :])
    f_b = R.inv().apply(np.asarray(f_w, dtype=float))
    return np.hstack([np.tile(omega_b, (n, 1)), np.zeros((n, 3)), f_b])


def test_gravity_alone_while_turning_gives_the_gain_exactly():
    h, k = 1e-3, 1.0007
    X = turning(2000, h, [3.0, -2.0, 4.0], [0.0, 0.0, k * G0])
    norm, change, turn = ss.gravity_steps(X, np.full(1999, h))
    assert np.max(np.abs(norm - k * G0)) < 1e-12 * G0  # |f| is the same at every sample
    # the midpoint rule's error per step is h³ |ω|³ |f| / 12 at most: 1e-9 · 125 · 9.8 / 12
    assert np.max(np.linalg.norm(change, axis=1)) < h ** 3 * 5.4 ** 3 * k * G0 / 12 * 1.01
    W = ss._gravity_window_steps(np.full(1999, h))
    assert W == 250
    windows = ss.gravity_windows(norm, change, turn, W)
    assert len(windows) == 1999 // 250  # every whole stretch; the trailing 249 steps are not one
    assert windows[:, 0] == pytest.approx(k * G0, rel=1e-12)
    # no scatter: the variance is (k − 1)² itself (to the rounding of k̂ − 1, ~1e-16 / 7e-4)
    assert ss.common_gain_variance(windows) == pytest.approx((k - 1.0) ** 2, rel=1e-9)
    sd = ss.common_gain_sd(X[:3], (k - 1.0) ** 2)
    assert sd[:, 0:3] == pytest.approx(np.abs(X[:3, 0:3]) * (k - 1.0) / 2, rel=1e-12)  # ω ∝ √k: δω = ω δk / 2
    assert sd[:, 6:9] == pytest.approx(np.abs(X[:3, 6:9]) * (k - 1.0), rel=1e-12)  # f ∝ k


def test_a_specific_force_that_moves_in_the_world_is_not_gravity():
    h = 1e-3
    n = 2000
    t = np.arange(n) * h
    R = Rotation.from_rotvec(t[:, None] * np.array([1.0, 0.0, 2.0]))
    X = turning(n, h, [1.0, 0.0, 2.0], [0.0, 0.0, G0])
    taken = ss.gravity_windows(*ss.gravity_steps(X, np.full(n - 1, h)), 250)
    assert len(taken) == 1999 // 250  # gravity alone, turning across it
    # plus a linear acceleration of 0.5 m/s² swinging at 2 Hz along x of the world: it moves by up to 0.5 m/s²
    # (5 % of g) within 0.25 s
    X[:, 6:9] += R.inv().apply(np.outer(0.5 * np.sin(2 * np.pi * 2.0 * t), [1.0, 0.0, 0.0]))
    norm, change, turn = ss.gravity_steps(X, np.full(n - 1, h))
    assert len(ss.gravity_windows(norm, change, turn, 250)) == 0
    # a steady specific force 2 % above the standard gravity: a linear acceleration, not a gain
    X = turning(n, h, [0.0, 1.0, 2.0], [0.0, 0.0, 1.02 * G0])
    norm, change, turn = ss.gravity_steps(X, np.full(n - 1, h))
    assert len(ss.gravity_windows(norm, change, turn, 250)) == 0
    X = turning(n, h, [0.0, 1.0, 2.0], [0.0, 0.0, 1.009 * G0])
    norm, change, turn = ss.gravity_steps(X, np.full(n - 1, h))
    assert len(ss.gravity_windows(norm, change, turn, 250)) == 1999 // 250
    # at rest, or turning about f only (a turntable whose axis is vertical), a steady linear acceleration
    # would read the same: not taken
    for omega in ([0.0, 0.0, 0.0], [0.0, 0.0, 3.0]):
        X = turning(n, h, omega, [0.0, 0.0, 1.001 * G0])
        assert len(ss.gravity_windows(*ss.gravity_steps(X, np.full(n - 1, h)), 250)) == 0
    # turning across f by 0.06 rad within the stretch at least: taken (0.25 rad/s over 0.25 s: 0.0625)
    X = turning(n, h, [0.25, 0.0, 0.0], [0.0, 0.0, 1.001 * G0])
    assert len(ss.gravity_windows(*ss.gravity_steps(X, np.full(n - 1, h)), 250)) == 1999 // 250
    # free fall: |f| ~ 0, nothing to read a scale from
    X[:, 6:9] = 0.0
    norm, change, turn = ss.gravity_steps(X, np.full(n - 1, h))
    assert len(ss.gravity_windows(norm, change, turn, 250)) == 0


@pytest.mark.parametrize("k", [1.0, 1.002])
def test_noise_of_known_level_gives_the_gain_less_its_own_scatter(k):
    """White noise of std s on each component of f̂: |f̂| scatters by s about k g0 (to s²/g0), each stretch's
    mean by s/√W, k̂ by s/(g0 √(K W)); var_k = (k̂ − 1)² − that scatter², so its expectation is (k − 1)²."""
    rng = np.random.default_rng(5)
    h, s, n = 1e-3, 0.01, 20001
    X = turning(n, h, [1.0, 0.5, -2.0], [0.0, 0.0, k * G0])
    X[:, 6:9] += rng.normal(0.0, s, (n, 3))
    norm, change, turn = ss.gravity_steps(X, np.full(n - 1, h))
    windows = ss.gravity_windows(norm, change, turn, 250)
    assert len(windows) == 80
    # the step's size averages two samples: its variance is s²/2 and the neighbours' sizes correlate
    # (lag 1: ½): the stretch's mean has about 2 s²/2 / W, which the steps' own variance / W understates by 2
    u = s / (G0 * math.sqrt(80 * 250))
    var = ss.common_gain_variance(windows)
    assert math.sqrt(var) == pytest.approx(k - 1.0, abs=5 * u)


def test_the_running_scale_reads_the_same_gain_as_the_batch_one():
    h, k, n = 2e-3, 1.001, 1500
    rng = np.random.default_rng(7)
    X = turning(n, h, [2.0, 1.0, 1.5], [0.0, 0.0, k * G0])
    X[:, 6:9] += rng.normal(0.0, 0.003, (n, 3))
    S = ARRAY.structure_matrix()
    y = np.hstack([X[:, 6:9], X[:, 3:6], quadratic_terms(X[:, 0:3])]) @ S.T
    sd = np.full((n, 9), 1e-3)
    noise = np.full(12, 0.01)
    batch = ss.calibrated_sigma(ARRAY, y, X, sd, noise, dt_s=np.full(n - 1, h))
    plain = ss.calibrated_sigma(ARRAY, y, X, sd, noise)
    norm, change, turn = ss.gravity_steps(X, np.full(n - 1, h))
    var = ss.common_gain_variance(ss.gravity_windows(norm, change, turn, ss._gravity_window_steps(np.full(n - 1, h))))
    assert var == pytest.approx((k - 1.0) ** 2, rel=0.05)
    assert batch ** 2 - plain ** 2 == pytest.approx(ss.common_gain_sd(X, var) ** 2, rel=1e-9, abs=1e-15)
    running = ss.RunningSigmaScale(ARRAY)
    seen = []
    for i in range(n):
        running.scaled(y[i], X[i], sd[i], noise, None, i * h)
        seen.append(running.gain.variance)
    assert running.gain.variance == pytest.approx(var, rel=1e-9)  # the same stretches, causal: known at the end
    steps = ss._gravity_window_steps(np.full(1, h))
    assert np.all(np.array(seen[:steps]) == 0.0) and seen[steps] > 0  # nothing before the first stretch ends


def test_a_seeded_stretch_gives_its_gain_at_once_and_is_not_counted_twice():
    """The fixed-lag smoother's first stretch, solved at once (its batch solution), seeds the running gain: its
    stretches count before any of its rows is given out (the variance the batch rule gives on those states), and
    when the same rows then pass one by one they are not counted again; the stretches after it are."""
    h, k, n = 2e-3, 1.001, 1500
    rng = np.random.default_rng(8)
    X = turning(n, h, [2.0, 1.0, 1.5], [0.0, 0.0, k * G0])
    X[:, 6:9] += rng.normal(0.0, 0.003, (n, 3))
    t = np.arange(n) * h
    steps = ss._gravity_window_steps(np.full(1, h))
    first = 3 * steps + 40  # the seeded stretch: three whole stretches and a part
    gain = ss.RunningGain(ARRAY)
    gain.seed(t[:first], X[:first])
    norm, change, turn = ss.gravity_steps(X[:first], np.diff(t[:first]))
    seeded = ss.common_gain_variance(ss.gravity_windows(norm, change, turn, steps))
    assert len(gain.windows) == 3 and gain.variance == seeded > 0
    for i in range(first):
        gain.take(X[i], t[i])
    assert len(gain.windows) == 3 and gain.variance == seeded  # the same rows: not counted again
    for i in range(first, n):
        gain.take(X[i], t[i])
    plain = ss.RunningGain(ARRAY)  # no seed: every stretch counted as it passes
    for i in range(n):
        plain.take(X[i], t[i])
    assert len(gain.windows) == len(plain.windows) == (n - 1) // steps
    assert gain.variance == pytest.approx(plain.variance, rel=1e-12)
