"""A log folder is always one run's: written whole or not at all, never through a link, and output
names that the file system can hold.

Each case runs the command line (in a subprocess where a signal is sent) and checks the exit status,
the one-line message naming the path, that the old log reads byte-identical afterwards, that nothing
outside the output folder changed and that no temporary file or folder is left.
"""

from __future__ import annotations

import errno
import hashlib
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from live_net import env as _env

from gfimu import io as gio
from gfimu.cli import main

REPO = Path(__file__).resolve().parents[1]


def snapshot(root: Path) -> dict[str, str]:
    """sha256 of every file under ``root``, links as their target, other types by mode."""
    out = {}
    for p in sorted(root.rglob("*")):
        st = os.lstat(p)
        key = str(p.relative_to(root))
        if stat.S_ISLNK(st.st_mode):
            out[key] = f"link -> {os.readlink(p)}"
        elif stat.S_ISREG(st.st_mode):
            out[key] = hashlib.sha256(p.read_bytes()).hexdigest()
        elif not stat.S_ISDIR(st.st_mode):
            out[key] = f"mode {stat.S_IFMT(st.st_mode):o}"
    return out


def temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


@pytest.fixture
def old_log(tmp_path) -> Path:
    """A simulated log with truth.csv and a file of the user's next to it."""
    d = tmp_path / "work" / "log"
    assert main(["simulate", "random3d", "--out", str(d), "--rate-hz", "200", "--duration-s", "1", "--no-progress",
                 "--quiet"]) == 0
    (d / "notes.txt").write_text("mine\n")
    return d


def test_sigint_during_simulate_force_leaves_the_old_log(old_log):
    """SIGINT while the new log is being written: exit 130, the old log byte-identical and still read,
    the temporary folder gone."""
    parent = old_log.parent
    before = snapshot(parent)
    proc = subprocess.Popen([sys.executable, "-m", "gfimu", "simulate", "random3d", "--out", str(old_log), "--force",
                             "--rate-hz", "1000", "--duration-s", "120", "--no-progress"],
                            env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    sent = False
    while time.monotonic() < deadline and proc.poll() is None:
        tmp = [p for p in parent.iterdir() if p.name.startswith(".log.") and p.is_dir()]
        if tmp and any(tmp[0].iterdir()):  # the new log's first files are being written
            proc.send_signal(signal.SIGINT)
            sent = True
            break
        time.sleep(0.01)
    out, err = proc.communicate(timeout=120)
    assert sent, f"the temporary folder never appeared: {err}"
    assert proc.returncode == 130, err
    assert "SIGINT" in err and "Traceback" not in err
    assert snapshot(parent) == before
    assert temporaries(parent) == []
    assert len(gio.read_log(old_log)) == 200


def test_a_full_disk_while_writing_leaves_the_old_log(old_log, capsys, monkeypatch):
    """A write that fails (no space left) half-way through the new log: exit 1 naming the file, the old
    log byte-identical, no temporary folder."""
    from gfimu.io import log_dir

    def full(motion, path, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(log_dir, "write_motion_csv", full)
    before = snapshot(old_log.parent)
    rc = main(["simulate", "random3d", "--out", str(old_log), "--force", "--duration-s", "0.5", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 1
    assert f"error: {old_log / 'truth.csv'}: no space left on the device" in err and "Traceback" not in err
    assert snapshot(old_log.parent) == before
    assert temporaries(old_log.parent) == []


def test_force_replaces_the_log_whole_and_keeps_other_files(old_log, capsys):
    outside = old_log.parent / "outside.csv"
    outside.write_text("not a log file\n")
    assert main(["simulate", "random3d", "--out", str(old_log), "--force", "--duration-s", "0.3", "--rate-hz", "100",
                 "--no-noise", "--no-progress"]) == 0
    assert sorted(p.name for p in old_log.iterdir()) == ["array.toml", "imu.csv", "notes.txt", "truth.csv"]
    assert (old_log / "notes.txt").read_text() == "mine\n"
    assert len(gio.read_log(old_log)) == 30
    assert outside.read_text() == "not a log file\n"
    assert temporaries(old_log.parent) == []


def test_a_link_planted_in_out_is_not_written_through(old_log, tmp_path, capsys):
    """imu.csv (and truth.csv) of the folder are links to files outside it: --force replaces the links
    by the new files; the files outside stay byte-identical."""
    victim = tmp_path / "victim.csv"
    victim.write_text("precious\n")
    other = tmp_path / "other.txt"
    other.write_text("also precious\n")
    (old_log / "imu.csv").unlink()
    os.symlink(victim, old_log / "imu.csv")
    os.symlink(other, old_log / "link-to-other.txt")  # a user's link: kept as a link
    assert main(["simulate", "random3d", "--out", str(old_log), "--force", "--duration-s", "0.2", "--rate-hz", "100",
                 "--no-progress"]) == 0
    assert victim.read_text() == "precious\n" and other.read_text() == "also precious\n"
    assert not (old_log / "imu.csv").is_symlink()
    assert os.readlink(old_log / "link-to-other.txt") == str(other)
    assert len(gio.read_log(old_log)) == 20


def test_convert_force_over_a_planted_link(tmp_path, capsys):
    """The same with convert: its --out folder holds imu.csv -> a file outside it."""
    from test_bad_inputs import data_bin

    src = data_bin(tmp_path / "data.bin")
    out = tmp_path / "log"
    out.mkdir()
    victim = tmp_path / "victim.csv"
    victim.write_text("precious\n")
    os.symlink(victim, out / "imu.csv")
    assert main(["convert", "mimu4444", str(src), "--out", str(out), "--force", "--no-progress"]) == 0
    capsys.readouterr()
    assert victim.read_text() == "precious\n"
    assert not (out / "imu.csv").is_symlink()
    assert len(gio.read_log(out)) == 40


def test_out_given_as_a_link_is_refused(old_log, tmp_path, capsys):
    link = tmp_path / "linked"
    os.symlink(old_log, link)
    before = snapshot(tmp_path)
    rc = main(["simulate", "random3d", "--out", str(link), "--force", "--duration-s", "0.2", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2
    assert f"--out {link}: is a symbolic link" in err and len(err.strip().splitlines()) == 1
    assert snapshot(tmp_path) == before


def test_out_given_as_a_file_is_refused(tmp_path, capsys):
    f = tmp_path / "afile"
    f.write_text("x\n")
    rc = main(["simulate", "random3d", "--out", str(f), "--force", "--duration-s", "0.2", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and f"--out {f}: exists and is a regular file" in err
    assert f.read_text() == "x\n"


def test_out_with_a_trailing_slash_is_not_written_as_a_file(old_log, tmp_path, capsys):
    before = snapshot(tmp_path)
    out = str(tmp_path / "est.csv") + "/"
    rc = main(["estimate", str(old_log), "--method", "inversion", "--out", out])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert f"{out}: ends with '/'" in err
    assert snapshot(tmp_path) == before


def test_a_255_byte_output_name_is_written(old_log, tmp_path, capsys):
    """The longest name the file system holds: the temporary name is shortened to fit."""
    name = "é" * 100 + "x" * 51 + ".csv"  # 255 bytes of UTF-8
    assert len(name.encode()) == 255
    out = tmp_path / name
    assert main(["estimate", str(old_log), "--method", "inversion", "--out", str(out), "--quiet"]) == 0, \
        capsys.readouterr().err
    assert len(gio.read_motion_csv(out)) == 200
    folder = tmp_path / ("L" * 255)
    assert main(["simulate", "random3d", "--out", str(folder), "--duration-s", "0.2", "--no-progress", "--quiet"]) == 0
    assert main(["simulate", "random3d", "--out", str(folder), "--force", "--duration-s", "0.3", "--rate-hz", "100",
                 "--no-progress", "--quiet"]) == 0
    assert len(gio.read_log(folder)) == 30
    assert temporaries(tmp_path) == []


def test_a_missing_input_file_and_a_missing_log_folder_both_exit_2(old_log, tmp_path, capsys):
    missing = tmp_path / "nope.toml"
    rc = main(["estimate", str(old_log), "--method", "inversion", "--calibration", str(missing), "--out", "-"])
    err = capsys.readouterr().err
    assert rc == 2 and f"{missing}: no such file or folder" in err and "Traceback" not in err
    rc = main(["estimate", str(tmp_path / "nolog"), "--method", "inversion", "--out", "-"])
    err = capsys.readouterr().err
    assert rc == 2 and f"{tmp_path / 'nolog'}: log folder not found" in err


def test_a_symlink_loop_log_is_one_failed_row_of_a_batch(old_log, tmp_path, capsys):
    pytest.importorskip("dask.distributed")
    import csv

    logs = tmp_path / "logs"
    logs.mkdir()
    os.symlink(logs / "loop2", logs / "loop")
    os.symlink(logs / "loop", logs / "loop2")
    out = tmp_path / "out"
    rc = main(["batch", str(old_log), str(logs / "loop"), "--method", "inversion", "--out", str(out), "--workers", "1",
               "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 1, err
    rows = {Path(r["log"]).name: r for r in csv.DictReader(open(out / "summary.csv"))}
    assert rows["log"]["status"] == "ok" and rows["log"]["samples"] == "200"
    assert rows["loop"]["status"] == "failed"
    assert "a loop of symbolic links" in rows["loop"]["message"]
    assert f"{logs / 'loop'}: failed: {logs / 'loop'}: a loop of symbolic links" in err


def test_out_dot_is_refused_naming_why(old_log, capsys, monkeypatch):
    monkeypatch.chdir(old_log)
    before = snapshot(old_log.parent)
    rc = main(["simulate", "random3d", "--out", ".", "--force", "--duration-s", "0.2", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and "--out .: the folder is replaced whole, so it must be named from outside it" in err
    assert snapshot(old_log.parent) == before
