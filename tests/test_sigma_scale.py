"""σ scaled by the readings' own misfit (gfimu.smoother.solve.sigma_scale) and its check by gfimu evaluate."""

import math

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.array import cube_array
from gfimu.cli import main
from gfimu.evaluation import evaluate, sigma_metrics
from gfimu.motion import Motion
from gfimu.rigid_body import quadratic_terms, quadratic_terms_jacobian
from gfimu.smoother.solve import sigma_scale as ss

ARRAY = cube_array(0.05, 0.01)


def readings(states, noise):
    S = ARRAY.structure_matrix()
    return np.hstack([states[:, 6:9], states[:, 3:6], quadratic_terms(states[:, 0:3])]) @ S.T + noise


def random_states(rng, n):
    return np.hstack([rng.normal(0, 3, (n, 3)), rng.normal(0, 10, (n, 3)), rng.normal(0, 5, (n, 3))])


def test_parity_residual_is_zero_on_rigid_readings_whatever_the_state_error():
    rng = np.random.default_rng(0)
    X = random_states(rng, 50)
    p, rank, single = ss.parity(ARRAY, readings(X, 0.0), X, np.full(12, 0.01))
    assert np.all(rank == 9) and np.max(np.abs(p)) < 1e-9 * 100  # readings ~ 100 m/s², whitened by 0.01
    # noise along the measurement Jacobian (what a small state error gives) is not seen either
    dx = 1e-4 * rng.standard_normal((50, 9))
    p2, _, _ = ss.parity(ARRAY, readings(X + np.hstack([dx[:, :3] * 0, dx[:, 3:]]), 0.0), X, np.full(12, 0.01))
    assert np.max(np.abs(p2)) < 1e-6  # an error in ω̇, f only: linear, wholly inside the Jacobian's span


def test_variance_factor_is_one_for_white_noise_of_the_stated_level_and_its_square_for_k_times_it():
    rng = np.random.default_rng(1)
    n = 4000
    X = random_states(rng, n)
    for k in (1.0, 3.0):
        y = readings(X, rng.normal(0, 0.01 * k, (n, 12)))
        p, rank, _ = ss.parity(ARRAY, y, X, np.full(12, 0.01))
        s2 = float(np.sum(p * p) / np.sum(12 - rank))
        # s² ~ k² χ²_ν/ν with ν = 3 n: relative std √(2/ν) = 1.3 %; 5 of them
        assert s2 == pytest.approx(k * k, rel=5 * math.sqrt(2 / (3 * n)))


def test_long_run_factor_of_full_and_no_correlation():
    assert ss.long_run_factors(np.ones(10)) == pytest.approx(np.r_[1.0, 1.0, np.arange(2, 11)], rel=1e-12)
    assert np.all(ss.long_run_factors(np.zeros(10)) == 1.0)
    # a misfit that alternates from one sample to the next (a vibration at half the rate) averages out
    # faster than white noise: τ(L) = 1 + 2 Σ_{k<L} (1 - k/L) (-1)^k, 0 for even L, 1/L for odd L
    rho = (-1.0) ** np.arange(1, 11)
    L = np.arange(2, 11)
    expected = np.where(L % 2 == 0, 0.0, 1.0 / L)
    assert ss.long_run_factors(rho)[2:] == pytest.approx(np.maximum(expected, ss.TAU_FLOOR), rel=1e-12)
    assert np.all(ss.long_run_factors(-np.ones(10))[2:] == ss.TAU_FLOOR)  # the floor, never 0


def test_running_scale_ends_on_the_whole_logs_factor():
    rng = np.random.default_rng(2)
    n = 300
    X = random_states(rng, n)
    e = np.cumsum(rng.normal(0, 0.01, (n, 12)), axis=0) * 0.3  # correlated in time
    y = readings(X, e)
    sd = np.full((n, 9), 0.01)
    run = ss.RunningSigmaScale(ARRAY)
    for i in range(n):
        run.scaled(y[i], X[i], sd[i], np.full(12, 0.01))
    # the running sums: s² of the newest local_window(3) samples (12 axes, rank 9: 3 degrees of freedom a
    # sample, 342 samples for 1024 of them: here all 300), ρ of all, as computed here from the residuals
    p, rank, single = ss.parity(ARRAY, y, X, np.full(12, 0.01))
    W = ss.local_window(3)
    assert W == 342
    assert run.variance_factor == pytest.approx(np.sum(p[-W:] ** 2) / np.sum(12 - rank[-W:]), rel=1e-9)
    rho = np.array([np.sum(p[k:] * p[:n - k]) for k in range(1, ss.MAX_LAG + 1)]) / np.sum(p * p)
    assert run.tau() == pytest.approx(ss.long_run_factors(rho), rel=1e-9)
    assert run.variance_factor > 4  # the misfit is well above the stated 0.01
    # the batch smoother's factor at a row: s² of the window centred on it, the same ρ
    whole = ss.calibrated_sigma(ARRAY, y, X, sd, np.full(12, 0.01))
    i = n // 2
    rows = slice(max(0, i - W // 2), min(n, i + W - W // 2))
    s2 = np.sum(p[rows] ** 2) / np.sum(12 - rank[rows])
    assert whole[i] == pytest.approx(sd[i] * ss.scale_factors(sd[i:i + 1], single[i:i + 1], s2, run.tau())[0], rel=1e-9)
    # causal: the first rows' factor does not know the later ones
    early = ss.RunningSigmaScale(ARRAY)
    firsts = [early.scaled(y[i], X[i], sd[i], np.full(12, 0.01)) for i in range(ss.MIN_SAMPLES - 1)]
    assert np.all(np.array(firsts) == 0.01)


def test_sigma_metrics_by_hand():
    err = np.array([[0.5, -1.5, 0.0], [-2.5, 0.2, 1.0], [0.9, 3.0, -0.1], [1.0, 1.0, 1.0]])
    sig = np.ones((4, 3))
    m = sigma_metrics(err, sig)
    assert m.coverage_1sigma == (0.5, 0.25, 0.5)  # |e| < 1 strictly
    assert m.coverage_2sigma == (0.75, 0.75, 1.0)
    assert m.mean_nees == pytest.approx(np.sum(err ** 2) / 4, rel=1e-15) and m.n_sigma == 4
    sig[1, 2] = np.nan  # a row without σ is left out
    assert sigma_metrics(err, sig).n_sigma == 3


def test_evaluate_reports_coverage_from_an_estimate_csv_with_sigma(tmp_path, capsys):
    t = np.arange(4, dtype=np.int64) * 10
    truth = Motion(t, omega_b_radps=np.zeros((4, 3)))
    est = Motion(t, omega_b_radps=np.array([[0.5, 0, 0], [3, 0, 0], [0, 1.5, 0], [0, 0, 0.1]]),
                 sigma={"omega_b_radps": np.ones((4, 3))})
    r = evaluate(est, truth)["omega"]
    assert r.sigma.coverage_1sigma == (0.75, 0.75, 1.0) and r.sigma.coverage_2sigma == (0.75, 1.0, 1.0)
    assert r.sigma.mean_nees == pytest.approx((0.25 + 9 + 2.25 + 0.01) / 4, rel=1e-15)
    gio.write_motion_csv(est, tmp_path / "est.csv")
    gio.write_motion_csv(truth, tmp_path / "truth.csv")
    assert main(["evaluate", str(tmp_path / "truth.csv"), str(tmp_path / "est.csv"), "--format", "csv"]) == 0
    out = capsys.readouterr().out.splitlines()
    row = dict(zip(out[0].split(","), out[1].split(",")))
    assert float(row["coverage_1sigma_x"]) == 0.75 and float(row["mean_nees"]) == pytest.approx(2.8775, rel=1e-12)
    assert main(["evaluate", str(tmp_path / "truth.csv"), str(tmp_path / "est.csv")]) == 0
    assert "| omega | 4 | 75 % | 75 % | 100 % | 75 % | 100 % | 100 % | 2.87" in capsys.readouterr().out


def _ar1(rng, shape, std, corr):
    out = np.empty(shape)
    e = rng.standard_normal(shape) * std * math.sqrt(1.0 - corr * corr)
    out[0] = rng.standard_normal(shape[1:]) * std
    for i in range(1, shape[0]):
        out[i] = corr * out[i - 1] + e[i]
    return out


def _coverage(log, estimator, white, monkeypatch):
    from gfimu.smoother.batch import engine as batch
    from gfimu.smoother.stream import fixed_lag

    with monkeypatch.context() as mp:
        if white:  # the model's σ alone, as before the scaling
            mp.setattr(batch, "_calibrates_sigma", lambda *a: False)
            mp.setattr(fixed_lag, "calibrates_stream", lambda *a: False)
        motion = estimator.estimate(log).motion
    err = motion.omega_b_radps - log.truth.omega_b_radps
    return sigma_metrics(err, motion.sigma["omega_b_radps"]), motion


@pytest.fixture(scope="module")
def simulated_logs():
    from dataclasses import replace

    from gfimu.simulate import SensorErrors, simulate

    clean = simulate("random3d", cube_array(0.05, 0.01), rate_hz=100.0, duration_s=30.0,
                     noise=SensorErrors(accel_noise_std_mps2=0.01), seed=3)
    # an error array.toml does not state: 0.05 m/s² per axis, correlated 0.95 from one sample to the next
    misfit = replace(clean, accel_mps2=clean.accel_mps2 + _ar1(np.random.default_rng(5), clean.accel_mps2.shape,
                                                               0.05, 0.95))
    return clean, misfit


@pytest.mark.slow
@pytest.mark.parametrize("method", ["smoother", "fixed-lag"])
def test_sigma_covers_an_unstated_correlated_misfit_and_stays_where_the_model_is_right(simulated_logs, method,
                                                                                        monkeypatch):
    from gfimu.methods import make_estimator

    clean, misfit = simulated_logs
    est = make_estimator(method, compute_sigma=True)
    white, m_white = _coverage(misfit, est, True, monkeypatch)
    scaled, m_scaled = _coverage(misfit, est, False, monkeypatch)
    assert np.array_equal(m_white.omega_b_radps, m_scaled.omega_b_radps)  # the estimate itself is untouched
    # the white-noise σ is several times too small: a third of the samples within 1σ at most
    assert max(white.coverage_1sigma) < 0.35 and white.mean_nees > 20
    # scaled: the target band over the three axes together (each axis' share, from 30 s of errors
    # correlated over a second or so, scatters by about ±0.06 about it)
    one, two = np.mean(scaled.coverage_1sigma), np.mean(scaled.coverage_2sigma)
    assert 0.60 <= one <= 0.76 and 0.90 <= two <= 0.99, scaled
    assert all(0.55 <= v <= 0.85 for v in scaled.coverage_1sigma), scaled  # the band less that scatter
    assert 1.0 < scaled.mean_nees < 4.0
    # a log with the stated white noise: the model's σ is too wide (the path's trapezoid residual is far below
    # the white jerk's, and half of ω's variance is that part), the reported σ follows the path's level into
    # the band (each axis' share scatters by about ±0.06 here, as above)
    right, m_right = _coverage(clean, est, False, monkeypatch)
    plain, m_plain = _coverage(clean, est, True, monkeypatch)
    assert min(plain.coverage_1sigma) > 0.8 and plain.mean_nees < 2.0, plain
    ratio = m_right.sigma["omega_b_radps"] / m_plain.sigma["omega_b_radps"]
    assert 0.6 < np.median(ratio) < 0.9
    assert 0.60 <= np.mean(right.coverage_1sigma) <= 0.76 and 0.90 <= np.mean(right.coverage_2sigma) <= 0.98, right
    assert all(0.55 <= v <= 0.80 for v in right.coverage_1sigma), right
    assert 2.0 < right.mean_nees < 4.0


def test_factor_is_a_function_of_the_residuals_only_and_follows_them_in_time():
    """The same misfit on another motion gives the same factor where the span is the same; k times the
    misfit gives k times the factor; a misfit in the second half only leaves the first half's σ alone."""
    rng = np.random.default_rng(7)
    n, W = 3000, ss.local_window(3)
    X = random_states(rng, n)
    sd = np.full((n, 9), 1e-6)  # a span of 0: τ(0) = 1, the factor is √s²
    e = rng.normal(0, 0.01, (n, 12))
    e[n // 2:] *= 4.0  # 4 times the stated level from the middle on
    f1 = ss.calibrated_sigma(ARRAY, readings(X, e), X, sd, np.full(12, 0.01)) / sd
    f3 = ss.calibrated_sigma(ARRAY, readings(X, 3 * e), X, sd, np.full(12, 0.01)) / sd
    assert f3 == pytest.approx(3 * f1, rel=1e-9)
    # s² of W samples' white residuals (ν = 3 W degrees of freedom): relative std of √s² is √(1/(2ν)) = 3.6 %
    tol = 4 * math.sqrt(1 / (6 * W))
    first, second = f1[: n // 2 - W], f1[n // 2 + W:]
    assert np.all(np.abs(first - 1.0) < tol) and np.all(np.abs(second - 4.0) < 4 * tol)
    # the same residuals about another motion: parity residuals differ only through the Jacobian's span
    Y = random_states(np.random.default_rng(8), n)
    g = ss.calibrated_sigma(ARRAY, readings(Y, e), Y, sd, np.full(12, 0.01)) / sd
    assert np.all(np.abs(g[: n // 2 - W] - 1.0) < tol) and np.all(np.abs(g[n // 2 + W:] - 4.0) < 4 * tol)


def test_running_factor_is_causal_and_local():
    rng = np.random.default_rng(9)
    n, W = 1400, ss.local_window(3)
    X = random_states(rng, n)
    e = rng.normal(0, 0.01, (n, 12))
    e[700:] *= 5.0
    y = readings(X, e)
    run = ss.RunningSigmaScale(ARRAY)
    s2 = []
    for i in range(n):
        run.scaled(y[i], X[i], np.full(9, 1e-6), np.full(12, 0.01))
        s2.append(run.variance_factor)
    s2 = np.array(s2)
    tol = 4 * math.sqrt(2 / (3 * W))  # relative std of s² over W samples' white residuals: √(2/ν), ν = 3 W
    assert np.all(np.abs(s2[W:700] - 1.0) < tol)  # before the change: unaffected by what comes later
    assert np.all(np.abs(s2[700 + W:] / 25.0 - 1.0) < tol)  # W samples after it: the new level alone


def test_the_batch_trapezoid_level_is_the_residuals_less_the_readings_part_over_the_rows_own():
    """calibrated_sigma with the motion model's steps: over each row's window, λ = (Σ r̂² − s² Σ b) / Σ a
    (trapezoid_level; a the trapezoid rows' own part, b the readings'), and ω's factor √(s² τ (1 − share) + λ share);
    on a path whose trapezoid residuals lie between the two parts, so that λ is neither 0 nor 1."""
    rng = np.random.default_rng(11)
    n, h, q = 1500, 0.01, 30.0
    dt = np.full(n - 1, h)
    density = np.full((n - 1, 3), q)
    steps = ss.jerk_steps(density, np.zeros(3), dt)
    d = np.cumsum(rng.normal(0.0, math.sqrt(q * q * h), (n, 3)), axis=0)
    w = np.vstack([np.zeros(3), np.cumsum(0.5 * h * (d[1:] + d[:-1])
                                          + math.sqrt(0.3 * steps[0][0, 0]) * rng.normal(size=(n - 1, 3)), axis=0)])
    X = np.hstack([w, d, rng.normal(0, 5, (n, 3))])
    y = readings(X, rng.normal(0, 0.01, (n, 12)))
    sd = np.full((n, 9), 1e6)  # far wider than one sample's: a span of 0, τ(0) = 1
    got = ss.calibrated_sigma(ARRAY, y, X, sd, np.full(12, 0.01), process=(density, np.zeros(3), dt)) / sd
    p, rank, single = ss.parity(ARRAY, y, X, np.full(12, 0.01))
    W = ss.local_window(float(np.median(p.shape[1] - rank)))
    s2 = ss.local_sums(np.sum(p * p, axis=1), W) / ss.local_sums(p.shape[1] - rank, W)
    share, a, b = ss.kinematic_shares(single, np.vstack([steps[0], steps[0][-1:]]), np.vstack([steps[1], steps[1][-1:]]),
                                      np.append(dt, h))
    r = ss.trapezoid_residuals(X, steps)
    sums = [ss.local_sums(np.append(v, 0.0), W) for v in (np.sum(r * r, axis=1), a[:-1].sum(axis=1), b[:-1].sum(axis=1))]
    level = np.clip((sums[0] - s2 * sums[2]) / sums[1], 0.0, 1.0)
    mid = slice(W, n - W)
    assert 0.05 < np.median(level[mid]) < 0.95  # neither end of the clip: the order of the parts matters
    want = np.sqrt(s2[:, None] * (1.0 - share) + level[:, None] * share)
    np.testing.assert_allclose(got[mid, 0:3], want[mid], rtol=1e-9)
    np.testing.assert_allclose(got[mid, 3:9], np.sqrt(s2)[mid, None] * np.ones(6), rtol=1e-9)


def _robust_fit(X, y, c, loss):
    """IRLS of y ≈ X b under the robust ``loss`` of threshold ``c`` (from least squares, to convergence)."""
    from gfimu.smoother.model.problem import robust_weight

    b = np.linalg.lstsq(X, y, rcond=None)[0]
    for _ in range(200):
        w = robust_weight(y - X @ b, c, loss)
        new = np.linalg.solve(X.T @ (w[:, None] * X), X.T @ (w * y))
        done = np.max(np.abs(new - b)) < 1e-12
        b = new
        if done:
            break
    return b, robust_weight(y - X @ b, c, loss)


@pytest.mark.parametrize("loss", ["cauchy", "huber"])
def test_sandwich_factor_gives_the_spread_of_a_robust_estimate(loss):
    """A robust regression (400 readings, 3 unknowns, 15 % of the readings with 6 times the noise): over 1200
    draws, the variance of the IRLS estimate against P = (X̃ᵀX̃)⁻¹ times the sandwich factor of each draw's own
    residuals. The sums are parity's (Σ w p², Σ w (1 − h), Σ h ψ'/w, Σ h); asymptotic theory makes the ratio 1
    up to O(k/n); the variance of 1200 draws scatters by √(2/1200) = 4 % (3σ: 12 %). P scaled by the level of
    the weighted residuals alone (no slope: what σ was before) misses it by 15-35 % either way."""
    rng = np.random.default_rng(11)
    n, k, c = 400, 3, 2.0
    X = rng.normal(size=(n, k))
    estimates, sandwich, level = [], [], []
    for _ in range(1200):
        y = X @ np.ones(k) + rng.normal(size=n) * np.where(rng.random(n) < 0.15, 6.0, 1.0)
        b, w = _robust_fit(X, y, c, loss)
        r = y - X @ b
        Xt, zt = np.sqrt(w)[:, None] * X, np.sqrt(w) * r
        P = np.linalg.inv(Xt.T @ Xt)
        h = np.einsum("ij,jk,ik->i", Xt, P, Xt)
        p = zt - Xt @ (P @ (Xt.T @ zt))
        slope = ss.robust_slope(r, w, c, loss)
        estimates.append(b)
        sandwich.append(np.diag(P) * ss.sandwich_factor(np.sum(w * p * p), np.sum(w * (1 - h)), np.sum(h * slope),
                                                        np.sum(h)))
        level.append(np.diag(P) * np.sum(p * p) / (n - k))
    spread = np.var(np.array(estimates), axis=0)
    np.testing.assert_allclose(np.mean(sandwich, axis=0) / spread, 1.0, atol=0.12)
    assert abs(np.mean(np.mean(level, axis=0) / spread) - 1.0) > 0.12  # (three unknowns pooled: ±2.5 %)


@pytest.mark.parametrize("loss", ["cauchy", "huber"])
def test_parity_sandwich_sums_by_hand(loss):
    """parity's ``slopes`` columns against the sums written out: IRLS weights of the whitened residuals, the
    whitened Jacobian's leverages (which sum to the rank) and ψ'/w; without a robust loss |p|², m − rank, rank."""
    from gfimu.smoother.model.problem import robust_weight

    rng = np.random.default_rng(5)
    X = np.column_stack([rng.normal(0, 3, (50, 3)), rng.normal(0, 30, (50, 3)), rng.normal(0, 10, (50, 3))])
    y = readings(X, 0.0) + rng.standard_t(2, (50, ARRAY.n_axes)) * 0.05
    std = np.full(ARRAY.n_axes, 0.02)
    p, rank, _, sums = ss.parity(ARRAY, y, X, std, (loss, 2.0), slopes=True)
    z = (y - readings(X, 0.0)) / std
    w = robust_weight(z, 2.0, loss)
    S = ARRAY.structure_matrix()
    for i in range(len(X)):
        J = np.hstack([S[:, 6:12] @ quadratic_terms_jacobian(X[i, :3]), S[:, 3:6], S[:, 0:3]]) / std[:, None]
        Jt = np.sqrt(w[i])[:, None] * J
        h = np.diag(Jt @ np.linalg.pinv(Jt))
        assert math.isclose(h.sum(), rank[i], abs_tol=1e-9)
        expected = [np.sum(w[i] * p[i] ** 2), np.sum(w[i] * (1 - h)), np.sum(h * ss.robust_slope(z[i], w[i], 2.0, loss))]
        np.testing.assert_allclose(sums[i], expected, rtol=1e-9, atol=1e-9 * ARRAY.n_axes)
    p0, rank0, _, plain = ss.parity(ARRAY, y, X, std, None, slopes=True)
    np.testing.assert_array_equal(plain, np.column_stack([np.sum(p0 * p0, axis=1), ARRAY.n_axes - rank0, rank0]))


@pytest.mark.parametrize("n", [3, 10, 101, 1000])
def test_local_sums_are_numpys_same_convolution_with_ones(n):
    # the window the guard's sums and s_i² take: exactly the convolution's for integer values (counts), to
    # rounding for real ones (cumulative sums of values of size v over n samples: n · v · eps at most)
    rng = np.random.default_rng(n)
    for width in sorted({1, 2, 3, 4, 5, 8, 9, n}):
        if width > n:
            continue
        k = rng.integers(0, 5, n)
        np.testing.assert_array_equal(ss.local_sums(k, width), np.convolve(k.astype(float), np.ones(width), "same"))
        v = 10.0 * rng.standard_normal(n)
        np.testing.assert_allclose(ss.local_sums(v, width), np.convolve(v, np.ones(width), "same"), rtol=0,
                                   atol=n * 10.0 * 8 * np.finfo(float).eps)
