"""Static calibration: synthetic still periods with known gains and biases, TOML round trip, real data."""

import numpy as np
import pytest

from gfimu import calibration as cal
from gfimu.array import Accelerometer, SensorArray, mimu4444_array
from gfimu.log import Log
from gfimu.rotations import matrix_from_rotation_vector

G = 9.80665


def rotated_array() -> SensorArray:
    """Four triads, two of them mounted rotated, so sensor frames differ from B."""
    r1 = matrix_from_rotation_vector(np.array([0.3, -0.2, 1.1]))
    r2 = matrix_from_rotation_vector(np.array([np.pi, 0.0, 0.0]))
    pos = 0.05 * np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    return SensorArray((Accelerometer("a1", pos[0]), Accelerometer("a2", pos[1], r1),
                        Accelerometer("a3", pos[2], r2), Accelerometer("a4", pos[3])), "rotated")


def true_errors(array, seed=1):
    rng = np.random.default_rng(seed)
    gains, biases = [], []
    for a in array.accelerometers:
        d = a.directions_b
        gains.append((np.eye(3) + 0.02 * rng.standard_normal((3, 3))) @ d)  # scale, cross-axis, misalignment
        biases.append(0.3 * rng.standard_normal(3))
    return gains, biases


def gauge_fixed(array, gains):
    """Apply the documented gauge (Procrustes to the nominal axes) to the true gains."""
    k = np.vstack(gains)
    d = array.axis_directions_b
    u, _, vt = np.linalg.svd(k.T @ d)
    s = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    q = u @ s @ vt
    return [g @ q for g in gains], q


def orientations(n, seed=2):
    rng = np.random.default_rng(seed)
    f = rng.standard_normal((n, 3))
    return G * f / np.linalg.norm(f, axis=1, keepdims=True)


def readings(gains, biases, f):
    return np.column_stack([f @ g.T + b for g, b in zip(gains, biases)])


def test_fit_static_noise_free_recovers_gains_and_biases():
    array = rotated_array()
    gains, biases = true_errors(array)
    f = orientations(12)
    y = readings(gains, biases, f)
    fg, fb, ff, info = cal.fit_static(array, y)
    ref, q = gauge_fixed(array, gains)
    for a, b in zip(fg, ref):
        assert np.allclose(a, b, atol=1e-8)
    for a, b in zip(fb, biases):
        assert np.allclose(a, b, atol=1e-8)
    assert np.allclose(ff, f @ q, atol=1e-7)
    assert info["residual_rms_mps2"] < 1e-9


def test_fit_from_log_with_noise_detects_periods_and_removes_spread():
    array = mimu4444_array(with_gyroscope=True)
    gains, biases = true_errors(array, seed=5)
    f = orientations(15, seed=6)
    rng = np.random.default_rng(7)
    rate, still_n, move_n = 62.5, 250, 60
    acc, gyro, truth_ranges = [], [], []
    n = 0
    for k in range(len(f)):
        yk = readings(gains, biases, np.tile(f[k], (still_n, 1))) + 0.03 * rng.standard_normal((still_n, 24))
        acc.append(yk)
        gyro.append(0.005 * rng.standard_normal((still_n, 3)))
        truth_ranges.append((n, n + still_n))
        n += still_n
        acc.append(readings(gains, biases, np.tile(f[k], (move_n, 1))) + 3.0 * rng.standard_normal((move_n, 24)))
        gyro.append(2.0 * rng.standard_normal((move_n, 3)))
        n += move_n
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    log = Log(array, t, np.vstack(acc), gyro_b_radps=np.vstack(gyro))
    periods = cal.find_still_periods(log)
    assert len(periods) == len(f)
    for p, (s, e) in zip(periods, truth_ranges):
        # edges lose half the 1 s window (31 samples) and the 0.25 s trim (16 samples) each
        assert s <= p.start and p.stop <= e and p.stop - p.start >= still_n - 2 * (31 + 16) - 2
    c = cal.fit(log)
    ref, _ = gauge_fixed(array, gains)
    # 0.03 m/s² noise averaged over ~200 samples per period, 15 periods
    for s, g, b in zip(c.sensors, ref, biases):
        assert np.allclose(s.gain, g, atol=2e-3)
        assert np.allclose(s.bias_mps2, b, atol=5e-3)
    assert c.info["spread_before_mps2"] > 0.3
    assert c.info["spread_after_mps2"] < 0.01
    # applying the calibration: every sensor now reads the same specific force
    fixed = cal.apply_calibration(log, c)
    p = periods[0]
    mean = fixed.accel_mps2[p].mean(axis=0).reshape(8, 3)
    assert np.max(np.linalg.norm(mean - mean.mean(axis=0), axis=1)) < 0.01
    assert np.linalg.norm(mean.mean(axis=0)) == pytest.approx(G, abs=0.01)
    assert np.allclose(c.gyro_bias_b_radps, 0.0, atol=2e-3)


def test_too_few_orientations_is_refused():
    array = rotated_array()
    gains, biases = true_errors(array)
    f = orientations(3)
    with pytest.raises(cal.CalibrationError, match="at least 4 orientations"):
        cal.fit_static(array, readings(gains, biases, f))
    # six periods, but all gravity directions in one plane
    ang = np.linspace(0, np.pi, 6, endpoint=False)
    flat = G * np.column_stack([np.cos(ang), np.sin(ang), 0 * ang])
    with pytest.raises(cal.CalibrationError, match="do not span"):
        cal.fit_static(array, readings(gains, biases, flat))


def test_identity_calibration_leaves_partial_axis_sensors_unchanged():
    array = SensorArray((Accelerometer("p1", [0.1, 0, 0], axes=("y", "z")), Accelerometer("p2", [0, 0.1, 0], axes=("x",)),
                         Accelerometer("p3", [0, 0, 0.1], matrix_from_rotation_vector(np.array([0.2, 0.5, -0.1])))))
    sensors = tuple(cal.SensorCalibration(a.name, a.axes, a.directions_b, np.zeros(len(a.axes))) for a in array.accelerometers)
    y = np.random.default_rng(3).standard_normal((5, array.n_axes))
    assert np.allclose(cal.correct_readings(array, cal.Calibration(sensors), y), y)
    # a bias on one axis is removed from that axis only
    first = array.accelerometers[0]
    sensors = (cal.SensorCalibration(first.name, first.axes, first.directions_b, np.array([0.5, 0.0])),) + sensors[1:]
    out = cal.correct_readings(array, cal.Calibration(sensors), y)
    assert np.allclose(out[:, 0], y[:, 0] - 0.5) and np.allclose(out[:, 1:], y[:, 1:])


def test_rotated_sensor_gain_applied_in_its_own_frame():
    array = rotated_array()
    gains, biases = true_errors(array)
    f = orientations(8)
    y = readings(gains, biases, f)
    c = cal.Calibration(tuple(cal.SensorCalibration(a.name, a.axes, g, b) for a, g, b in zip(array.accelerometers, gains, biases)))
    # calibrated readings equal the ideal readings of the nominal array
    assert np.allclose(cal.correct_readings(array, c, y), f @ array.axis_directions_b.T, atol=1e-10)


def test_toml_round_trip(tmp_path):
    array = rotated_array()
    gains, biases = true_errors(array)
    c = cal.Calibration(tuple(cal.SensorCalibration(a.name, a.axes, g, b) for a, g, b in zip(array.accelerometers, gains, biases)),
                        np.array([0.01, -0.02, 0.003]), info={"still_periods": 12, "spread_after_mps2": 0.0031, "source": 'a "b"'})
    path = tmp_path / "calibration.toml"
    cal.write_calibration(c, path)
    back = cal.read_calibration(path)
    for s, t in zip(c.sensors, back.sensors):
        assert s.name == t.name and s.axes == t.axes
        assert np.array_equal(s.gain, t.gain) and np.array_equal(s.bias_mps2, t.bias_mps2)
    assert np.array_equal(back.gyro_bias_b_radps, c.gyro_bias_b_radps)
    assert back.info == c.info
    assert [p.name for p in tmp_path.iterdir()] == ["calibration.toml"]


def test_read_calibration_errors(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text('format = "gfimu-calibration/1"\n[[accelerometers]]\nname = "a1"\nbias_mps2 = [0, 0]\ngain = [[1,0,0],[0,1,0],[0,0,1]]\n')
    with pytest.raises(cal.CalibrationError, match=r"accelerometers\[0\].*gain must be 3x3 and bias 3"):
        cal.read_calibration(p)
    p.write_text('format = "other"\n')
    with pytest.raises(cal.CalibrationError, match="format must be"):
        cal.read_calibration(p)


def test_missing_sensor_in_calibration(tmp_path):
    array = mimu4444_array()
    c = cal.Calibration((cal.SensorCalibration("imu1", ("x", "y", "z"), np.eye(3), np.zeros(3)),))
    with pytest.raises(cal.CalibrationError, match="no accelerometer 'imu2'"):
        cal.correct_readings(array, c, np.zeros((2, 24)))


def test_real_recordings_spread(mimu4444_dir):
    from gfimu.io.readers.mimu4444 import read_mimu4444

    log, _ = read_mimu4444(mimu4444_dir / "exp_1" / "data.bin", with_gyro=True)
    c = cal.fit(log)
    assert c.info["still_periods"] >= 18  # about 20 orientations in the static phase
    assert c.info["spread_per_axis_before_mps2"] == pytest.approx(0.3, abs=0.05)
    assert c.info["spread_before_mps2"] == pytest.approx(0.52, abs=0.05)
    assert c.info["spread_after_mps2"] < 0.01
    # the calibration also holds on another recording of the same board (not fitted there)
    other, _ = read_mimu4444(mimu4444_dir / "exp_3" / "data.bin", with_gyro=True)
    means = cal.still_means(other, cal.find_still_periods(other))
    before = cal.inter_sensor_spread(other.array, means)
    after = cal.inter_sensor_spread(other.array, cal.correct_readings(other.array, c, means))
    assert before > 0.45 and after < 0.05


def test_calibrate_and_apply_cli(tmp_path, capsys):
    from gfimu import io as gio
    from gfimu.cli import main

    array = mimu4444_array()
    gains, biases = true_errors(array, seed=11)
    f = orientations(8, seed=12)
    rng = np.random.default_rng(13)
    parts = []
    for k in range(len(f)):
        parts.append(readings(gains, biases, np.tile(f[k], (260, 1))) + 0.02 * rng.standard_normal((260, 24)))
        parts.append(readings(gains, biases, np.tile(f[k], (40, 1))) + 4.0 * rng.standard_normal((40, 24)))
    y = np.vstack(parts)
    log = Log(array, (np.arange(len(y)) * 16_000_000).astype(np.int64), y)
    gio.write_log(log, tmp_path / "log")
    assert main(["calibrate", str(tmp_path / "log"), "--out", str(tmp_path / "cal.toml")]) == 0
    out = capsys.readouterr().out
    assert "8 still periods" in out
    c = cal.read_calibration(tmp_path / "cal.toml")
    ref, _ = gauge_fixed(array, gains)
    err = max(np.max(np.abs(s.gain - g)) for s, g in zip(c.sensors, ref))
    nominal_err = max(np.max(np.abs(a.directions_b - g)) for a, g in zip(array.accelerometers, ref))
    assert err < 6e-3 < 0.02 < nominal_err, (err, nominal_err)  # 8 orientations, 0.02 m/s² noise
    assert c.info["spread_after_mps2"] < 0.01 < 0.3 < c.info["spread_before_mps2"]
    # too few orientations: a clear error and exit status 2
    gio.write_log(log.select(slice(0, 900)), tmp_path / "short")
    assert main(["calibrate", str(tmp_path / "short"), "--out", str(tmp_path / "bad.toml")]) == 2
    assert "at least 4 orientations" in capsys.readouterr().err


def test_calibrate_cli_without_still_periods_says_what_to_do_on_the_command_line(tmp_path, capsys):
    from gfimu import io as gio
    from gfimu.cli import main

    array = mimu4444_array()
    gains, biases = true_errors(array, seed=11)
    rng = np.random.default_rng(14)
    y = readings(gains, biases, np.tile(orientations(1, seed=12)[0], (500, 1))) + 4.0 * rng.standard_normal((500, 24))
    gio.write_log(Log(array, (np.arange(len(y)) * 16_000_000).astype(np.int64), y), tmp_path / "moving")
    assert main(["calibrate", str(tmp_path / "moving"), "--out", str(tmp_path / "cal.toml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no still period found" in err
    assert "held still for at least 2 s" in err and "several orientations" in err
    for option in ("--accel-std", "--gyro-std", "--window-s", "--min-duration-s"):
        assert option in err
    assert "gfimu.calibration" not in err and "StillDetector" not in err
    assert not (tmp_path / "cal.toml").exists()


def test_read_calibration_names_the_line_and_key_of_a_value_that_is_no_number(tmp_path):
    """'could not convert string to float' never reaches the user: the file, line and key are named."""
    from gfimu.cli import main

    good = 'format = "gfimu-calibration/1"\n[[accelerometers]]\nname = "a"\ngain = [[1,0,0],[0,1,0],[0,0,1]]\n'
    cases = {
        "bias": (good + 'bias_mps2 = ["abc", 0, 0]\n', "c.toml:5: accelerometers[0].bias_mps2: expected 3 numbers "
                 "[m/s²], got ['abc', 0, 0]"),
        "gain": (good.replace("[0,0,1]]", '[0,0,"x"]]') + "bias_mps2 = [0, 0, 0]\n",
                 "c.toml:4: accelerometers[0].gain: expected 3 rows of 3 numbers"),
        "gyro": (good + "bias_mps2 = [0, 0, 0]\n[gyroscope]\nbias_b_radps = [\"x\", 1, 2]\n",
                 "c.toml:7: gyroscope.bias_b_radps: expected 3 numbers [rad/s], got ['x', 1, 2]"),
        "gravity": ('gravity_mps2 = "abc"\n' + good + "bias_mps2 = [0, 0, 0]\n",
                    "c.toml:1: gravity_mps2: expected a number > 0 [m/s²], got 'abc'"),
    }
    for name, (text, message) in cases.items():
        p = tmp_path / "c.toml"
        p.write_text(text)
        with pytest.raises(cal.CalibrationError) as info:
            cal.read_calibration(p)
        assert str(info.value) == f"{tmp_path}/{message}" or str(info.value).startswith(f"{tmp_path}/{message}"), name
    # and from the command line: exit 2, one line naming the file, line and key, nothing written
    (tmp_path / "b.csv").write_text("t [ms],ax [g],ay [g],az [g]\n0,0,0,1\n10,0,0,1\n")
    (tmp_path / "m.toml").write_text('format = "gfimu-csv-map/1"\n[time]\ncolumn = "t"\n[[accelerometers]]\n'
                                     'name = "a"\nx = "ax"\ny = "ay"\nz = "az"\n')
    p.write_text(cases["bias"][0])
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(["convert", "csv", str(tmp_path / "b.csv"), "--map", str(tmp_path / "m.toml"), "--calibration",
                   str(p), "--out", str(tmp_path / "log")])
    assert rc == 2 and err.getvalue().strip() == f"gfimu convert: error: {tmp_path}/{cases['bias'][1]}"
    assert not (tmp_path / "log").exists()
