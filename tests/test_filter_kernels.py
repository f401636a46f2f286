"""The fixed-lag filter's compiled kernels against the numpy expressions they replace (the oracle)."""

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.simulate import simulate
from gfimu.simulate.sensor_errors import SensorErrors
from gfimu.smoother.stream import kernels
from gfimu.smoother.stream import window_filter as flf
from gfimu.smoother.stream import array_model as model
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator
from gfimu.smoother.model.problem import SmootherOptions
from gfimu.smoother.solve.restarts import branch


def _random_spd(rng, n, scale):
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T + n * np.eye(n))


def _filter(slope=0.0, robust=0.0, branches=True):
    array = cube_array(0.05, noise_std_mps2=0.05)
    options = SmootherOptions()
    m = model.ArrayModel(array, options.model_groups)
    f = flf.WindowFilter(m, branches=branches)
    if slope or robust:
        m.accel_noise_slope_mps2_per_radps = slope
        m.accel_robust_threshold = robust
        f.set_model(m)
    return f, m


@pytest.mark.parametrize("slope, robust", [(0.0, 0.0), (0.02, 0.0), (0.0, 2.0), (0.02, 2.0)])
def test_solve_is_the_numpy_gauss_newton(slope, robust):
    f, m = _filter(slope, robust)
    rng = np.random.default_rng(3)
    n_acc = m.S_q.shape[0]
    R0, S_q, S_dw, S_f, slope_k, c_k, loss = f._kernel_model
    for trial in range(20):
        x_true = rng.normal(size=9) * np.repeat([3.0, 20.0, 5.0], 3)
        xp = x_true + rng.normal(size=9) * 0.3
        P = _random_spd(rng, 9, 0.05)
        q = np.array([x_true[0] ** 2 + x_true[1] ** 2, x_true[0] ** 2 + x_true[2] ** 2, x_true[1] ** 2 + x_true[2] ** 2,
                      x_true[0] * x_true[1], x_true[0] * x_true[2], x_true[1] * x_true[2]])
        y = m.S_q @ q + m.S_dw @ x_true[3:6] + m.S_f @ x_true[6:] + rng.normal(size=n_acc) * 0.05
        if trial % 5 == 0:
            y[trial % n_acc] += 3.0  # an outlier for the robust loss
        iterations = max(f.iterations, 1) + (1 if robust > 0 else 0)
        want = f._solve(y, None, xp, P, xp, None)
        got = kernels.solve(y, xp, P, xp.copy(), R0, S_q, S_dw, S_f, slope_k, c_k, loss, iterations,
                            f.step_tolerance_radps, True)
        assert got[4]
        # the same arithmetic in another order: agreement to rounding scaled by the problem's condition
        scale = np.abs(want[0]).max() + 1.0
        np.testing.assert_allclose(got[0], want[0], rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(got[1], want[1], rtol=0, atol=1e-9 * scale)
        # Hᵀ S⁻¹ [H, ν] of the numpy update (its S⁻¹ [H, ν] an m × m solve; the kernel's a 9 × 9 one)
        want_AG = want[1].T @ want[2]
        np.testing.assert_allclose(got[2], want_AG, rtol=0, atol=1e-8 * np.abs(want_AG).max())
        assert got[3] == pytest.approx(want[3], rel=1e-7, abs=1e-9)


def test_singular_innovation_is_reported_not_raised():
    f, m = _filter()
    R0, S_q, S_dw, S_f, slope, c, loss = f._kernel_model
    y = np.zeros(m.S_q.shape[0])
    got = kernels.solve(y, np.zeros(9), np.zeros((9, 9)), np.zeros(9), np.zeros_like(R0), S_q, S_dw, S_f, slope, c, loss,
                        3, 1e-6, True)
    assert got[4] is False


def test_the_lu_solve_is_numpys_solve():
    rng = np.random.default_rng(5)
    for n in (1, 3, 9, 24, 48):
        S = rng.normal(size=(n, n)) + n * np.eye(n)
        B = rng.normal(size=(n, 10))
        want = np.linalg.solve(S, B)
        S_work, B_work = S.copy(), B.copy()
        assert kernels._lu_solve(S_work, B_work)
        np.testing.assert_allclose(B_work, want, rtol=0, atol=1e-12 * np.abs(want).max() * np.linalg.cond(S))


def _eliminated(S, B):
    """Gaussian elimination with partial pivoting of S with B along (each right-hand side eliminated as S is),
    in plain Python floats: the textbook order of operations, the oracle of the factored kernels' bits."""
    S, B = [list(map(float, r)) for r in S], [list(map(float, r)) for r in B]
    n = len(S)
    for c in range(n):
        p = max(range(c, n), key=lambda r: (abs(S[r][c]), -r))
        S[c], S[p], B[c], B[p] = S[p], S[c], B[p], B[c]
        inv = 1.0 / S[c][c]
        for r in range(c + 1, n):
            f = S[r][c] * inv
            if f != 0.0:
                for j in range(c + 1, n):
                    S[r][j] -= f * S[c][j]
                for j in range(len(B[0])):
                    B[r][j] -= f * B[c][j]
    for c in range(n - 1, -1, -1):
        inv = 1.0 / S[c][c]
        for j in range(len(B[0])):
            v = B[c][j]
            for i in range(c + 1, n):
                v -= S[c][i] * B[i][j]
            B[c][j] = v * inv
    return np.array(B)


def test_a_factored_matrix_solves_as_elimination_with_the_right_hand_side_to_the_bit():
    """:func:`kernels._lu_factor` once, then :func:`kernels._lu_apply` for each right-hand side (the swaps first,
    then the eliminations): the same bits as eliminating each right-hand side along with the matrix, rows swapped
    (the pivots) or not, zeros below the diagonal or not; :func:`kernels._lu_solve` is the two in one call; the
    quadratic form of the factored matrix is the unfactored one's, -1 where it is singular."""
    rng = np.random.default_rng(11)
    for n, shuffle in ((1, False), (3, True), (9, True), (9, False), (24, True)):
        S = rng.normal(size=(n, n)) + n * np.eye(n)
        if shuffle:  # rows reversed: the largest of each column off the diagonal, pivots swap rows
            S = S[::-1].copy()
        if n > 2:
            S[2, 0] = 0.0  # a multiplier of exactly zero: no update of that row
        LU, piv = S.copy(), np.empty(n, dtype=np.int64)
        assert kernels._lu_factor(LU, piv)
        assert shuffle == bool(np.any(piv != np.arange(n))) or n == 1
        for _ in range(3):
            B = rng.normal(size=(n, 4))
            want = _eliminated(S, B)
            got = B.copy()
            kernels._lu_apply(LU, piv, got)
            assert got.tobytes() == want.tobytes()
            in_one, S_work = B.copy(), S.copy()
            assert kernels._lu_solve(S_work, in_one)
            assert in_one.tobytes() == want.tobytes()
            d = rng.normal(size=n)
            factored = kernels._factored(S)
            assert kernels._factored_form_inverse(*factored, d) == kernels._quadratic_form_inverse(S, d)
    singular = np.zeros((9, 9))
    assert kernels._factored_form_inverse(*kernels._factored(singular), np.ones(9)) == -1.0
    assert kernels._quadratic_form_inverse(singular, np.ones(9)) == -1.0


@pytest.mark.parametrize("kind", [0, 1, 2, 3])
def test_branch_state_is_the_branch_map(kind):
    rng = np.random.default_rng(kind)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    x = rng.normal(size=9)
    w, dw = branch(kind, x[0:3], x[3:6], normal)
    got = kernels.branch_state(kind, x, normal)
    np.testing.assert_allclose(got[0:3], w, rtol=0, atol=1e-15)
    np.testing.assert_allclose(got[3:6], dw, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(got[6:], x[6:])


def test_update_window_is_the_numpy_update():
    rng = np.random.default_rng(11)
    n, m = 7, 12
    cross = rng.normal(size=(n, 9, 9))
    mean = rng.normal(size=(n, 9))
    var = np.abs(rng.normal(size=(n, 9))) + 1.0
    H = rng.normal(size=(m, 9))
    Z = rng.normal(size=(m, 10)) * 0.1
    P = _random_spd(rng, 9, 0.1)
    T, u, W = rng.normal(size=(9, 9)), rng.normal(size=9), rng.normal(size=(9, 9))
    # the numpy expression of WindowFilter._update
    g, A = H.T @ Z[:, -1], H.T @ Z[:, :-1]
    want_u, want_W, want_T = u + T @ g, W + (T @ A) @ T.T, T - (T @ A) @ P
    want_mean = mean + np.einsum("lij,j->li", cross, g)
    CA = cross @ A
    want_var = var - np.einsum("lij,lij->li", CA, cross)
    want_cross = cross - CA @ P
    want_P = P - P @ A @ P
    want_P = 0.5 * (want_P + want_P.T)
    got_mean, got_var, got_cross = mean.copy(), var.copy(), cross.copy()
    T2, u2, W2, P2, ok = kernels.update_window(H.T @ Z, P, T, u, W, got_mean, got_var, got_cross)
    assert ok
    for got, want in ((T2, want_T), (u2, want_u), (W2, want_W), (P2, want_P), (got_mean, want_mean),
                      (got_var, want_var), (got_cross, want_cross)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * (np.abs(want).max() + 1.0))
    Z[0, 0] = np.nan
    before = got_mean.copy()
    assert not kernels.update_window(H.T @ Z, P, T, u, W, got_mean, got_var, got_cross)[4]
    np.testing.assert_array_equal(got_mean, before)  # nothing moved


def _chain_step_numpy(prev_w, prev_dw, w, dw, normal, h, c2, cost):
    """The streaming sign chain's step as numpy expressions (the oracle of kernels.chain_step)."""
    n = len(cost)
    cur = [branch(b, w, dw, normal) for b in range(n)]
    step = np.empty((n, n))
    for a in range(n):
        for b in range(n):
            e = cur[b][0] - prev_w[a] - 0.5 * h * (prev_dw[a] + cur[b][1])
            step[a, b] = float(e @ e)
    total = cost[:, None] + c2 * np.log1p(step / c2)
    back = np.argmin(total, axis=0)
    new = total[back, np.arange(n)]
    return np.array([c[0] for c in cur]), np.array([c[1] for c in cur]), back, new - new.min()


@pytest.mark.parametrize("n_branches", [2, 4])
def test_chain_step_is_the_numpy_chain(n_branches):
    rng = np.random.default_rng(7)
    normal = np.array([0.0, 0.6, 0.8])
    for _ in range(50):
        prev_w, prev_dw = rng.normal(size=(n_branches, 3)), rng.normal(size=(n_branches, 3)) * 10
        w, dw = rng.normal(size=3), rng.normal(size=3) * 10
        cost = np.abs(rng.normal(size=n_branches))
        want = _chain_step_numpy(prev_w, prev_dw, w, dw, normal, 0.002, 0.3, cost)
        back = np.full(n_branches, -1)
        lowest = kernels.chain_step(prev_w, prev_dw, w, dw, normal, 0.002, 0.3, cost, back)  # (in place)
        for a, b in zip((prev_w, prev_dw), want[:2]):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)
        np.testing.assert_array_equal(back, want[2])
        np.testing.assert_allclose(cost, want[3], rtol=0, atol=1e-12)
        assert lowest == int(np.argmin(cost)) and cost[lowest] == 0.0  # the lowest branch, its cost 0


@pytest.mark.parametrize("scenario, noise", [pytest.param("random3d", 0.07, marks=pytest.mark.slow), ("reversal", 0.02)])
def test_a_whole_stream_through_the_kernels_is_the_numpy_stream(monkeypatch, scenario, noise):
    log = simulate(scenario, array=cube_array(0.025, noise_std_mps2=noise), rate_hz=500.0, duration_s=6.0, seed=4)
    estimator = FixedLagEstimator(tune_window_s=2.0)
    compiled = estimator.estimate(log).motion
    monkeypatch.setattr(flf.WindowFilter, "compiled", False)
    oracle = estimator.estimate(log).motion
    # the same updates in another order of summation: differences at the level of the solver's rounding,
    # far below the estimate's error against the truth (about 1e-2 rad/s here)
    np.testing.assert_allclose(compiled.omega_b_radps, oracle.omega_b_radps, rtol=0, atol=1e-7)
    np.testing.assert_allclose(compiled.omega_dot_b_radps2, oracle.omega_dot_b_radps2, rtol=0, atol=1e-4)
    np.testing.assert_allclose(compiled.specific_force_b_mps2, oracle.specific_force_b_mps2, rtol=0, atol=1e-6)


def test_the_kernels_readings_are_the_arrays_rigid_body_equation():
    """h(x) of the compiled update is Ho & Lin 2009's eq. 6 through the array's structure matrix, S [f, ω̇, q(ω)],
    and its Jacobian the derivative of that (central differences)."""
    from gfimu.rigid_body import quadratic_terms

    f, m = _filter()
    array = cube_array(0.05, noise_std_mps2=0.05)
    S = array.structure_matrix()
    rng = np.random.default_rng(2)
    R0, S_q, S_dw, S_f, *_ = f._kernel_model
    for _ in range(5):
        x = rng.normal(size=9) * np.repeat([4.0, 30.0, 9.0], 3)
        pred, H = np.empty(S.shape[0]), np.zeros((S.shape[0], 9))
        kernels._predict_readings(x, S_q, S_dw, S_f, pred, H)
        want = S @ np.concatenate([x[6:9], x[3:6], quadratic_terms(x[0:3])])
        np.testing.assert_allclose(pred, want, rtol=0, atol=1e-12 * np.abs(want).max())
        step = 1e-6
        for j in range(9):
            d = np.zeros(9)
            d[j] = step
            hi, lo = np.empty_like(pred), np.empty_like(pred)
            kernels._predict_readings(x + d, S_q, S_dw, S_f, hi, np.zeros_like(H))
            kernels._predict_readings(x - d, S_q, S_dw, S_f, lo, np.zeros_like(H))
            # h is quadratic: the central difference is exact up to rounding of |h| / step
            np.testing.assert_allclose(H[:, j], (hi - lo) / (2 * step), rtol=0, atol=1e-9 * np.abs(want).max() / step)


@pytest.mark.slow
def test_a_robust_stream_through_the_kernels_is_the_numpy_stream(monkeypatch):
    """The robust model (Cauchy loss on the readings and on the motion model's steps, noise growing with |ω|)
    through the compiled update and through the numpy one: the same estimates to rounding."""
    from gfimu.smoother.stream.window_filter import WindowFilter
    from gfimu.smoother.stream.fixed_lag import FixedLagSmoother

    log = simulate("random3d", array=cube_array(0.025, noise_std_mps2=0.05), rate_hz=400.0, duration_s=3.0, seed=8)
    y = log.accel_mps2.copy()
    y[::97, 2] += 4.0  # outliers for the robust losses

    def run():
        sm = FixedLagSmoother(log.array, SmootherOptions().model_groups, lag_s=0.1, rate_hz=400.0)
        # the values the stream's robust model sets (smoother/stream/model_choice.py), set here on its model directly
        sm.model.robust_loss = "cauchy"
        sm.model.accel_robust_threshold = sm.model.process_robust_threshold = 2.0
        sm.model.accel_noise_slope_mps2_per_radps = 0.01
        out = []
        for t, row in zip(log.timestamps_ns, y):
            out.extend(sm.push(t, row).smoothed)
        out.extend(sm.flush())
        return np.array([s.omega_b_radps for s in out])

    compiled = run()
    monkeypatch.setattr(WindowFilter, "compiled", False)
    oracle = run()
    assert compiled.shape == oracle.shape == (len(log), 3)
    np.testing.assert_allclose(compiled, oracle, rtol=0, atol=1e-7)


def test_flush_window_is_the_numpy_flush():
    rng = np.random.default_rng(13)
    n = 40
    cross, mean, var = rng.normal(size=(n, 9, 9)), rng.normal(size=(n, 9)), np.abs(rng.normal(size=(n, 9))) + 2.0
    T, u, W = rng.normal(size=(9, 9)), rng.normal(size=9), rng.normal(size=(9, 9))
    want_mean = mean + np.einsum("lij,j->li", cross, u)
    want_var = var - np.einsum("lij,jk,lik->li", cross, W, cross)
    want_cross = cross @ T
    kernels.flush_window(T, u, W, mean, var, cross)
    for got, want in ((mean, want_mean), (var, want_var), (cross, want_cross)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * (np.abs(want).max() + 1.0))


def _window_states(f):
    """Means and marginal variances of every state of the window (the lazy ones brought up to date)."""
    ks = range(f._base + f._lo, f._base + f._hi)
    return np.array([f.mean(k) for k in ks]), np.array([f.sigma(k) for k in ks])


@pytest.mark.parametrize("noise, robust", [(0.0, 0.0), (0.07, 0.0), (0.07, 2.0)])
def test_the_fused_advance_is_the_numpy_predict_and_measure(monkeypatch, noise, robust):
    """One sample in one compiled call (prediction, update, window) against the numpy prediction and update it
    fuses, state by state over a stream long enough to compact and flush the window: the same means of every
    state of the window to 1e-9 relative (1e-8 in the first 0.1 s) and variances to 1e-8 (1e-7), on a noise-free and
    a noisy stream."""
    array = cube_array(0.05, noise_std_mps2=max(noise, 0.01))
    log = simulate("random3d", array=array, rate_hz=500.0, duration_s=1.2, seed=11,
                   noise=None if noise > 0 else SensorErrors.none())
    filters = []
    for compiled in (True, False):
        m = model.ArrayModel(array, SmootherOptions().model_groups)
        if robust:
            m.robust_loss = "cauchy"
            m.accel_robust_threshold = m.process_robust_threshold = robust
        f = flf.WindowFilter(m, capacity=64, branches=True)
        f.compiled = compiled
        filters.append(f)
    fused, oracle = filters
    lag = 40
    calls = []
    real = kernels.advance_update
    h = 1.0 / 500.0
    for i, (t, y) in enumerate(zip(log.timestamps_ns, log.accel_mps2)):
        for f in filters:
            if i == 0:  # the same first state for both (its weak priors make its update ill-conditioned: the
                # m × m and 9 × 9 forms of it differ by 1e-7), then each sample through either path
                f.start(0)
                f.compiled = True
                f.measure(y)
                f.compiled = f is fused
            else:
                f.advance(i, f.model.step(h), int(t), y)
            if len(f) > lag:
                f.drop_oldest()
        if i == 1:  # the fused kernel is what the compiled filter runs
            monkeypatch.setattr(kernels, "advance_update", lambda *a: calls.append(1) or real(*a))
        if i == 2:
            monkeypatch.setattr(kernels, "advance_update", real)
        m1, v1 = _window_states(fused)
        m0, v0 = _window_states(oracle)
        scale = np.abs(m0).max(axis=0) + 1e-3
        # the two forms of the update (an m × m system, a 9 × 9 one) agree to rounding scaled by its
        # condition: poor while the weak priors of the first state still weigh (the first 0.1 s), then 1e-9
        tol = 1e-8 if i < 50 else 1e-9
        np.testing.assert_allclose(m1 / scale, m0 / scale, rtol=0, atol=tol)
        # variances likewise: while the first state's prior variance (1e4 rad²/s²) still weighs against a
        # posterior one near 1e-4, rounding is scaled by that ratio (1e8 × 2.2e-16 ≈ 2e-8: 1.1e-8 is seen
        # with another BLAS kernel), then 1e-8
        np.testing.assert_allclose(v1, v0, rtol=1e-7 if i < 50 else 1e-8, atol=0)
    assert calls == [1]
    assert fused._base > 0 and fused.n_updates == oracle.n_updates == len(log)
    if noise == 0:  # noise-free readings: the filter on the true ω
        np.testing.assert_allclose(fused.mean(len(log) - 1)[:3], log.truth.omega_b_radps[-1], atol=1e-2)


@pytest.mark.parametrize("robust", [0.0, 2.0])
def test_the_fused_advance_is_the_two_compiled_calls_bit_for_bit(robust):
    """The fused call (:func:`kernels.advance_update`, its factors T, u, W and the newest covariance P written
    into the filter's own arrays) gives the very numbers of the two compiled calls it fuses
    (:func:`kernels.predict_window`, then :func:`kernels.measure_update`), every state of the window, the factors
    and P equal to the last bit, over a stream long enough to close epochs and compact the window."""
    array = cube_array(0.05, noise_std_mps2=0.07)
    log = simulate("random3d", array=array, rate_hz=500.0, duration_s=0.8, seed=5)
    filters = []
    for _ in range(2):
        m = model.ArrayModel(array, SmootherOptions().model_groups)
        if robust:
            m.robust_loss = "cauchy"
            m.accel_robust_threshold = m.process_robust_threshold = robust
        filters.append(flf.WindowFilter(m, capacity=64, branches=True))
    fused, apart = filters
    h = 1.0 / 500.0
    in_place = 0
    for i, y in enumerate(log.accel_mps2):
        if i == 0:
            for f in filters:
                f.start(0)
                f.measure(y)
            continue
        lazy = fused._lazy
        before = (lazy.T, lazy.u, lazy.W, fused._newest.P)
        fused.advance(i, fused.model.step(h), 0, y)
        in_place += all(a is b for a, b in zip(before, (lazy.T, lazy.u, lazy.W, fused._newest.P)))
        apart.predict(i, apart.model.step(h))
        apart.measure(y)
        for f in filters:
            if len(f) > 40:
                f.drop_oldest()
        for a, b in ((fused._store, apart._store), (fused._lazy, apart._lazy), (fused._newest, apart._newest)):
            for name in a.__slots__:
                va, vb = getattr(a, name), getattr(b, name)
                # (tmp: scratch; the steps: kept by advance(), which the two calls apart do not use)
                if isinstance(va, np.ndarray) and name not in ("tmp", "F", "Q", "has_step"):
                    np.testing.assert_array_equal(va, vb, err_msg=f"{name} at sample {i}")
        assert (fused._store.lo, fused._store.hi, fused._store.split) == (apart._store.lo, apart._store.hi,
                                                                          apart._store.split)
    assert fused._base > 0 and in_place > len(log) // 2  # (an epoch's end makes new factors: not in place)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_non_finite_update_is_a_filter_failure_on_both_paths(compiled):
    """A reading that makes the update non-finite: FilterFailure from the fused kernel as from the numpy path,
    and the window still answers for the states before it."""
    f, m = _filter()
    f.compiled = compiled
    log = simulate("random3d", array=cube_array(0.05, noise_std_mps2=0.05), rate_hz=500.0, duration_s=0.1, seed=2)
    f.start(0)
    f.measure(log.accel_mps2[0])
    for i in range(1, 10):
        f.advance(i, m.step(0.002), 0, log.accel_mps2[i])
    before = f.mean(5).copy()
    y = log.accel_mps2[10].copy()
    y[3] = np.inf
    with pytest.raises(flf.FilterFailure):
        f.advance(10, m.step(0.002), 0, y)
    np.testing.assert_array_equal(f.mean(5), before)
