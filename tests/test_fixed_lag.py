"""Fixed-lag smoother (method "fixed-lag") and its streaming API."""

from dataclasses import replace

import gtsam
import numpy as np
import pytest

from gfimu.array import Gyroscope, cube_array, paper001_array, single_triad
from gfimu.methods import make_estimator
from gfimu.factors import accelerometer, kinematics, process
from gfimu.log import Log
from gfimu.simulate import SensorErrors, simulate
from gfimu.smoother.stream import array_model as model
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator, FixedLagSmoother, FixedLagSmootherError, fixed_lag_reason
from gfimu.smoother.model.problem import SmootherOptions

RATE_HZ = 500.0


def omega_rmse(motion, truth):
    e = motion.omega_b_radps - truth.omega_b_radps
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


def wrong_sign_share(motion, truth, min_norm_radps=0.5):
    """Share of samples with |ω| > min_norm whose estimate points to the other half-space."""
    w = truth.omega_b_radps
    big = np.linalg.norm(w, axis=1) > min_norm_radps
    return float(np.mean(np.sum(motion.omega_b_radps * w, axis=1)[big] < 0))


def values_of(keys_and_vectors):
    values = gtsam.Values()
    for key, v in keys_and_vectors:
        values.insert(key, np.asarray(v, dtype=float))
    return values


# --- factors: the fast path equals gfimu.factors ------------------------------------------

def test_fast_accelerometer_factor_equals_per_sensor_factors_and_numerical_jacobian():
    rng = np.random.default_rng(4)
    arr = cube_array(0.05, 0.07)
    m = model.ArrayModel(arr, SmootherOptions().model_groups, fast_measurement=True)
    w, dw, f = rng.normal(size=(3, 3)) * [[4.0], [30.0], [9.0]]
    y = arr.predict_readings(f, dw, w) + rng.normal(0, 0.3, arr.n_axes)
    kw, kd, kf = model.keys(7)
    assert (kw, kd, kf) == (gtsam.symbol("w", 7), gtsam.symbol("d", 7), gtsam.symbol("f", 7))
    graph = gtsam.NonlinearFactorGraph()
    m.add_measurement(graph, 7, y)
    fast = graph.at(0)
    values = values_of([(kw, w), (kd, dw), (kf, f)])
    r_fast = fast.unwhitenedError(values)
    r_ref = np.concatenate([
        accelerometer.accelerometer_residual(w, dw, f, y[cols], d, p)[0][0] for d, p, cols, _ in m.sensors])
    np.testing.assert_allclose(r_fast, r_ref, atol=1e-12)
    # Jacobian of the whitened error against central differences
    lin = fast.linearize(values)
    A, b = lin.jacobian()
    eps = 1e-6
    num = []
    for key, x in ((kw, w), (kd, dw), (kf, f)):
        for i in range(3):
            e = np.zeros(3)
            e[i] = eps
            others = [(k, v) for k, v in ((kw, w), (kd, dw), (kf, f)) if k != key]
            plus = fast.whitenedError(values_of(others + [(key, x + e)]))
            minus = fast.whitenedError(values_of(others + [(key, x - e)]))
            num.append((plus - minus) / (2 * eps))
    num = np.column_stack(num)
    order = [list(lin.keys()).index(k) for k in (kw, kd, kf)]
    A_ordered = np.hstack([A[:, 3 * j:3 * j + 3] for j in order])
    np.testing.assert_allclose(A_ordered, num, rtol=1e-6, atol=1e-5)


@pytest.mark.parametrize("frequencies_hz", [(0.0, 0.0, 0.0), (1.5, 0.0, 3.0)])
def test_steps_prepared_at_once_are_the_steps_made_one_at_a_time(frequencies_hz):
    """ArrayModel.prepare_steps (the step lengths another model met, made in one view) gives each step
    length the very numbers step() makes for it alone: rows, transition and noise, bit for bit."""
    opts = SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=7.5, process_axis_factors=(0.1, 0.5, 2.0),
                           specific_force_random_walk_mps2_per_sqrt_s=0.4, process_axis_frequencies_hz=frequencies_hz)
    keys = [16_000_123, 15_999_877, 16_000_000, 2_000_000, 50_000]
    alone, at_once = (model.ArrayModel(cube_array(), opts.model_groups, fast_measurement=True) for _ in range(2))
    at_once.prepare_steps(keys + [16_000_000, 0])
    assert sorted(at_once._step_cache) == sorted(keys)
    for key in keys:
        a, b = alone.step(key * 1e-9), at_once._step_cache[key][1.0]
        assert at_once.step(key * 1e-9) is b  # (taken from the cache)
        for name in ("J0", "J1", "r0", "F", "FT", "Q"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert a.c is None and b.c is None and a.H0 is None and b.H0 is None
        for x, y in zip(alone._step_cache[key]["rows"], at_once._step_cache[key]["rows"]):
            assert np.array_equal(x, y)
        assert np.array_equal(alone.step(key * 1e-9, 0.3).Q, at_once.step(key * 1e-9, 0.3).Q)


def test_step_is_the_white_jerk_of_the_batch_model():
    """The stream's step comes from the batch model's groups: for the white jerk its transition is
    x1 = [[I, h I], [0, I]] x0 on (ω, ω̇) and f1 = f0, its noise the closed form of the trapezoid and the
    ω̇ random walk (σ_int² + h²/4 σ_ω̇², h/2 σ_ω̇², σ_ω̇² per axis, σ_f² on f), and the gtsam engine's factor
    has the error of those three residuals, whitened."""
    rng = np.random.default_rng(5)
    opts = SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=7.5, process_axis_factors=(0.1, 0.5, 2.0),
                           specific_force_random_walk_mps2_per_sqrt_s=0.4)
    m = model.ArrayModel(cube_array(), opts.model_groups, fast_measurement=True)
    h = 0.002
    step = m.step(h)
    I3 = np.eye(3)
    F = np.eye(9)
    F[0:3, 3:6] = h * I3
    np.testing.assert_allclose(step.F, F, atol=1e-12)
    axis = np.array([0.1, 0.5, 2.0])
    s_int = kinematics.trapezoid_sigma(7.5, h) * axis
    s_dw = process.random_walk_sigma(7.5, h) * axis
    s_f = process.random_walk_sigma(0.4, h)
    Q = np.zeros((9, 9))
    Q[0:3, 0:3] = np.diag(s_int**2 + 0.25 * h * h * s_dw**2)
    Q[0:3, 3:6] = Q[3:6, 0:3] = np.diag(0.5 * h * s_dw**2)
    Q[3:6, 3:6] = np.diag(s_dw**2)
    Q[6:, 6:] = s_f**2 * I3
    np.testing.assert_allclose(step.Q, Q, rtol=1e-9, atol=1e-18)
    assert step.c is None and step.H0 is None
    graph = gtsam.NonlinearFactorGraph()
    m.add_process(graph, 3, 4, h)
    assert graph.size() == 1
    w0, w1, d0, d1, f0, f1 = rng.normal(size=(6, 3))
    keys0, keys1 = model.keys(3), model.keys(4)
    values = values_of([(keys0[0], w0), (keys1[0], w1), (keys0[1], d0), (keys1[1], d1), (keys0[2], f0), (keys1[2], f1)])
    r_trap, _ = kinematics.angular_velocity_residual(w0, w1, d0, d1, h)
    expected = 0.5 * (np.sum((r_trap[0] / s_int) ** 2) + np.sum(((d1 - d0) / s_dw) ** 2) + np.sum(((f1 - f0) / s_f) ** 2))
    assert graph.at(0).error(values) == pytest.approx(expected, rel=1e-10)


def test_fast_and_shared_factor_paths_give_the_same_estimate():
    log = simulate("reversal", cube_array(0.05, 0.07), rate_hz=RATE_HZ, duration_s=0.8, seed=10)
    fast = FixedLagEstimator(fast_measurement=True, tune_process_noise=False).estimate(log).motion
    shared = FixedLagEstimator(fast_measurement=False, tune_process_noise=False).estimate(log).motion
    np.testing.assert_allclose(fast.omega_b_radps, shared.omega_b_radps, atol=1e-6)
    np.testing.assert_allclose(fast.specific_force_b_mps2, shared.specific_force_b_mps2, atol=1e-6)


# --- accuracy -----------------------------------------------------------------------------

def test_noise_free_random_motion_is_recovered():
    log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=RATE_HZ, duration_s=2.0, noise=SensorErrors.none(), seed=3)
    est = FixedLagEstimator(tune_process_noise=False).estimate(log).motion
    assert omega_rmse(est, log.truth) < 2e-3
    e_dw = est.omega_dot_b_radps2 - log.truth.omega_dot_b_radps2
    e_f = est.specific_force_b_mps2 - log.truth.specific_force_b_mps2
    assert np.sqrt(np.mean(np.sum(e_dw**2, axis=1))) < 0.05
    assert np.sqrt(np.mean(np.sum(e_f**2, axis=1))) < 2e-3


def test_sign_carried_through_zero_crossings_when_starting_spinning():
    """ω(t) = ω₀ cos(2π 0.5 t) about a tilted axis: starts at full rate, crosses zero twice."""
    arr = cube_array(0.05, 0.07)
    t = np.arange(int(4.0 * RATE_HZ)) / RATE_HZ
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    w = -6.0 * np.cos(np.pi * t)[:, None] * axis
    dw = 6.0 * np.pi * np.sin(np.pi * t)[:, None] * axis
    f = np.column_stack([np.sin(t), np.cos(t), np.full_like(t, 9.8)])
    y = arr.predict_readings(f, dw, w) + np.random.default_rng(0).normal(0, 0.07, (t.size, arr.n_axes))
    log = Log(arr, np.round(t * 1e9).astype(np.int64), y)
    est = FixedLagEstimator().estimate(log).motion
    from gfimu.motion import Motion
    truth = Motion(log.timestamps_ns, omega_b_radps=w)
    assert wrong_sign_share(est, truth) == 0.0
    assert omega_rmse(est, truth) < 0.05


def test_gyroscope_is_used():
    """Lu, Tsai & Lin 2010's 9-axis array with a gyro: ω follows the gyro (noise 0.01 rad/s) closely."""
    arr = paper001_array()
    log = simulate("random3d", arr, rate_hz=RATE_HZ, duration_s=1.5, seed=2)
    assert log.gyro_b_radps is not None
    est = FixedLagEstimator(tune_process_noise=False).estimate(log).motion
    assert omega_rmse(est, log.truth) < 0.01


# --- streaming API ------------------------------------------------------------------------

def test_push_returns_lagged_smoothed_states_and_newest_filtered():
    log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=RATE_HZ, duration_s=1.2, seed=4)
    lag_s = 0.1
    # no hold of the start (hold_max_s=0): every row comes out lag_s after its sample once the warm-up is done
    sm = FixedLagSmoother(log.array, SmootherOptions().model_groups, lag_s=lag_s, rate_hz=RATE_HZ, warmup_s=0.05, hold_max_s=0.0)
    lag_ns = round(lag_s * 1e9)
    emitted = []
    warmup_n = int(round(0.05 * RATE_HZ))
    for i in range(len(log)):
        upd = sm.push(log.timestamps_ns[i], log.accel_mps2[i])
        if i < warmup_n - 1:
            assert upd.filtered is None and upd.smoothed == ()
            continue
        assert upd.filtered.timestamp_ns == log.timestamps_ns[i]
        for s in upd.smoothed:
            assert log.timestamps_ns[i] - s.timestamp_ns >= lag_ns - 1000
        if i > warmup_n + lag_s * RATE_HZ:  # steady state: exactly the sample at t - lag
            assert [s.timestamp_ns for s in upd.smoothed] == [log.timestamps_ns[i] - lag_ns]
        emitted.extend(upd.smoothed)
    rest = sm.flush()
    emitted.extend(rest)
    assert len(rest) == int(lag_s * RATE_HZ)
    np.testing.assert_array_equal([s.timestamp_ns for s in emitted], log.timestamps_ns)
    # the newest filtered estimate is worse than the smoothed one, both are sane
    filtered_err = np.linalg.norm(upd.filtered.omega_b_radps - log.truth.omega_b_radps[-1])
    assert filtered_err < 0.2


def test_memory_stays_bounded_over_a_long_stream():
    """60 s at 100 Hz (6000 samples): gtsam's keys and factors and the Python window stay bounded."""
    rate_hz, lag_s, block_s = 100.0, 0.2, 0.3
    log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=rate_hz, duration_s=60.0, seed=5)
    sm = FixedLagSmoother(log.array, SmootherOptions().model_groups, lag_s=lag_s, rate_hz=rate_hz, marginalise_every_s=block_s)
    max_states = int(np.ceil((lag_s + 2 * block_s) * rate_hz)) + 3
    keys, factors, window = [], [], []
    smoothed = 0
    for i in range(len(log)):
        smoothed += len(sm.push(log.timestamps_ns[i], log.accel_mps2[i]).smoothed)
        if i % 97 == 0:
            keys.append(sm.n_keys)
            factors.append(sm.n_factor_slots)
            window.append(sm.window_length)
    assert max(keys) <= 3 * max_states
    assert max(window) <= lag_s * rate_hz + 2
    # factor slots are reused: the last quarter holds no more than the second quarter
    q = len(factors) // 4
    assert max(factors[-q:]) <= max(factors[q:2 * q]) + 10
    assert smoothed + len(sm.flush()) == len(log)


def test_gap_restarts_without_integrating_across():
    """A 0.5 s hole in the data: both sides accurate, and the push after the hole flushes the window."""
    full = simulate("random3d", cube_array(0.05, 0.07), rate_hz=RATE_HZ, duration_s=3.0, seed=6)
    keep = np.ones(len(full), bool)
    keep[600:850] = False
    log = Log(full.array, full.timestamps_ns[keep], full.accel_mps2[keep], truth=full.truth.select(keep))
    assert len(log.gaps()) == 1
    est = FixedLagEstimator().estimate(log).motion
    assert np.all(np.isfinite(est.omega_b_radps))
    assert omega_rmse(est, log.truth) < 0.05
    assert wrong_sign_share(est, log.truth) == 0.0
    sm = FixedLagSmoother(log.array, SmootherOptions().model_groups, lag_s=0.2, rate_hz=RATE_HZ)
    out = []
    for i in range(600):
        out.extend(sm.push(log.timestamps_ns[i], log.accel_mps2[i]).smoothed)
    assert len(out) == 600 - 100  # the window after sample 599 holds 0.2 s
    # sample 600 comes after the gap: the old window is flushed, the new segment is warming up
    upd = sm.push(log.timestamps_ns[600], log.accel_mps2[600])
    assert len(upd.smoothed) == 100 and upd.filtered is None
    np.testing.assert_array_equal([s.timestamp_ns for s in out + list(upd.smoothed)], log.timestamps_ns[:600])
    assert sm.window_length == 1


def test_jittery_timestamps_every_sample_estimated_once():
    """Steps of 0.6 to 1.45 nominal steps (no gaps): each sample comes out once, in order, accurate."""
    rng = np.random.default_rng(11)
    arr = cube_array(0.05, 0.07)
    h = 1.0 / RATE_HZ
    t = np.cumsum(np.r_[0.0, rng.uniform(0.6, 1.45, 1499) * h])
    w = np.column_stack([2.0 * np.sin(2.0 * t), 1.5 * np.cos(1.3 * t), 3.0 * np.sin(0.9 * t + 0.4)])
    dw = np.column_stack([4.0 * np.cos(2.0 * t), -1.95 * np.sin(1.3 * t), 2.7 * np.cos(0.9 * t + 0.4)])
    f = np.column_stack([np.sin(t), np.cos(t), np.full_like(t, 9.8)])
    y = arr.predict_readings(f, dw, w) + rng.normal(0, 0.07, (t.size, arr.n_axes))
    log = Log(arr, np.round(t * 1e9).astype(np.int64), y)
    assert log.gaps() == []
    est = FixedLagEstimator(gap_factor=2.0, tune_process_noise=False).estimate(log).motion
    from gfimu.motion import Motion
    truth = Motion(log.timestamps_ns, omega_b_radps=w)
    assert omega_rmse(est, truth) < 0.03
    assert wrong_sign_share(est, truth) == 0.0


def test_sigma_matches_the_actual_error():
    log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=RATE_HZ, duration_s=1.5, seed=7)
    est = FixedLagEstimator(compute_sigma=True, tune_process_noise=False).estimate(log).motion
    sig = est.sigma["omega_b_radps"]
    assert np.all(np.isfinite(sig)) and np.all(sig > 0)
    err = est.omega_b_radps - log.truth.omega_b_radps
    ratio = np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(sig**2))
    assert 0.5 < ratio < 2.0


# --- errors -------------------------------------------------------------------------------

def test_bad_input_is_refused_with_the_cause():
    arr = cube_array()
    sm = FixedLagSmoother(arr, SmootherOptions().model_groups, lag_s=0.2, rate_hz=RATE_HZ)
    with pytest.raises(ValueError, match="12 axes"):
        sm.push(0, np.zeros(5))
    bad = np.zeros(12)
    bad[4] = np.nan
    with pytest.raises(ValueError, match="a2_y"):
        sm.push(0, bad)
    sm.push(1000, np.zeros(12))
    assert sm.push(1000, np.zeros(12)).dropped == "duplicate" and sm.n_duplicates == 1
    with pytest.raises(ValueError, match="lag_s"):
        FixedLagSmoother(arr, SmootherOptions().model_groups, lag_s=0.0)
    assert "gyroscope" in FixedLagEstimator().applicable(single_triad())
    assert FixedLagEstimator().applicable(replace(single_triad(), gyroscope=Gyroscope(0.01))) is None
    assert "self_calibrate_bias" in fixed_lag_reason(arr, SmootherOptions(self_calibrate_bias=True).model_groups)
    assert "motion_model" in FixedLagEstimator(motion_model="snap").applicable(arr)
    with pytest.raises(ValueError, match="no option"):
        make_estimator("fixed-lag", lag=0.2)


class _FailingSmoother:
    def update(self, *args):
        raise RuntimeError("Indeterminant linear system detected while working near variable 8574853690513424434")


def test_gtsam_solver_failure_rebuilds_the_window_once_then_reports_the_time(monkeypatch):
    log = simulate("reversal", cube_array(0.05, 0.07), rate_hz=RATE_HZ, duration_s=1.0, seed=8)
    sm = FixedLagSmoother(log.array, SmootherOptions().model_groups, lag_s=0.2, rate_hz=RATE_HZ, warmup_s=0.02, engine="gtsam")
    out = []
    for i in range(300):
        out.extend(sm.push(log.timestamps_ns[i], log.accel_mps2[i]).smoothed)
    # one failed update of gtsam's smoother (inside the engine): a warning, the window is rebuilt from
    # its raw samples, nothing is lost
    monkeypatch.setattr(sm._segment.engine, "_smoother", _FailingSmoother())
    with pytest.warns(RuntimeWarning, match=r"t = 0\.600000 s.*Indeterminant.*re-initialising"):
        upd = sm.push(log.timestamps_ns[300], log.accel_mps2[300])
    out.extend(upd.smoothed)
    for i in range(301, len(log)):
        out.extend(sm.push(log.timestamps_ns[i], log.accel_mps2[i]).smoothed)
    out.extend(sm.flush())
    np.testing.assert_array_equal([s.timestamp_ns for s in out], log.timestamps_ns)
    w = np.array([s.omega_b_radps for s in out])
    from gfimu.motion import Motion
    est = Motion(log.timestamps_ns, omega_b_radps=w)
    assert wrong_sign_share(est, log.truth) == 0.0
    assert omega_rmse(est, log.truth) < 0.05
    # a failure that persists: a clear error naming the time
    sm = FixedLagSmoother(log.array, SmootherOptions().model_groups, lag_s=0.2, rate_hz=RATE_HZ, warmup_s=0.02, engine="gtsam")
    for i in range(50):
        sm.push(log.timestamps_ns[i], log.accel_mps2[i])
    monkeypatch.setattr(sm._segment.engine, "_smoother", _FailingSmoother())
    new_engine = sm._new_smoother

    def failing_engine():
        engine = new_engine()
        engine._smoother = _FailingSmoother()
        return engine

    monkeypatch.setattr(sm, "_new_smoother", failing_engine)
    with pytest.warns(RuntimeWarning), pytest.raises(FixedLagSmootherError, match=r"t = 0\.100000 s.*Indeterminant"):
        sm.push(log.timestamps_ns[50], log.accel_mps2[50])


# --- command line -------------------------------------------------------------------------

def test_cli_estimate_fixed_lag_on_a_log_folder(tmp_path, capsys):
    from gfimu import io as gio
    from gfimu.cli import main

    log = simulate("reversal", cube_array(0.05, 0.07), rate_hz=RATE_HZ, duration_s=1.5, seed=9)
    gio.write_log(log, tmp_path / "log")
    out = tmp_path / "fl.csv"
    assert main(["estimate", str(tmp_path / "log"), "--method", "fixed-lag", "--lag-s", "0.1", "--out", str(out),
                 "--no-progress"]) == 0
    est = gio.read_motion_csv(out)
    np.testing.assert_array_equal(est.timestamps_ns, log.timestamps_ns)
    assert omega_rmse(est, log.truth) < 0.05
    direct = FixedLagEstimator(lag_s=0.1).estimate(gio.read_log(tmp_path / "log")).motion
    np.testing.assert_allclose(est.omega_b_radps, direct.omega_b_radps, atol=1e-5)


@pytest.mark.parametrize("rate_hz, lag_s, screen, expected_s", [
    (500.0, 0.2, True, 0.2 - (28 + 10) / 500.0),  # the screening's 28 samples and a 10-sample block inside the lag
    (20000.0, 0.2, True, 0.2 - (28 + 400) / 20000.0),
    (62.5, 0.2, True, 0.2),  # 28 samples are 0.45 s at 62.5 Hz: more than half the lag, so on top of it
    (500.0, 0.1, True, 0.1),  # 0.076 s is more than half of 0.1 s
    (500.0, 0.2, False, 0.2),  # no screening, nothing to wait for
])
def test_the_screenings_wait_is_taken_from_the_lag_where_it_fits(rate_hz, lag_s, screen, expected_s):
    """lag_s is the delay of an estimate after its sample arrives: the stream screening's wait comes out of
    the smoother's own lag where it is at most half of it."""
    from gfimu.smoother.stream.fixed_lag import FixedLagEstimator

    estimator = FixedLagEstimator(lag_s=lag_s, screen_readings=screen)
    assert estimator.window_lag_s(rate_hz) == pytest.approx(expected_s, rel=1e-12)
