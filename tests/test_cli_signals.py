"""SIGINT and SIGTERM at any time of a command, once or twice: one line, exit 130 / 143, no traceback.

The signal is sent while the command imports numpy (seen in the process's memory map), before any
work: the moment where the handler used to be missing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _start(tmp_path, entry=("-m", "gfimu")):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    program = [sys.executable, *entry] if entry[0] == "-m" else list(entry)
    return subprocess.Popen(program + ["simulate", "random3d", "--out", str(tmp_path / "log"), "--duration-s", "600",
                                       "--no-progress"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def test_the_console_script_too(tmp_path):
    """The ``gfimu`` entry point of pyproject.toml (gfimu.cli:main), two SIGINTs 50 ms apart."""
    script = Path(sys.executable).with_name("gfimu")
    if not script.exists():
        pytest.skip("no gfimu console script next to this Python")
    proc = _start(tmp_path, (str(script),))
    _wait_for_numpy(proc)
    err = _interrupt(proc)
    assert proc.returncode == 130, err
    assert err.strip() == "gfimu: stopped by SIGINT; no output was left half-written"


def _interrupt(proc) -> str:
    """Ctrl-C (a second one if the first did not end it within 50 ms); the command's standard error."""
    proc.send_signal(signal.SIGINT)
    time.sleep(0.05)
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    return proc.communicate(timeout=60)[1]


def _wait_for_numpy(proc, timeout_s: float = 60.0) -> None:
    maps = Path(f"/proc/{proc.pid}/maps")
    if not maps.exists():
        pytest.skip("no /proc here")
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            if "numpy" in maps.read_text():
                return
        except (OSError, ProcessLookupError):
            return
        time.sleep(0.001)
    raise AssertionError("numpy was never loaded")


@pytest.mark.parametrize("sig, status, twice", [(signal.SIGINT, 130, False), (signal.SIGINT, 130, True),
                                                (signal.SIGTERM, 143, False), (signal.SIGTERM, 143, True)])
def test_a_signal_while_numpy_imports(tmp_path, sig, status, twice):
    proc = _start(tmp_path)
    _wait_for_numpy(proc)
    proc.send_signal(sig)
    if twice:
        time.sleep(0.05)
        if proc.poll() is None:
            proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == status, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert len(err.strip().splitlines()) <= 1, err
    assert not (tmp_path / "log").exists()
    assert [p.name for p in tmp_path.iterdir()] == []


@pytest.mark.parametrize("delay_s", [0.01, 0.1, 0.3, 0.8])
def test_two_sigints_50_ms_apart(tmp_path, delay_s):
    """From the import of numpy on (the first heavy step of a command), through the work: exit 130, never
    -2, never a traceback. (Before the interpreter runs any of gfimu, in its own start-up, a signal is
    the interpreter's.)"""
    proc = _start(tmp_path)
    _wait_for_numpy(proc)
    time.sleep(delay_s)
    err = _interrupt(proc)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert [p.name for p in tmp_path.iterdir()] == []
