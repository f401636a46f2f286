"""Screening of accelerometer readings for gross errors (gfimu.readings) and its use by the CLI."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.readings import screen, screen_log
from gfimu.simulate import simulate

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    """The clean 10 s log (random3d, 500 Hz, seed 3) written once, and its estimate by each method computed once
    for the module: ``clean_run(method)`` gives (log, log folder, estimate CSV, command before ``--out``)."""
    root = tmp_path_factory.mktemp("clean")
    log = simulate("random3d", seed=3)
    folder = root / "log"
    gio.write_log(log, folder)
    done = {}

    def run(method):
        cmd = [sys.executable, "-m", "gfimu", "estimate", str(folder), "--method", method, "--no-progress"]
        if method not in done:
            clean = root / f"clean-{method}.csv"
            assert subprocess.run(cmd + ["--out", str(clean)], env=ENV, capture_output=True).returncode == 0
            done[method] = clean
        return log, folder, done[method], cmd

    return run


def test_clean_logs_are_left_alone():
    log = simulate("random3d", seed=1)
    clean, result = screen_log(log)
    assert result.count == 0 and clean is log


def test_gross_errors_found_and_replaced_by_the_neighbours_median():
    rng = np.random.default_rng(0)
    t = np.arange(2000) * 0.002
    y = np.column_stack([np.sin(2 * np.pi * t), np.cos(3 * t), 9.81 + 0.0 * t]) + rng.normal(size=(2000, 3)) * 0.05
    bad = y.copy()
    bad[100, 0], bad[500, 1], bad[900, 2], bad[1300, 0] = np.nan, 1e30, 9.81 + 1000.0, 200.0
    out, result = screen(bad, range_mps2=np.array([160.0, np.nan, np.nan]), sensor_of_axis=np.array([0, 1, 2]))
    # 1e30 is beyond any accelerometer's range (readings.OUT_OF_ANY_RANGE_MPS2), stated or not
    assert result.replaced.sum() == 4 and result.non_finite == 1 and result.out_of_range == 2 and result.spikes == 1
    assert set(zip(*np.nonzero(result.replaced))) == {(100, 0), (500, 1), (900, 2), (1300, 0)}
    for r, c in ((100, 0), (500, 1), (900, 2), (1300, 0)):
        assert abs(out[r, c] - np.median(y[r - 2:r + 3, c])) < 0.2  # the neighbours' level
    np.testing.assert_array_equal(out[~result.replaced], bad[~result.replaced])
    assert "row 100 x" in result.describe(["x", "y", "z"])


def test_a_spike_on_every_accelerometer_at_once_is_motion():
    """A knock felt by two accelerometers at the same sample is kept (a real event of the body)."""
    y = np.zeros((200, 6)) + np.random.default_rng(1).normal(size=(200, 6)) * 0.01
    y[100, 0] += 50.0
    y[100, 3] += 50.0
    _, result = screen(y, sensor_of_axis=np.array([0, 0, 0, 1, 1, 1]))
    assert result.count == 0
    _, alone = screen(y, sensor_of_axis=np.array([0, 0, 0, 0, 0, 0]))
    assert alone.count == 2


@pytest.mark.parametrize("power", [1, 2])
def test_a_smooth_ramp_is_not_a_spike_at_the_first_or_last_row(power):
    """One triad, noise free, every axis a line or a parabola in time: nothing is replaced, not even at the ends,
    where the median window is cut short."""
    t = np.arange(400) * 0.01
    y = np.column_stack([0.5 + 3.0 * t ** power, 9.81 - 2.0 * t ** power, -1.0 + 0.7 * t ** power])
    out, result = screen(y, sensor_of_axis=np.zeros(3, dtype=int), rate_hz=100.0)
    assert result.count == 0, result.describe(["x", "y", "z"])
    np.testing.assert_array_equal(out, y)


@pytest.mark.parametrize("power", [1, 2])
@pytest.mark.parametrize("row", [0, 1, -2, -1])
def test_a_spike_at_the_first_or_last_rows_of_a_ramp_is_still_found(power, row):
    rng = np.random.default_rng(2)
    t = np.arange(400) * 0.01
    y = np.column_stack([0.5 + 3.0 * t ** power, 9.81 - 2.0 * t ** power, -1.0 + 0.7 * t ** power])
    y += rng.normal(size=y.shape) * 0.01
    bad = y.copy()
    bad[row, 1] += 100.0
    out, result = screen(bad, sensor_of_axis=np.zeros(3, dtype=int), rate_hz=100.0)
    assert result.spikes == 1 and result.replaced[row, 1] and result.count == 1
    assert abs(out[row, 1] - y[row, 1]) < 0.5  # back near the ramp
    _, clean = screen(y, sensor_of_axis=np.zeros(3, dtype=int), rate_hz=100.0)
    assert clean.count == 0


@pytest.mark.parametrize("method", ["smoother", "ml"])
@pytest.mark.parametrize("value", ["1e30", "spike"])
def test_one_corrupt_cell_does_not_spoil_the_estimate(tmp_path, clean_run, method, value):
    """10 s at 500 Hz, one corrupt cell (1e30, or 1000 m/s² added to one sensor's axis): the ω RMSE
    away from it (±0.5 s) stays within 1.5x of the clean log's, exit 0, a warning naming the row."""
    log, folder, clean, run = clean_run(method)
    row, col = 2500, 4
    y = log.accel_mps2.copy()
    y[row, col] = 1e30 if value == "1e30" else y[row, col] + 1000.0
    bad = tmp_path / "bad"
    gio.write_log(log.replace(accel_mps2=y), bad)
    out = tmp_path / "bad.csv"
    proc = subprocess.run(run[:4] + [str(bad)] + run[5:] + ["--out", str(out)], env=ENV, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert f"row {row} {log.array.accel_columns[col]}" in proc.stderr
    away = np.abs(log.times_s - log.times_s[row]) > 0.5

    def rmse(path):
        w = gio.read_motion_csv(path).omega_b_radps
        return float(np.sqrt(np.mean(np.sum((w[away] - log.truth.omega_b_radps[away]) ** 2, axis=1))))

    assert rmse(out) < 1.5 * rmse(clean), (rmse(out), rmse(clean))


def test_stuck_and_clipped_runs_found_and_replaced_by_the_rigid_body_prediction():
    """Five triads (15 axes): a stuck channel and a channel clipped at its range are replaced by the prediction of
    the other 14 axes, within a few noise stds of the truth; the rest is untouched."""
    from gfimu.array import random_array

    array = random_array(5, 0.05, noise_std_mps2=0.02, seed=3)
    log = simulate("random3d", array=array, seed=4)
    exact = log.array.predict_readings(log.truth.specific_force_b_mps2, log.truth.omega_dot_b_radps2,
                                       log.truth.omega_b_radps)
    y = log.accel_mps2.copy()
    y[1000:1400, 2] = y[1000, 2]
    limit = 0.9 * np.abs(y[:, 7]).max()
    rng = np.full(15, np.inf)
    rng[7] = limit
    y[:, 7] = np.clip(y[:, 7], -limit, limit)
    out, result = screen(y, rng, array.axis_owner, 500.0, array.structure_matrix())
    assert result.stuck == 400 and result.clipped == int(np.sum(np.abs(log.accel_mps2[:, 7]) >= 0.999 * limit))
    assert ("stuck", 2, 1000, 1399) in result.runs
    assert np.all(result.replaced[1000:1400, 2]) and not result.replaced[1400:, 2].any()
    err = (out - exact)[result.replaced]
    assert np.sqrt(np.mean(err**2)) < 0.1, np.sqrt(np.mean(err**2))  # 14 axes at 0.02 m/s² predict the 15th
    np.testing.assert_array_equal(out[~result.replaced], y[~result.replaced])
    assert "a" in result.describe(array.accel_columns) and "stuck rows 1000-1399" in result.describe(array.accel_columns)


def test_a_quiet_array_at_rest_is_not_stuck():
    """Every channel repeating (a still, coarsely quantised array) is rest, not a stuck channel."""
    y = np.round(np.random.default_rng(0).normal(size=(2000, 6)) * 0.3) * 0.05 + 9.81
    y[500:1500] = y[500]  # all channels still at once
    _, result = screen(y, sensor_of_axis=np.array([0, 0, 0, 1, 1, 1]), rate_hz=500.0)
    assert result.stuck == 0


@pytest.mark.parametrize("method", ["smoother", "ml"])
def test_a_stuck_channel_and_a_clipped_stretch_do_not_spoil_the_estimate(tmp_path, clean_run, method):
    """10 s at 500 Hz on the 5 cm cube: one channel stuck for 1 s, one clipped at its stated range; the ω RMSE away
    from them (±0.5 s) stays within 1.5x of the clean log's, exit 0, a warning naming the runs."""
    from dataclasses import replace as dc_replace

    log, folder, clean, run = clean_run(method)
    y = log.accel_mps2.copy()
    y[2000:2500, 4] = y[2000, 4]  # a2_y stuck for 1 s
    limit = 0.85 * np.abs(y[:, 7]).max()  # a3_y clipped at a stated range below its peaks
    clipped = np.abs(y[:, 7]) >= limit
    y[:, 7] = np.clip(y[:, 7], -limit, limit)
    accs = [dc_replace(a, range_mps2=float(limit)) if a.name == "a3" else a for a in log.array.accelerometers]
    bad = tmp_path / "bad"
    gio.write_log(log.replace(accel_mps2=y, array=log.array.with_accelerometers(accs)), bad)
    out = tmp_path / "bad.csv"
    proc = subprocess.run(run[:4] + [str(bad)] + run[5:] + ["--out", str(out)], env=ENV, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "a2_y stuck rows 2000-2499" in proc.stderr and "a3_y clipped rows" in proc.stderr
    assert f"{int(clipped.sum())} clipped at the range" in proc.stderr and "500 stuck" in proc.stderr
    t = log.times_s
    faulty = np.zeros(len(log), bool)
    faulty[2000:2500] = True
    faulty |= clipped
    near = np.array([np.any(np.abs(t[faulty] - ti) <= 0.5) for ti in t])
    away = ~near
    assert away.sum() > 1000

    def rmse(path):
        w = gio.read_motion_csv(path).omega_b_radps
        return float(np.sqrt(np.mean(np.sum((w[away] - log.truth.omega_b_radps[away]) ** 2, axis=1))))

    assert rmse(out) < 1.5 * rmse(clean), (rmse(out), rmse(clean))


def test_rolling_median_equals_the_nan_aware_median_of_every_window():
    import warnings

    from gfimu.readings import _rolling_median

    rng = np.random.default_rng(1)
    for n in (1, 2, 3, 7, 500):
        x = rng.normal(size=(n, 4))
        x[rng.random((n, 4)) < 0.1] = np.nan
        if n > 3:
            x[:, 2] = np.nan  # a whole column missing
        for half in (1, 2, 5):
            padded = np.concatenate([np.full((half, 4), np.nan), x, np.full((half, 4), np.nan)])
            windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1, axis=0)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                expected = np.nanmedian(windows, axis=2)
            assert np.array_equal(_rolling_median(x, half), expected, equal_nan=True)


def test_a_reading_of_1e308_is_out_of_range_without_a_stated_range():
    """No accelerometer reads 1e308 m/s²: replaced as out of range (before, it overflowed the spike test,
    stayed, and made the estimate infinite)."""
    y = np.column_stack([np.sin(np.arange(300) * 0.05), np.zeros(300), 9.81 + np.zeros(300)])
    y += np.random.default_rng(3).normal(size=y.shape) * 0.01
    bad = y.copy()
    bad[150, 1] = 1e308
    bad[151, 1] = -1e7 * 1.0001
    with np.errstate(all="raise"):
        out, result = screen(bad)
    assert result.out_of_range == 2 and result.count == 2
    assert np.all(np.isfinite(out)) and abs(out[150, 1]) < 0.05 and abs(out[151, 1]) < 0.05


def _stream_screened(array, y, timestamps_ns, rate_hz, range_mps2=None):
    """(rows out of a StreamScreen pushed the rows of ``y`` one by one and flushed, its Screening), with the given
    per-axis range (the array's when None)."""
    from types import SimpleNamespace

    from gfimu.readings import StreamScreen

    view = SimpleNamespace(accel_columns=array.accel_columns, axis_owner=array.axis_owner,
                           structure_matrix=array.structure_matrix,
                           range_per_axis_mps2=array.range_per_axis_mps2 if range_mps2 is None else range_mps2)
    stream = StreamScreen(view, rate_hz)
    rows = []
    for t, row in zip(timestamps_ns, y):
        rows.extend(stream.push(t, row))
    rows.extend(stream.flush())
    return rows, stream.screening(len(y))


@pytest.mark.parametrize("rate_hz", [62.5, 500.0, 2000.0])
@pytest.mark.parametrize("case", range(4))
def test_the_stream_screening_takes_the_whole_log_decisions(rate_hz, case):
    """Readings screened as they come (StreamScreen, each decided from a buffer around it) get the decisions and the
    values of screen() on the whole log, at 62.5-2000 Hz: spikes (also at the first and last rows), readings that are
    not finite or beyond any range, a channel stuck for 5 samples to 0.6 s, a channel clipped at its stated range, a
    run of 35 missing readings; every row comes out once, in order, with its own timestamp. The one difference: the
    stream does not wait for a stuck run, so where the shortest stuck run is longer than the delay (at 500 and
    2000 Hz) a run's first readings, at most stuck_min_samples - 1 - delay of them, pass as they are."""
    from gfimu.array import random_array

    array = random_array(5, 0.05, noise_std_mps2=0.02, seed=3)
    log = simulate("random3d", array=array, seed=4, rate_hz=rate_hz, duration_s=min(10.0, 4000 / rate_hz))
    n = len(log)
    rng = np.random.default_rng(case)
    y = log.accel_mps2.copy()
    k, c = rng.integers(0, n, size=8), rng.integers(0, 15, size=8)
    y[k, c] += rng.choice([-1, 1], 8) * rng.uniform(5, 500, 8)
    y[rng.integers(0, n, 3), rng.integers(0, 15, 3)] = np.nan
    y[rng.integers(0, n, 2), rng.integers(0, 15, 2)] = 1e9
    start, length, column = rng.integers(0, n - 1), rng.integers(5, int(0.6 * rate_hz)), rng.integers(0, 15)
    y[start:start + length, column] = y[start, column]
    limit = np.full(15, np.inf)
    clipped = rng.integers(0, 15)
    limit[clipped] = 0.8 * np.nanmax(np.abs(y[:, clipped][np.abs(y[:, clipped]) < 1e8]))
    y[:, clipped] = np.clip(y[:, clipped], -limit[clipped], limit[clipped])
    if case == 1:
        y[:2, 1], y[-2:, 4] = 77.0, -55.0
    if case == 2:
        y[5:40, 6] = np.nan
    from gfimu.readings import stream_delay_samples, stuck_min_samples

    whole, expected = screen(y, limit, array.axis_owner, rate_hz, array.structure_matrix())
    rows, got = _stream_screened(array, y, log.timestamps_ns, rate_hz, limit)
    assert [r[0] for r in rows] == log.timestamps_ns.tolist()
    assert expected.count > 0
    passed = max(stuck_min_samples(rate_hz) - 1 - stream_delay_samples(rate_hz), 0)
    missed = expected.replaced & ~got.replaced
    assert not np.any(got.replaced & ~expected.replaced)
    first_of_run = np.zeros_like(missed)
    first_of_run[start:start + passed, column] = True
    assert not np.any(missed & ~first_of_run)  # only the stuck run's first readings
    if rate_hz == 62.5:
        assert not missed.any()
    assert (got.non_finite, got.out_of_range, got.spikes, got.clipped) == (
        expected.non_finite, expected.out_of_range, expected.spikes, expected.clipped)
    assert got.stuck == expected.stuck - int(missed.sum())
    same = ~missed.any(axis=1)
    np.testing.assert_allclose(np.vstack([r[1] for r in rows])[same], whole[same], rtol=0, atol=1e-12)
    got_runs = {(r[0], r[1], r[3]): r[2] for r in got.runs}
    assert set(got_runs) == {(r[0], r[1], r[3]) for r in expected.runs}
    for kind, col, first, last in expected.runs:
        assert first <= got_runs[kind, col, last] <= first + passed


def test_the_stream_screening_waits_its_delay_and_no_longer():
    """Each reading leaves the stream screening once stream_delay_samples later ones arrived (the 28 samples of
    the spike rule's reach, at every rate), in blocks of STREAM_BLOCK_S."""
    from gfimu.readings import STREAM_BLOCK_S, StreamScreen, stream_delay_samples, stream_wait_s

    assert stream_delay_samples(500.0) == 28 and stream_delay_samples(62.5) == 28
    block = round(STREAM_BLOCK_S * 500.0)
    assert stream_wait_s(500.0) == pytest.approx((28 + block) / 500.0, rel=1e-12)
    log = simulate("random3d", seed=1, duration_s=2.0)
    stream = StreamScreen(log.array, 500.0)
    decided = 0
    for i in range(len(log)):
        out = stream.push(log.timestamps_ns[i], log.accel_mps2[i])
        if out:
            assert out[0][0] == log.timestamps_ns[decided] and out[-1][0] == log.timestamps_ns[i - 28]
            decided += len(out)
        if i >= 2 * 25:  # the rule decides once its buffer holds a whole local-scale window (51 rows)
            assert i - 28 - block < decided  # never more than the delay and one block behind
    assert decided + len(stream.flush()) == len(log)


def _spiky_log(rate_hz: float, samples: int, spikes: int, seed: int, stuck: int):
    """(array, log, readings, rng): five triads in random motion, ``spikes`` readings off by 300 m/s² and one
    channel stuck for ``stuck`` samples from a third of the log."""
    from gfimu.array import random_array

    array = random_array(5, 0.05, noise_std_mps2=0.02, seed=3)
    log = simulate("random3d", array=array, seed=4, rate_hz=rate_hz, duration_s=min(10.0, samples / rate_hz))
    n = len(log)
    rng = np.random.default_rng(seed)
    y = log.accel_mps2.copy()
    y[rng.integers(0, n, spikes), rng.integers(0, 15, spikes)] += 300.0
    y[n // 3:n // 3 + stuck, 5] = y[n // 3, 5]
    return array, log, y, rng


@pytest.mark.parametrize("rate_hz", [62.5, 500.0])
def test_a_logs_stream_screening_passes_clean_blocks_as_the_rule_would(rate_hz):
    """screen_stream passes the blocks whose neighbourhood the whole-log rule finds clean without running the rule
    on them; it gives the rows, decisions and runs of pushing the rows one by one through the rule."""
    from gfimu.readings import screen_stream

    array, log, y, _ = _spiky_log(rate_hz, 4000, 6, 9, int(0.5 * rate_hz))
    n = len(log)
    y[n // 2, 3] = np.nan
    log = log.replace(accel_mps2=y)
    fast, fast_result = screen_stream(log)
    rows, slow_result = _stream_screened(array, y, log.timestamps_ns, rate_hz)
    assert fast_result.count > 0
    np.testing.assert_array_equal(fast_result.replaced, slow_result.replaced)
    assert fast_result.runs == slow_result.runs
    np.testing.assert_array_equal(fast.accel_mps2, np.vstack([r[1] for r in rows]))


@pytest.mark.parametrize("rate_hz", [62.5, 500.0, 20000.0])
def test_rows_given_at_once_are_screened_as_rows_pushed_one_by_one(rate_hz):
    """StreamScreen.extend (the rows of a log at once, as screen_stream gives them) decides at the rows where a push
    would: the same rows out, in the same batches' order, the same replaced readings and runs, the same gyroscope rows
    (those beyond range NaN and counted), also when extend and push alternate."""
    from gfimu.readings import GYRO_OUT_OF_RANGE_RADPS, StreamScreen

    array, log, y, rng = _spiky_log(rate_hz, 6000, 8, 11, 40)
    n = len(log)
    gyro = rng.normal(0.0, 1.0, (n, 3))
    gyro[rng.integers(0, n, 5), rng.integers(0, 3, 5)] = 2 * GYRO_OUT_OF_RANGE_RADPS
    t = log.timestamps_ns

    one = StreamScreen(array, rate_hz)
    pushed = [one.push(t[i], y[i], gyro[i]) for i in range(n)]
    by_push = [r for rows in pushed for r in rows] + one.flush()

    cuts = sorted(set(rng.integers(1, n - 1, 6).tolist()))
    many = StreamScreen(array, rate_hz)
    by_extend, a = [], 0
    for b in cuts:  # the rows before b at once, row b pushed on its own
        by_extend += many.extend(t[a:b], y[a:b], gyro[a:b])
        by_extend += many.push(t[b], y[b], gyro[b])
        a = b + 1
    by_extend += many.extend(t[a:], y[a:], gyro[a:])
    by_extend += many.flush()
    assert len(by_push) == n
    assert [r[0] for r in by_extend] == [r[0] for r in by_push]
    np.testing.assert_array_equal(np.vstack([r[1] for r in by_extend]), np.vstack([r[1] for r in by_push]))
    np.testing.assert_array_equal(np.vstack([r[2] for r in by_extend]), np.vstack([r[2] for r in by_push]))
    assert many.gyro_out_of_range == one.gyro_out_of_range == 5
    np.testing.assert_array_equal(many.screening().replaced, one.screening().replaced)
    assert many.screening().runs == one.screening().runs and one.count > 0


@pytest.mark.slow
@pytest.mark.parametrize("exp, replaced", [(1, 1), (2, 8), (3, 7)])
def test_the_stream_screening_of_a_real_recording_is_the_whole_log_screening(mimu4444_dir, exp, replaced):
    """The three MIMU4444 recordings as gfimu convert reads them: screened row by row (what gfimu live and
    estimate --method fixed-lag do) they get the same replaced readings (1, 8 and 7: spikes and clipped readings)
    and the same values as screened whole (what the other methods do)."""
    from gfimu.io.readers.mimu4444 import read_mimu4444
    from gfimu.readings import screen_stream

    log, _ = read_mimu4444(mimu4444_dir / f"exp_{exp}" / "data.bin")
    whole, expected = screen_log(log)
    stream, got = screen_stream(log)
    assert expected.count == replaced
    np.testing.assert_array_equal(got.replaced, expected.replaced)
    assert got.runs == expected.runs and got.describe(log.array.accel_columns) == expected.describe(
        log.array.accel_columns)
    np.testing.assert_array_equal(stream.accel_mps2, whole.accel_mps2)
