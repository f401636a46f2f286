"""gfimu live's faults, from outside: bad rows skipped and counted, signals on an idle pipe, a TCP
reset, the header rules of imu.csv, the rate taken from the stream, and the same estimate file as
gfimu estimate over standard input and over TCP."""

from __future__ import annotations

import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from live_net import OneShotServer
from live_net import env as _env
from live_net import free_port as _free_port
from live_net import wait_until_bound as _wait_until_bound

from gfimu import io as gio
from gfimu.simulate import simulate

REPO = Path(__file__).resolve().parents[1]


def _live(*args):
    return [sys.executable, "-m", "gfimu", "live", *map(str, args)]


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory):
    """A simulated 500 Hz log whose array.toml states no rate_hz."""
    folder = tmp_path_factory.mktemp("live") / "log"
    gio.write_log(simulate("reversal", duration_s=3.0, seed=4), folder)
    assert "rate_hz" not in (folder / "array.toml").read_text()
    return folder


def _wait_for(proc, text: str, timeout_s: float = 120.0) -> list[str]:
    """Lines of the command's standard error up to the one holding ``text``."""
    seen = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        seen.append(line)
        if text in line:
            return seen
    raise AssertionError(f"{text!r} never came: {''.join(seen)}")


@pytest.mark.slow
def test_stdin_without_rate_gives_the_estimate_file_byte_for_byte(log_dir, tmp_path):
    """array.toml without rate_hz and no --rate-hz: the rate comes from the first timestamps (said on
    standard error) and the file is gfimu estimate --method fixed-lag's, to the last byte."""
    batch = tmp_path / "batch.csv"
    proc = subprocess.run([sys.executable, "-m", "gfimu", "estimate", str(log_dir), "--method", "fixed-lag", "--out",
                           str(batch), "--no-progress"], env=_env(), capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    live = tmp_path / "live.csv"
    with open(log_dir / "imu.csv", "rb") as rows:
        proc = subprocess.run(_live("--array", log_dir / "array.toml", "--source", "-", "--out", live, "--quiet"),
                              stdin=rows, env=_env(), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "rate 500 Hz, from the median period of the first 64 samples" in proc.stderr
    assert "1500 samples in, 1500 estimates out" in proc.stderr and "ended: end of input" in proc.stderr
    assert live.read_bytes() == batch.read_bytes()


def test_udp_overflowing_and_infinite_timestamps_are_skipped(log_dir, tmp_path):
    """Datagrams with a 25-digit, a -25-digit and an inf timestamp: each skipped and counted with its
    reason, the session goes on, every good row is estimated."""
    port = _free_port()
    out = tmp_path / "udp.csv"
    proc = subprocess.Popen(_live("--array", log_dir / "array.toml", "--rate-hz", "500", "--source",
                                  f"udp://127.0.0.1:{port}", "--out", out, "--quiet"),
                            env=_env(), stderr=subprocess.PIPE, text=True)
    rows = (log_dir / "imu.csv").read_text().splitlines()[1:601]
    values = rows[0].split(",", 1)[1]
    bad = {100: "1" * 25, 200: "-" + "9" * 25, 300: "inf"}
    _wait_until_bound(port, proc)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for i, row in enumerate(rows):
            s.sendto(row.encode(), ("127.0.0.1", port))
            if i in bad:
                s.sendto(f"{bad[i]},{values}".encode(), ("127.0.0.1", port))
            if i % 50 == 0:
                time.sleep(0.01)
        time.sleep(0.5)
        s.sendto(b"EOF", ("127.0.0.1", port))
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert "OverflowError" not in err and "Traceback" not in err
    assert f"datagram 102 skipped: timestamp '{'1' * 25}' is out of range for 64-bit nanoseconds" in err
    assert f"datagram 203 skipped: timestamp '-{'9' * 25}' is out of range" in err
    assert "datagram 304 skipped: timestamp 'inf' is not a finite number" in err
    assert "600 samples in, 600 estimates out; 3 bad rows" in err and "ended: EOF datagram" in err
    est = gio.read_motion_csv(out)
    assert len(est) == 600


@pytest.mark.parametrize("sig, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_ends_a_session_on_an_idle_pipe(log_dir, tmp_path, sig, status):
    """Standard input an open pipe that sends nothing more: SIGINT / SIGTERM end the session at once,
    with every estimate written and the summary."""
    out = tmp_path / "idle.csv"
    proc = subprocess.Popen(_live("--array", log_dir / "array.toml", "--rate-hz", "500", "--source", "-", "--out",
                                  out, "--status-s", "0.3", "-O", "tune_process_noise=False"),
                            env=_env(), stdin=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    rows = (log_dir / "imu.csv").read_text().splitlines()[:201]
    proc.stdin.write("\n".join(rows) + "\n")
    proc.stdin.flush()
    _wait_for(proc, "200 in,")  # a status line: every row read, the pipe left open and idle
    t0 = time.monotonic()
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        pytest.fail(f"{signal.Signals(sig).name} did not end the session: {err}")
    elapsed = time.monotonic() - t0
    assert proc.returncode == status, err
    assert elapsed < 5.0
    assert "200 samples in, 200 estimates out" in err and f"ended: {signal.Signals(sig).name}" in err
    assert "Traceback" not in err
    assert len(gio.read_motion_csv(out)) == 200


def _packet(counter: int, ticks: int, raw: np.ndarray) -> bytes:
    body = struct.pack(">BHBI", 0xAA, counter % 65536, 100, ticks % (1 << 32)) + np.asarray(raw, ">i2").tobytes()
    return body + struct.pack(">H", sum(body) % 65536)


@pytest.mark.slow
def test_a_tcp_reset_ends_the_session_with_the_summary(tmp_path):
    """The board's server resets the connection: a line saying so, the summary, exit 1, and the rows
    estimated before it are in the file."""
    from gfimu.array import mimu4444_array

    gio.write_array_toml(mimu4444_array(), tmp_path / "array.toml")
    raw = np.zeros((8, 6), dtype=np.int16)
    raw[:, 2] = 2048
    data = b"".join(_packet(k, k * 1_024_000, raw) for k in range(300))
    out = tmp_path / "tcp.csv"
    with OneShotServer(data, hold_s=1.5, reset=True) as server:
        port = server.port
        proc = subprocess.run(_live("--array", tmp_path / "array.toml", "--source", f"tcp://127.0.0.1:{port}", "--out",
                                    out, "--quiet", "-O", "tune_process_noise=False"),
                              env=_env(), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1, proc.stderr
    assert f"gfimu live: error: tcp://127.0.0.1:{port}: connection reset by the other side" in proc.stderr
    assert "300 samples in, 300 estimates out" in proc.stderr and "ended: connection lost" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(gio.read_motion_csv(out)) == 300


def test_the_header_rules_of_imu_csv(log_dir, tmp_path):
    """A '#timestamp [µs]' header (read by imu.csv) is read by live too, the times converted; a header
    imu.csv refuses is refused naming the line, exit 2."""
    lines = (log_dir / "imu.csv").read_text().splitlines()[:301]
    header = lines[0].replace("#timestamp [ns]", "#timestamp [µs]")
    rows = [f"{int(r.split(',', 1)[0]) // 1000}.{int(r.split(',', 1)[0]) % 1000:03d},{r.split(',', 1)[1]}"
            for r in lines[1:]]
    text = "\n".join([header] + rows) + "\n"
    as_log = tmp_path / "us"
    as_log.mkdir()
    (as_log / "array.toml").write_bytes((log_dir / "array.toml").read_bytes())
    (as_log / "imu.csv").write_text(text, encoding="utf-8")
    assert gio.read_log(as_log).timestamps_ns.tolist() == [int(r.split(",", 1)[0]) for r in lines[1:]]
    out = tmp_path / "us.csv"
    proc = subprocess.run(_live("--array", log_dir / "array.toml", "--rate-hz", "500", "--source", "-", "--out", out,
                                "--quiet"), input=text, env=_env(), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "300 samples in, 300 estimates out; 0 bad rows" in proc.stderr
    np.testing.assert_array_equal(gio.read_motion_csv(out).timestamps_ns, gio.read_log(as_log).timestamps_ns)

    bad = "\n".join([lines[0].replace("#timestamp [ns]", "#timestamp [fortnights]")] + lines[1:]) + "\n"
    proc = subprocess.run(_live("--array", log_dir / "array.toml", "--rate-hz", "500", "--source", "-", "--out",
                                tmp_path / "bad.csv", "--quiet"), input=bad, env=_env(), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "error: standard input:1: timestamp unit [fortnights] not understood" in proc.stderr
    assert "0 samples in, 0 estimates out" in proc.stderr and "Traceback" not in proc.stderr


def test_binary_bytes_on_stdin_are_skipped_as_one_bad_row(log_dir, tmp_path):
    """A megabyte of NUL bytes among the rows: one bad row naming its line, the rows after it read."""
    lines = (log_dir / "imu.csv").read_bytes().split(b"\n")
    data = b"\n".join(lines[:101]) + b"\n" + b"\0" * (1 << 20) + b"\n" + b"\n".join(lines[101:201]) + b"\n"
    out = tmp_path / "nul.csv"
    proc = subprocess.run(_live("--array", log_dir / "array.toml", "--rate-hz", "500", "--source", "-", "--out", out,
                                "--quiet"), input=data, env=_env(), capture_output=True, timeout=120)
    err = proc.stderr.decode()
    assert proc.returncode == 0, err
    assert "line 102 skipped: line longer than 65536 bytes" in err
    assert "200 samples in, 200 estimates out; 1 bad rows" in err
    assert len(gio.read_motion_csv(out)) == 200


@pytest.mark.slow
def test_mimu4444_over_tcp_gives_the_estimate_of_the_converted_log(mimu4444_dir, tmp_path):
    """The first ~20 s of a real recording's bytes: converted and estimated with --method fixed-lag, and
    sent over TCP into gfimu live (rate from the stream): the same file, to the last byte."""
    data = (mimu4444_dir / "exp_1" / "data.bin").read_bytes()[:106 * 1250]
    part = tmp_path / "part.bin"
    part.write_bytes(data)
    log = tmp_path / "log"
    proc = subprocess.run([sys.executable, "-m", "gfimu", "convert", "mimu4444", str(part), "--out", str(log),
                           "--quiet", "--no-progress"], env=_env(), capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    toml = log / "array.toml"
    toml.write_text("".join(ln for ln in toml.read_text().splitlines(True) if not ln.startswith("rate_hz")))
    batch = tmp_path / "batch.csv"
    proc = subprocess.run([sys.executable, "-m", "gfimu", "estimate", str(log), "--method", "fixed-lag", "--out",
                           str(batch), "--no-progress"], env=_env(), capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr

    live = tmp_path / "live.csv"
    with OneShotServer(data, chunk=1001) as server:
        proc = subprocess.run(_live("--array", toml, "--source", f"tcp://127.0.0.1:{server.port}", "--out", live,
                                    "--quiet"), env=_env(), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "from the median period of the first 64 samples" in proc.stderr
    n = len(gio.read_log(log))
    assert f"{n} samples in, {n} estimates out" in proc.stderr
    assert len(gio.read_motion_csv(live)) == n
    assert live.read_bytes() == batch.read_bytes()


def test_the_three_parts_in_python_and_an_output_that_fails(log_dir):
    """source -> gfimu.live.run -> sink from Python: the frozen LiveResult; an output that fails half-way
    (a full disk) ends the session with its counts and the reason, not an exception."""
    import dataclasses
    import errno
    import io

    from gfimu.io.sources import StdinSource
    from gfimu.live import EstimateSink, run
    from gfimu.methods import make_estimator

    array, _ = gio.load_array_toml(log_dir / "array.toml")
    # streams from the first row (no tuning stretch, no hold of the start)
    estimator = make_estimator("fixed-lag", tune_process_noise=False, auto_model=False, hold_max_s=0.0)

    def source_of(data: bytes) -> StdinSource:
        r, w = os.pipe()
        threading.Thread(target=lambda: (os.write(w, data), os.close(w)), daemon=True).start()
        return StdinSource(array, fd=r, name="pipe")

    text = (log_dir / "imu.csv").read_bytes()
    lines = text.split(b"\n")
    data = b"\n".join(lines[:101] + [b"1e25," + lines[5].split(b",", 1)[1]] + lines[101:301]) + b"\n"
    buf = io.StringIO()
    result = run(source_of(data), estimator, EstimateSink(buf), rate_hz=500.0, signals=False)
    assert (result.counts.rows_in, result.counts.rows_out, result.counts.bad_rows) == (300, 300, 1)
    assert result.counts.bad_reasons == ("line 102: timestamp '1e25' is out of range for 64-bit nanoseconds",)
    assert result.ended == "end of input" and result.failure is None and result.signal_exit is None
    assert result.rate_hz == 500.0 and result.rate_from == "given"
    assert buf.getvalue().splitlines()[0] == ("#timestamp [ns],w_x [rad s^-1],w_y [rad s^-1],w_z [rad s^-1],"
                                              "dw_x [rad s^-2],dw_y [rad s^-2],dw_z [rad s^-2],f_x [m s^-2],"
                                              "f_y [m s^-2],f_z [m s^-2]")
    assert len(buf.getvalue().splitlines()) == 301
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.counts.rows_in = 0

    class Full(io.StringIO):
        def write(self, s):
            if self.tell() > 5_000:  # while the stream goes on, before the window is flushed
                raise OSError(errno.ENOSPC, "No space left on device", "est.csv")
            return super().write(s)

    result = run(source_of(data), estimator, EstimateSink(Full()), rate_hz=500.0, signals=False)
    assert result.ended == "stopped by an error"
    assert result.failure == "est.csv: No space left on device"
    assert 0 < result.counts.rows_out < 300


@pytest.mark.slow
def test_live_on_a_whole_real_recording_gives_the_estimate_file_byte_for_byte(mimu4444_dir, tmp_path):
    """The MIMU4444 recording exp_2 converted (39,301 samples; 8 readings the screening replaces, the first at row
    24,199) and fed row by row on standard input into gfimu live: the file gfimu estimate --method fixed-lag writes
    with the guard off (live runs so: the guard compares spans of the whole log after the fact, and where estimate's
    replaces one the files differ there, docs/live.md), to the last byte, and both say the same 8 readings were
    replaced."""
    log = tmp_path / "log"
    proc = subprocess.run([sys.executable, "-m", "gfimu", "convert", "mimu4444", str(mimu4444_dir / "exp_2" / "data.bin"),
                           "--out", str(log), "--quiet", "--no-progress"], env=_env(), capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    batch = tmp_path / "batch.csv"
    proc = subprocess.run([sys.executable, "-m", "gfimu", "estimate", str(log), "--method", "fixed-lag", "-O",
                           "guard=off", "--out", str(batch), "--no-progress"], env=_env(), capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "8 accelerometer reading(s) replaced" in proc.stderr and "row 24199 imu6_z" in proc.stderr
    live = tmp_path / "live.csv"
    with open(log / "imu.csv", "rb") as rows:
        proc = subprocess.run(_live("--array", log / "array.toml", "--source", "-", "--out", live, "--quiet",
                                    "--queue", 1_000_000), stdin=rows, env=_env(), capture_output=True, text=True,
                              timeout=900)
    assert proc.returncode == 0, proc.stderr
    assert "39301 samples in, 39301 estimates out" in proc.stderr and "8 readings replaced by the screening" in proc.stderr
    assert "row 24199 imu6_z" in proc.stderr
    assert live.read_bytes() == batch.read_bytes()


def test_random_mimu_counters_over_tcp_are_named(tmp_path):
    """A MIMU4444 stream whose packet counter does not count: one warning naming the source and the
    counter, and the session goes on (exit 0, every decoded row estimated)."""
    from gfimu.array import mimu4444_array

    gio.write_array_toml(mimu4444_array(), tmp_path / "array.toml")
    raw = np.zeros((8, 6), dtype=np.int16)
    raw[:, 2] = 2048
    counters = np.random.default_rng(3).permutation(65536)[:250]  # distinct, in no order
    data = b"".join(_packet(int(c), k * 1_024_000, raw) for k, c in enumerate(counters))
    out = tmp_path / "tcp.csv"
    with OneShotServer(data) as server:
        port = server.port
        proc = subprocess.run(_live("--array", tmp_path / "array.toml", "--rate-hz", "62.5", "--source",
                                    f"tcp://127.0.0.1:{port}", "--out", out, "-O", "tune_process_noise=False"),
                              env=_env(), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    said = [line for line in proc.stderr.splitlines() if "packet counter does not count" in line]
    assert len(said) == 1 and said[0].startswith(f"gfimu live: warning: tcp://127.0.0.1:{port}: the packet counter"), proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("command", ["live", "estimate"])
def test_a_noise_that_leaves_the_readings_no_weight_is_refused_by_live_as_by_estimate(tmp_path, command):
    """array.toml states 5000 m/s² for one accelerometer: warned of when read, then refused before any
    row is read or written (exit 2, one error line naming the file and the sensor)."""
    from gfimu.array import cube_array

    log = simulate("random3d", array=cube_array(0.05, noise_std_mps2=0.07), rate_hz=200, duration_s=0.5, seed=1)
    gio.write_log(log, tmp_path / "log")
    toml = tmp_path / "log" / "array.toml"
    text = toml.read_text()
    toml.write_text(text.replace("noise_std_mps2 = 0.07", "noise_std_mps2 = 5000.0", 1))
    imu = (tmp_path / "log" / "imu.csv").read_bytes()
    out = tmp_path / "out.csv"
    if command == "live":
        args = _live("--array", toml, "--rate-hz", "200", "--source", "-", "--out", out)
    else:
        args = [sys.executable, "-m", "gfimu", "estimate", str(tmp_path / "log"), "--out", str(out)]
    proc = subprocess.run(args, input=imu, env=_env(), capture_output=True, timeout=120)
    err = proc.stderr.decode()
    assert proc.returncode == 2, err
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and f"{toml}: accelerometer " in errors[0] and "noise_std_mps2 = 5000" in errors[0], err
    assert not out.exists() and "Traceback" not in err
