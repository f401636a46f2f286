"""gfimu live: standard input, UDP datagrams, MIMU4444 packets over TCP, signals."""

import signal
import socket
import subprocess
import sys
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


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("live") / "log"
    gio.write_log(simulate("reversal", duration_s=5.0, seed=2), folder)
    return folder


@pytest.mark.slow
def test_stdin_rows_give_the_fixed_lag_estimate(log_dir, tmp_path):
    """Fed a log's imu.csv on standard input: the same rows and values as gfimu estimate --method fixed-lag."""
    batch = tmp_path / "batch.csv"
    assert subprocess.run([sys.executable, "-m", "gfimu", "estimate", str(log_dir), "--method", "fixed-lag", "--out",
                           str(batch), "--no-progress"], env=_env(), capture_output=True).returncode == 0
    live = tmp_path / "live.csv"
    with open(log_dir / "imu.csv") as rows:
        proc = subprocess.run([sys.executable, "-m", "gfimu", "live", "--array", str(log_dir / "array.toml"),
                               "--rate-hz", "500", "--source", "-", "--out", str(live), "--quiet"], stdin=rows,
                              env=_env(), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "2500 samples in, 2500 estimates out" in proc.stderr
    a, b = gio.read_motion_csv(live), gio.read_motion_csv(batch)
    np.testing.assert_array_equal(a.timestamps_ns, b.timestamps_ns)
    for name in ("omega_b_radps", "omega_dot_b_radps2", "specific_force_b_mps2"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-9)


def test_udp_datagrams_with_a_bad_a_repeated_and_a_late_one(log_dir, tmp_path):
    """One data row per datagram: a bad row is skipped with a warning naming it, a repeated and a late
    sample are dropped and counted, a lost one is counted as missing, the rest estimated; the run
    ends on an EOF datagram."""
    port = _free_port()
    out = tmp_path / "udp.csv"
    proc = subprocess.Popen([sys.executable, "-m", "gfimu", "live", "--array", str(log_dir / "array.toml"),
                             "--rate-hz", "500", "--source", f"udp://127.0.0.1:{port}", "--out", str(out), "--quiet"],
                            env=_env(), stderr=subprocess.PIPE, text=True)
    rows = (log_dir / "imu.csv").read_text().splitlines()[1:1001]
    _wait_until_bound(port, proc)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for i, row in enumerate(rows):
            if i == 500:
                continue                                            # lost
            s.sendto(row.encode(), ("127.0.0.1", port))
            if i == 100:
                s.sendto(b"1,2,three", ("127.0.0.1", port))       # bad
            if i == 200:
                s.sendto(row.encode(), ("127.0.0.1", port))        # repeated
            if i == 300:
                s.sendto(rows[250].encode(), ("127.0.0.1", port))  # late
            if i % 50 == 0:
                time.sleep(0.01)
        time.sleep(0.5)
        s.sendto(b"EOF", ("127.0.0.1", port))
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert "datagram 102 skipped" in err
    assert "999 estimates out; 1 bad rows, 2 late or repeated, 1 missing (gaps)" in err
    est = gio.read_motion_csv(out)
    assert len(est) == 999 and np.all(np.diff(est.timestamps_ns) > 0)


def test_sigterm_flushes_and_summarises(log_dir, tmp_path):
    """SIGTERM while waiting for data: the window is flushed, the file is complete, the summary printed."""
    port = _free_port()
    out = tmp_path / "term.csv"
    proc = subprocess.Popen([sys.executable, "-m", "gfimu", "live", "--array", str(log_dir / "array.toml"),
                             "--rate-hz", "500", "--source", f"udp://127.0.0.1:{port}", "--out", str(out), "--quiet",
                             "-O", "tune_process_noise=False"], env=_env(), stderr=subprocess.PIPE, text=True)
    rows = (log_dir / "imu.csv").read_text().splitlines()[1:401]
    _wait_until_bound(port, proc)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for row in rows:
            s.sendto(row.encode(), ("127.0.0.1", port))
            time.sleep(0.0005)
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "400 samples in, 400 estimates out" in err and err.rstrip().endswith("ended: SIGTERM")
    assert len(gio.read_motion_csv(out)) == 400


@pytest.mark.slow
def test_mimu4444_packets_over_tcp(mimu4444_dir, tmp_path):
    """Real MIMU4444 bytes over TCP, in odd-sized chunks: the rows decoded live are those of
    gfimu convert mimu4444 (timestamps exactly), and every one is estimated."""
    from gfimu.io.readers.mimu4444 import StreamDecoder, read_mimu4444

    data = (mimu4444_dir / "exp_1" / "data.bin").read_bytes()[:40_000]
    log, _ = read_mimu4444(mimu4444_dir / "exp_1" / "data.bin")
    decoder = StreamDecoder()
    rows = []
    for i in range(0, len(data), 777):
        rows += decoder.feed(data[i:i + 777])
    np.testing.assert_array_equal([t for t, _ in rows], log.timestamps_ns[:len(rows)])
    np.testing.assert_array_equal(np.array([a for _, a in rows]), log.accel_mps2[:len(rows)])

    gio.write_array_toml(log.array, tmp_path / "array.toml")
    out = tmp_path / "tcp.csv"
    with OneShotServer(data, chunk=777) as server:
        proc = subprocess.run([sys.executable, "-m", "gfimu", "live", "--array", str(tmp_path / "array.toml"),
                               "--rate-hz", "62.5", "--source", f"tcp://127.0.0.1:{server.port}", "--out", str(out),
                               "--quiet"], env=_env(), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    est = gio.read_motion_csv(out)
    np.testing.assert_array_equal(est.timestamps_ns, log.timestamps_ns[:len(rows)])


def test_bad_sources_are_refused(log_dir, tmp_path):
    for source, message in (("ftp://x", "expected -, udp://"), ("serial:///dev/nonexistent-port?baud=9600", "")):
        proc = subprocess.run([sys.executable, "-m", "gfimu", "live", "--array", str(log_dir / "array.toml"),
                               "--rate-hz", "500", "--source", source, "--out", str(tmp_path / "x.csv")],
                              env=_env(), capture_output=True, text=True, timeout=60)
        assert proc.returncode != 0 and "Traceback" not in proc.stderr and message in proc.stderr
