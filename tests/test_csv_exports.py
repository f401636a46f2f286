"""``gfimu convert csv`` reads the exports phone apps and datasets write, as they are: phyphox's per-sensor
files (folder or zip), Sensor Logger's Android and iOS exports (the right file, unit and sign, and the report
says what was read), a EuRoC dataset folder at any level, quoted fields holding the delimiter; errors of a
preset name the recording, never a line of the preset."""

from __future__ import annotations

import contextlib
import hashlib
import io
from pathlib import Path

import numpy as np
import pytest

from csv_exports import G, T0_NS, euroc_dataset, motion, phyphox_export, sensor_logger_export
from gfimu import io as gio
from gfimu.cli import main


def snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file()}


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(["convert", "csv", *argv])
    return rc, out.getvalue(), err.getvalue()


def converted(root: Path, src: Path, *options: str):
    before = snapshot(root)
    rc, out, err = run(str(src), *options, "--out", str(root / "log"))
    assert rc == 0, err
    assert {k: v for k, v in snapshot(root).items() if not k.startswith("log")} == before  # inputs untouched
    return gio.read_log(root / "log"), out


@pytest.mark.parametrize("style", ["comma", "tab", "semicolon"])
@pytest.mark.parametrize("as_zip", [False, True])
def test_phyphox_per_sensor_export_folder_or_zip(tmp_path, style, as_zip):
    src = phyphox_export(tmp_path / ("export.zip" if as_zip else "export"), style=style, as_zip=as_zip)
    log, out = converted(tmp_path, src, "--map", "phyphox")
    t_s = log.timestamps_ns * 1e-9
    f, _, w = motion(t_s)
    assert log.timestamps_ns[0] == 17_300_000  # the first accelerometer time inside the gyroscope's span
    assert len(log) == 799 and set(np.diff(log.timestamps_ns).tolist()) == {5_000_000}
    np.testing.assert_allclose(log.accel_mps2, f, rtol=0, atol=1e-8)  # 10 significant digits in the file
    np.testing.assert_allclose(log.gyro_b_radps, w, rtol=0, atol=2e-5)  # linear interpolation over 5 ms
    assert "phyphox: Accelerometer.csv, the specific force (gravity included)" in out
    member = src / "Gyroscope.csv"
    assert f"{member}: 800 rows, time from 'Time (s)' in [s]" in out


def test_phyphox_linear_accelerometer_export(tmp_path):
    src = phyphox_export(tmp_path / "export", linear=True)
    log, out = converted(tmp_path, src, "--map", "phyphox")
    np.testing.assert_allclose(log.accel_mps2, motion(log.timestamps_ns * 1e-9)[1], rtol=0, atol=1e-8)
    assert "phyphox: Linear Accelerometer.csv, the linear acceleration (gravity removed by the phone)" in out
    assert log.array.readings == "linear_acceleration"
    assert 'readings = "linear_acceleration"' in (tmp_path / "log" / "array.toml").read_text()


def test_phyphox_errors_name_the_export_not_the_preset(tmp_path):
    src = phyphox_export(tmp_path / "export", gyro=False)
    text = (src / "Accelerometer.csv").read_text().splitlines()
    text[5] = text[5].replace(",", ",abc,", 1)
    (src / "Accelerometer.csv").write_text("\n".join(text) + "\n")
    before = snapshot(tmp_path)
    rc, out, err = run(str(src), "--map", "phyphox", "--out", str(tmp_path / "log"))
    assert rc == 2 and err.strip() == (f"gfimu convert: error: {src / 'Accelerometer.csv'}:6: row has 5 fields, the "
                                       "header has 4")
    (src / "Accelerometer.csv").unlink()
    rc, out, err = run(str(src), "--map", "phyphox", "--out", str(tmp_path / "log"))
    assert rc == 2 and "preset" not in err.split(":")[1] and str(src) in err
    assert "holds neither Accelerometer.csv, Linear Accelerometer.csv nor Raw Data.csv" in err
    zipped = phyphox_export(tmp_path / "e.zip", linear=True, as_zip=True)
    rc, out, err = run(str(zipped), "--map", "sensorlogger", "--out", str(tmp_path / "log"))
    assert rc == 2 and err.strip() == (f"gfimu convert: error: {zipped}: {zipped / 'TotalAcceleration.csv'}: file "
                                       "not found (read with the preset sensorlogger)")
    assert not (tmp_path / "log").exists()


@pytest.mark.parametrize("as_zip", [False, True])
def test_sensor_logger_android_reads_total_acceleration(tmp_path, as_zip):
    src = sensor_logger_export(tmp_path / ("rec.zip" if as_zip else "rec"), "android", as_zip=as_zip)
    log, out = converted(tmp_path, src, "--map", "sensorlogger")
    f, _, w = motion((log.timestamps_ns - T0_NS) * 1e-9)
    np.testing.assert_allclose(log.accel_mps2, f, rtol=0, atol=1e-12)
    np.testing.assert_allclose(log.gyro_b_radps, w, rtol=0, atol=1e-12)
    assert "Sensor Logger: TotalAcceleration.csv, the specific force (gravity included)" in out


@pytest.mark.parametrize("standardised", [False, True])
@pytest.mark.parametrize("gravity", [False, True])
def test_sensor_logger_ios_reads_the_acceleration_without_gravity_in_androids_signs(tmp_path, standardised, gravity):
    src = sensor_logger_export(tmp_path / "rec", "ios", standardised=standardised)
    if not gravity:
        (src / "Gravity.csv").unlink()
    log, out = converted(tmp_path, src, "--map", "sensorlogger")
    f, a, w = motion((log.timestamps_ns - T0_NS) * 1e-9)
    # with Gravity.csv beside it, the phone's gravity is added back: the specific force, a sum of two numbers
    # below 12 m/s² (a few ulps of 10, 2e-15 each); without it, the linear acceleration as read
    np.testing.assert_allclose(log.accel_mps2, f if gravity else a, rtol=0, atol=1e-12)  # +x when it accelerates to +x
    np.testing.assert_allclose(log.gyro_b_radps, w, rtol=0, atol=1e-12)
    assert "platform ios, app 1.41.1): Accelerometer.csv, the acceleration without gravity in m/s²" in out
    assert ("its signs turned" in out) != standardised
    assert "not the specific force (no TotalAcceleration.csv)" in out
    assert log.array.readings == ("specific_force" if gravity else "linear_acceleration")
    assert ('readings = "linear_acceleration"' in (tmp_path / "log" / "array.toml").read_text()) != gravity
    assert ("the linear acceleration plus the phone's own gravity vector (Gravity.csv)" in out) == gravity
    assert ("(the export holds no Gravity.csv to add back)" in out) != gravity


def test_sensor_logger_accelerometer_without_metadata_is_ambiguous(tmp_path):
    src = sensor_logger_export(tmp_path / "rec", "ios", metadata=False)
    before = snapshot(tmp_path)
    rc, out, err = run(str(src), "--map", "sensorlogger", "--out", str(tmp_path / "log"))
    assert rc == 2 and err.startswith(f"gfimu convert: error: {src}: holds Accelerometer.csv but no "
                                      "TotalAcceleration.csv, and no Metadata.csv naming the platform")
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("level", ["", "mav0", "mav0/imu0", "mav0/imu0/data.csv"])
def test_euroc_dataset_folder_at_any_level(tmp_path, level):
    root = euroc_dataset(tmp_path / "MH_01_easy")
    log, out = converted(tmp_path, root / level if level else root, "--map", "euroc")
    assert len(log) == 400 and log.timestamps_ns[0] == 1_403_636_579_758_555_392
    f, _, w = motion((log.timestamps_ns - log.timestamps_ns[0]) * 1e-9)
    np.testing.assert_allclose(log.accel_mps2, f, rtol=0, atol=1e-12)
    np.testing.assert_allclose(log.gyro_b_radps, w, rtol=0, atol=1e-12)


def test_euroc_folder_without_data_csv(tmp_path):
    (tmp_path / "empty").mkdir()
    rc, out, err = run(str(tmp_path / "empty"), "--map", "euroc", "--out", str(tmp_path / "log"))
    assert rc == 2 and err.strip() == (f"gfimu convert: error: {tmp_path / 'empty'}: holds no mav0/imu0/data.csv, "
                                       "imu0/data.csv or data.csv (give a EuRoC dataset folder, its mav0 or "
                                       "mav0/imu0 folder, or the data.csv)")


QUOTED_MAP = '''format = "gfimu-csv-map/1"
[csv]
decimal = "{decimal}"
[time]
column = "time"
unit = "ns"
[[accelerometers]]
name = "a"
unit = "m/s^2"
x = "ax"
y = "ay"
z = "az"
'''


def test_quoted_fields_holding_the_delimiter_with_decimal_commas(tmp_path):
    """A spreadsheet's export: comma-delimited, every field quoted, decimal commas, times in E notation."""
    rows = ['"time","ax","ay","az"']
    for k in range(4):
        rows.append(f'"1,70136286270{131 + k}E+018","0,{5 + k}","-0,25","9,{75 + k}"')
    (tmp_path / "x.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "map.toml").write_text(QUOTED_MAP.format(decimal="auto"))
    log, out = converted(tmp_path, tmp_path / "x.csv", "--map", str(tmp_path / "map.toml"))
    assert log.timestamps_ns.tolist() == [1_701_362_862_701_310_000 + k * 10_000 for k in range(4)]
    assert log.accel_mps2.tolist() == [[float(f"0.{5 + k}"), -0.25, float(f"9.{75 + k}")] for k in range(4)]
    # with the default decimal point the value is refused, naming the file, line, column and the fix
    (tmp_path / "map.toml").write_text(QUOTED_MAP.format(decimal="."))
    rc, out, err = run(str(tmp_path / "x.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "o"))
    assert rc == 2 and "x.csv:2: 'time': timestamp '1,70136286270131E+018' is not a number" in err


def test_an_unquoted_comma_file_with_a_decimal_comma_map_is_refused(tmp_path):
    (tmp_path / "x.csv").write_text("time,ax,ay,az\n0,1,2,3\n10,1,2,3\n")
    (tmp_path / "map.toml").write_text(QUOTED_MAP.format(decimal=","))
    rc, out, err = run(str(tmp_path / "x.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "o"))
    assert rc == 2 and "a decimal comma and a comma delimiter, but no field is quoted" in err


def test_a_decimal_comma_value_under_a_decimal_point_map_names_the_fix(tmp_path):
    (tmp_path / "x.csv").write_text("time;ax;ay;az\n0;1;2;3\n10;1,5;2;3\n")
    (tmp_path / "map.toml").write_text(QUOTED_MAP.format(decimal="."))
    rc, out, err = run(str(tmp_path / "x.csv"), "--map", str(tmp_path / "map.toml"), "--out", str(tmp_path / "o"))
    assert rc == 2 and err.strip() == (f"gfimu convert: error: {tmp_path / 'x.csv'}:3: 'ax' (field 2) value '1,5' "
                                       "is not a number (a decimal comma: give [csv] decimal = \",\" or \"auto\" "
                                       "in the map)")


def test_a_zip_with_one_top_folder_and_phyphox_raw_data_in_a_zip(tmp_path):
    import zipfile

    folder = sensor_logger_export(tmp_path / "2023-11-14_22-13-20", "android")
    with zipfile.ZipFile(tmp_path / "sl.zip", "w") as z:
        for p in sorted(folder.iterdir()):
            z.write(p, arcname=f"{folder.name}/{p.name}")
    log, out = converted(tmp_path, tmp_path / "sl.zip", "--map", "sensorlogger")
    np.testing.assert_allclose(log.accel_mps2, motion((log.timestamps_ns - T0_NS) * 1e-9)[0], rtol=0, atol=1e-12)
    raw = ("Time (s),Acceleration x (m/s^2),Acceleration y (m/s^2),Acceleration z (m/s^2),"
           "Absolute acceleration (m/s^2)\n0.0,0.1,0.2,9.8,9.8\n0.01,0.1,0.25,9.8,9.8\n0.02,0.1,0.2,9.75,9.8\n")
    with zipfile.ZipFile(tmp_path / "raw.zip", "w") as z:
        z.writestr("Raw Data.csv", raw)
    rc, out, err = run(str(tmp_path / "raw.zip"), "--map", "phyphox", "--out", str(tmp_path / "log2"))
    assert rc == 0, err
    log = gio.read_log(tmp_path / "log2", check=False)
    assert log.timestamps_ns.tolist() == [0, 10_000_000, 20_000_000]
    assert log.accel_mps2.tolist() == [[0.1, 0.2, 9.8], [0.1, 0.25, 9.8], [0.1, 0.2, 9.75]]


def test_sensor_logger_export_resaved_with_a_decimal_comma_gets_the_hint_on_its_time_column(tmp_path):
    """A spreadsheet in a decimal-comma locale re-saves the export with ';' and '1,70000000000000E+018': the time
    column's error gives the same hint as a value column's."""
    src = sensor_logger_export(tmp_path / "rec", "android")
    for path in src.glob("*.csv"):
        if path.name == "Metadata.csv":
            continue
        lines = path.read_text().splitlines()
        rows = [lines[0].replace(",", ";")]
        for line in lines[1:]:
            v = line.split(",")
            time = f"{float(v[0]):.14E}".replace("E+18", "E+018").replace(".", ",")
            rows.append(";".join([time] + [x.replace(".", ",") for x in v[1:]]))
        path.write_text("\n".join(rows) + "\n")
    before = snapshot(tmp_path)
    rc, out, err = run(str(src), "--map", "sensorlogger", "--out", str(tmp_path / "log"))
    hint = ' (a decimal comma: give [csv] decimal = "," or "auto" in the map)'
    assert rc == 2 and err.strip() == (f"gfimu convert: error: {src / 'TotalAcceleration.csv'}:2: 'time': timestamp "
                                       f"'1,70000000000000E+018' is not a number{hint}")
    assert snapshot(tmp_path) == before
    text = (src / "TotalAcceleration.csv").read_text().replace("1,70000000000000E+018", "1700000000000000000", 1)
    (src / "TotalAcceleration.csv").write_text(text)
    rc, out, err = run(str(src), "--map", "sensorlogger", "--out", str(tmp_path / "log"))
    assert rc == 2 and err.strip().endswith(f"is not a number{hint}") and ":3: 'time'" in err
