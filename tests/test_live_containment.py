"""gfimu live and gfimu batch hold against a careless user, from outside: units checked on the first rows,
an unreadable header ending the session, options applied or refused, a rate change measured again, one writer
per output file, and batch's outputs never through a link, never two logs onto one folder."""

from __future__ import annotations

import hashlib
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from live_net import env as _env
from live_net import free_port as _free_port
from live_net import wait_until_bound as _wait_until_bound

from gfimu import io as gio
from gfimu.log import Log
from gfimu.simulate import simulate


def _gfimu(*args, **kw):
    return subprocess.run([sys.executable, "-m", "gfimu", *map(str, args)], env=_env(), capture_output=True,
                          text=True, timeout=kw.pop("timeout", 300), **kw)


def _digest(folder: Path) -> dict:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()}


def _errors(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ": error: " in ln]


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("contain") / "log"
    gio.write_log(simulate("reversal", duration_s=3.0, seed=4), folder)
    return folder


@pytest.mark.slow  # the fault campaign's case live-g-header runs the same in the default set
def test_readings_in_m_per_s2_under_a_g_header_are_named_with_the_factor(log_dir, tmp_path):
    """The rows of the log with every accelerometer unit written [g]: live warns on the first rows with the check
    and words gfimu estimate uses (|f| ≈ 9.81 × gravity, the unit read named); with the right header, no warning."""
    lines = (log_dir / "imu.csv").read_text().splitlines()
    wrong = tmp_path / "g.csv"
    wrong.write_text("\n".join([lines[0].replace("[m s^-2]", "[g]")] + lines[1:]) + "\n")
    before = _digest(log_dir)
    with open(wrong, "rb") as rows:
        proc = _gfimu("live", "--array", log_dir / "array.toml", "--source", "-", "--out", tmp_path / "l.csv",
                      "--quiet", stdin=rows)
    assert proc.returncode == 0, proc.stderr
    warning = [ln for ln in proc.stderr.splitlines() if "× gravity" in ln or "would read gravity" in ln]
    assert len(warning) == 1 and warning[0].startswith("gfimu live: warning: standard input (first ")
    assert "[g]" in warning[0]
    with open(log_dir / "imu.csv", "rb") as rows:
        proc = _gfimu("live", "--array", log_dir / "array.toml", "--source", "-", "--out", tmp_path / "ok.csv",
                      "--quiet", stdin=rows)
    assert proc.returncode == 0 and "gravity" not in proc.stderr, proc.stderr
    assert _digest(log_dir) == before


@pytest.mark.slow
def test_a_map_unit_off_by_any_factor_is_caught_by_convert_estimate_and_diagnose(tmp_path):
    """m/s² values under a map's unit "mg" (readings 102 times too small, no ratio the old list knew): convert,
    estimate and diagnose each name it, with the factor that brings them to gravity."""
    log = simulate("reversal", duration_s=3.0, seed=4)
    rows = ["t [ns]," + ",".join(f"s{i}{a}" for i in range(4) for a in "xyz")]
    rows += [f"{t}," + ",".join(f"{v:.6f}" for v in r) for t, r in zip(log.timestamps_ns, log.accel_mps2)]
    (tmp_path / "data.csv").write_text("\n".join(rows) + "\n")
    acc = log.array.accelerometers
    (tmp_path / "map.toml").write_text(
        'format = "gfimu-csv-map/1"\nname = "b"\n[csv]\nfile = "data.csv"\n[time]\ncolumn = "t"\n' + "".join(
            f'[[accelerometers]]\nname = "s{i}"\nposition_m = {[float(x) for x in a.position_m]}\nunit = "mg"\n'
            f'x = "s{i}x"\ny = "s{i}y"\nz = "s{i}z"\n' for i, a in enumerate(acc)))
    before = _digest(tmp_path)
    proc = _gfimu("convert", "csv", tmp_path / "data.csv", "--map", tmp_path / "map.toml", "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    assert "likely the values are in m/s², not [mg]" in proc.stderr
    assert all(_digest(tmp_path).get(k) == v for k, v in before.items())
    proc = _gfimu("estimate", tmp_path / "out", "--method", "inversion", "--out", tmp_path / "e.csv")
    assert proc.returncode == 0 and "would read gravity" in proc.stderr, proc.stderr
    factor = float(proc.stderr.split("scaled by ")[1].split()[0])
    assert factor == pytest.approx(1 / 9.80665e-3, rel=0.1)  # the values are m/s² read as mg
    proc = _gfimu("diagnose", tmp_path / "out")
    assert "would read gravity" in proc.stdout + proc.stderr


def test_guard_replace_is_refused_by_live_not_ignored(log_dir, tmp_path):
    proc = _gfimu("live", "--array", log_dir / "array.toml", "--source", "-", "--out", tmp_path / "l.csv",
                  "-O", "guard=replace", input="")
    assert proc.returncode == 2
    assert _errors(proc.stderr) == [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert _errors(proc.stderr)[0].startswith("gfimu live: error: -O guard=replace: ")
    assert not (tmp_path / "l.csv").exists()
    proc = _gfimu("live", "--array", log_dir / "array.toml", "--source", "-", "--out", tmp_path / "l.csv",
                  "-O", "guard=off", "--quiet", input=(log_dir / "imu.csv").read_text())
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("source, words", [
    ("udp://127.0.0.1", "give the port to listen on"),
    ("serial:///dev/null?baud=-5", "baud=-5 is no baud rate"),
])
def test_sources_that_cannot_be_meant_are_refused(log_dir, tmp_path, source, words):
    proc = _gfimu("live", "--array", log_dir / "array.toml", "--source", source, "--out", tmp_path / "l.csv",
                  input="", timeout=60)
    assert proc.returncode == 2 and len(_errors(proc.stderr)) == 1 and words in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


def test_an_unreadable_header_datagram_ends_the_session(log_dir, tmp_path):
    """A header datagram with the columns reversed and one unit misspelt: exit 2 naming the datagram; the rows
    after it are never read in the default column order."""
    port = _free_port()
    out = tmp_path / "udp.csv"
    proc = subprocess.Popen([sys.executable, "-m", "gfimu", "live", "--array", log_dir / "array.toml", "--rate-hz",
                             "500", "--source", f"udp://127.0.0.1:{port}", "--out", out, "--quiet"],
                            env=_env(), stderr=subprocess.PIPE, text=True)
    lines = (log_dir / "imu.csv").read_text().splitlines()
    head = lines[0].split(",")
    head = [head[0]] + head[1:][::-1]
    head[1] = head[1].replace("[m s^-2]", "[m s^-9]")
    _wait_until_bound(port, proc)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(",".join(head).encode(), ("127.0.0.1", port))
        for row in lines[1:200]:
            s.sendto(row.encode(), ("127.0.0.1", port))
        s.sendto(b"EOF", ("127.0.0.1", port))
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 2, err
    errors = _errors(err)
    assert len(errors) == 1 and f"udp://127.0.0.1:{port} datagram 1" in errors[0], err
    assert "0 samples in, 0 estimates out" in err
    assert "Traceback" not in err


def _rmse(path: Path, log: Log, rows) -> float:
    e = gio.read_motion_csv(path)
    idx = np.searchsorted(log.timestamps_ns, e.timestamps_ns)
    sel = np.isin(idx, rows)
    d = e.omega_b_radps[sel] - log.truth.omega_b_radps[idx[sel]]
    return float(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))


@pytest.mark.slow
def test_a_rate_that_halves_mid_stream_is_measured_again(tmp_path):
    """500 Hz for 4 s, then every other datagram: live says the rate changed, measures it again (250 Hz) and
    restarts once, instead of once per sample; ω on the second half is as good as on the first (measured:
    0.013 rad/s, against 3.1 rad/s when every step was a gap)."""
    log = simulate("reversal", duration_s=8.0, seed=4)
    gio.write_log(log, tmp_path / "log")
    lines = (tmp_path / "log" / "imu.csv").read_text().splitlines()[1:]
    n = len(lines)
    keep = [k for k in range(n) if k < n // 2 or k % 2 == 0]
    port = _free_port()
    out = tmp_path / "l.csv"
    proc = subprocess.Popen([sys.executable, "-m", "gfimu", "live", "--array", tmp_path / "log" / "array.toml",
                             "--rate-hz", "500", "--source", f"udp://127.0.0.1:{port}", "--out", out, "--quiet"],
                            env=_env(), stderr=subprocess.PIPE, text=True)
    _wait_until_bound(port, proc)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for i, k in enumerate(keep):
            s.sendto(lines[k].encode(), ("127.0.0.1", port))
            if i % 50 == 0:
                time.sleep(0.01)
        time.sleep(0.5)
        s.sendto(b"EOF", ("127.0.0.1", port))
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert "the stream's rate changed" in err and "250 Hz" in err
    assert f"{len(keep)} samples in, {len(keep)} estimates out" in err
    assert "32 missing (gaps)" in err  # the steps that told the change, not one per sample
    first = _rmse(out, log, [k for k in keep if 0.5 * 500 <= k < n // 2])
    second = _rmse(out, log, [k for k in keep if k >= n // 2 + 0.5 * 500])
    assert second < max(3 * first, 0.05), (first, second)


@pytest.mark.slow
def test_a_second_live_session_on_the_same_output_is_refused(log_dir, tmp_path):
    """One session writing l.csv (on an idle pipe); a second one on the same file: exit 2, one line, before any
    work; the first goes on and its file holds its own rows only."""
    out = tmp_path / "l.csv"
    first = subprocess.Popen([sys.executable, "-m", "gfimu", "live", "--array", log_dir / "array.toml", "--source",
                              "-", "--out", out, "--quiet"], env=_env(), stdin=subprocess.PIPE,
                             stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (out.exists() and out.stat().st_size > 0):
            time.sleep(0.1)  # the header row is written once the session runs
        proc = _gfimu("live", "--array", log_dir / "array.toml", "--source", "-", "--out", out, input="")
        assert proc.returncode == 2
        errors = _errors(proc.stderr)
        assert len(errors) == 1 and "another gfimu process is writing this file" in errors[0] and str(out) in errors[0]
        first.stdin.write((log_dir / "imu.csv").read_bytes())
        first.stdin.close()
        err = first.stderr.read().decode()
        assert first.wait(timeout=120) == 0, err
    finally:
        if first.poll() is None:
            first.kill()
    assert "1500 samples in, 1500 estimates out" in err
    assert len(gio.read_motion_csv(out)) == 1500
    assert not any(p.name.endswith(".lock") for p in tmp_path.iterdir())  # the lock goes with its session


def test_live_says_when_its_reader_goes_away(log_dir, tmp_path):
    """--out - into a reader that closed: exit 1 and one line saying so, no traceback, not exit 0 in silence."""
    r, w = os.pipe()
    os.close(r)
    try:
        proc = subprocess.run([sys.executable, "-m", "gfimu", "live", "--array", str(log_dir / "array.toml"),
                               "--source", "-", "--out", "-", "--quiet"], env=_env(), stdout=w,
                              input=(log_dir / "imu.csv").read_bytes(), stderr=subprocess.PIPE, timeout=120)
    finally:
        os.close(w)
    err = proc.stderr.decode()
    assert proc.returncode == 1, err
    assert "Traceback" not in err and len(_errors(err)) == 1 and "closed by its reader" in err


def test_live_whose_reader_goes_away_mid_stream_ends_with_its_summary(log_dir):
    """The reader of --out - reads the first rows, then goes away: exit 1, one line saying so, then the
    session's summary (ended: output closed by its reader), no traceback."""
    proc = subprocess.Popen([sys.executable, "-m", "gfimu", "live", "--array", str(log_dir / "array.toml"),
                             "--source", "-", "--out", "-", "--quiet", "-O", "auto_model=False",
                             "-O", "tune_process_noise=False", "-O", "hold_max_s=0"], env=_env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    import threading

    watchdog = threading.Timer(120.0, proc.kill)  # a hung session fails the test instead of hanging the run
    watchdog.start()
    rows = (log_dir / "imu.csv").read_bytes().splitlines(keepends=True)
    proc.stdin.write(b"".join(rows[:400]))
    proc.stdin.flush()
    for _ in range(5):  # the header and a few rows
        assert proc.stdout.readline()
    proc.stdout.close()
    try:
        proc.stdin.write(b"".join(rows[400:]))
        proc.stdin.close()
    except BrokenPipeError:
        pass
    err = proc.stderr.read().decode()
    proc.wait(timeout=120)
    watchdog.cancel()
    assert proc.returncode == 1, err
    assert "Traceback" not in err and len(_errors(err)) == 1 and "closed by its reader" in err
    assert "samples in," in err and "ended: output closed by its reader" in err


@pytest.mark.parametrize("command", [["estimate", "{log}", "--method", "inversion", "--out", "-"],
                                     ["live", "--array", "{log}/array.toml", "--source", "-", "--out", "-"]])
def test_standard_output_on_a_full_disk_is_named(log_dir, command):
    """--out - redirected to /dev/full: exit 1 and one line naming standard output, not an internal error."""
    args = [a.replace("{log}", str(log_dir)) for a in command]
    with open("/dev/full", "wb") as full, open(log_dir / "imu.csv", "rb") as rows:
        proc = subprocess.run([sys.executable, "-m", "gfimu", *args], env=_env(), stdout=full, stdin=rows,
                              stderr=subprocess.PIPE, timeout=120)
    err = proc.stderr.decode()
    assert proc.returncode == 1, err
    assert _errors(err) == [f"gfimu {command[0]}: error: standard output (--out -): no space left on the device"]
    assert "Traceback" not in err and "internal error" not in err


# --- batch -----------------------------------------------------------------------------------------------

@pytest.fixture()
def logs(tmp_path):
    gio.write_log(simulate("reversal", duration_s=0.5, seed=1), tmp_path / "a" / "log")
    gio.write_log(simulate("reversal", duration_s=0.5, seed=2), tmp_path / "b" / "log")
    gio.write_log(simulate("reversal", duration_s=0.5, seed=3), tmp_path / "c" / "log-2")
    return tmp_path


def test_batch_never_writes_through_a_link_in_its_output_folder(logs):
    (logs / "elsewhere").mkdir()
    (logs / "bout").mkdir()
    os.symlink("../elsewhere", logs / "bout" / "log")
    before = _digest(logs)
    proc = _gfimu("batch", logs / "a" / "log", "--method", "inversion", "--out", logs / "bout", "--workers", "1")
    assert proc.returncode == 2
    errors = _errors(proc.stderr)
    assert len(errors) == 1 and "is a symbolic link" in errors[0] and str(logs / "bout" / "log") in errors[0]
    assert not any((logs / "elsewhere").iterdir()) and _digest(logs) == before


@pytest.mark.slow
def test_batch_gives_every_log_its_own_folder(logs):
    """a/log, b/log and c/log-2: three folders, three estimates (b/log no longer becomes log-2)."""
    proc = _gfimu("batch", logs / "a" / "log", logs / "b" / "log", logs / "c" / "log-2", "--method", "inversion",
                  "--out", logs / "bout", "--workers", "1", "--quiet")
    assert proc.returncode == 0, proc.stderr
    names = sorted(p.name for p in (logs / "bout").iterdir())
    assert names == ["a__log", "b__log", "log-2", "summary.csv"]
    for folder, log in (("a__log", "a/log"), ("b__log", "b/log"), ("log-2", "c/log-2")):
        est = gio.read_motion_csv(logs / "bout" / folder / "estimate.csv")
        assert np.array_equal(est.timestamps_ns, gio.read_log(logs / log).timestamps_ns)


def test_batch_refuses_one_log_twice_before_any_work(logs):
    proc = _gfimu("batch", logs / "a" / "log", str(logs / "a" / "log") + "/", "--method", "inversion", "--out",
                  logs / "bout", "--workers", "1")
    assert proc.returncode == 2 and len(_errors(proc.stderr)) == 1 and "given twice" in proc.stderr
    assert not (logs / "bout").exists()
