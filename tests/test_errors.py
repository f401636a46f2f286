"""One error base (gfimu.errors): a mistake of the user or data that cannot support the request ends in
exit 2 and one line naming the file, key, row or option; a bug ends in exit 1 as an internal error.

The commands run in-process through ``gfimu.cli.main`` on a short simulated log; every case also
checks that no file under the test folder changed.
"""

from __future__ import annotations

import errno
import hashlib
import shutil
import stat
from pathlib import Path

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.cli import main
from gfimu.errors import DataError, GfimuError, InputError, ResourceError


@pytest.fixture(scope="module")
def base_log(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("base") / "log"
    assert main(["simulate", "random3d", "--out", str(d), "--rate-hz", "100", "--duration-s", "1", "-q"]) == 0
    return d


@pytest.fixture
def work(tmp_path, base_log) -> Path:
    shutil.copytree(base_log, tmp_path / "log")
    return tmp_path


def snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if stat.S_ISREG(p.lstat().st_mode)}


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))


CALIBRATION = 'format = "gfimu-calibration/1"\n{extra}[[accelerometers]]\nname = "{name}"\n' \
              'gain = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nbias_mps2 = [0, 0, 0]\n'


def setup_case(w: Path, case: str) -> None:
    """Spoil one thing in the work folder ``w`` (a copy of the log in ``w/log``)."""
    log = w / "log"
    if case == "array-noise":
        edit(log / "array.toml", "noise_std_mps2 = 0.07", 'noise_std_mps2 = "loud"')
    elif case == "imu-unit":
        edit(log / "imu.csv", "a1_x [m s^-2]", "a1_x [furlong]")
    elif case == "imu-cell":
        lines = (log / "imu.csv").read_text().split("\n")
        cells = lines[4].split(",")
        cells[2] = "x1"
        lines[4] = ",".join(cells)
        (log / "imu.csv").write_text("\n".join(lines))
    elif case == "cal-format":
        (w / "cal.toml").write_text('format = "other"\n')
    elif case == "cal-gravity":
        (w / "cal.toml").write_text(CALIBRATION.format(extra='gravity_mps2 = "strong"\n', name="a1"))
    elif case == "cal-sensor":
        (w / "cal.toml").write_text(CALIBRATION.format(extra="", name="zz"))
    elif case == "one-row":
        for name in ("imu.csv", "truth.csv"):
            (log / name).write_text("\n".join((log / name).read_text().split("\n")[:2]) + "\n")
    elif case == "no-truth":
        (log / "truth.csv").unlink()
    elif case == "short-estimate":
        (w / "est.csv").write_text("\n".join((log / "truth.csv").read_text().split("\n")[:40]) + "\n")


BAD = [
    # (case, argv, message naming the thing); {log} and {w} are filled in
    ("imm-option", ["estimate", "{log}", "--method", "imm", "-O", "t1=-5", "--out", "{w}/e.csv"],
     "imm option t1 must be a finite number >= 0, got -5"),
    ("smoother-option", ["estimate", "{log}", "-O", "motion_model='wobble'", "--out", "{w}/e.csv"],
     "-O motion_model='wobble': expected 'jerk' or 'snap' (option of method 'smoother', default 'jerk')"),
    ("preset", ["estimate", "{log}", "--preset", "nope", "--out", "{w}/e.csv"], "unknown smoother preset 'nope'"),
    ("fixed-lag-engine", ["estimate", "{log}", "--method", "fixed-lag", "-O", "engine='x'", "--out", "{w}/e.csv"],
     "-O engine='x': expected 'numpy' or 'gtsam' (option of method 'fixed-lag', default 'numpy')"),
    ("array-noise", ["estimate", "{log}", "--method", "inversion", "--out", "{w}/e.csv"],
     "log/array.toml:9: accelerometers[0].noise_std_mps2: expected a finite number >= 0, got 'loud'"),
    ("imu-unit", ["estimate", "{log}", "--method", "inversion", "--out", "{w}/e.csv"],
     "log/imu.csv:1: column 'a1_x' has unit [furlong]"),
    ("imu-cell", ["estimate", "{log}", "--method", "inversion", "--out", "{w}/e.csv"],
     "log/imu.csv:5: column 'a1_y' (field 3) value 'x1' is not a number"),
    ("cal-format", ["estimate", "{log}", "--method", "inversion", "--calibration", "{w}/cal.toml", "--out", "{w}/e.csv"],
     "cal.toml: format must be 'gfimu-calibration/1', got 'other'"),
    ("cal-gravity", ["estimate", "{log}", "--method", "inversion", "--calibration", "{w}/cal.toml", "--out", "{w}/e.csv"],
     "cal.toml:2: gravity_mps2: expected a number > 0 [m/s²], got 'strong'"),
    ("cal-sensor", ["compare", "{log}", "--methods", "inversion", "--calibration", "{w}/cal.toml"],
     "cal.toml: calibration has no accelerometer 'a1'; it has ['zz']"),
    ("cal-sensor", ["diagnose", "{log}", "--calibration", "{w}/cal.toml"],
     "cal.toml: calibration has no accelerometer 'a1'; it has ['zz']"),
    ("scenario-option", ["simulate", "random3d", "--out", "{w}/sim", "-O", "n_components='many'"],
     "scenario 'random3d' option n_components: expected an integer, got 'many'"),
    ("factor-groups", ["estimate", "{log}", "-O", "factor_groups=3", "--out", "{w}/e.csv"],
     "-O factor_groups=3: expected a tuple of FactorGroup objects (gfimu.smoother.model.groups)"),
    ("orientation", ["estimate", "{log}", "--method", "inversion", "--orientation", "gyro", "--out", "{w}/e.csv"],
     "orientation source 'gyro' needs gyroscope columns w_x, w_y, w_z"),
    ("no-truth", ["compare", "{log}", "--methods", "inversion"], "the log has neither truth.csv nor reference.csv"),
    ("short-estimate", ["evaluate", "{w}/est.csv", "{log}"],
     "estimate and truth timestamps do not match (the estimate has 39 rows, the truth 100)"),
    # the data cannot support the request
    ("one-row", ["estimate", "{log}", "--method", "fixed-lag", "--out", "{w}/e.csv"],
     "the log has 1 sample(s); the fixed-lag smoother needs at least 2"),
    ("moving", ["calibrate", "{log}", "--out", "{w}/c.toml"], "log: no still period found"),
]


@pytest.mark.parametrize("case, argv, message", BAD, ids=[f"{c[1][0]}-{c[0]}" for c in BAD])
def test_bad_inputs_exit_2_naming_the_thing(work, capsys, case, argv, message):
    setup_case(work, case)
    argv = [a.format(log=work / "log", w=work) for a in argv] + ["-q"]
    before = snapshot(work)
    rc = main(argv)
    err = [ln for ln in capsys.readouterr().err.splitlines() if "warning:" not in ln]
    assert rc == 2, err
    assert len(err) == 1 and err[0].startswith(f"gfimu {argv[0]}: error: "), err
    assert message in err[0], err
    assert "internal error" not in err[0] and "Traceback" not in err[0]
    assert snapshot(work) == before


@pytest.mark.parametrize("exc", [TypeError("unsupported operand"), ValueError("shapes (3,) and (4,) not aligned"),
                                 KeyError("omega"), IndexError("index 7 is out of bounds"),
                                 RuntimeError("solver state lost")])
def test_a_bug_is_an_internal_error_not_bad_input(work, capsys, monkeypatch, exc):
    """An exception gfimu did not raise on purpose, even a ValueError, is reported as a bug: exit 1."""
    import gfimu.readings

    def broken(*args, **kwargs):
        raise exc

    monkeypatch.setattr(gfimu.readings, "screen_log", broken)
    before = snapshot(work)
    rc = main(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "e.csv"), "-q"])
    err = capsys.readouterr().err.strip()
    assert rc == 1
    name = type(exc).__name__
    assert err == f"gfimu estimate: internal error: {name}: {str(exc)} (run with --debug for the traceback)"
    assert snapshot(work) == before
    with pytest.raises(type(exc)):  # --debug: the exception itself, with its traceback
        main(["--debug", "estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "e.csv"), "-q"])


def test_resource_errors_exit_1_with_their_message(work, capsys, monkeypatch):
    from gfimu.io import atomic

    def full(*args, **kwargs):
        raise ResourceError(errno.ENOSPC, "No space left on device", str(work / "e.csv"))

    monkeypatch.setattr(atomic.os, "replace", full)
    rc = main(["estimate", str(work / "log"), "--method", "inversion", "--out", str(work / "e.csv"), "-q"])
    assert rc == 1
    assert capsys.readouterr().err.strip() == f"gfimu estimate: error: {work / 'e.csv'}: no space left on the device"


def test_the_kinds(work):
    """The module errors are the kind they are, and stay the built-in class they were."""
    from gfimu.array import ArrayModelError
    from gfimu.calibration import CalibrationError, CalibrationFileError
    from gfimu.cli import CLIError
    from gfimu.cli.options import OptionError
    from gfimu.io.errors import LogFormatError, OutputError
    from gfimu.io.sources import SourceError
    from gfimu.methods import UnknownMethodError, make_estimator
    from gfimu.smoother.stream.fixed_lag import FixedLagSmootherClosed, FixedLagSmootherError

    for cls in (LogFormatError, ArrayModelError, OptionError, CLIError, SourceError, UnknownMethodError,
                CalibrationFileError, OutputError, FixedLagSmootherClosed):
        assert issubclass(cls, InputError) and issubclass(cls, ValueError), cls
    for cls in (CalibrationError, FixedLagSmootherError):
        assert issubclass(cls, DataError), cls
    assert issubclass(OutputError, OSError) and issubclass(FixedLagSmootherError, RuntimeError)
    assert issubclass(FixedLagSmootherClosed, RuntimeError)
    assert issubclass(ResourceError, OSError) and issubclass(ResourceError, GfimuError)
    assert not issubclass(ResourceError, ValueError)
    assert ResourceError.exit_status == 1 and InputError.exit_status == DataError.exit_status == 2

    with pytest.raises(UnknownMethodError) as info:  # a KeyError too, but printed without quotes
        make_estimator("nope")
    assert isinstance(info.value, KeyError) and str(info.value).startswith("unknown method 'nope'; choose one of")

    log = gio.read_log(work / "log")
    bad = log.replace(accel_mps2=np.where(np.arange(len(log))[:, None] == 3, np.nan, log.accel_mps2))
    with pytest.raises(DataError, match=r"non-finite accelerometer reading at sample 3, column a1_x"):
        make_estimator("ml").estimate(bad)
    with pytest.raises(InputError, match="imm option t1"):
        make_estimator("imm", t1=-1.0)
