"""A line longer than any row of a CSV table is refused at once, naming the file and line: a file of NUL
bytes with no line end must not make reading slow down (or run out of memory)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from gfimu import io as gio
from gfimu.cli import main
from gfimu.io.tables import MAX_LINE_BYTES

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def log(tmp_path) -> Path:
    d = tmp_path / "log"
    assert main(["simulate", "random3d", "--out", str(d), "--rate-hz", "100", "--duration-s", "0.2", "--no-progress",
                 "--quiet"]) == 0
    (d / "truth.csv").unlink()
    return d


def _header(log: Path) -> bytes:
    return (log / "imu.csv").read_bytes().split(b"\n", 1)[0] + b"\n"


def test_fifty_megabytes_of_nul_bytes_are_refused_at_once(log, tmp_path):
    head = _header(log)
    with open(log / "imu.csv", "wb") as fh:
        fh.write(head)
        fh.write(b"\0" * (50 << 20))
    before = (log / "imu.csv").stat().st_size
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "gfimu", "estimate", str(log), "--method", "inversion", "--out",
                           str(tmp_path / "e.csv")], capture_output=True, text=True, timeout=60,
                          env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})
    elapsed = time.monotonic() - t0
    assert proc.returncode == 2, proc.stderr
    assert f"{log / 'imu.csv'}:2: line is longer than {MAX_LINE_BYTES} bytes" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert elapsed < 2.0 + 1.5  # the command's own start-up (imports) is most of it
    assert (log / "imu.csv").stat().st_size == before and not (tmp_path / "e.csv").exists()


def test_reading_a_nul_file_takes_no_time(log):
    """The reader itself, without the command's start-up: 50 MB of NULs after the header in < 2 s."""
    with open(log / "imu.csv", "wb") as fh:
        fh.write(_header(log))
        fh.write(b"\0" * (50 << 20))
    t0 = time.monotonic()
    with pytest.raises(gio.LogFormatError, match=r"imu.csv:2: line is longer than 65536 bytes"):
        gio.read_log(log)
    assert time.monotonic() - t0 < 2.0


def test_a_long_line_with_a_line_end_is_refused_naming_it(log):
    lines = (log / "imu.csv").read_bytes().split(b"\n")
    lines[5] = lines[5] + b"," + b"1" * (MAX_LINE_BYTES + 10)
    (log / "imu.csv").write_bytes(b"\n".join(lines))
    with pytest.raises(gio.LogFormatError, match=r"imu.csv:6: line is longer than 65536 bytes \(65\d+ bytes\)"):
        gio.read_log(log)


def test_the_last_line_without_a_line_end_too(log):
    data = (log / "imu.csv").read_bytes() + b"9" * (MAX_LINE_BYTES + 1)
    (log / "imu.csv").write_bytes(data)
    n = data.count(b"\n") + 1
    with pytest.raises(gio.LogFormatError, match=rf"imu.csv:{n}: line is longer than 65536 bytes"):
        gio.read_log(log)


def test_a_motion_table_of_nul_bytes(tmp_path):
    path = tmp_path / "est.csv"
    path.write_bytes(b"\0" * (3 << 20))
    with pytest.raises(gio.LogFormatError, match=r"est.csv:1: line is longer than 65536 bytes"):
        gio.read_motion_csv(path)
