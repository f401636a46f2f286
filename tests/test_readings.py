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
    assert result.replaced.sum() == 4 and result.non_finite == 1 and result.out_of_range == 1 and result.spikes == 2
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


@pytest.mark.parametrize("method", ["smoother", "ml"])
@pytest.mark.parametrize("value", ["1e30", "spike"])
def test_one_corrupt_cell_does_not_spoil_the_estimate(tmp_path, method, value):
    """10 s at 500 Hz, one corrupt cell (1e30, or 1000 m/s² added to one sensor's axis): the ω RMSE
    away from it (±0.5 s) stays within 1.5x of the clean log's, exit 0, a warning naming the row."""
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    log = simulate("random3d", seed=3)
    folder = tmp_path / "log"
    gio.write_log(log, folder)
    clean = tmp_path / "clean.csv"
    run = [sys.executable, "-m", "gfimu", "estimate", str(folder), "--method", method, "--no-progress"]
    assert subprocess.run(run + ["--out", str(clean)], env=env, capture_output=True).returncode == 0
    row, col = 2500, 4
    y = log.accel_mps2.copy()
    y[row, col] = 1e30 if value == "1e30" else y[row, col] + 1000.0
    bad = tmp_path / "bad"
    gio.write_log(log.replace(accel_mps2=y), bad)
    out = tmp_path / "bad.csv"
    proc = subprocess.run(run[:4] + [str(bad)] + run[5:] + ["--out", str(out)], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert f"row {row} {log.array.accel_columns[col]}" in proc.stderr
    away = np.abs(log.times_s - log.times_s[row]) > 0.5

    def rmse(path):
        w = gio.read_motion_csv(path).omega_b_radps
        return float(np.sqrt(np.mean(np.sum((w[away] - log.truth.omega_b_radps[away]) ** 2, axis=1))))

    assert rmse(out) < 1.5 * rmse(clean), (rmse(out), rmse(clean))
