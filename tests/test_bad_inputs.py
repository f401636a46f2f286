"""Bad or careless command lines and inputs: each ends in one clear message, a non-zero exit, and no lost file.

Every case checks the exit status, the message (one line, no traceback) and
that every file under the test folder is byte-identical afterwards (and that
no temporary file is left behind). The commands run in-process through
``gfimu.cli.main``; the signal cases run the command line in a subprocess.
"""

from __future__ import annotations

import errno
import hashlib
import os
import shutil
import signal
import stat
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from live_net import env as _env

from gfimu import io as gio
from gfimu.array import cube_array
from gfimu.cli import main, os_error_message
from gfimu.log import Log

REPO = Path(__file__).resolve().parents[1]
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


# --- fixtures and helpers ------------------------------------------------------------

@pytest.fixture(scope="module")
def base_log(tmp_path_factory) -> Path:
    """A short simulated log (cube array, 200 Hz, 2 s) with truth.csv, written once."""
    d = tmp_path_factory.mktemp("base") / "log"
    assert main(["simulate", "random3d", "--out", str(d), "--rate-hz", "200", "--duration-s", "2",
                 "--no-progress"]) == 0
    return d


@pytest.fixture
def work(tmp_path, base_log) -> Path:
    """A fresh folder holding a copy of the log as ``log/`` and an estimate ``est.csv``."""
    shutil.copytree(base_log, tmp_path / "log")
    truth = gio.read_motion_csv(tmp_path / "log" / "truth.csv")
    gio.write_motion_csv(truth.replace(omega_b_radps=truth.omega_b_radps + 0.1, accel_b_mps2=None,
                                       quaternion_wb=None), tmp_path / "est.csv")
    return tmp_path


def snapshot(root: Path) -> dict[str, str]:
    """sha256 of every file under ``root`` (and the type of anything that is not a regular file)."""
    out = {}
    for p in sorted(root.rglob("*")):
        st = os.lstat(p)
        if stat.S_ISREG(st.st_mode):
            out[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
        elif not stat.S_ISDIR(st.st_mode):
            out[str(p.relative_to(root))] = f"mode {stat.S_IFMT(st.st_mode):o}"
    return out


def refused(argv: list[str], root: Path, capsys, message: str, status: int | None = None) -> str:
    """Run ``gfimu argv``; assert it fails with ``message`` on one line and leaves ``root`` unchanged."""
    before = snapshot(root)
    rc = main(argv)
    err = capsys.readouterr().err.strip()
    assert rc != 0, f"exit 0 for {argv}"
    if status is not None:
        assert rc == status, err
    assert message in err, err
    assert "Traceback" not in err
    assert len(err.splitlines()) == 1 or all("warning:" in ln for ln in err.splitlines()[:-1]), err
    assert snapshot(root) == before
    return err


def packet(counter: int, ticks: int, raw: np.ndarray) -> bytes:
    """One MIMU4444 packet (header, counter, length, ticks, 48 int16 counts, checksum)."""
    body = struct.pack(">BHBI", 0xAA, counter % 65536, 100, ticks % (1 << 32)) + np.asarray(raw, ">i2").tobytes()
    return body + struct.pack(">H", sum(body) % 65536)


def data_bin(path: Path, n: int = 40) -> Path:
    raw = np.zeros((8, 6), dtype=np.int16)
    raw[:, 2] = 2048  # 1 g on z
    path.write_bytes(b"".join(packet(k, k * 1_024_000, raw) for k in range(n)))
    return path


# --- outputs onto inputs -----------------------------------------------------------------

@pytest.mark.parametrize("name", ["imu.csv", "truth.csv", "array.toml"])
def test_estimate_never_writes_over_a_file_of_its_log(work, capsys, name):
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "log" / name)], work,
            capsys, "is an input of this command", status=2)


@pytest.mark.parametrize("name", ["imu.csv", "truth.csv", "array.toml"])
def test_compare_calibrate_and_plot_never_write_over_the_log(work, capsys, name):
    target = str(work / "log" / name)
    refused(["compare", str(work / "log"), "--methods", "inversion", "--out", target], work, capsys,
            "is an input of this command")
    refused(["calibrate", str(work / "log"), "--out", target], work, capsys, "is an input of this command")
    refused(["plot", str(work / "log"), str(work / "est.csv"), "--out", target], work, capsys,
            "is an input of this command")


def test_an_estimate_kept_in_its_log_folder_can_be_written_again(work, capsys):
    """A file next to the log's own files is no input: estimating twice into LOG/est.csv works, and so do
    calibrate and plot; the log's own files stay refused."""
    target = work / "log" / "est.csv"
    for _ in range(2):
        assert main(["estimate", str(work / "log"), "--method", "inversion", "--out", str(target), "--quiet"]) == 0
    assert gio.read_motion_csv(target).omega_b_radps is not None
    assert main(["estimate", str(work / "log"), "--method", "inversion", "--out", str(target), "--quiet"]) == 0
    capsys.readouterr()
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "log" / "imu.csv")], work,
            capsys, "is an input of this command", status=2)
    refused(["evaluate", str(work / "log"), str(target), "--out", str(target)], work, capsys,
            "is an input of this command")


def test_evaluate_never_writes_over_truth_or_estimate(work, capsys):
    for target in (work / "log" / "truth.csv", work / "est.csv"):
        refused(["evaluate", str(work / "est.csv"), str(work / "log"), "--out", str(target)], work, capsys,
                "is an input of this command")
    refused(["evaluate", str(work / "est.csv"), str(work / "log" / "truth.csv"), "--out",
             str(work / "log" / "imu.csv")], work, capsys, "is an input of this command")


def test_hard_and_symbolic_links_to_an_input_are_refused(work, capsys):
    os.link(work / "log" / "imu.csv", work / "hard.csv")
    os.symlink(work / "log" / "truth.csv", work / "soft.csv")
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "hard.csv")], work, capsys,
            "the same file")
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "soft.csv")], work, capsys,
            "is an input of this command")


def test_calibration_input_is_protected_too(work, capsys):
    assert main(["calibrate", str(work / "log"), "--out", str(work / "cal.toml"), "--window-s", "0.1"]) in (0, 2)
    capsys.readouterr()
    if not (work / "cal.toml").exists():
        (work / "cal.toml").write_text("placeholder\n")
    refused(["estimate", str(work / "log"), "--method", "inversion", "--calibration", str(work / "cal.toml"),
             "--out", str(work / "cal.toml")], work, capsys, "is an input of this command")


# --- outputs onto things that are not regular files ----------------------------------------

def test_output_onto_a_fifo_is_refused(work, capsys):
    os.mkfifo(work / "pipe")
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "pipe")], work, capsys,
            "is a FIFO")
    assert stat.S_ISFIFO(os.stat(work / "pipe").st_mode)


def test_output_onto_a_folder_is_refused(work, capsys):
    (work / "folder").mkdir()
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "folder")], work, capsys,
            "is a folder")
    refused(["evaluate", str(work / "est.csv"), str(work / "log"), "--out", str(work / "folder")], work, capsys,
            "is a folder")
    refused(["simulate", "random3d", "--out", str(work / "est.csv"), "--duration-s", "0.1", "--no-progress"], work,
            capsys, "a log is written into a folder")


def test_output_onto_a_device_is_refused(work, capsys):
    if not os.path.exists("/dev/null") or not stat.S_ISCHR(os.stat("/dev/null").st_mode):
        pytest.skip("no /dev/null character device")
    before = os.stat("/dev/null")
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", "/dev/null"], work, capsys,
            "is a character device")
    refused(["calibrate", str(work / "log"), "--out", "/dev/null"], work, capsys, "is a character device")
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev


def test_missing_output_folder_is_named_not_a_temporary_file(work, capsys):
    err = refused(["estimate", str(work / "log"), "--method", "inversion", "--out",
                   str(work / "no" / "such" / "est.csv")], work, capsys, "the output folder")
    assert str(work / "no" / "such") in err and ".tmp" not in err


def test_read_only_output_folder(work, capsys):
    ro = work / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        if os.access(ro, os.W_OK):
            pytest.skip("permissions are not enforced for this user (root)")
        err = refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(ro / "est.csv")], work,
                      capsys, "permission denied", status=1)
        assert str(ro) in err
    finally:
        ro.chmod(0o755)


def test_dash_writes_the_estimate_to_standard_output(work, capsys):
    before = snapshot(work)
    assert main(["estimate", str(work / "log"), "--method", "inversion", "--out", "-", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("#timestamp [ns],w_x [rad s^-1]") and len(out.splitlines()) == 401
    assert snapshot(work) == before
    refused(["plot", str(work / "log"), str(work / "est.csv"), "--out", "-"], work, capsys,
            "cannot go to standard output")


# --- log folders: stale files and --force -------------------------------------------------

def test_simulate_refuses_a_non_empty_folder_without_force(work, capsys):
    refused(["simulate", "random3d", "--out", str(work / "log"), "--duration-s", "0.5", "--no-progress"], work, capsys,
            "the folder is not empty")


def test_convert_with_force_leaves_no_stale_truth(work, capsys):
    src = data_bin(work / "data.bin")
    (work / "log" / "notes.txt").write_text("kept\n")
    refused(["convert", "mimu4444", str(src), "--out", str(work / "log")], work, capsys, "use --force")
    assert main(["convert", "mimu4444", str(src), "--out", str(work / "log"), "--force"]) == 0
    capsys.readouterr()
    names = sorted(p.name for p in (work / "log").iterdir())
    assert names == ["array.toml", "imu.csv", "notes.txt", "reference.csv"]  # truth.csv of the simulation is gone
    log = gio.read_log(work / "log")
    assert log.truth is None and len(log) == 40
    # evaluate against the folder now uses the converted reference, not a stale simulated truth
    assert main(["evaluate", str(work / "est.csv"), str(work / "log"), "--against", "truth"]) == 2
    assert "no truth.csv" in capsys.readouterr().err


def test_simulate_with_force_removes_a_stale_reference(work, capsys):
    src = data_bin(work / "data.bin")
    out = work / "out"
    assert main(["convert", "mimu4444", str(src), "--out", str(out)]) == 0
    assert main(["simulate", "random3d", "--out", str(out), "--force", "--duration-s", "0.2", "--no-progress"]) == 0
    capsys.readouterr()
    assert sorted(p.name for p in out.iterdir()) == ["array.toml", "imu.csv", "truth.csv"]


def test_force_never_replaces_an_input(work, capsys):
    refused(["simulate", "random3d", "--array", str(work / "log" / "array.toml"), "--out", str(work / "log"),
             "--force", "--duration-s", "0.2", "--no-progress"], work, capsys, "is an input of this command")
    src = data_bin(work / "imu.csv")  # a recording that happens to be called imu.csv
    refused(["convert", "mimu4444", str(src), "--out", str(work), "--force"], work, capsys,
            "is an input of this command")


# --- parameters ----------------------------------------------------------------------------

@pytest.mark.parametrize("argv, message", [
    (["calibrate", "{log}", "--out", "{w}/c.toml", "--window-s", "0"], "argument --window-s: must be a number > 0"),
    (["calibrate", "{log}", "--out", "{w}/c.toml", "--window-s", "-1"], "argument --window-s: must be a number > 0"),
    (["calibrate", "{log}", "--out", "{w}/c.toml", "--window-s", "abc"], "argument --window-s: expected a number"),
    (["calibrate", "{log}", "--out", "{w}/c.toml", "--until-s", "nan"], "argument --until-s: expected a finite"),
    (["simulate", "random3d", "--out", "{w}/s", "--rate-hz", "0"], "argument --rate-hz: must be a number > 0 and"),
    (["simulate", "random3d", "--out", "{w}/s", "--rate-hz", "1e9"], "<= 100000 [Hz], got '1e9'"),
    (["simulate", "random3d", "--out", "{w}/s", "--duration-s", "inf"], "argument --duration-s: expected a finite"),
    (["simulate", "random3d", "--out", "{w}/s", "--seed", "-3"], "argument --seed: must be an integer >= 0"),
    (["estimate", "{log}", "--method", "fixed-lag", "--out", "{w}/e.csv", "--lag-s", "0"], "argument --lag-s"),
    (["evaluate", "{w}/est.csv", "{log}", "--sign-threshold", "-1"], "argument --sign-threshold"),
    (["demo", "--rate-hz", "-5"], "argument --rate-hz"),
    (["plot", "{log}", "{w}/est.csv", "--out", "{w}/f.png", "--start-s", "1", "--end-s", "0.5"],
     "--end-s 0.5 must be after --start-s 1"),
    (["plot", "{log}", "{w}/est.csv", "--out", "{w}/f.xyz"], "the figure format comes from the suffix"),
])
def test_out_of_range_options_name_the_option(work, capsys, argv, message):
    argv = [a.format(log=work / "log", w=work) for a in argv]
    refused(argv, work, capsys, message, status=2)


@pytest.mark.parametrize("argv, message", [
    (["estimate", "{log}", "--method", "smoother", "-O", "default_accel_noise_std_mps2=abc"],
     "-O default_accel_noise_std_mps2='abc': expected a number > 0 [m/s²] (option of method 'smoother', default 0.07)"),
    (["estimate", "{log}", "--method", "smoother", "-O", "use_gyro=3"], "-O use_gyro=3: expected true or false"),
    (["estimate", "{log}", "--method", "smoother", "-O", "no_such_option=1"], "has no option 'no_such_option'"),
    (["estimate", "{log}", "--method", "smoother", "-O", "noequals"], "-O 'noequals': expected KEY=VALUE"),
    (["estimate", "{log}", "--method", "fixed-lag", "-O", "lag_s=nan"], "-O lag_s=nan: expected a finite number"),
    (["estimate", "{log}", "--method", "smoother", "-O", "default_accel_noise_std_mps2=-1"],
     "-O default_accel_noise_std_mps2=-1: expected a number > 0 [m/s²]"),
    (["compare", "{log}", "--methods", "imm", "-O", "imm.t2=abc"], "-O imm.t2='abc': expected a number"),
    (["compare", "{log}", "--methods", "imm", "-O", "imm=3"], "expected METHOD.KEY=VALUE"),
    (["compare", "{log}", "--methods", "imm", "-O", "ml.x=3"], "method 'ml' is not among --methods imm"),
    (["compare", "{log}", "--methods", ""], "--methods: no method named"),
])
def test_bad_method_options_are_one_clear_message(work, capsys, argv, message):
    argv = [a.format(log=work / "log") for a in argv]
    if argv[0] == "estimate":
        argv += ["--out", str(work / "e.csv"), "--no-progress"]
    err = refused(argv, work, capsys, message)
    assert "Traceback" not in err


def test_compare_fails_when_a_method_fails_and_names_it(work, capsys):
    before = snapshot(work)
    rc = main(["compare", str(work / "log"), "--methods", "inversion,imm", "-O", "imm.t1=-5", "--no-bounds"])
    captured = capsys.readouterr()
    assert rc == 1
    assert "method 'imm' failed" in captured.err and "inversion" not in captured.err
    assert "| inversion" in captured.out  # the table of the methods that ran is still printed
    assert snapshot(work) == before


def test_compare_fails_when_every_method_cannot_run(work, capsys):
    text = (work / "log" / "array.toml").read_text()
    import re

    (work / "log" / "array.toml").write_text(re.sub(r"position_m = \[[^\]]*\]", "position_m = [0.0, 0.0, 0.0]", text))
    before = snapshot(work)
    rc = main(["compare", str(work / "log"), "--methods", "inversion,ml", "--no-bounds"])
    err = capsys.readouterr().err
    assert rc == 1 and "method 'inversion' not applicable" in err and "method 'ml' not applicable" in err
    assert snapshot(work) == before


# --- corrupt and implausible inputs -----------------------------------------------------------

def set_cell(path: Path, line: int, field: int, value: str) -> None:
    lines = path.read_text().split("\n")
    parts = lines[line - 1].split(",")
    parts[field] = value
    lines[line - 1] = ",".join(parts)
    path.write_text("\n".join(lines))


def test_one_corrupt_cell_names_file_line_and_column(work, capsys):
    set_cell(work / "log" / "imu.csv", 7, 3, "1.2.3")
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "e.csv")], work, capsys,
            "imu.csv:7: column 'a1_z' (field 4) value '1.2.3' is not a number", status=2)


def test_a_nan_reading_is_let_through_with_a_warning(work, capsys):
    set_cell(work / "log" / "imu.csv", 7, 3, "nan")
    main(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "e.csv"), "--no-progress"])
    err = capsys.readouterr().err
    assert "warning:" in err
    assert "imu.csv:7: 1 accelerometer reading(s) are NaN or infinite (first in column 'a1_z')" in err


def rewrite_times(path: Path, fn) -> None:
    lines = path.read_text().split("\n")
    out = [lines[0]]
    for ln in lines[1:]:
        if ln:
            t, rest = ln.split(",", 1)
            ln = f"{fn(int(t))},{rest}"
        out.append(ln)
    path.write_text("\n".join(out))


def test_milliseconds_under_a_nanosecond_header(work, capsys):
    for name in ("imu.csv", "truth.csv"):
        rewrite_times(work / "log" / name, lambda t: t // 1_000_000)  # 5 ms steps written as 5 under [ns]
    assert main(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "e.csv"),
                 "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "step by a median 5 ns, a sample rate of 2e+08 Hz" in err
    assert "likely the timestamps are in [ms] (200 Hz): write the header as '#timestamp [ms]'" in err


def test_wrong_rate_hz_in_array_toml(work, capsys):
    path = work / "log" / "array.toml"
    path.write_text(path.read_text().replace('name = "cube', 'rate_hz = 100.0\nname = "cube', 1))
    with pytest.warns(gio.LogPlausibilityWarning, match=r"rate_hz = 100, but the timestamps of .*imu\.csv step by a "
                      r"median 5 ms \(200 Hz\)"):
        gio.read_log(work / "log")
    path.write_text(path.read_text().replace("rate_hz = 100.0", "rate_hz = -200"))
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "e.csv")], work, capsys,
            "rate_hz: expected the nominal sample rate in Hz, a number > 0, got -200")


def test_positions_in_millimetres(work):
    import re

    path = work / "log" / "array.toml"
    path.write_text(re.sub(r"position_m = \[([^\]]*)\]",
                           lambda m: "position_m = [" + ", ".join(str(float(v) * 1000) for v in m.group(1).split(","))
                           + "]", path.read_text()))
    with pytest.warns(gio.LogPlausibilityWarning, match=r"sits 86\.6 m from the body origin; position_m is in metres: "
                      r"likely the positions were written in mm or cm"):
        gio.read_log(work / "log")


def still_log(tmp_path: Path, scale: float, unit: str = "m s^-2") -> Path:
    """A cube array lying still for 2 s at 100 Hz, readings multiplied by ``scale`` and labelled ``unit``."""
    array = cube_array(0.05)
    n = 200
    rng = np.random.default_rng(1)
    f = np.tile([0.0, 0.0, 9.80665], (n, len(array.accelerometers)))
    log = Log(array, np.arange(n) * 10_000_000, f + rng.normal(0, 0.01, f.shape))
    d = tmp_path / "still"
    gio.write_log(log.replace(accel_mps2=log.accel_mps2 * scale), d)
    if unit != "m s^-2":
        path = d / "imu.csv"
        path.write_text(path.read_text().replace("[m s^-2]", f"[{unit}]"))
    return d


@pytest.mark.parametrize("scale, unit, message", [
    (1 / 9.80665, "m s^-2", "likely the readings are in g; write the column units as [g]"),
    (1000 / 9.80665, "m s^-2", "likely the readings are in mg; write the column units as [mg]"),
    (1.0, "g", "likely readings in m/s² under a [g] header"),
])
def test_gravity_at_rest_tells_g_and_mg(tmp_path, scale, unit, message):
    with pytest.warns(gio.LogPlausibilityWarning, match=r"at rest the accelerometers read \|f\| = .*" + message.replace(
            "[", r"\[").replace("]", r"\]")):
        gio.read_log(still_log(tmp_path, scale, unit))


def test_plausible_logs_raise_no_warning(tmp_path, base_log):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", gio.LogPlausibilityWarning)
        gio.read_log(base_log)
        gio.read_log(still_log(tmp_path, 1.0))


def test_co_located_accelerometers_are_refused(work, capsys):
    import re

    path = work / "log" / "array.toml"
    path.write_text(re.sub(r"position_m = \[[^\]]*\]", "position_m = [0.01, 0.0, 0.0]", path.read_text()))
    for method in ("smoother", "fixed-lag", "inversion", "ml"):
        err = refused(["estimate", str(work / "log"), "--method", method, "--out", str(work / "e.csv"),
                       "--no-progress"], work, capsys, f"method {method!r} cannot run on", status=2)
        assert "warning:" in err and "have the same position_m" in err


def test_fixed_lag_refuses_a_one_row_log(work, capsys):
    for name in ("imu.csv", "truth.csv"):
        path = work / "log" / name
        path.write_text("\n".join(path.read_text().split("\n")[:2]) + "\n")
    refused(["estimate", str(work / "log"), "--method", "fixed-lag", "--out", str(work / "e.csv"), "--no-progress"],
            work, capsys, "the log has 1 sample(s); the fixed-lag smoother needs at least 2")


def test_fixed_lag_solver_failure_is_named_not_leaked(work, capsys, monkeypatch):
    """A gtsam failure while reading the state (as IndeterminantLinearSystem does) becomes one message with the time."""
    from gfimu.smoother.stream import fixed_lag

    real_new = fixed_lag.FixedLagSmoother._new_smoother

    class Failing:
        def __init__(self, inner):
            self.inner, self.calls = inner, 0

        def __getattr__(self, name):
            return getattr(self.inner, name)

        def calculateEstimateVector(self, key):  # noqa: N802 - gtsam's name
            self.calls += 1
            if self.calls > 30:
                raise RuntimeError("Indeterminant linear system detected while working near variable\n7 (Symbol: w7).")
            return self.inner.calculateEstimateVector(key)

    def failing_engine(self):
        engine = real_new(self)  # the gtsam engine; its iSAM2 smoother fails
        engine._smoother = Failing(engine._smoother)
        return engine

    monkeypatch.setattr(fixed_lag.FixedLagSmoother, "_new_smoother", failing_engine)
    err = refused(["estimate", str(work / "log"), "--method", "fixed-lag", "--out", str(work / "e.csv"),
                   "--no-progress", "-O", "tune_process_noise=False", "-O", "engine=gtsam"], work, capsys,
                  "the estimation problem is under-determined", status=2)  # the data's kind (gfimu.errors.DataError)
    assert "could not solve the state at t = " in err and "s after the stream start" in err


# --- operating-system errors --------------------------------------------------------------------

def test_calibration_that_is_a_folder_or_under_a_file(work, capsys):
    (work / "calfolder").mkdir()
    refused(["estimate", str(work / "log"), "--method", "inversion", "--calibration", str(work / "calfolder"),
             "--out", str(work / "e.csv")], work, capsys, f"{work / 'calfolder'}: is a folder, a file was expected",
            status=1)
    refused(["estimate", str(work / "log"), "--method", "inversion", "--calibration", str(work / "est.csv" / "x"),
             "--out", str(work / "e.csv")], work, capsys, "a part of this path is a file, not a folder", status=2)


@pytest.mark.parametrize("exc, message", [
    (OSError(errno.EBUSY, "Device or resource busy", "/mnt/card/log"), "/mnt/card/log: device or resource busy"),
    (FileExistsError(errno.EEXIST, "File exists", "/a", None, "/b"), "/a -> /b: already exists"),
    (PermissionError(errno.EACCES, "Permission denied", "/root/x"), "/root/x: permission denied"),
    (OSError(errno.ENOSPC, "No space left on device", "/full/imu.csv"), "/full/imu.csv: no space left on the device"),
    (IsADirectoryError(errno.EISDIR, "Is a directory", "/tmp"), "/tmp: is a folder, a file was expected"),
])
def test_os_errors_become_one_line_naming_the_path(exc, message):
    assert os_error_message(exc) == message


def test_os_error_inside_a_command_is_one_line(work, capsys, monkeypatch):
    from gfimu.io import atomic

    def busy(*args, **kwargs):
        raise OSError(errno.EBUSY, "Device or resource busy", str(work / "e.csv"))

    monkeypatch.setattr(atomic.os, "replace", busy)
    refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "e.csv"), "--no-progress"],
            work, capsys, f"{work / 'e.csv'}: device or resource busy", status=1)


@pytest.mark.parametrize("where, exc, what", [
    ("mkstemp", PermissionError(errno.EACCES, "Permission denied", "/somewhere/.e.csv.x1y2.tmp"), "permission denied"),
    ("fsync", OSError(errno.ENOSPC, "No space left on device"), "no space left on the device"),
])
def test_write_errors_name_the_destination_not_the_temporary_file(work, capsys, monkeypatch, where, exc, what):
    from gfimu.io import atomic

    def fail(*args, **kwargs):
        raise exc

    monkeypatch.setattr(atomic.tempfile if where == "mkstemp" else atomic.os, where, fail)
    err = refused(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "e.csv"),
                   "--no-progress"], work, capsys, f"{work / 'e.csv'}: {what}",
                  status=1)
    assert ".tmp" not in err


def test_debug_keeps_the_traceback(work):
    proc = subprocess.run([sys.executable, "-m", "gfimu", "--debug", "estimate", str(work / "log"), "--method",
                           "inversion", "--out", str(work / "log" / "imu.csv")],
                          capture_output=True, text=True, env=_env(), timeout=120)
    assert proc.returncode != 0 and "Traceback" in proc.stderr and "OutputError" in proc.stderr


# --- signals --------------------------------------------------------------------------------------

SLOW_WRITER = """
import sys, time
from gfimu.io import tables
real = tables._format_block
def slow(*args):
    time.sleep(0.2)
    return real(*args)
tables._format_block = slow
tables._ROWS_PER_BLOCK = 10
from gfimu.cli import main
raise SystemExit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("sig, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_while_writing_removes_the_temporary_file(work, sig, status):
    out = work / "e.csv"
    out.write_text("old estimate\n")
    proc = subprocess.Popen([sys.executable, "-c", SLOW_WRITER, "estimate", str(work / "log"), "--method",
                             "inversion", "--out", str(out), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    deadline = time.monotonic() + 60
    while not list(work.glob(".e.csv.*")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert list(work.glob(".e.csv.*")), "the temporary file never appeared"
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == status, err
    assert not list(work.glob(".e.csv.*"))
    assert out.read_text() == "old estimate\n"
    assert "Traceback" not in err


def test_an_output_is_refused_as_a_folder_before_as_an_input_and_a_link_as_the_file_it_names(tmp_path):
    from gfimu.io.errors import OutputError
    from gfimu.io.outputs import check_output

    folder = tmp_path / "d"
    folder.mkdir()
    with pytest.raises(OutputError, match=rf"^--out {folder}: exists and is a folder; refusing to replace it"):
        check_output(folder, [folder])
    data, link, hard = tmp_path / "in.csv", tmp_path / "link.csv", tmp_path / "hard.csv"
    data.write_text("t\n")
    os.symlink(data, link)
    os.link(data, hard)
    with pytest.raises(OutputError, match=rf"^--out {link}: is an input of this command; refusing to overwrite it"):
        check_output(link, [data])
    with pytest.raises(OutputError, match=rf"^--tum {hard}: is an input of this command \({link}, the same file\); "
                                          r"refusing"):
        check_output(hard, [link], "--tum")
    assert check_output(link, [tmp_path / "other.csv"]) == data  # the file a link names is written
    assert check_output(tmp_path / "new.csv", [data, link]) == tmp_path / "new.csv"
