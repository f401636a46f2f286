"""Bounded resources and the machine's refusals, from outside: zip members inflated with a limit (a zip bomb
refused at once), a zip holding one name twice, lone CR line ends, a full disk as ResourceError, pool workers
ending quietly with their parent, a scheduler address that never answers or is no Dask scheduler."""

from __future__ import annotations

import errno
import resource
import signal
import socket
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from csv_exports import phyphox_export
from live_net import env as _env

from gfimu import io as gio
from gfimu.errors import ResourceError
from gfimu.simulate import simulate



def _run(args, limit_as: int | None = None, **kw):
    def limit():
        if limit_as:
            resource.setrlimit(resource.RLIMIT_AS, (limit_as, limit_as))
    return subprocess.run([sys.executable, "-m", "gfimu", *map(str, args)], env=_env(), capture_output=True,
                          text=True, preexec_fn=limit, timeout=kw.pop("timeout", 300), **kw)


def _one_error(stderr: str, command: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip() and ": warning: " not in ln]
    assert len(lines) == 1 and lines[0].startswith(f"gfimu {command}: error: "), stderr
    assert "Traceback" not in stderr
    return lines[0]


def _bomb(path: Path, inflated: int = 200 << 20) -> Path:
    """A phyphox zip whose Accelerometer.csv inflates to ``inflated`` bytes of one repeated row."""
    row = b"0.0100000000E0,0.0000000000E0,0.0000000000E0,9.8100000000E0\n"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as z:
        with z.open("Accelerometer.csv", "w", force_zip64=True) as fh:
            fh.write(b'"Time (s)","X (m/s^2)","Y (m/s^2)","Z (m/s^2)"\n')
            block = row * ((1 << 20) // len(row))
            for _ in range(inflated // len(block)):
                fh.write(block)
    return path


@pytest.mark.slow
def test_a_zip_bomb_is_refused_at_once_with_bounded_memory(tmp_path):
    """A phyphox zip of a few hundred KiB whose Accelerometer.csv inflates to 200 MiB: refused naming the member,
    in seconds, under a 1.5 GB address-space limit (it once took 3 GB in 7 s)."""
    zipped = _bomb(tmp_path / "export.zip")
    assert zipped.stat().st_size < 1 << 20
    t0 = time.monotonic()
    proc = _run(["convert", "csv", zipped, "--map", "phyphox", "--out", tmp_path / "log"], limit_as=3 << 29)
    assert proc.returncode == 2, proc.stderr
    line = _one_error(proc.stderr, "convert")
    assert "Accelerometer.csv" in line and "zip bomb" in line
    assert time.monotonic() - t0 < 60
    assert not (tmp_path / "log").exists()


def test_a_member_inflating_far_beyond_its_size_stops_at_the_limit(tmp_path, monkeypatch):
    """The limit holds while inflating, whatever size the archive's directory claims (checked in-process with
    small limits)."""
    from gfimu.io.readers.csv import files as reader

    monkeypatch.setattr(reader, "ZIP_BOMB_BYTES", 1 << 20)
    zipped = _bomb(tmp_path / "export.zip", inflated=8 << 20)
    with pytest.raises(gio.LogFormatError, match="inflates to 8.0 MiB from .* KiB"):
        reader._zip_member(zipped, "Accelerometer.csv", zipped / "Accelerometer.csv")
    ok = phyphox_export(tmp_path / "ok.zip", as_zip=True)
    assert reader._zip_member(ok, "Accelerometer.csv", ok / "Accelerometer.csv").startswith(b'"Time (s)"')


def test_a_zip_holding_one_member_twice_is_refused(tmp_path):
    src = phyphox_export(tmp_path / "export.zip", as_zip=True)
    with zipfile.ZipFile(src) as z:
        text = z.read("Accelerometer.csv")
    with pytest.warns(UserWarning, match="Duplicate name"):
        with zipfile.ZipFile(src, "a") as z:
            z.writestr("Accelerometer.csv", text.replace(b"E0", b"E1"))
    before = src.read_bytes()
    proc = _run(["convert", "csv", src, "--map", "phyphox", "--out", tmp_path / "log"])
    assert proc.returncode == 2
    line = _one_error(proc.stderr, "convert")
    assert "'Accelerometer.csv' 2 times" in line and str(src) in line
    assert src.read_bytes() == before and not (tmp_path / "log").exists()


@pytest.mark.parametrize("end", [pytest.param(b"\r", marks=pytest.mark.slow), b"\r\n"])
def test_cr_and_crlf_line_ends_read_as_line_ends(tmp_path, end):
    """imu.csv of 5 MB (several read blocks, a CR then its LF may fall on either side of a block's end) with
    lone CR or CRLF line ends: the same log as with LF."""
    gio.write_log(simulate("reversal", duration_s=60.0, seed=2), tmp_path / "log")
    lf = gio.read_log(tmp_path / "log")
    imu = tmp_path / "log" / "imu.csv"
    imu.write_bytes(imu.read_bytes().replace(b"\n", end))
    assert imu.stat().st_size > 3 << 20
    other = gio.read_log(tmp_path / "log")
    assert np.array_equal(other.timestamps_ns, lf.timestamps_ns) and np.array_equal(other.accel_mps2, lf.accel_mps2)
    proc = _run(["estimate", tmp_path / "log", "--method", "inversion", "--out", tmp_path / "e.csv", "--quiet"])
    assert proc.returncode == 0, proc.stderr


def _full_disk():
    """In the child: files may not grow past 64 KiB (EFBIG, the error a full disk gives a writer: no space)."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 16, 1 << 16))


def test_write_log_on_a_full_disk_raises_resource_error(tmp_path):
    code = ("import sys, errno\n"
            "from gfimu import io as gio\nfrom gfimu.errors import ResourceError\nfrom gfimu.simulate import simulate\n"
            "log = simulate('reversal', duration_s=5.0, seed=1)\n"
            "try:\n    gio.write_log(log, sys.argv[1])\n"
            "except ResourceError as exc:\n    print(type(exc).__name__, exc.errno, exc.filename)\n")
    proc = subprocess.run([sys.executable, "-c", code, str(tmp_path / "log")], env=_env(), capture_output=True,
                          text=True, preexec_fn=_full_disk, timeout=120)
    assert proc.returncode == 0, proc.stderr
    name, number, filename = proc.stdout.split()
    assert int(number) == errno.EFBIG and filename == str(tmp_path / "log" / "imu.csv")
    assert not (tmp_path / "log").exists() and list(tmp_path.iterdir()) == []  # nothing half-written left
    proc = subprocess.run([sys.executable, "-m", "gfimu", "simulate", "reversal", "--duration-s", "5", "--out",
                           str(tmp_path / "log"), "--quiet", "--no-progress"], env=_env(), capture_output=True,
                          text=True, preexec_fn=_full_disk, timeout=120)
    assert proc.returncode == 1
    assert str(tmp_path / "log" / "imu.csv") in _one_error(proc.stderr, "simulate")


def test_resource_error_keeps_the_type_it_had():
    from gfimu.io.atomic import resource_error

    exc = resource_error(PermissionError(errno.EACCES, "Permission denied", "x"), "y")
    assert isinstance(exc, ResourceError) and isinstance(exc, PermissionError) and exc.filename == "y"
    assert type(resource_error(FileNotFoundError(errno.ENOENT, "No such file", "x"))) is FileNotFoundError


def _children(pid: int) -> list[int]:
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry.name))
    return out


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
def test_pool_workers_end_quietly_when_their_parent_is_killed(tmp_path):
    gio.write_log(simulate("random3d", duration_s=60.0, seed=1), tmp_path / "log")
    proc = subprocess.Popen([sys.executable, "-m", "gfimu", "estimate", str(tmp_path / "log"), "--method", "smoother",
                             "-O", "workers=2", "-O", "window_s=5", "--out", str(tmp_path / "e.csv"), "--no-progress"],
                            env=_env(), stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    workers: list[int] = []
    while time.monotonic() < deadline and len(workers) < 2 and proc.poll() is None:
        workers = _children(proc.pid)
        time.sleep(0.2)
    assert len(workers) >= 2, "the pool never started"
    time.sleep(1.0)
    proc.kill()
    err = proc.stderr.read().decode()  # the workers hold it too: it ends when they have
    proc.wait(timeout=30)
    time.sleep(0.5)
    assert not [w for w in workers if Path(f"/proc/{w}").exists() and "Z" not in
                (Path(f"/proc/{w}/stat").read_text().rsplit(")", 1)[1].split()[0])]
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


class _Peer:
    """A TCP server on 127.0.0.1 that accepts and says ``greeting`` (or nothing) and never more."""

    def __init__(self, greeting: bytes = b""):
        self.srv = socket.socket()
        self.srv.bind(("127.0.0.1", 0))
        self.srv.listen(8)
        self.port = self.srv.getsockname()[1]
        self.conns = []
        self.greeting = greeting
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                c, _ = self.srv.accept()
            except OSError:
                return
            self.conns.append(c)
            if self.greeting:
                c.sendall(self.greeting)

    def close(self):
        self.srv.close()
        for c in self.conns:
            c.close()


def test_a_scheduler_address_that_is_an_ssh_port_is_refused(tmp_path):
    pytest.importorskip("dask.distributed")
    gio.write_log(simulate("reversal", duration_s=0.5, seed=1), tmp_path / "log")
    peer = _Peer(b"SSH-2.0-OpenSSH_9.6\r\n")
    try:
        proc = _run(["batch", tmp_path / "log", "--out", tmp_path / "out", "--scheduler",
                     f"tcp://127.0.0.1:{peer.port}"], limit_as=3 << 30, timeout=120)
    finally:
        peer.close()
    assert proc.returncode == 2
    line = _one_error(proc.stderr, "batch")
    assert f"--scheduler tcp://127.0.0.1:{peer.port}: answers 'SSH-2.0-'" in line


@pytest.mark.slow
def test_a_scheduler_that_accepts_and_never_answers_is_given_up_after_20_s(tmp_path):
    pytest.importorskip("dask.distributed")
    gio.write_log(simulate("reversal", duration_s=0.5, seed=1), tmp_path / "log")
    peer = _Peer()
    t0 = time.monotonic()
    try:
        proc = _run(["batch", tmp_path / "log", "--out", tmp_path / "out", "--scheduler",
                     f"tcp://127.0.0.1:{peer.port}"], timeout=120)
    finally:
        peer.close()
    seconds = time.monotonic() - t0
    assert proc.returncode == 2 and 20 <= seconds < 50, (seconds, proc.stderr)
    assert "says nothing within 20 s" in _one_error(proc.stderr, "batch")
