"""The fixed-lag smoother's model chosen from the stream (gfimu.smoother.stream.model_choice): the branch
group, the streaming branch chain on a constructed stream, a window moved onto another branch, the
local density and the stillness test."""

from __future__ import annotations

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.estimators.ml import MLEstimator
from gfimu.simulate import simulate
from gfimu.smoother.stream.window_filter import WindowFilter
from gfimu.smoother.stream.array_model import ArrayModel
from gfimu.smoother.tuning.model_choice import check_model
from gfimu.smoother.model.problem import SmootherOptions
from gfimu.smoother.stream.model_choice import LocalDensity, StreamSignChain, branch, is_still

NORMAL = np.array([0.0, 0.0, 1.0])


def test_the_four_branches_are_a_group_of_involutions():
    rng = np.random.default_rng(0)
    w, dw = rng.normal(size=3) * 5, rng.normal(size=3) * 50
    for a in range(4):
        wa, da = branch(a, w, dw, NORMAL)
        for b in range(4):
            wab, dab = branch(b, wa, da, NORMAL)
            wc, dc = branch(a ^ b, w, dw, NORMAL)
            np.testing.assert_allclose(wab, wc, atol=1e-12)
            np.testing.assert_allclose(dab, dc, atol=1e-12)
    wm, dm = branch(2, w, dw, NORMAL)
    assert wm[2] == pytest.approx(-w[2]) and np.allclose(wm[:2], w[:2])


def _rotation(n: int = 200, h: float = 0.01):
    """A rotation whose ω passes through zero and reverses (ω̇ keeps its sign), with its exact ω̇."""
    t = np.arange(n) * h
    omega = np.stack([3.0 - 6.0 * t, 1.0 + 0.5 * np.sin(3 * t), 2.0 - 4.0 * t], axis=1)
    omega_dot = np.stack([np.full(n, -6.0), 1.5 * np.cos(3 * t), np.full(n, -4.0)], axis=1)
    return (t * 1e9).astype(np.int64), omega, omega_dot


@pytest.mark.parametrize("kind", [1, 2, 3])
def test_the_chain_finds_a_run_on_another_branch_and_where_it_starts(kind):
    t_ns, omega, omega_dot = _rotation()
    start = 120
    chain = StreamSignChain(window=60, normal=NORMAL)
    moved = None
    for k in range(len(t_ns)):
        w, dw = (omega[k], omega_dot[k]) if k < start else branch(kind, omega[k], omega_dot[k], NORMAL)
        out = chain.push(k, int(t_ns[k]), w, dw, scale_radps=0.05, oldest_k=max(0, k - 50))
        if out is not None and moved is None:
            moved = (k, out)
    assert moved is not None
    k_found, (first, found_kind) = moved
    assert found_kind == kind and first == start and k_found - start < 10


def test_the_chain_keeps_a_consistent_stream():
    t_ns, omega, omega_dot = _rotation()
    chain = StreamSignChain(window=60, normal=NORMAL)
    assert all(chain.push(k, int(t_ns[k]), omega[k], omega_dot[k], 0.05, max(0, k - 50)) is None
               for k in range(len(t_ns)))
    assert chain.flips == 0


def test_moving_a_window_onto_a_branch_twice_gives_it_back():
    log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=200, duration_s=0.5, seed=1)
    filt = WindowFilter(ArrayModel(log.array, SmootherOptions().model_groups), capacity=64)
    filt._normal = NORMAL
    filt.start(0)
    filt.measure(log.accel_mps2[0])
    for k in range(1, 30):
        filt.predict(k, 0.005)
        filt.measure(log.accel_mps2[k])
    filt._flush()  # the older states brought up to date (as a mirror's move does first): stored = current
    mean = filt._mean[filt._lo:filt._hi].copy()
    cross = filt._cross[filt._lo:filt._hi].copy()
    P = filt._P.copy()
    filt.move_branch(10, 3)
    w, dw = branch(3, mean[10, 0:3], mean[10, 3:6], NORMAL)
    np.testing.assert_allclose(filt.mean(10)[0:3], w)
    np.testing.assert_allclose(filt.mean(10)[3:6], dw)
    np.testing.assert_allclose(filt.mean(5), mean[5])  # before the first moved state: untouched
    filt.move_branch(10, 3)
    np.testing.assert_allclose(filt._mean[filt._lo:filt._hi], mean, atol=1e-9)
    np.testing.assert_allclose(filt._cross[filt._lo:filt._hi], cross, atol=1e-12)
    np.testing.assert_allclose(filt._P, P, atol=1e-12)


def test_local_density_is_the_noise_at_rest_and_rises_with_motion():
    array = cube_array(0.05, 0.07)
    S = array.structure_matrix()
    rng = np.random.default_rng(2)
    density = LocalDensity(array, period_s=0.5)
    rest = np.zeros(12)
    rest[2] = 9.81
    h_ns = 5_000_000
    for k in range(200):
        density.push(k * h_ns, S @ rest + rng.normal(0, 0.07, S.shape[0]), 0.07**2)
    assert not density.resolved
    moving = rest.copy()
    for k in range(200, 400):
        moving[3:6] += rng.normal(0, 100.0 * np.sqrt(0.005), 3)  # a white-jerk ω̇ of 100 rad/s²/√s
        q = density.push(k * h_ns, S @ moving + rng.normal(0, 0.07, S.shape[0]), 0.07**2)
    assert density.resolved and 50.0 < q < 200.0


def test_a_still_stretch_and_a_slow_turntable():
    array = cube_array(0.05, 0.07)
    turn = simulate("turntable", array, rate_hz=500, duration_s=3.0, seed=3)
    ml = MLEstimator(workers=1).estimate_motion(turn)
    assert not is_still(turn, ml, check_model(turn, ml))
    S = array.structure_matrix()
    x = np.zeros(12)
    x[2] = 9.81
    still = turn.__class__(array, turn.timestamps_ns, S @ x + np.random.default_rng(0).normal(0, 0.07, turn.accel_mps2.shape))
    ml = MLEstimator(workers=1).estimate_motion(still)
    assert is_still(still, ml, check_model(still, ml))


@pytest.mark.parametrize("compiled", [True, False])
def test_older_states_brought_up_only_when_read_give_the_flushed_numbers(compiled):
    """A long window (600 states, a lag of 1.2 s at 500 Hz) whose older states wait for their epochs and are
    brought up to date only where they are read (:meth:`WindowFilter._boundary`): the states leaving the
    window one by one, and every state of the window at the end, have the means and one-sigma of a window
    flushed at every epoch's end, to rounding (the products are grouped differently: relative 1e-9), also
    where ω is flipped on lazy states (moved as stored) rather than after a flush."""
    log = simulate("reversal", cube_array(0.05, 0.07), rate_hz=500, duration_s=2.0, seed=5)
    runs = {}
    for deferred in (True, False):
        filt = WindowFilter(ArrayModel(log.array, SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=20.0).model_groups),
                            capacity=4096)
        filt.compiled, filt.deferred = compiled, deferred
        filt.start(0)
        filt.measure(log.accel_mps2[0], start=np.r_[log.truth.omega_b_radps[0], np.zeros(6)])
        left = []
        for k in range(1, len(log)):
            filt.predict(k, 0.002)
            filt.measure(log.accel_mps2[k])
            if k == 700:  # ω flipped from a lazy state to the newest, then a run in the middle
                filt.move_branch(k - 300, 1)
            if k == 900:
                filt.move_branch(k - 450, 1, k - 350)
            if len(filt) > 600:
                oldest = k - len(filt) + 1
                left.append(np.r_[filt.mean(oldest), filt.sigma(oldest)])
                filt.drop_oldest()
        ks = range(len(log) - len(filt), len(log))
        window = np.array([np.r_[filt.mean(k), filt.sigma(k)] for k in ks])
        runs[deferred] = (np.array(left), window)
        if deferred:
            assert filt._epochs.n > 10  # the epochs were kept, not flushed at each end
    for got, want in zip(runs[True], runs[False]):
        assert got.shape == want.shape and len(got) > 300
        scale = np.abs(want).max(axis=0)  # each column's own scale
        np.testing.assert_allclose(got / scale, want / scale, rtol=0, atol=1e-9)


def test_the_lazy_window_gives_the_eager_numbers(monkeypatch):
    """The older states brought up to date every LAZY_STEPS updates (T, u, W) give every state's mean
    and one-sigma of the update-by-update window to rounding."""
    import gfimu.smoother.stream.window_filter as flt

    log = simulate("reversal", cube_array(0.05, 0.07), rate_hz=500, duration_s=0.6, seed=4)
    out = {}
    for steps in (1, 32):
        monkeypatch.setattr(flt, "LAZY_STEPS", steps)
        filt = WindowFilter(ArrayModel(log.array, SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=20.0).model_groups),
                            capacity=512)
        filt.start(0)
        filt.measure(log.accel_mps2[0], start=np.r_[log.truth.omega_b_radps[0], np.zeros(6)])
        for k in range(1, 250):
            filt.predict(k, 0.002)
            filt.measure(log.accel_mps2[k])
            if k >= 150:
                filt.drop_oldest()
        ks = range(249 - len(filt) + 1, 250)
        out[steps] = (np.array([filt.mean(k) for k in ks]), np.array([filt.sigma(k) for k in ks]))
    np.testing.assert_allclose(out[32][0], out[1][0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out[32][1], out[1][1], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("robust", [False, True])
@pytest.mark.parametrize("planar", [False, True])
def test_the_compiled_settle_path_is_the_numpy_viterbi(robust, planar):
    """WindowFilter._settle_path through kernels.settle_path against its numpy expressions (the costs of
    _step_costs and _readings_costs, then the Viterbi path): the same branch for every state, on windows whose
    states sit on every branch, for a nearly planar board (four branches fit its readings) and a cube, with and
    without the robust losses."""
    from gfimu.array import mimu4444_array
    from gfimu.smoother.solve.restarts import branch

    array = mimu4444_array(0.05) if planar else cube_array(0.05, noise_std_mps2=0.05)
    options = SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=30.0)
    if robust:
        options = SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=30.0, robust_loss="cauchy",
                                  accel_robust_threshold=2.0, process_robust_threshold=3.0)
    log = simulate("random3d", array, rate_hz=200, duration_s=1.0, seed=9)
    filt = WindowFilter(ArrayModel(log.array, options.model_groups), capacity=64)
    step = filt.model.step(0.005)
    rng = np.random.default_rng(3)
    moved = 0
    for trial in range(40):
        n = int(rng.integers(3, 14))
        j0 = int(rng.integers(0, len(log) - n))
        X = np.column_stack([log.truth.omega_b_radps[j0:j0 + n], log.truth.omega_dot_b_radps2[j0:j0 + n],
                             log.truth.specific_force_b_mps2[j0:j0 + n]])
        X = X + rng.normal(scale=0.02, size=X.shape)
        a, b = sorted(rng.integers(1, n, size=2))
        kind = int(rng.integers(0, 4))  # a run on another branch
        X[a:b + 1, 0:3], X[a:b + 1, 3:6] = branch(kind, X[a:b + 1, 0:3], X[a:b + 1, 3:6], filt._normal)
        Y = log.accel_mps2[j0 + 1:j0 + n]
        steps = [(step.F, step.Q)] * (n - 1)
        filt.compiled = True
        got = filt._settle_path(X, steps, Y)
        filt.compiled = False
        want = filt._settle_path(X, steps, Y)
        np.testing.assert_array_equal(got, want)
        moved += int(np.any(want != 0))
    assert moved >= 10  # paths off branch 0 were compared, not only the trivial one


def _local_density_numpy(array, samples, period_s=0.5):
    """LocalDensity.push as numpy and Python (the oracle of kernels.local_density_push): (density or None,
    resolved) after each of ``samples`` ((t_ns, readings, noise variance))."""
    from collections import deque

    S = array.structure_matrix()
    pinv_dw, c_dw = np.linalg.pinv(S)[3:6], float(np.sum(np.diag(np.linalg.pinv(S.T @ S))[3:6]))
    steps, sums, prev, resolved, out = deque(), [0.0, 0.0], None, False, []
    for t_ns, y, noise_var in samples:
        dw, var = pinv_dw @ y, c_dw * noise_var
        prev, last = (t_ns, dw, var), prev
        h = None if last is None else (t_ns - last[0]) * 1e-9
        if h is None or not h > 0:
            out.append((None, resolved))
            continue
        d = dw - last[1]
        step, noise = float(d @ d) / h, (var + last[2]) / h
        steps.append((t_ns, step, noise))
        sums[0] += step
        sums[1] += noise
        while steps and steps[0][0] <= t_ns - int(period_s * 1e9):
            _, s0, n0 = steps.popleft()
            sums[0] -= s0
            sums[1] -= n0
        mean_steps, mean_noise = max(sums[0], 0.0) / len(steps), max(sums[1], 0.0) / len(steps)
        resolved = mean_steps > 4.0 * mean_noise
        out.append((np.sqrt(max(mean_steps - mean_noise, mean_noise) / 3.0), resolved))
    return out


def test_the_compiled_local_density_is_the_numpy_one():
    """LocalDensity (its ring grown past 256 steps, a repeated timestamp, a pause longer than the period,
    motion starting) against the numpy oracle: the same densities to rounding, the same verdicts."""
    array = cube_array(0.05, 0.07)
    S = array.structure_matrix()
    rng = np.random.default_rng(5)
    x = np.zeros(12)
    x[2] = 9.81
    samples, t = [], 0
    for k in range(1500):
        t += 0 if k == 40 else (2_000_000_000 if k == 900 else 1_000_000)  # 1 kHz: 500 steps in the period
        if k > 600:
            x[3:6] += rng.normal(0, 80.0 * np.sqrt(0.001), 3)
        samples.append((t, S @ x + rng.normal(0, 0.07, S.shape[0]), 0.07**2 * (1 + k % 3)))
    density = LocalDensity(array, period_s=0.5)
    got = [(density.push(*s), density.resolved) for s in samples]
    want = _local_density_numpy(array, samples)
    assert len(density._t) >= 512  # the ring grew
    assert [g[0] is None for g in got] == [w[0] is None for w in want]
    assert sum(g[0] is None for g in got) == 2  # the first sample and the repeated timestamp
    assert [g[1] for g in got] == [w[1] for w in want] and any(g[1] for g in got) and not all(g[1] for g in got)
    g = np.array([v[0] for v in got if v[0] is not None])
    w = np.array([v[0] for v in want if v[0] is not None])
    np.testing.assert_allclose(g, w, rtol=1e-9)
