"""Readings that are the linear acceleration (gravity removed by the phone), not the specific force: the
converters record it in array.toml (``readings``), add the export's own gravity back when it holds it
(Sensor Logger's and phyphox's ``Gravity.csv``), and ``gfimu estimate`` refuses attitude and gravity-free
outputs of a log that has no gravity left, saying why, while ω and a are still estimated.

The real exports (a Sensor Logger iOS recording with Gravity.csv, a phyphox "Linear Accelerometer" recording)
are read from ``$GFIMU_PHONE_EXPORTS_DIR`` (folders ``sensorlogger-ios`` and ``phyphox-linear``) when set;
the public ones measured are named in docs/convert.md."""

from __future__ import annotations

import contextlib
import io
import os
from pathlib import Path

import numpy as np
import pytest

from csv_exports import G, T0_NS, motion, phyphox_export, sensor_logger_export
from gfimu import io as gio
from gfimu.cli import main
from gfimu.rotations import matrix_from_quaternion

REFUSAL = 'readings = "linear_acceleration": the phone removed gravity from the readings'


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(list(argv))
    return rc, out.getvalue(), err.getvalue()


def convert(src: Path, out: Path, preset: str) -> str:
    rc, text, err = run("convert", "csv", str(src), "--map", preset, "--out", str(out))
    assert rc == 0, err
    return text


def estimate_table(path: Path) -> dict[str, np.ndarray]:
    header = path.read_text().splitlines()[0].split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {h.split(" ")[0].lstrip("#"): data[:, j] for j, h in enumerate(header)}


def up_in_body(table: dict[str, np.ndarray], row: int = 0) -> np.ndarray:
    q = np.array([table[f"q_{c}"][row] for c in "wxyz"])
    return matrix_from_quaternion(q).T @ np.array([0.0, 0.0, 1.0])


def angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(u @ v / np.linalg.norm(u) / np.linalg.norm(v), -1.0, 1.0))))


def test_array_toml_readings_key(tmp_path):
    base = 'format = "gfimu-array/1"\n{extra}[[accelerometers]]\nname = "a"\nposition_m = [0, 0, 0]\n'
    path = tmp_path / "array.toml"
    path.write_text(base.format(extra=""))
    assert gio.read_array_toml(path).readings == "specific_force"  # the contract's readings, when not said
    path.write_text(base.format(extra='readings = "linear_acceleration"\n'))
    array = gio.read_array_toml(path)
    assert array.readings == "linear_acceleration"
    gio.write_array_toml(array, tmp_path / "again.toml")
    assert gio.read_array_toml(tmp_path / "again.toml").readings == "linear_acceleration"
    path.write_text(base.format(extra='readings = "acceleration"\n'))
    with pytest.raises(gio.LogFormatError, match=r"array.toml:2: readings: expected what the accelerometers report"):
        gio.read_array_toml(path)


@pytest.mark.parametrize("app", ["sensorlogger", "phyphox"])
def test_an_export_with_its_gravity_gives_attitude_and_gravity_free_acceleration(tmp_path, app):
    seconds = 10.0
    if app == "sensorlogger":
        src = sensor_logger_export(tmp_path / "rec", "ios", seconds=seconds)
    else:
        src = phyphox_export(tmp_path / "rec", seconds=seconds, linear=True, gravity=True)
    out = convert(src, tmp_path / "log", app)
    assert "the linear acceleration plus the phone's own gravity vector (Gravity.csv)" in out
    log = gio.read_log(tmp_path / "log")
    t0 = T0_NS if app == "sensorlogger" else 0
    f, a, _ = motion((log.timestamps_ns - t0) * 1e-9)
    assert log.array.readings == "specific_force"
    # phyphox writes 10 significant digits: 1e-9 of 10 m/s², twice
    np.testing.assert_allclose(log.accel_mps2, f, rtol=0, atol=1e-12 if app == "sensorlogger" else 2e-8)
    rc, _, err = run("estimate", str(tmp_path / "log"), "--orientation", "gyro", "--tum", str(tmp_path / "t.tum"),
                     "--out", str(tmp_path / "est.csv"), "--quiet")
    assert rc == 0, err
    est = estimate_table(tmp_path / "est.csv")
    # the first attitude is the mean specific force over 0.05 s (a still body assumed): off the phone's gravity
    # by the angle the linear acceleration tilts that mean, which the motion bounds
    n0 = int(np.count_nonzero(log.timestamps_ns - log.timestamps_ns[0] <= 50_000_000))
    gravity0 = f[0] - a[0]
    expected = angle_deg(f[:n0].mean(axis=0), gravity0)
    assert angle_deg(up_in_body(est), gravity0) <= expected + 0.5
    # gravity-free at that row: a = f - g·up, off the phone's own a by the chord of that angle (later rows
    # follow the gyro, which this generated motion does not make consistent with its gravity)
    a0 = np.array([est["a_x"][0], est["a_y"][0], est["a_z"][0]])
    assert np.linalg.norm(a0 - a[0]) <= 2 * G * np.sin(np.radians(expected + 0.5) / 2) + 1e-9
    assert np.linalg.norm(a0) < 0.5 * G  # 9.8 m/s² when the readings were taken for the specific force
    assert len((tmp_path / "t.tum").read_text().splitlines()) == len(log) + 1


@pytest.mark.parametrize("app", ["sensorlogger", "phyphox"])
def test_a_linear_acceleration_log_refuses_attitude_and_still_gives_omega(tmp_path, app):
    if app == "sensorlogger":
        src = sensor_logger_export(tmp_path / "rec", "ios")
        (src / "Gravity.csv").unlink()
    else:
        src = phyphox_export(tmp_path / "rec", linear=True)
    convert(src, tmp_path / "log", app)
    log_dir = str(tmp_path / "log")
    for argv in (["--orientation", "gyro"], ["--orientation", "estimate", "--tum", str(tmp_path / "t.tum")],
                 ["-O", "estimate_attitude=True"]):
        rc, _, err = run("estimate", log_dir, *argv, "--out", str(tmp_path / "est.csv"))
        assert rc == 2 and REFUSAL in err and "refused" in err, err
        assert "Traceback" not in err and err.strip().splitlines()[-1].startswith("gfimu estimate: error: ")
        assert not (tmp_path / "est.csv").exists() and not (tmp_path / "t.tum").exists()
    rc, _, err = run("calibrate", log_dir, "--out", str(tmp_path / "cal.toml"))
    assert rc == 2 and 'readings = "linear_acceleration"' in err and "fits the accelerometers against gravity" in err
    assert not (tmp_path / "cal.toml").exists()
    rc, _, err = run("estimate", log_dir, "--out", str(tmp_path / "est.csv"), "--quiet")
    assert rc == 0, err
    est = estimate_table(tmp_path / "est.csv")
    log = gio.read_log(tmp_path / "log")
    assert {"w_x", "a_x"} <= set(est) and "f_x" not in est and "q_w" not in est
    _, a, w = motion((log.timestamps_ns - (T0_NS if app == "sensorlogger" else 0)) * 1e-9)
    # the readings are a (one phone, at the body origin): the estimate's a follows them, not f = a - g
    assert np.median(np.linalg.norm(np.column_stack([est["a_x"], est["a_y"], est["a_z"]]) - a, axis=1)) < 0.1
    assert np.sqrt(np.mean(np.sum((np.column_stack([est["w_x"], est["w_y"], est["w_z"]]) - w) ** 2, axis=1))) < 0.05


EXPORTS = os.environ.get("GFIMU_PHONE_EXPORTS_DIR")


@pytest.mark.skipif(not EXPORTS or not (Path(EXPORTS or ".") / "sensorlogger-ios").is_dir(),
                    reason="set GFIMU_PHONE_EXPORTS_DIR to a folder holding a real Sensor Logger iOS export "
                           "(sensorlogger-ios/ with Accelerometer.csv, Gravity.csv, Gyroscope.csv, Metadata.csv)")
def test_real_sensor_logger_ios_export(tmp_path):
    src = Path(EXPORTS) / "sensorlogger-ios"
    convert(src, tmp_path / "log", "sensorlogger")
    rc, _, err = run("estimate", str(tmp_path / "log"), "--orientation", "gyro", "--out", str(tmp_path / "e.csv"),
                     "--quiet")
    assert rc == 0, err
    est = estimate_table(tmp_path / "e.csv")
    grav = np.loadtxt(src / "Gravity.csv", delimiter=",", skiprows=1, usecols=(4, 3, 2), max_rows=1)
    linear = np.loadtxt(src / "Accelerometer.csv", delimiter=",", skiprows=1, usecols=(4, 3, 2))
    # iOS signs: gravity reads -9.81 up; the first attitude within 10° of the phone's own vertical, and the
    # gravity-free acceleration's median |a| within 50 % of the phone's own linear acceleration's (a
    # hand-held phone; 9.8 m/s² when gravity was added back to a linear acceleration)
    assert angle_deg(up_in_body(est), -grav) < 10.0
    median_a = np.median(np.linalg.norm(np.column_stack([est["a_x"], est["a_y"], est["a_z"]]), axis=1))
    assert abs(median_a / np.median(np.linalg.norm(linear, axis=1)) - 1) < 0.5


@pytest.mark.skipif(not EXPORTS or not (Path(EXPORTS or ".") / "phyphox-linear").is_dir(),
                    reason="set GFIMU_PHONE_EXPORTS_DIR to a folder holding a real phyphox export "
                           "(phyphox-linear/ with Linear Accelerometer.csv, Gyroscope.csv)")
def test_real_phyphox_linear_export(tmp_path):
    convert(Path(EXPORTS) / "phyphox-linear", tmp_path / "log", "phyphox")
    rc, _, err = run("estimate", str(tmp_path / "log"), "--orientation", "gyro", "--out", str(tmp_path / "e.csv"))
    assert rc == 2 and REFUSAL in err
    rc, _, err = run("estimate", str(tmp_path / "log"), "--out", str(tmp_path / "e.csv"), "--quiet")
    assert rc == 0, err
    est = estimate_table(tmp_path / "e.csv")
    assert "a_x" in est and "q_w" not in est and np.all(np.isfinite(est["w_x"]))
