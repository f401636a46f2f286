"""Bad inputs seen from outside: the command, its exit status, one line naming the file, row, key or option,
and the inputs byte for byte as they were."""

from __future__ import annotations

import hashlib
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gfimu.cli import main
from gfimu.io.tables import MAX_LINE_BYTES

REPO = Path(__file__).resolve().parents[1]
EUROC_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n")


def _digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _gfimu(*args: str, cwd: Path, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gfimu", *args], capture_output=True, text=True, timeout=timeout,
                          cwd=cwd, env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin", "OMP_NUM_THREADS": "1"})


def _one_error_line(proc: subprocess.CompletedProcess, command: str) -> str:
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"gfimu {command}: error: "), proc.stderr
    return lines[0]


@pytest.fixture
def log(tmp_path) -> Path:
    d = tmp_path / "log"
    assert main(["simulate", "random3d", "--out", str(d), "--rate-hz", "100", "--duration-s", "1", "--no-progress",
                 "--quiet"]) == 0
    return d


def test_a_fifty_megabyte_line_of_a_converted_csv_is_refused_at_once(tmp_path):
    data = tmp_path / "data.csv"
    with open(data, "wb") as fh:
        fh.write(EUROC_HEADER.encode())
        fh.write(b"".join(b"%d,0.1,0.2,0.3,0,0,9.81\n" % (k * 5_000_000) for k in range(10)))
        fh.write(b"\0" * (50 << 20))
    before = _digest(tmp_path)
    t0 = time.monotonic()
    proc = _gfimu("convert", "csv", str(data), "--map", "euroc", "--out", str(tmp_path / "out"), cwd=tmp_path)
    elapsed = time.monotonic() - t0
    assert proc.returncode == 2
    line = _one_error_line(proc, "convert")
    assert f"{data}:12: line is longer than {MAX_LINE_BYTES} bytes" in line
    assert elapsed < 2.0 + 1.5  # start-up (imports) is most of it
    assert _digest(tmp_path) == before and not (tmp_path / "out").exists()


def test_a_long_line_with_its_line_end_is_named(tmp_path):
    data = tmp_path / "data.csv"
    data.write_bytes(EUROC_HEADER.encode() + b"0," + b"7" * (MAX_LINE_BYTES + 10) + b"\n5000000,1,2,3,4,5,6\n")
    proc = _gfimu("convert", "csv", str(data), "--map", "euroc", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert proc.returncode == 2
    assert f"{data}:2: line is longer than {MAX_LINE_BYTES} bytes ({MAX_LINE_BYTES + 12} bytes)" in \
        _one_error_line(proc, "convert")


def test_initial_omega_takes_three_numbers_in_any_form(log, tmp_path):
    texts = []
    for k, value in enumerate(["1,2,3", "[1,2,3]", "(1, 2, 3)", "-1,-2,-3"]):
        out = tmp_path / f"e{k}.csv"
        assert main(["estimate", str(log), "--method", "integration", "-O", f"initial_omega={value}", "--out",
                     str(out), "--quiet"]) == 0
        texts.append(out.read_text())
    assert texts[0] == texts[1] == texts[2]
    first = [float(v) for v in texts[0].splitlines()[1].split(",")[1:4]]
    flipped = [float(v) for v in texts[3].splitlines()[1].split(",")[1:4]]
    assert max(abs(v) for v in first) > 0.1
    assert first == pytest.approx([-v for v in flipped], abs=1e-12)  # the start chooses the sign of ω


@pytest.mark.parametrize("value, expected", [
    ("[1,2]", "-O initial_omega=[1, 2]: expected three numbers as initial_omega=1,2,3 or initial_omega=[1,2,3], got 2"),
    ("1", "-O initial_omega=1: expected text or three numbers as initial_omega=1,2,3"),
    ("[1,'a',3]", "-O initial_omega=[1, 'a', 3]: expected text or three numbers"),
])
def test_initial_omega_of_another_shape_is_refused(log, tmp_path, capsys, value, expected):
    assert main(["estimate", str(log), "--method", "integration", "-O", f"initial_omega={value}", "--out",
                 str(tmp_path / "e.csv")]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1
    assert not (tmp_path / "e.csv").exists()


def test_process_axis_factors_take_three_numbers(log, tmp_path, capsys):
    assert main(["estimate", str(log), "--method", "smoother", "-O", "process_axis_factors=1,2", "--out",
                 str(tmp_path / "e.csv")]) == 2
    assert ("-O process_axis_factors=(1, 2): expected three numbers as process_axis_factors=1,2,3 or "
            "process_axis_factors=[1,2,3], got 2 (option of method 'smoother')") in capsys.readouterr().err


def test_a_huge_option_value_is_quoted_in_part(log, tmp_path):
    value = "a" * 129_000
    for args, command in ((["estimate", str(log), "--method", "smoother", "-O", f"window_s={value}"], "estimate"),
                          (["estimate", str(log), "--method", "integration", "-O", f"initial_omega={value}"],
                           "estimate"),
                          (["simulate", "random3d", "--rate-hz", value], "simulate")):
        proc = _gfimu(*args, "--out", str(tmp_path / "o"), cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr
        assert len(proc.stderr) < 600, len(proc.stderr)
        assert "129,0" in proc.stderr and "characters)" in proc.stderr, proc.stderr
        assert proc.stderr.startswith(f"gfimu {command}: error: ") or proc.stderr.startswith("gfimu: error: ")


def test_compare_writes_no_estimate_into_the_log_folder(log, tmp_path):
    before = _digest(log)
    for folder in (str(log), str(log) + "/", str(log / ".")):
        proc = _gfimu("compare", str(log), "--methods", "inversion", "--estimates-dir", folder, cwd=tmp_path)
        assert proc.returncode == 2
        assert f"--estimates-dir {log}: is the input log folder" in _one_error_line(proc, "compare")
    assert _digest(log) == before


@pytest.mark.parametrize("edit, key", [
    (('position_m = [', 'position_m = [1e300, '), "accelerometers[0].position_m: [1e+300, 0.05, 0.05] puts the "
                                                 "accelerometer 1e+300 m from the body origin; an accelerometer of "
                                                 "one rigid body lies within 100 m"),
    (('axes = [', 'rotation_body_sensor = [[1e308, 0, 0], [0, 1e308, 0], [0, 0, 1e308]]\naxes = ['),
     "accelerometers[0].rotation_body_sensor: [[1e+308, 0.0, 0.0]"),
])
def test_array_values_no_rotation_or_position_can_be(log, tmp_path, edit, key):
    text = (log / "array.toml").read_text()
    old, new = edit
    head, _, tail = text.partition(old)
    if old == 'position_m = [':
        tail = tail.split(",", 1)[1]  # drop the first coordinate, replaced
    (log / "array.toml").write_text(head + new + tail)
    before = _digest(log)
    proc = _gfimu("estimate", str(log), "--method", "inversion", "--out", str(tmp_path / "e.csv"), cwd=tmp_path)
    assert proc.returncode == 2
    line = _one_error_line(proc, "estimate")
    assert f"{log / 'array.toml'}:" in line and key in line
    assert _digest(log) == before


def test_deeply_nested_toml_inputs_are_refused_naming_them(log, tmp_path):
    deep = "x = " + "[" * 5000 + "]" * 5000 + "\n"
    calibration = tmp_path / "cal.toml"
    calibration.write_text(deep)
    cmap = tmp_path / "map.toml"
    cmap.write_text('format = "gfimu-csv-map/1"\n' + "y = " + "{a=" * 3000 + "1" + "}" * 3000 + "\n")
    (tmp_path / "data.csv").write_text(EUROC_HEADER + "0,1,2,3,4,5,6\n")
    array = log / "array.toml"
    array.write_text(deep + array.read_text())
    cases = [(["estimate", str(log), "--method", "inversion", "--out", str(tmp_path / "e.csv")], str(array)),
             (["convert", "csv", str(tmp_path / "data.csv"), "--map", str(cmap), "--out", str(tmp_path / "o")],
              str(cmap))]
    log2 = tmp_path / "log2"
    assert main(["simulate", "random3d", "--out", str(log2), "--rate-hz", "100", "--duration-s", "1", "--quiet"]) == 0
    cases.append((["estimate", str(log2), "--calibration", str(calibration), "--method", "inversion", "--out",
                   str(tmp_path / "e.csv")], str(calibration)))
    for args, named in cases:
        proc = _gfimu(*args, cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr
        line = _one_error_line(proc, args[0])
        assert f"{named}: nested deeper than 64 levels" in line


def test_a_delimiter_of_the_wrong_type_is_named(tmp_path):
    (tmp_path / "data.csv").write_text(EUROC_HEADER + "0,1,2,3,4,5,6\n")
    cmap = tmp_path / "map.toml"
    cmap.write_text('format = "gfimu-csv-map/1"\n[csv]\ndelimiter = [1, 2]\n[time]\ncolumn = 0\nunit = "ns"\n'
                    '[[accelerometers]]\nname = "a"\nx = 4\ny = 5\nz = 6\nunit = "m/s^2"\n')
    proc = _gfimu("convert", "csv", str(tmp_path / "data.csv"), "--map", str(cmap), "--out", str(tmp_path / "o"),
                  cwd=tmp_path)
    assert proc.returncode == 2
    assert f"{cmap}:3: csv.delimiter: expected" in _one_error_line(proc, "convert")


def test_a_log_with_forty_percent_timing_jitter_is_one_segment(log, tmp_path):
    """Android-like timing: steps of 10 ms ± 40 % (uniform) stay under the log's gap rule (1.5 × the median
    step), so the estimators run over the whole log without a restart and without a gap warning."""
    import numpy as np

    from gfimu import io as gio

    lines = (log / "imu.csv").read_text().splitlines()
    rng = np.random.default_rng(7)
    steps = np.round(10_000_000 * (1 + rng.uniform(-0.4, 0.4, len(lines) - 2))).astype(np.int64)
    t = np.concatenate([[0], np.cumsum(steps)])
    (log / "imu.csv").write_text("\n".join([lines[0]] + [f"{t[k]}," + ln.split(",", 1)[1]
                                                         for k, ln in enumerate(lines[1:])]) + "\n")
    (log / "truth.csv").unlink()
    assert len(gio.read_log(log).segments()) == 1
    proc = _gfimu("estimate", str(log), "--method", "integration", "--out", str(tmp_path / "e.csv"), cwd=tmp_path)
    assert proc.returncode == 0 and "gap" not in proc.stderr, proc.stderr
    # one step of 2.5 periods is a gap: said, with its line
    t2 = t.copy()
    t2[50:] += 15_000_000
    (log / "imu.csv").write_text("\n".join([lines[0]] + [f"{t2[k]}," + ln.split(",", 1)[1]
                                                         for k, ln in enumerate(lines[1:])]) + "\n")
    proc = _gfimu("estimate", str(log), "--method", "integration", "--out", str(tmp_path / "e.csv"), cwd=tmp_path)
    assert proc.returncode == 0
    assert f"{log / 'imu.csv'}: 1 gap(s) in time" in proc.stderr and "before line 52" in proc.stderr


def test_a_reading_of_1e308_gives_a_finite_estimate_and_a_warning_naming_it(log, tmp_path):
    import numpy as np

    lines = (log / "imu.csv").read_text().splitlines()
    fields = lines[11].split(",")
    fields[3] = "1e308"
    lines[11] = ",".join(fields)
    (log / "imu.csv").write_text("\n".join(lines) + "\n")
    for method in ("inversion", "smoother"):
        out = tmp_path / f"{method}.csv"
        proc = _gfimu("estimate", str(log), "--method", method, "--out", str(out), cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        assert "1 accelerometer reading(s) replaced by the median of their neighbours (1 out of range): row 10 a1_z" \
            in proc.stderr
        assert "overflow" not in proc.stderr and "internal error" not in proc.stderr
        values = np.loadtxt(out, delimiter=",", skiprows=1)
        assert values.shape[0] == 100 and np.all(np.isfinite(values))


def test_a_column_of_nan_is_refused_naming_the_file_and_column(log, tmp_path):
    lines = (log / "imu.csv").read_text().splitlines()
    rows = [ln.split(",") for ln in lines[1:]]
    for r in rows:
        r[5] = "nan"
    (log / "imu.csv").write_text("\n".join([lines[0]] + [",".join(r) for r in rows]) + "\n")
    for args in (["estimate", str(log), "--method", "ml", "--out", str(tmp_path / "e.csv")],
                 ["calibrate", str(log), "--out", str(tmp_path / "c.toml")]):
        proc = _gfimu(*args, cwd=tmp_path)
        assert proc.returncode == 2
        errors = [ln for ln in proc.stderr.splitlines() if ": error: " in ln]
        assert errors == [f"gfimu {args[0]}: error: {log}/imu.csv: column 'a2_y': 100 of 100 readings are not "
                          "finite, the first at row 0, with no finite reading near them to replace them"], proc.stderr


@pytest.mark.parametrize("text, expected", [
    ('accelerometers = [5, 6]\n', ": accelerometers[0]: expected an [[accelerometers]] table, got 5"),
    ('gyroscope = 5\n[[accelerometers]]\nname = "a1"\naxes = 5\nbias_mps2 = [0, 0, 0]\ngain = [[1, 0, 0], [0, 1, 0], '
     '[0, 0, 1]]\n', ':5: accelerometers[0].axes: axes must be a list among "x", "y", "z"; got 5'),
    ('gyroscope = 5\n[[accelerometers]]\nname = "a1"\nbias_mps2 = [0, 0, 0]\ngain = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n',
     ":2: gyroscope: expected a table [gyroscope], got 5"),
])
def test_a_calibration_key_of_the_wrong_type_is_named(log, tmp_path, text, expected):
    calibration = tmp_path / "cal.toml"
    calibration.write_text('format = "gfimu-calibration/1"\n' + text)
    proc = _gfimu("estimate", str(log), "--calibration", str(calibration), "--method", "inversion", "--out",
                  str(tmp_path / "e.csv"), cwd=tmp_path)
    assert proc.returncode == 2
    assert f"{calibration}{expected}" in _one_error_line(proc, "estimate")


def test_a_gyroscope_reading_of_1e308_is_read_as_nan_and_named(tmp_path):
    import numpy as np

    array = tmp_path / "array.toml"
    log = tmp_path / "glog"
    assert main(["simulate", "random3d", "--out", str(tmp_path / "plain"), "--rate-hz", "100", "--duration-s", "1",
                 "--quiet"]) == 0
    array.write_text((tmp_path / "plain" / "array.toml").read_text() + "\n[gyroscope]\nnoise_std_radps = 0.01\n")
    assert main(["simulate", "random3d", "--array", str(array), "--out", str(log), "--rate-hz", "100",
                 "--duration-s", "1", "--quiet"]) == 0
    lines = (log / "imu.csv").read_text().splitlines()
    column = lines[0].split(",").index("w_y [rad s^-1]")
    fields = lines[31].split(",")
    fields[column] = "1e308"
    lines[31] = ",".join(fields)
    (log / "imu.csv").write_text("\n".join(lines) + "\n")
    warning = (f"gfimu estimate: warning: {log / 'imu.csv'}:32: 1 gyroscope reading(s) beyond ±10000 rad/s (first in "
               "column 'w_y', 1e+308): no gyroscope reads that; read as NaN")
    proc = _gfimu("estimate", str(log), "--method", "gyro-aided", "--out", str(tmp_path / "g.csv"), cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [warning, (
        f"gfimu estimate: error: {log}/imu.csv:32: gyroscope column 'w_y' is not finite (1 reading(s) NaN, infinite "
        "or beyond ±1e4 rad/s); method 'gyro-aided' needs every gyroscope reading")]
    out = tmp_path / "e.csv"
    proc = _gfimu("estimate", str(log), "--method", "inversion", "--out", str(out), cwd=tmp_path)
    assert proc.returncode == 0 and warning in proc.stderr and "overflow" not in proc.stderr, proc.stderr
    assert np.all(np.isfinite(np.loadtxt(out, delimiter=",", skiprows=1)))


@pytest.mark.slow
@pytest.mark.parametrize("value", ["1e308", "nan"])
def test_live_replaces_a_reading_beyond_any_range_as_estimate_does(log, tmp_path, value):
    """A reading of 1e308 or NaN in the stream is replaced by the screening, as gfimu estimate replaces it in the
    log: live's file equals estimate --method fixed-lag's byte for byte, and both name the reading. With
    screen_readings=False, live skips the row instead and says why, and estimate refuses the log naming the line."""
    import numpy as np

    lines = (log / "imu.csv").read_text().splitlines()
    fields = lines[50].split(",")
    fields[2] = value
    lines[50] = ",".join(fields)
    (log / "imu.csv").write_text("\n".join(lines) + "\n")
    env = {"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin", "OMP_NUM_THREADS": "1"}
    est = tmp_path / "est.csv"
    proc = _gfimu("estimate", str(log), "--method", "fixed-lag", "--out", str(est), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    kind = "out of range" if value == "1e308" else "not finite"
    named = f"1 accelerometer reading(s) replaced by the median of their neighbours (1 {kind}): row 49 a1_y"
    assert named in proc.stderr
    out = tmp_path / "live.csv"
    proc = subprocess.run([sys.executable, "-m", "gfimu", "live", "--array", str(log / "array.toml"), "--source", "-",
                           "--out", str(out)], input="\n".join(lines) + "\n", capture_output=True, text=True,
                          timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    assert "100 samples in, 100 estimates out; 0 bad rows" in proc.stderr
    assert "1 readings replaced by the screening" in proc.stderr and named[2:] in proc.stderr
    assert "overflow" not in proc.stderr and "Eigenvalues" not in proc.stderr
    assert out.read_bytes() == est.read_bytes()
    assert np.all(np.isfinite(np.loadtxt(out, delimiter=",", skiprows=1)))
    proc = subprocess.run([sys.executable, "-m", "gfimu", "live", "--array", str(log / "array.toml"), "--source", "-",
                           "--out", str(out), "-O", "screen_readings=False"], input="\n".join(lines) + "\n",
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    reason = ("is beyond any accelerometer's range (±1e+07 m/s²)" if value == "1e308" else "is not finite")
    assert f"line 51 skipped: field 3 '{value}' {reason}" in proc.stderr
    assert "99 samples in, 99 estimates out; 1 bad rows" in proc.stderr
    assert np.all(np.isfinite(np.loadtxt(out, delimiter=",", skiprows=1)))
    proc = _gfimu("estimate", str(log), "--method", "fixed-lag", "-O", "screen_readings=False", "--out",
                  str(tmp_path / "unscreened.csv"), cwd=tmp_path)
    assert proc.returncode == 2 and not (tmp_path / "unscreened.csv").exists()
    assert f"{log / 'imu.csv'}:51: column 'a1_y' reads {float(value):g} (1 such reading(s)): not a reading; with " \
        "screen_readings=False the readings are used as they are" in proc.stderr


@pytest.mark.parametrize("method, option, expected", [
    ("ml", "grid_directions=0", "ml option grid_directions must be a whole number >= 1 (the size of the starting "
                                "grid), got 0"),
    ("ml", "grid_magnitudes=-1", "ml option grid_magnitudes must be a whole number >= 1"),
    ("ml", "max_omega_radps=0", "ml option max_omega_radps must be a number > 0 [rad/s]"),
    ("fixed-lag", "tune_window_s=0", "-O tune_window_s=0: expected a number > 0 [s] (option of method 'fixed-lag', "
                                     "default 3.0)"),
    ("smoother", "window_s=1e308", "-O window_s=1e+308: expected 0 or a number of magnitude 1e-100 to 1e+12 (option "
                                   "of method 'smoother', default 30.0)"),
    ("smoother", "specific_force_random_walk_mps2_per_sqrt_s=1e-40",
     "-O specific_force_random_walk_mps2_per_sqrt_s=1e-40: expected a number >= 1e-09 [m/s²/√s] (a smaller noise "
     "density leaves the normal equations singular)"),
    ("fixed-lag", "initial_omega_std_radps=1e-320", "-O initial_omega_std_radps=1e-320: expected 0 or a number of "
                                                    "magnitude 1e-100 to 1e+12"),
])
def test_an_option_out_of_its_range_is_an_input_error(log, tmp_path, capsys, method, option, expected):
    assert main(["estimate", str(log), "--method", method, "-O", option, "--out", str(tmp_path / "e.csv")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gfimu estimate: error: ") and expected in err and "internal error" not in err


def test_simulate_refuses_an_absurd_length_before_any_work(tmp_path, capsys):
    assert main(["simulate", "random3d", "--duration-s", "1e12", "--out", str(tmp_path / "s")]) == 2
    assert capsys.readouterr().err == (
        "gfimu simulate: error: --duration-s 1e+12 at 500 Hz is 5e+14 samples; a simulated log holds at most 2e+07 "
        "(give a shorter --duration-s or a lower --rate-hz)\n")
    assert not (tmp_path / "s").exists()
