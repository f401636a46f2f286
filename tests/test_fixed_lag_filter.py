"""The numpy window filter of the fixed-lag smoother against a dense least-squares solve and gtsam."""

import numpy as np
import pytest

from gfimu.array import cube_array, paper001_array
from gfimu.factors import kinematics, process
from gfimu.simulate import simulate
from gfimu.smoother.stream import array_model as model
from gfimu.smoother.stream.window_filter import FilterFailure, WindowFilter
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator, FixedLagSmoother, FixedLagSmootherError
from gfimu.smoother.model.problem import SmootherOptions

RATE_HZ = 500.0


def omega_rmse(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def dense_map(m: model.ArrayModel, times_s, Y, x_init, iterations=20):
    """Minimum of the segment's whitened residuals (priors, process factors, readings) by dense Gauss-Newton,
    written from the factor-graph form (trapezoid + random walks, or the oscillator step)."""
    o = m.model
    n = len(times_s)
    prior_sd = np.repeat([o.initial_omega_std_radps, o.initial_omega_dot_std_radps2,
                          o.initial_specific_force_std_mps2], 3)
    sig = m.accel_sigma_mps2
    axis_factors = np.asarray(o.process_axis_factors, dtype=float)
    natural_frequency_radps = 2 * np.pi * np.asarray(o.process_axis_frequencies_hz, dtype=float)
    X = np.array(x_init, dtype=float)
    for _ in range(iterations):
        rows, res = [], []

        def add(blocks, r):
            J = np.zeros((len(r), 9 * n))
            for k, B in blocks:
                J[:, 9 * k:9 * k + 9] += B
            rows.append(J)
            res.append(r)

        add([(0, np.diag(1 / prior_sd))], X[0] / prior_sd)
        for k in range(1, n):
            h = times_s[k] - times_s[k - 1]
            q = o.omega_dot_random_walk_radps2_per_sqrt_s
            if np.any(natural_frequency_radps > 0):
                phi = process.oscillator_transition(h, natural_frequency_radps)[0]
                cov = process.oscillator_step_covariance(q, h, natural_frequency_radps, axis_factors)[0]
                W = np.linalg.inv(np.linalg.cholesky(cov))
                Phi = np.zeros((6, 6))
                for i in range(3):
                    Phi[np.ix_([i, 3 + i], [i, 3 + i])] = phi[i]
                A0, A1 = np.zeros((6, 9)), np.zeros((6, 9))
                A0[:, :6], A1[:, :6] = -Phi, np.eye(6)
                add([(k - 1, W @ A0), (k, W @ A1)], W @ (X[k, :6] - Phi @ X[k - 1, :6]))
            else:
                s_int = kinematics.trapezoid_sigma(q, h) * axis_factors
                s_dw = process.random_walk_sigma(q, h) * axis_factors
                A0, A1 = np.zeros((3, 9)), np.zeros((3, 9))
                A0[:, :3], A0[:, 3:6] = -np.eye(3), -0.5 * h * np.eye(3)
                A1[:, :3], A1[:, 3:6] = np.eye(3), -0.5 * h * np.eye(3)
                r = X[k, :3] - X[k - 1, :3] - 0.5 * h * (X[k, 3:6] + X[k - 1, 3:6])
                add([(k - 1, A0 / s_int[:, None]), (k, A1 / s_int[:, None])], r / s_int)
                B0, B1 = np.zeros((3, 9)), np.zeros((3, 9))
                B0[:, 3:6], B1[:, 3:6] = -np.eye(3), np.eye(3)
                add([(k - 1, B0 / s_dw[:, None]), (k, B1 / s_dw[:, None])], (X[k, 3:6] - X[k - 1, 3:6]) / s_dw)
            s_f = process.random_walk_sigma(o.specific_force_random_walk_mps2_per_sqrt_s, h)
            C0, C1 = np.zeros((3, 9)), np.zeros((3, 9))
            C0[:, 6:], C1[:, 6:] = -np.eye(3) / s_f, np.eye(3) / s_f
            add([(k - 1, C0), (k, C1)], (X[k, 6:] - X[k - 1, 6:]) / s_f)
        filt = WindowFilter(m)
        for k in range(n):
            pred, H = filt._measure(X[k], None)
            add([(k, H / sig[:, None])], (pred - Y[k]) / sig)
        J, r = np.vstack(rows), np.concatenate(res)
        dx = np.linalg.solve(J.T @ J, -(J.T @ r))  # the normal equations: J has full column rank (the prior)
        X = X + dx.reshape(n, 9)
        if np.max(np.abs(dx)) < 1e-12:
            break
    cov = np.linalg.inv(J.T @ J)
    return X, np.sqrt(np.diag(cov)).reshape(n, 9)


@pytest.mark.parametrize("frequencies_hz", [(0.0, 0.0, 0.0), (0.8, 1.5, 0.0)])
@pytest.mark.parametrize("noise_mps2", [0.07, 0.007])
def test_window_equals_the_dense_least_squares_minimum(frequencies_hz, noise_mps2):
    """Every state of a 60-sample segment (the window holds it whole) against the dense Gauss-Newton minimum
    of the same factors: the filter linearises each reading once, so the difference shrinks faster than the
    noise (measured: 1.4e-3 rad/s at 0.07 m/s², 5.7e-5 at 0.007, 1.2e-6 at 0.0007), far inside the error
    against the truth (3e-2, 5e-3)."""
    arr = cube_array(0.05, noise_mps2)
    log = simulate("random3d", arr, rate_hz=RATE_HZ, duration_s=0.12, seed=21)
    opts = SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=40.0, process_axis_frequencies_hz=frequencies_hz,
                           process_axis_factors=(1.0, 0.5, 2.0))
    m = model.ArrayModel(arr, opts.model_groups)
    times = log.timestamps_ns * 1e-9
    truth = np.hstack([log.truth.omega_b_radps, log.truth.omega_dot_b_radps2, log.truth.specific_force_b_mps2])
    filt = WindowFilter(m, capacity=16)  # grows and compacts on the way
    for k in range(len(log)):
        if k == 0:
            filt.start(100)
        else:
            filt.predict(100 + k, times[k] - times[k - 1])
        filt.measure(log.accel_mps2[k], start=truth[k] if k == 0 else None)
    assert len(filt) == len(log)
    means = np.array([filt.mean(100 + k) for k in range(len(log))])
    sds = np.array([filt.sigma(100 + k) for k in range(len(log))])
    ref, ref_sd = dense_map(m, times, log.accel_mps2, truth)
    err = np.abs(means - ref)
    tol = {0.07: 3e-3, 0.007: 1.5e-4}[noise_mps2]
    assert err[:, :3].max() < tol
    assert err[:, 6:].max() < 10 * tol
    np.testing.assert_allclose(sds, ref_sd, rtol=2e-2)
    # the window's error against the truth is the minimum's (the comparison is not between two wrong answers)
    assert omega_rmse(means[:, :3], truth[:, :3]) < 1.05 * omega_rmse(ref[:, :3], truth[:, :3]) + tol


@pytest.mark.parametrize("scenario, array, rate_hz, duration_s, tune_window_s", [
    ("random3d", cube_array(0.05, 0.07), RATE_HZ / 2, 1.5, 1.0),  # short: iSAM2's sigma costs ~15 ms a sample
    pytest.param("random3d", cube_array(0.05, 0.07), RATE_HZ, 4.0, 1.5, marks=pytest.mark.slow),  # ~25 s each
    pytest.param("reversal", cube_array(0.05, 0.07), RATE_HZ, 4.0, 1.5, marks=pytest.mark.slow),
    pytest.param("random3d", paper001_array(), RATE_HZ, 4.0, 1.5, marks=pytest.mark.slow),
])
def test_numpy_engine_gives_the_gtsam_engines_answers(scenario, array, rate_hz, duration_s, tune_window_s):
    """The two window solvers on the same log, tuning included: the same estimates within a tenth of their
    error against the truth (a quarter with the gyroscope, whose noise is small), the same accuracy within 2 %
    and the same one-sigma values within 1 %."""
    log = simulate(scenario, array, rate_hz=rate_hz, duration_s=duration_s, seed=1)
    kw = dict(tune_window_s=tune_window_s, compute_sigma=True)
    ref = FixedLagEstimator(engine="gtsam", **kw).estimate(log).motion
    new = FixedLagEstimator(engine="numpy", **kw).estimate(log).motion
    rmse_ref = omega_rmse(ref.omega_b_radps, log.truth.omega_b_radps)
    rmse_new = omega_rmse(new.omega_b_radps, log.truth.omega_b_radps)
    share = 0.25 if array.gyroscope is not None else 0.1
    assert omega_rmse(new.omega_b_radps, ref.omega_b_radps) < share * rmse_ref
    assert rmse_new < 1.02 * rmse_ref
    f_rmse_ref = omega_rmse(ref.specific_force_b_mps2, log.truth.specific_force_b_mps2)
    assert omega_rmse(new.specific_force_b_mps2, ref.specific_force_b_mps2) < share * f_rmse_ref
    ratio = new.sigma["omega_b_radps"] / ref.sigma["omega_b_radps"]
    assert np.all(np.abs(ratio - 1) < 0.01)


def test_a_failed_update_rebuilds_the_window_once_then_names_the_time(monkeypatch):
    log = simulate("reversal", cube_array(0.05, 0.07), rate_hz=RATE_HZ, duration_s=1.0, seed=8)
    sm = FixedLagSmoother(log.array, SmootherOptions().model_groups, lag_s=0.2, rate_hz=RATE_HZ, warmup_s=0.02)
    out = []
    for i in range(300):
        out.extend(sm.push(log.timestamps_ns[i], log.accel_mps2[i]).smoothed)
    real = WindowFilter.advance  # (a sample's update: one compiled call, or the prediction then measure())
    calls = {"n": 0}

    def fail_once(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 1:
            raise FilterFailure("singular innovation covariance")
        return real(self, *a, **k)

    monkeypatch.setattr(WindowFilter, "advance", fail_once)
    with pytest.warns(RuntimeWarning, match=r"t = 0\.600000 s.*singular.*re-initialising"):
        out.extend(sm.push(log.timestamps_ns[300], log.accel_mps2[300]).smoothed)
    for i in range(301, len(log)):
        out.extend(sm.push(log.timestamps_ns[i], log.accel_mps2[i]).smoothed)
    out.extend(sm.flush())
    np.testing.assert_array_equal([s.timestamp_ns for s in out], log.timestamps_ns)
    w = np.array([s.omega_b_radps for s in out])
    assert omega_rmse(w, log.truth.omega_b_radps) < 0.05

    def always_fail(self, *a, **k):
        raise FilterFailure("singular innovation covariance")

    sm = FixedLagSmoother(log.array, SmootherOptions().model_groups, lag_s=0.2, rate_hz=RATE_HZ, warmup_s=0.02)
    for i in range(50):
        sm.push(log.timestamps_ns[i], log.accel_mps2[i])
    monkeypatch.setattr(WindowFilter, "measure", always_fail)
    monkeypatch.setattr(WindowFilter, "advance", always_fail)
    with pytest.warns(RuntimeWarning), pytest.raises(FixedLagSmootherError,
                                                     match=r"failed at t = 0\.000000 s.*singular"):  # the rebuild's first
        sm.push(log.timestamps_ns[50], log.accel_mps2[50])


def test_unknown_engine_is_refused():
    with pytest.raises(ValueError, match="^fixed-lag smoother option engine must be 'numpy' or 'gtsam', got 'cuda'$"):
        FixedLagSmoother(cube_array(), SmootherOptions().model_groups, engine="cuda")
