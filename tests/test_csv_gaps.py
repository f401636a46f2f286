"""``gfimu convert csv`` never interpolates across a gap of a file: the rows of the time base inside a gap
are left out (the log has a time gap there), the report says which file, where and how many rows; timing
jitter up to ``--max-gap-periods`` is interpolated over; ``--resample-hz`` puts the log on a uniform grid,
again never across a gap; every converter writes the rate it measured into array.toml."""

from __future__ import annotations

import hashlib
import tomllib
from pathlib import Path

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.cli import main

T0 = 1_700_000_000_000_000_000


def snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file()}


def omega(t_ns):
    """Angular velocity linear in time: linear interpolation reproduces it to rounding."""
    s = (np.asarray(t_ns, dtype=np.int64) - T0) * 1e-9
    return np.column_stack([0.5 + 0.01 * s, -0.02 * s, 0.25 + 0.005 * s])


def sensor_logger_export(folder: Path, acc_t: np.ndarray, gyr_t: np.ndarray) -> None:
    """The layout of Sensor Logger's Android CSV export: time [ns], seconds_elapsed, z, y, x."""
    folder.mkdir(parents=True)
    k = np.arange(acc_t.size)
    acc = np.column_stack([0.1 * np.sin(k * 0.01), 0.2 * np.cos(k * 0.013), 9.8 + 0.05 * np.sin(k * 0.007)])
    with open(folder / "TotalAcceleration.csv", "w") as f:
        f.write("time,seconds_elapsed,z,y,x\n")
        for t, a in zip(acc_t.tolist(), acc.tolist()):
            f.write(f"{t},{(t - T0) * 1e-9!r},{a[2]!r},{a[1]!r},{a[0]!r}\n")
    w = omega(gyr_t)
    with open(folder / "Gyroscope.csv", "w") as f:
        f.write("time,seconds_elapsed,z,y,x\n")
        for t, v in zip(gyr_t.tolist(), w.tolist()):
            f.write(f"{t},{(t - T0) * 1e-9!r},{v[2]!r},{v[1]!r},{v[0]!r}\n")
    (folder / "Metadata.csv").write_text("version,device name,recording epoch time,platform,appVersion\n"
                                         f"3,test,{T0},android,1.64\n")


def stamps(n: int, period_ns: int, offset_ns: int = 0, jitter_ns: int = 0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = T0 + offset_ns + period_ns * np.arange(n, dtype=np.int64)
    if jitter_ns:
        t = t + rng.integers(-jitter_ns, jitter_ns + 1, size=n)
    return t


def run(*argv: str) -> tuple[int, str, str]:
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(["convert", "csv", *argv])
    return rc, out.getvalue(), err.getvalue()


@pytest.fixture
def holed(tmp_path):
    """200 s at 100 Hz; the gyroscope (100 Hz, 3 ms later) misses 85.5 s from 60 s on."""
    acc_t = stamps(20_000, 10_000_000)
    gyr_t = stamps(20_000, 10_000_000, offset_ns=3_000_000)
    hole = (gyr_t > T0 + 60_000_000_000) & (gyr_t < T0 + 145_500_000_000)
    gyr_t = gyr_t[~hole]
    sensor_logger_export(tmp_path / "rec", acc_t, gyr_t)
    return tmp_path, acc_t, gyr_t


def test_a_gap_in_the_gyroscope_file_is_left_out_not_interpolated(holed):
    root, acc_t, gyr_t = holed
    before = snapshot(root / "rec")
    rc, out, err = run(str(root / "rec"), "--map", "sensorlogger", "--gyro-as-reference", "--out", str(root / "log"))
    assert rc == 0, err
    assert snapshot(root / "rec") == before  # inputs byte-identical
    k = int(np.flatnonzero(np.diff(gyr_t) > 1e9)[0])
    a, b = int(gyr_t[k]), int(gyr_t[k + 1])
    inside = (acc_t > a) & (acc_t < b)
    in_span = (acc_t >= gyr_t[0]) & (acc_t <= gyr_t[-1])
    expected_t = acc_t[in_span & ~inside]
    n_out = int(np.count_nonzero(inside))
    assert n_out == 8_551  # 85.5 s at 100 Hz, the rows strictly inside the hole
    log = gio.read_log(root / "log")
    assert log.timestamps_ns.tolist() == expected_t.tolist()
    assert not np.any((log.timestamps_ns > a) & (log.timestamps_ns < b))
    np.testing.assert_allclose(log.gyro_b_radps, omega(expected_t), rtol=0, atol=1e-12)
    ref = log.reference
    assert ref.timestamps_ns.tolist() == expected_t.tolist()
    # the report: which file, from when to when (and its lines), how many rows
    gap_lines = [ln for ln in out.splitlines() if ln.startswith("gap: ")]
    assert len(gap_lines) == 1, out
    line = gap_lines[0]
    assert str(root / "rec" / "Gyroscope.csv") in line
    first = int(expected_t[0])
    assert f"from {(a - first) * 1e-9:.3f} s to {(b - first) * 1e-9:.3f} s" in line
    assert f"lines {k + 2} to {k + 3}" in line and f"{n_out} row(s)" in line and "not interpolated" in line
    assert f"gaps: 1 step(s) over 3 periods in the interpolated files, {n_out} row(s)" in out
    # the log has one break there, and only there
    gaps = log.gaps()
    assert len(gaps) == 1 and log.timestamps_ns[gaps[0].index - 1] < a < b < log.timestamps_ns[gaps[0].index]


def test_resampling_never_crosses_the_gap(holed):
    root, acc_t, gyr_t = holed
    rc, out, err = run(str(root / "rec"), "--map", "sensorlogger", "--resample-hz", "50", "--out", str(root / "log"))
    assert rc == 0, err
    log = gio.read_log(root / "log")
    k = int(np.flatnonzero(np.diff(gyr_t) > 1e9)[0])
    a, b = int(gyr_t[k]), int(gyr_t[k + 1])
    lo, hi = max(acc_t[0], gyr_t[0]), min(acc_t[-1], gyr_t[-1])
    grid = lo + 20_000_000 * np.arange((hi - lo) // 20_000_000 + 1)
    expected = grid[~((grid > a) & (grid < b))]
    assert log.timestamps_ns.tolist() == expected.tolist()
    np.testing.assert_allclose(log.gyro_b_radps, omega(expected), rtol=0, atol=1e-12)
    assert "uniform grid at 50 Hz (every 20000000 ns)" in out
    assert f"{int(np.count_nonzero((grid > a) & (grid < b)))} row(s) of the time base in it left out" in out
    assert tomllib.loads((root / "log" / "array.toml").read_text())["rate_hz"] == 50.0


def test_android_jitter_is_not_a_gap_and_resampling_removes_the_breaks(tmp_path):
    """±4 ms of jitter on a 10 ms period: steps up to 18 ms, none over 3 periods; the gyro is interpolated
    over all of them. On the accelerometer's own times the log has steps over 1.5 periods, which the report
    counts; --resample-hz gives a uniform log with no break."""
    acc_t = np.sort(stamps(3000, 10_000_000, jitter_ns=4_000_000, seed=1))
    gyr_t = np.sort(stamps(3000, 10_000_000, offset_ns=2_000_000, jitter_ns=4_000_000, seed=2))
    sensor_logger_export(tmp_path / "rec", acc_t, gyr_t)
    rc, out, err = run(str(tmp_path / "rec"), "--map", "sensorlogger", "--out", str(tmp_path / "log"))
    assert rc == 0, err
    assert "gaps: no step over 3 periods in the interpolated files" in out
    log = gio.read_log(tmp_path / "log")
    in_span = (acc_t >= gyr_t[0]) & (acc_t <= gyr_t[-1])
    assert log.timestamps_ns.tolist() == acc_t[in_span].tolist()  # nothing left out
    dt = np.diff(acc_t[in_span])
    breaks = int(np.count_nonzero(dt > 1.5 * np.median(dt)))
    assert breaks > 0 and f"timing: {breaks} step(s) of the log's timestamps exceed 1.5" in out
    assert f"--resample-hz {1e9 / np.median(dt):.4g} puts the log on a uniform grid" in out
    assert tomllib.loads((tmp_path / "log" / "array.toml").read_text())["rate_hz"] == 1e9 / float(np.median(dt))
    rc, out, err = run(str(tmp_path / "rec"), "--map", "sensorlogger", "--resample-hz", "100", "--out",
                       str(tmp_path / "uniform"))
    assert rc == 0, err
    uniform = gio.read_log(tmp_path / "uniform")
    assert set(np.diff(uniform.timestamps_ns).tolist()) == {10_000_000}
    assert uniform.gaps() == [] and "timing:" not in out
    np.testing.assert_allclose(uniform.gyro_b_radps, omega(uniform.timestamps_ns), rtol=0, atol=1e-12)


def test_max_gap_periods_decides_what_is_a_gap(tmp_path):
    """Two missing gyro rows (a 30 ms step): interpolated over at the default 3 periods, left out at 2."""
    acc_t = stamps(500, 10_000_000)
    gyr_t = np.delete(stamps(500, 10_000_000, offset_ns=1_000_000), [200, 201])
    sensor_logger_export(tmp_path / "rec", acc_t, gyr_t)
    rc, out, err = run(str(tmp_path / "rec"), "--map", "sensorlogger", "--out", str(tmp_path / "a"))
    assert rc == 0, err
    assert len(gio.read_log(tmp_path / "a")) == 499  # acc_t[0] is before the first gyro row
    rc, out, err = run(str(tmp_path / "rec"), "--map", "sensorlogger", "--max-gap-periods", "2", "--out",
                       str(tmp_path / "b"))
    assert rc == 0, err
    log = gio.read_log(tmp_path / "b")
    assert len(log) == 496 and "3 row(s) of the time base in it left out" in out


@pytest.mark.parametrize("option, value, message", [
    ("--max-gap-periods", "1", "--max-gap-periods: expected a number >= 1.5, got 1.0"),
    ("--max-gap-periods", "nan", "--max-gap-periods: expected a number >= 1.5"),
    ("--resample-hz", "0", "--resample-hz: expected a rate in Hz above 0"),
    ("--resample-hz", "-5", "--resample-hz: expected a rate in Hz above 0"),
])
def test_bad_gap_and_rate_options_are_refused(holed, option, value, message):
    root = holed[0]
    before = snapshot(root)
    rc, out, err = run(str(root / "rec"), "--map", "sensorlogger", option, value, "--out", str(root / "log"))
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert snapshot(root) == before and not (root / "log").exists()


def test_every_converter_writes_the_rate_it_measured(tmp_path):
    """array.toml's rate_hz is 1e9 / the median step of the log written, for csv, mimu4444 and rosbag."""
    from test_mimu4444 import make_packet, raw_for

    # mimu4444: 1,024,000 ticks of 64 us per packet
    src = tmp_path / "data.bin"
    src.write_bytes(b"".join(make_packet(k, 7 + k * 1_024_000, raw_for(k)) for k in range(8)))
    assert main(["convert", "mimu4444", str(src), "--out", str(tmp_path / "m"), "--no-progress"]) == 0
    log = gio.read_log(tmp_path / "m")
    rate = tomllib.loads((tmp_path / "m" / "array.toml").read_text())["rate_hz"]
    assert rate == 1e9 / float(np.median(np.diff(log.timestamps_ns)))
    # csv
    acc_t = stamps(100, 2_000_000)
    sensor_logger_export(tmp_path / "rec", acc_t, acc_t)
    rc, out, err = run(str(tmp_path / "rec"), "--map", "sensorlogger", "--out", str(tmp_path / "c"))
    assert rc == 0, err
    assert tomllib.loads((tmp_path / "c" / "array.toml").read_text())["rate_hz"] == 500.0


def test_the_rosbag_converter_writes_the_rate_it_measured(tmp_path, capsys):
    pytest.importorskip("rosbags")
    from test_rosbag import T0_NS, array_file, write_bag

    from gfimu.array import cube_array
    from gfimu.simulate import simulate

    log = simulate("random3d", array=cube_array(0.025), rate_hz=400.0, duration_s=0.5, seed=1)
    streams = [{"topic": f"/imu/{a.name}", "frame_id": a.name, "stamps_ns": log.timestamps_ns + T0_NS,
                "accel": log.accel_mps2[:, 3 * i:3 * i + 3]} for i, a in enumerate(log.array.accelerometers)]
    bag = write_bag(tmp_path / "bag", "mcap", streams)
    assert main(["convert", "rosbag", str(bag), "--array", str(array_file(tmp_path / "array.toml", log.array)),
                 "--out", str(tmp_path / "r"), "--no-progress"]) == 0
    assert tomllib.loads((tmp_path / "r" / "array.toml").read_text())["rate_hz"] == 400.0


def test_gaps_of_the_time_base_counted_only_where_the_written_log_has_them(tmp_path):
    """The accelerometer file has 7 gaps: 3 before the gyroscope starts, 3 inside the gyroscope's own gap (both
    sets in rows left out) and 1 in the written log: the report counts 1, and says where the rest went."""
    acc_t = stamps(20_000, 10_000_000)
    drop = np.zeros(acc_t.size, bool)
    for start_s in (1.0, 2.0, 3.0, 70.0, 80.0, 90.0, 150.0):
        drop[int(start_s * 100):int(start_s * 100) + 20] = True  # 0.21 s steps: 21 periods
    acc_t = acc_t[~drop]
    gyr_t = stamps(20_000, 10_000_000, offset_ns=3_000_000)
    gyr_t = gyr_t[(gyr_t > T0 + 5_000_000_000) & ~((gyr_t > T0 + 60_000_000_000) & (gyr_t < T0 + 100_000_000_000))]
    sensor_logger_export(tmp_path / "rec", acc_t, gyr_t)
    rc, out, err = run(str(tmp_path / "rec"), "--map", "sensorlogger", "--out", str(tmp_path / "log"))
    assert rc == 0, err
    line = next(x for x in out.splitlines() if x.startswith("gaps of the time base"))
    assert line.endswith("1 step(s) over 3 of its 10 ms periods, kept as time gaps of the log (6 more in rows "
                         "left out)"), line
    t = gio.read_log(tmp_path / "log").timestamps_ns
    steps = np.diff(t)
    # the written log: the accelerometer's one gap (0.21 s) and the gyroscope's (40 s), nothing else over 3 periods
    big = sorted(steps[steps > 30_000_000].tolist())
    assert len(big) == 2 and big[0] == 210_000_000 and 40e9 < big[1] < 40.1e9
