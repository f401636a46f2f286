"""``gfimu convert csv``: small files in the styles users record (phyphox, Sensor Logger, EuRoC, TUM-style
whitespace, a logger's own CSV) converted with a column map and read back with known values; the real EuRoC
rows shipped with GTSAM; and every bad input refused with one line, exit status 2 and nothing written."""

from __future__ import annotations

import hashlib
import os
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.cli import main
from gfimu.datasets.gtsam_recordings import EUROC_FILE, data_dir
from gfimu.io.readers import get_reader, reader_names
from gfimu.io.readers.csv import PRESETS, resample_linear

G = 9.80665
DEG = np.pi / 180.0


def convert(capsys, *argv: str) -> str:
    rc = main(["convert", "csv", *argv])
    out = capsys.readouterr()
    assert rc == 0, out.err
    return out.out


def snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file()}


def refused(capsys, root: Path, message: str, *argv: str) -> str:
    """Run ``gfimu convert csv argv``: exit 2, ``message`` on one line, no traceback, nothing written."""
    before = snapshot(root)
    rc = main(["convert", "csv", *argv])
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert message in err, err
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert snapshot(root) == before
    assert not (root / "log").exists()
    return err


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


# --- styles ---------------------------------------------------------------------------------

def test_the_reader_is_registered():
    assert "csv" in reader_names()
    assert get_reader("csv").name == "csv"
    assert main(["convert", "--help"]) == 0


def test_phyphox_export(tmp_path, capsys):
    write(tmp_path / "Raw Data.csv",
          '"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)","Acceleration z (m/s^2)",'
          '"Absolute acceleration (m/s^2)"\n'
          "0.000000000E0,1.25E-1,-2.5E-1,9.81E0,9.8\n"
          "1.0001E-2,1.5E-1,-2.25E-1,9.80E0,9.8\n"
          "2.0003E-2,1.75E-1,-2E-1,9.79E0,9.8\n")
    out = convert(capsys, str(tmp_path / "Raw Data.csv"), "--map", "phyphox", "--out", str(tmp_path / "log"))
    assert "gyroscope: not in" in out
    log = gio.read_log(tmp_path / "log")
    assert log.timestamps_ns.tolist() == [0, 10_001_000, 20_003_000]
    assert log.accel_mps2.tolist() == [[0.125, -0.25, 9.81], [0.15, -0.225, 9.80], [0.175, -0.2, 9.79]]
    assert log.gyro_b_radps is None and log.array.gyroscope is None
    assert log.array.accelerometers[0].position_m.tolist() == [0.0, 0.0, 0.0]


def test_phyphox_linear_acceleration_with_gyroscope_semicolons_and_decimal_commas(tmp_path, capsys):
    write(tmp_path / "raw.csv",
          "Time (s);Linear Acceleration x (m/s^2);Linear Acceleration y (m/s^2);Linear Acceleration z (m/s^2);"
          "Gyroscope x (rad/s);Gyroscope y (rad/s);Gyroscope z (rad/s)\n"
          "0,0;0,5;-0,5;0,25;1,5;-2,5;0,125\n"
          "0,005;0,75;-0,75;0,5;1,75;-2,25;0,25\n")
    write(tmp_path / "map.toml", PRESETS["phyphox"].replace('decimal = "auto"', 'decimal = ","'))
    convert(capsys, str(tmp_path / "raw.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "log"))
    log = gio.read_log(tmp_path / "log")
    assert log.timestamps_ns.tolist() == [0, 5_000_000]
    assert log.accel_mps2.tolist() == [[0.5, -0.5, 0.25], [0.75, -0.75, 0.5]]
    assert log.gyro_b_radps.tolist() == [[1.5, -2.5, 0.125], [1.75, -2.25, 0.25]]


@pytest.mark.parametrize("delimiter,decimal", [(";", ","), ("\t", ","), (";", "."), ("\t", "."), (",", ".")])
def test_phyphox_preset_reads_every_csv_export_of_phyphox(tmp_path, capsys, delimiter, decimal):
    """phyphox exports CSV with a comma, tab or semicolon and a decimal point or comma: the preset reads all."""
    header = ["Time (s)", "Acceleration x (m/s^2)", "Acceleration y (m/s^2)", "Acceleration z (m/s^2)",
              "Absolute acceleration (m/s^2)"]
    rows = [["0.000000000E+00", "1.250000000E-01", "-2.500000000E-01", "9.810000000E+00", "9.8"],
            ["1.000100000E-02", "1.500000000E-01", "-2.250000000E-01", "9.800000000E+00", "9.8"]]
    text = delimiter.join(f'"{h}"' for h in header) + "\n"
    text += "".join(delimiter.join(f.replace(".", decimal) for f in r) + "\n" for r in rows)
    write(tmp_path / "Raw Data.csv", text)
    convert(capsys, str(tmp_path / "Raw Data.csv"), "--map", "phyphox", "--out", str(tmp_path / "log"))
    log = gio.read_log(tmp_path / "log")
    assert log.timestamps_ns.tolist() == [0, 10_001_000]
    assert log.accel_mps2.tolist() == [[0.125, -0.25, 9.81], [0.15, -0.225, 9.80]]


def test_sensor_logger_folder_interpolates_the_gyroscope_onto_the_accelerometer(tmp_path, capsys):
    t0 = 1_700_000_000_000_000_000
    acc_t = t0 + np.arange(6) * 10_000_000  # 100 Hz
    gyr_t = t0 - 2_000_000 + np.arange(6) * 9_000_000  # about 111 Hz, 2 ms earlier: ends before acc_t[5]
    rows = "".join(f"{t},{float(t - t0) * 1e-9!r},{9.5 + k},{0.25 * k},{-0.5 * k}\n" for k, t in enumerate(acc_t))
    write(tmp_path / "rec" / "TotalAcceleration.csv", "time,seconds_elapsed,z,y,x\n" + rows)

    def omega(t):  # linear in time: interpolation is exact
        s = (np.asarray(t, dtype=np.int64) - t0) * 1e-9
        return np.column_stack([1.0 + 2.0 * s, -3.0 * s, 0.5 + s])

    w = omega(gyr_t)
    rows = "".join(f"{t},{float(t - t0) * 1e-9!r},{float(w[k, 2])!r},{float(w[k, 1])!r},{float(w[k, 0])!r}\n"
                   for k, t in enumerate(gyr_t))
    write(tmp_path / "rec" / "Gyroscope.csv", "time,seconds_elapsed,z,y,x\n" + rows)
    out = convert(capsys, str(tmp_path / "rec"), "--map", "sensorlogger", "--out", str(tmp_path / "log"))
    assert "linearly interpolated onto the timestamps of" in out and "1 row(s)" in out
    log = gio.read_log(tmp_path / "log")
    assert log.timestamps_ns.tolist() == acc_t[:5].tolist()  # acc_t[5] is after the last gyro sample
    k = np.arange(5)
    assert log.accel_mps2.tolist() == np.column_stack([-0.5 * k, 0.25 * k, 9.5 + k]).tolist()
    np.testing.assert_allclose(log.gyro_b_radps, omega(acc_t[:5]), rtol=0, atol=1e-12)


def test_resample_linear_known_values():
    t = np.array([0, 10, 20], dtype=np.int64)
    v = np.array([[0.0, 1.0], [10.0, 1.0], [0.0, 3.0]])
    assert resample_linear(t, v, np.array([5, 10, 15])).tolist() == [[5.0, 1.0], [10.0, 1.0], [5.0, 2.0]]


EUROC_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n")


def test_euroc_style_file_keeps_nanoseconds_exact(tmp_path, capsys):
    write(tmp_path / "imu0" / "data.csv", EUROC_HEADER
          + "1403715273262142976,0.5,-0.25,0.125,9.5,0.75,-3.5\n1403715273267142912,0.25,-0.5,1,9.25,0.5,-3.25\n")
    convert(capsys, str(tmp_path / "imu0" / "data.csv"), "--map", "euroc", "--out", str(tmp_path / "log"),
            "--gyro-as-reference")
    log = gio.read_log(tmp_path / "log")
    assert log.timestamps_ns.tolist() == [1403715273262142976, 1403715273267142912]
    assert log.accel_mps2.tolist() == [[9.5, 0.75, -3.5], [9.25, 0.5, -3.25]]
    assert log.gyro_b_radps.tolist() == [[0.5, -0.25, 0.125], [0.25, -0.5, 1.0]]
    assert log.reference.omega_b_radps.tolist() == log.gyro_b_radps.tolist()


def test_tum_style_whitespace_file_by_index_with_units_and_signs_in_the_map(tmp_path, capsys):
    write(tmp_path / "imu.txt", "# timestamp ax ay az\n# a comment line\n"
                                "1.5   0.5  -1.0   1.0\n1.502 0.25 -0.75  1.25\n\n1.504 0.0 -0.5 1.5\n")
    write(tmp_path / "map.toml", '''format = "gfimu-csv-map/1"
[csv]
delimiter = "whitespace"
[time]
column = 0
unit = "s"
[[accelerometers]]
name = "a"
unit = "g"
x = 1
y = { column = 2, sign = -1 }
z = { column = "az", unit = "mg" }
''')
    convert(capsys, str(tmp_path / "imu.txt"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "log"))
    log = gio.read_log(tmp_path / "log", check=False)
    assert log.timestamps_ns.tolist() == [1_500_000_000, 1_502_000_000, 1_504_000_000]
    mg = G * 1e-3
    expected = np.array([[0.5 * G, 1.0 * G, 1.0 * mg], [0.25 * G, 0.75 * G, 1.25 * mg], [0.0, 0.5 * G, 1.5 * mg]])
    assert log.accel_mps2.tolist() == expected.tolist()


@pytest.mark.parametrize("time_unit, scale_ns", [("ns", 1), ("us", 1_000), ("µs", 1_000), ("ms", 1_000_000),
                                                  ("s", 1_000_000_000)])
@pytest.mark.parametrize("accel_unit, factor", [("m/s^2", 1.0), ("m s^-2", 1.0), ("g", G), ("mg", G * 1e-3)])
def test_units_in_headers(tmp_path, capsys, time_unit, scale_ns, accel_unit, factor):
    write(tmp_path / "f.csv", f"t [{time_unit}],ax [{accel_unit}],ay [{accel_unit}],az [{accel_unit}],"
                              "gx [deg s^-1],gy [rad/s],gz [deg/s]\n"
                              "1000,1.5,-2,4,90,0.5,-45\n2000,2.5,-3,5,180,0.25,45\n")
    write(tmp_path / "map.toml", '''format = "gfimu-csv-map/1"
[time]
column = "t"
[[accelerometers]]
name = "a"
x = "ax"
y = "ay"
z = "az"
[gyroscope]
x = "gx"
y = "gy"
z = "gz"
''')
    convert(capsys, str(tmp_path / "f.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "log"))
    log = gio.read_log(tmp_path / "log", check=False)
    assert log.timestamps_ns.tolist() == [1000 * scale_ns, 2000 * scale_ns]
    assert log.accel_mps2.tolist() == (np.array([[1.5, -2, 4], [2.5, -3, 5]]) * factor).tolist()
    assert log.gyro_b_radps.tolist() == [[90 * DEG, 0.5, -45 * DEG], [180 * DEG, 0.25, 45 * DEG]]


TWO_SENSOR_MAP = '''format = "gfimu-csv-map/1"
name = "pair"
[time]
column = "t"
unit = "ms"
[[accelerometers]]
name = "left"
{left}
x = "l_x"
y = "l_y"
z = "l_z"
[[accelerometers]]
name = "right"
{right}
x = "r_x"
y = "r_y"
'''
TWO_SENSOR_CSV = "t,l_x [g],l_y [g],l_z [g],r_x [m/s^2],r_y [m/s^2]\n0,0,0,1,0.5,-0.5\n2,0,0.5,1,0.25,-0.25\n"


def test_geometry_in_the_map(tmp_path, capsys):
    write(tmp_path / "f.csv", TWO_SENSOR_CSV)
    write(tmp_path / "map.toml", TWO_SENSOR_MAP.format(
        left="position_m = [-0.05, 0.0, 0.0]",
        right="position_m = [0.05, 0.0, 0.0]\nrotation_body_sensor = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]"))
    convert(capsys, str(tmp_path / "f.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "log"))
    log = gio.read_log(tmp_path / "log", check=False)
    left, right = log.array.accelerometers
    assert (left.position_m.tolist(), right.position_m.tolist()) == ([-0.05, 0.0, 0.0], [0.05, 0.0, 0.0])
    assert right.rotation_body_sensor.tolist() == [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    assert right.axes == ("x", "y") and log.array.accel_columns == ["left_x", "left_y", "left_z", "right_x", "right_y"]
    assert log.timestamps_ns.tolist() == [0, 2_000_000]
    assert log.accel_mps2.tolist() == [[0, 0, G, 0.5, -0.5], [0, 0.5 * G, G, 0.25, -0.25]]


def test_geometry_from_an_array_toml_in_its_order(tmp_path, capsys):
    write(tmp_path / "f.csv", TWO_SENSOR_CSV)
    write(tmp_path / "map.toml", TWO_SENSOR_MAP.format(left="", right=""))
    write(tmp_path / "array.toml", '''format = "gfimu-array/1"
name = "given"
[[accelerometers]]
name = "right"
position_m = [0.0, 0.02, 0.0]
axes = ["x", "y"]
[[accelerometers]]
name = "left"
position_m = [0.0, -0.02, 0.0]
''')
    convert(capsys, str(tmp_path / "f.csv"), "--map", str(tmp_path / "map.toml"), "--array",
            str(tmp_path / "array.toml"), "--out", str(tmp_path / "log"))
    log = gio.read_log(tmp_path / "log", check=False)
    assert [a.name for a in log.array.accelerometers] == ["right", "left"]
    assert log.array.accelerometers[0].position_m.tolist() == [0.0, 0.02, 0.0]
    assert log.accel_mps2[1].tolist() == [0.25, -0.25, 0, 0.5 * G, G]


def test_one_file_per_sensor_in_the_map(tmp_path, capsys):
    write(tmp_path / "rec" / "a.csv", "t [s],x,y,z\n0.0,1,2,3\n0.01,4,5,6\n0.02,7,8,9\n")
    write(tmp_path / "rec" / "b.csv", "t [s],x,y,z\n0.005,10,20,30\n0.015,20,40,60\n0.025,30,60,90\n")
    write(tmp_path / "map.toml", '''format = "gfimu-csv-map/1"
[time]
column = "t"
[[accelerometers]]
name = "a"
file = "a.csv"
unit = "m/s^2"
position_m = [0.0, 0.0, 0.0]
x = "x"
y = "y"
z = "z"
[[accelerometers]]
name = "b"
file = "b.csv"
unit = "m/s^2"
position_m = [0.1, 0.0, 0.0]
x = "x"
y = "y"
z = "z"
''')
    out = convert(capsys, str(tmp_path / "rec"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "log"))
    assert "b.csv linearly interpolated onto the timestamps of" in out
    log = gio.read_log(tmp_path / "log", check=False)
    assert log.timestamps_ns.tolist() == [10_000_000, 20_000_000]  # a.csv's rows inside b.csv's span
    assert log.accel_mps2.tolist() == [[4, 5, 6, 15, 30, 45], [7, 8, 9, 25, 50, 75]]


def test_real_euroc_imu0_rows(tmp_path, capsys):
    """The EuRoC V1_01_easy imu0 rows shipped with GTSAM (eqvio_processed_30s.csv holds them with times in
    seconds), written as EuRoC's mav0/imu0/data.csv and read with the euroc preset."""
    src = data_dir() / EUROC_FILE
    if not src.is_file():
        pytest.skip(f"{src} not found")
    header = src.read_text().splitlines()[0].split(",")
    col = {name: header.index(name) for name in ("t_abs", "gx", "gy", "gz", "ax", "ay", "az")}
    rows = [ln.split(",") for ln in src.read_text().splitlines()[1:] if ln.startswith("imu,")]
    t_ns = [int((Decimal(r[col["t_abs"]]) * 10**9).to_integral_value()) for r in rows]
    lines = [f"{t},{r[col['gx']]},{r[col['gy']]},{r[col['gz']]},{r[col['ax']]},{r[col['ay']]},{r[col['az']]}"
             for t, r in zip(t_ns, rows)]
    write(tmp_path / "mav0" / "imu0" / "data.csv", EUROC_HEADER + "\n".join(lines) + "\n")
    convert(capsys, str(tmp_path / "mav0" / "imu0" / "data.csv"), "--map", "euroc", "--out", str(tmp_path / "log"))
    log = gio.read_log(tmp_path / "log")
    assert len(log) == len(rows) == 6001
    assert log.timestamps_ns.tolist() == t_ns
    assert log.rate_hz == pytest.approx(200.0, rel=1e-3)
    assert log.gyro_b_radps.tolist() == [[float(r[col[c]]) for c in ("gx", "gy", "gz")] for r in rows]
    assert log.accel_mps2.tolist() == [[float(r[col[c]]) for c in ("ax", "ay", "az")] for r in rows]
    assert log.accel_mps2[0].tolist() == [9.0874956666666655, 0.13075533333333333, -3.6938381666666662]
    assert np.linalg.norm(log.accel_mps2[:200].mean(axis=0)) == pytest.approx(G, rel=0.05)


# --- bad inputs -------------------------------------------------------------------------------

SIMPLE_MAP = '''format = "gfimu-csv-map/1"
[time]
column = "t"
{time_unit}
[[accelerometers]]
name = "a"
x = "ax"
y = "ay"
z = "{z}"
'''


@pytest.fixture
def bad(tmp_path):
    write(tmp_path / "f.csv", "t [ms],ax [g],ay [g],az [g]\n0,0,0,1\n1,0,0,1\n2,0,0,1\n")
    return tmp_path


def run_bad(capsys, root, message, csv_text=None, map_text=None, extra=()):
    if csv_text is not None:
        write(root / "f.csv", csv_text)
    if map_text is not None:
        write(root / "map.toml", map_text)
    return refused(capsys, root, message, str(root / "f.csv"), "--map", str(root / "map.toml"), "--out",
                   str(root / "log"), *extra)


def test_time_without_a_unit_is_ambiguous(bad, capsys):
    err = run_bad(capsys, bad, "its unit is ambiguous", csv_text="t,ax [g],ay [g],az [g]\n0,0,0,1\n1,0,0,1\n",
                  map_text=SIMPLE_MAP.format(time_unit="", z="az"))
    assert "map.toml:3: time.column:" in err and "f.csv" in err


def test_a_missing_column(bad, capsys):
    err = run_bad(capsys, bad, "column 'acc_z' is not in", map_text=SIMPLE_MAP.format(time_unit="", z="acc_z"))
    assert "map.toml:9: accelerometers[0].z:" in err and "'az [g]'" in err


def test_conflicting_units(bad, capsys):
    run_bad(capsys, bad, "conflicting units for 't [ms]'", map_text=SIMPLE_MAP.format(time_unit='unit = "s"', z="az"))


def test_conflicting_axis_units(bad, capsys):
    text = SIMPLE_MAP.format(time_unit="", z="az").replace('z = "az"', 'z = { column = "az", unit = "m/s^2" }')
    run_bad(capsys, bad, "[g] in the header, [m/s^2] in the map", map_text=text)


def test_time_that_goes_back(bad, capsys):
    err = run_bad(capsys, bad, "time must be strictly increasing",
                  csv_text="t [ms],ax [g],ay [g],az [g]\n0,0,0,1\n2,0,0,1\n1,0,0,1\n",
                  map_text=SIMPLE_MAP.format(time_unit="", z="az"))
    assert "f.csv:4:" in err


def test_repeated_time(bad, capsys):
    run_bad(capsys, bad, "f.csv:3: time 0 ('t [ms]') is not after",
            csv_text="t [ms],ax [g],ay [g],az [g]\n0,0,0,1\n0,0,0,1\n", map_text=SIMPLE_MAP.format(time_unit="", z="az"))


def test_a_unit_that_is_not_understood(bad, capsys):
    run_bad(capsys, bad, "unit [furlong] of 'az [furlong]'",
            csv_text="t [ms],ax [g],ay [g],az [furlong]\n0,0,0,1\n1,0,0,1\n", map_text=SIMPLE_MAP.format(time_unit="", z="az"))


def test_an_axis_without_a_unit(bad, capsys):
    run_bad(capsys, bad, "column 'az' of", csv_text="t [ms],ax [g],ay [g],az\n0,0,0,1\n1,0,0,1\n",
            map_text=SIMPLE_MAP.format(time_unit="", z="az"))


def test_seconds_under_a_nanosecond_header_are_not_called_a_step_back(bad, capsys):
    """EuRoC-style times written in seconds under '[ns]': increasing times that round to one nanosecond are
    refused as such, pointing at the unit, not as time going back."""
    run_bad(capsys, bad, "f.csv:3: time 1403715273.267143 ('t [ns]') and the previous row's 1403715273.262143 "
                         "(line 2) are the same nanosecond in [ns]; is the time unit right?",
            csv_text="t [ns],ax [g],ay [g],az [g]\n1403715273.262143,0,0,1\n1403715273.267143,0,0,1\n",
            map_text=SIMPLE_MAP.format(time_unit="", z="az"))
    run_bad(capsys, bad, "f.csv:3: time 1403715273.2 ('t [ns]') is not after the previous row's 1403715273.3",
            csv_text="t [ns],ax [g],ay [g],az [g]\n1403715273.3,0,0,1\n1403715273.2,0,0,1\n")


def test_times_in_milliseconds_under_a_seconds_header_are_warned_about(tmp_path, capsys):
    """A 200 Hz recording written in ms under '[s]' reads as 0.2 Hz: the log is written, with one warning naming
    the file, the column and the likely unit."""
    write(tmp_path / "f.csv", "t [s],ax [g],ay [g],az [g]\n" + "".join(f"{5 * k},0,0,1\n" for k in range(20)))
    write(tmp_path / "map.toml", SIMPLE_MAP.format(time_unit="", z="az"))
    assert main(["convert", "csv", str(tmp_path / "f.csv"), "--map", str(tmp_path / "map.toml"), "--out",
                 str(tmp_path / "log"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err == (f"gfimu convert: warning: {tmp_path / 'f.csv'}: the times of 't [s]' step by a median 5 s, a "
                   "sample rate of 0.2 Hz, implausible for an accelerometer array: is the time unit [s] right; in "
                   "[ms] that is 200 Hz?\n")
    write(tmp_path / "g.csv", "t [ms],ax [g],ay [g],az [g]\n" + "".join(f"{5 * k},0,0,1\n" for k in range(20)))
    assert main(["convert", "csv", str(tmp_path / "g.csv"), "--map", str(tmp_path / "map.toml"), "--out",
                 str(tmp_path / "log2"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""


def test_text_in_a_value_and_a_ragged_row(bad, capsys):
    run_bad(capsys, bad, "f.csv:3: 'ay [g]' (field 3) value 'n/a' is not a number",
            csv_text="t [ms],ax [g],ay [g],az [g]\n0,0,0,1\n1,0,n/a,1\n", map_text=SIMPLE_MAP.format(time_unit="", z="az"))
    run_bad(capsys, bad, "f.csv:2: row has 3 fields, the header has 4",
            csv_text="t [ms],ax [g],ay [g],az [g]\n0,0,1\n1,0,0,1\n")


def test_a_missing_map_and_a_bad_map(bad, capsys):
    refused(capsys, bad, "column map not found", str(bad / "f.csv"), "--map", str(bad / "nomap.toml"), "--out",
            str(bad / "log"))
    run_bad(capsys, bad, "expected format = \"gfimu-csv-map/1\"", map_text='format = "gfimu-array/1"\n')
    run_bad(capsys, bad, "sign must be 1 or -1",
            map_text=SIMPLE_MAP.format(time_unit="", z="az").replace('z = "az"', 'z = { column = "az", sign = 2 }'))


def test_several_accelerometers_without_a_place(tmp_path, capsys):
    write(tmp_path / "f.csv", TWO_SENSOR_CSV)
    write(tmp_path / "map.toml", TWO_SENSOR_MAP.format(left="", right=""))
    refused(capsys, tmp_path, "accelerometer(s) left, right have no position or rotation", str(tmp_path / "f.csv"),
            "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "log"))


def test_geometry_in_two_places(tmp_path, capsys):
    write(tmp_path / "f.csv", TWO_SENSOR_CSV)
    write(tmp_path / "map.toml", TWO_SENSOR_MAP.format(left="position_m = [0.0, 0.0, 0.0]", right=""))
    write(tmp_path / "array.toml", 'format = "gfimu-array/1"\n[[accelerometers]]\nname = "left"\n'
                                   'position_m = [0.0, 0.0, 0.0]\n')
    refused(capsys, tmp_path, "give it in one place", str(tmp_path / "f.csv"), "--map", str(tmp_path / "map.toml"),
            "--array", str(tmp_path / "array.toml"), "--out", str(tmp_path / "log"))


def test_files_without_a_common_time_span(tmp_path, capsys):
    write(tmp_path / "rec" / "TotalAcceleration.csv", "time,seconds_elapsed,z,y,x\n100,0,1,0,0\n200,0,1,0,0\n")
    write(tmp_path / "rec" / "Gyroscope.csv", "time,seconds_elapsed,z,y,x\n300,0,1,0,0\n400,0,1,0,0\n")
    refused(capsys, tmp_path, "share no common time span", str(tmp_path / "rec"), "--map", "sensorlogger", "--out",
            str(tmp_path / "log"))


def test_a_folder_without_the_named_file(tmp_path, capsys):
    (tmp_path / "rec").mkdir()
    refused(capsys, tmp_path, "TotalAcceleration.csv: file not found", str(tmp_path / "rec"), "--map",
            "sensorlogger", "--out", str(tmp_path / "log"))


def test_a_map_naming_a_missing_file_names_the_map_key(bad, capsys):
    """A sensor's `file` (or [csv] `file`) that does not exist: the map's line and key, and the path looked for."""
    sensor_file = SIMPLE_MAP.format(time_unit='unit = "ms"', z="az").replace('name = "a"', 'name = "a"\nfile = "right.csv"')
    run_bad(capsys, bad, f"map.toml:7: accelerometers[0].file: {bad / 'right.csv'}: file not found",
            map_text=sensor_file)
    csv_file = SIMPLE_MAP.format(time_unit="", z="az").replace("[time]", '[csv]\nfile = "board.csv"\n[time]')
    run_bad(capsys, bad, f"map.toml:3: csv.file: {bad / 'board.csv'}: file not found", map_text=csv_file)


def test_gyro_as_reference_without_the_optional_gyroscope_says_where_it_looked(tmp_path, capsys):
    write(tmp_path / "rec" / "TotalAcceleration.csv", "time,seconds_elapsed,z,y,x\n100,0,1,0,0\n200,0,1,0,0\n")
    refused(capsys, tmp_path, f"{tmp_path / 'rec'}: --gyro-as-reference: no gyroscope to take as the reference: "
                              f"{tmp_path / 'rec' / 'Gyroscope.csv'} is not there", str(tmp_path / "rec"), "--map",
            "sensorlogger", "--gyro-as-reference", "--out", str(tmp_path / "log"))
    write(tmp_path / "Raw Data.csv", '"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)",'
                                     '"Acceleration z (m/s^2)"\n0,0,0,9.8\n0.01,0,0,9.8\n')
    refused(capsys, tmp_path, "no gyroscope to take as the reference: its columns (Gyroscope x, Gyroscope y, "
                              f"Gyroscope z) are not in {tmp_path / 'Raw Data.csv'}", str(tmp_path / "Raw Data.csv"),
            "--map", "phyphox", "--gyro-as-reference", "--out", str(tmp_path / "log"))


def test_the_documented_example(tmp_path, capsys):
    """The column map, board.csv and right.csv of docs/convert.md, converted as documented."""
    import re

    text = (Path(__file__).resolve().parents[1] / "docs" / "convert.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```(toml|text)\n(.*?)```", text, flags=re.DOTALL)
    assert [b[0] for b in blocks] == ["toml", "text", "text"]
    write(tmp_path / "board-map.toml", blocks[0][1])
    write(tmp_path / "rec" / "board.csv", blocks[1][1])
    write(tmp_path / "rec" / "right.csv", blocks[2][1])
    out = convert(capsys, str(tmp_path / "rec"), "--map", str(tmp_path / "board-map.toml"), "--out",
                  str(tmp_path / "log"))
    assert "right.csv linearly interpolated" in out
    log = gio.read_log(tmp_path / "log", check=False)
    assert log.timestamps_ns.tolist() == [10_000_000, 20_000_000]
    mg = G * 1e-3
    assert log.accel_mps2[:, :3].tolist() == [[0.02 * G, 0.01 * G, 999 * mg], [0.03 * G, -0.0 * G, 1000 * mg]]
    np.testing.assert_allclose(log.accel_mps2[:, 3:], [[0.15, 0.25, 9.75], [0.25, 0.35, 9.65]], rtol=0, atol=1e-12)
    assert log.gyro_b_radps.tolist() == [[1.25 * DEG, -1.5 * DEG, 0.25 * DEG], [1.0 * DEG, -1.0 * DEG, 0.0]]
    assert log.array.accelerometers[1].rotation_body_sensor.tolist() == [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    assert log.array.name == "board"


def test_the_map_unit_stands_where_the_header_holds_no_unit(bad, capsys):
    write(bad / "f.csv", "t [ms],ax (raw),ay [g],az [g]\n0,1,0,1\n1,2,0,1\n")
    write(bad / "map.toml", SIMPLE_MAP.format(time_unit="", z="az").replace('x = "ax"', 'x = { column = "ax", unit = "mg" }'))
    convert(capsys, str(bad / "f.csv"), "--map", str(bad / "map.toml"), "--out", str(bad / "log"))
    log = gio.read_log(bad / "log", check=False)
    assert log.accel_mps2[:, 0].tolist() == [G * 1e-3, 2 * (G * 1e-3)]


# --- the gravity a file counts [g] in ----------------------------------------------------------

G_MAP = '''format = "gfimu-csv-map/1"
{g}
[time]
column = "t"
unit = "ms"
[[accelerometers]]
name = "a"
x = "ax"
y = "ay"
z = {{ column = "az", unit = "mg" }}
[gyroscope]
unit = "deg/s"
x = "gx"
y = "gy"
z = "gz"
'''


@pytest.mark.parametrize("g", [9.8, 9.81, 9.7, 9.9])
def test_a_map_states_the_gravity_its_file_counts_g_in(tmp_path, capsys, g):
    """A tool that writes accelerations in g of 9.8 m/s² (not the standard 9.80665): ``g_mps2`` in the map
    converts its [g] and [mg] columns with that g; [m/s²] columns and the gyroscope are left as they are."""
    write(tmp_path / "f.csv", "t,ax [g],ay [m/s^2],az,gx,gy,gz\n0,1.5,-2,1000,90,0,0\n1,0.25,3,-500,0,90,0\n")
    write(tmp_path / "map.toml", G_MAP.format(g=f"g_mps2 = {g}"))
    convert(capsys, str(tmp_path / "f.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "log"))
    log = gio.read_log(tmp_path / "log", check=False)
    # one product of the value and the unit's factor, the factor g / 9.80665 times the standard unit's: a few
    # ulps of the exact value
    expected = np.array([[1.5 * g, -2.0, 1000 * 1e-3 * g], [0.25 * g, 3.0, -500 * 1e-3 * g]])
    np.testing.assert_allclose(log.accel_mps2, expected, rtol=4 * np.finfo(float).eps, atol=0)
    assert log.accel_mps2[:, 1].tolist() == [-2.0, 3.0]
    np.testing.assert_allclose(log.gyro_b_radps, [[90 * DEG, 0, 0], [0, 90 * DEG, 0]], rtol=0, atol=1e-15)


def test_without_g_mps2_a_file_counts_in_standard_gravity(tmp_path, capsys):
    write(tmp_path / "f.csv", "t,ax [g],ay [m/s^2],az,gx,gy,gz\n0,1.5,-2,1000,90,0,0\n1,0.25,3,-500,0,90,0\n")
    write(tmp_path / "map.toml", G_MAP.format(g=""))
    convert(capsys, str(tmp_path / "f.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "log"))
    log = gio.read_log(tmp_path / "log", check=False)
    assert log.accel_mps2.tolist() == [[1.5 * G, -2.0, 1000 * (G * 1e-3)], [0.25 * G, 3.0, -500 * (G * 1e-3)]]


@pytest.mark.parametrize("value", ["98", "9.6", "9.95", "\"9.8\"", "true", "0"])
def test_a_gravity_off_the_earth_is_refused(bad, capsys, value):
    err = run_bad(capsys, bad, "g_mps2: expected the gravity the file's [g] values count in",
                  map_text=G_MAP.format(g=f"g_mps2 = {value}"))
    assert "map.toml:2:" in err


def test_a_misspelt_top_level_key_is_refused_not_passed_over(bad, capsys):
    """``g_mps`` for ``g_mps2`` would leave every reading off by the ratio of the two g: refused, naming the key."""
    err = run_bad(capsys, bad, "unknown key 'g_mps'", map_text=G_MAP.format(g="g_mps = 9.8"))
    assert "map.toml:2:" in err and "g_mps2" in err
