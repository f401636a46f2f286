#!/usr/bin/env python3
"""Replay a log over UDP at its own rate into ``gfimu live`` and measure when each estimate row appears.

Starts ``gfimu live --source udp://127.0.0.1:PORT --out -`` on the log's array, sends each imu.csv row as
one datagram at the time it was recorded (1x, or ``--speed``), then an ``EOF`` datagram, and reads the
estimate rows from the command's standard output as they are written. Each row's latency is the time
from its sample's datagram being sent to the row being read here (the lag, the screening, the smoother's
processing and the pipe); the tool prints p50/p99/max of it over the whole replay and past its first
10 s, the rows in and out, how long the replay took against the recording (above real time: the rows
kept up), the live command's own summary line, and its peak memory (:class:`Launcher`: its own, not this
tool's).

    python3 tools/replay_udp.py LOG [--seconds 60] [--lag-s 0.2] [--speed 1]
    python3 tools/replay_udp.py --simulate 60            # a simulated 500 Hz random3d log
    python3 tools/replay_udp.py --cell impacts-20kHz     # a regime-matrix cell's log (tools/regime_matrix.py)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

STEADY_AFTER_S = 10.0


def _wait_bound(port: int, proc, timeout_s: float = 60.0) -> None:
    """Until a UDP socket is bound to ``port`` on this machine (Linux: /proc/net/udp), the command has ended,
    or ``timeout_s``; elsewhere 3 s."""
    table = Path("/proc/net/udp")
    if not table.exists():
        time.sleep(3.0)
        return
    key = f":{port:04X} "
    end = time.monotonic() + timeout_s
    while time.monotonic() < end and proc.poll() is None:
        if any(key in line.split("rem_address")[0] for line in table.read_text().splitlines()[1:]):
            time.sleep(0.2)  # its reader thread starts
            return
        time.sleep(0.05)


def _percentiles(values_s) -> str:
    if not len(values_s):
        return "none"
    v = np.asarray(values_s) * 1e3
    return f"p50 {np.percentile(v, 50):.1f} ms, p99 {np.percentile(v, 99):.1f} ms, max {v.max():.1f} ms"


class Launcher:
    """A lean interpreter started before this tool builds or reads the log, that becomes the measured command
    (``exec``) when :meth:`start` gives it: the command's peak memory is then its own.

    Linux keeps a process's peak resident set across ``exec``: the peak that ``os.wait4`` reports for a
    child is the largest of its own and of the image it replaced, and a child spawned by this tool starts as
    this tool's image (vfork or fork). Spawned straight from here once the log is held (a 600 s simulation
    and its rows: about 1.4 GiB here), ``gfimu live`` would report this tool's peak as its own. The launcher
    carries only the peak this tool had when it started (printed beside the figure)."""

    CODE = ("import json, os, sys\n"
            "line = sys.stdin.readline()\n"
            "if not line.strip():\n"
            "    sys.exit(0)\n"  # not started: the tool ended before the command
            "argv = json.loads(line)\n"
            "os.dup2(os.open(os.devnull, os.O_RDONLY), 0)\n"
            "os.execv(argv[0], argv)\n")

    def __init__(self, env=None, cwd=None):
        self.floor_mib = _own_peak_mib()
        self.proc = subprocess.Popen([sys.executable, "-I", "-c", self.CODE], env=env, cwd=cwd,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, bufsize=1)

    def start(self, argv) -> subprocess.Popen:
        """The launcher replaced by ``argv`` (standard input from /dev/null; its output on the pipes made at the
        start): the Popen of the command (the same process)."""
        self.proc.stdin.write(json.dumps([str(a) for a in argv]) + "\n")
        self.proc.stdin.close()
        self.proc.stdin = None
        return self.proc


def _own_peak_mib() -> float:
    """This process's peak resident memory so far [MiB]: the high-water mark of its own memory (Linux:
    /proc/self/status VmHWM, what a child it spawns starts with), not ``getrusage``'s, which also counts
    the image this process replaced (whatever started it); elsewhere ``getrusage``'s, 0 where none."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    try:
        import resource
    except ImportError:
        return 0.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / (1024 if sys.platform.startswith("linux") else 2**20)


def _wait_peak_mib(proc: subprocess.Popen, timeout_s: float) -> float:
    """Wait for ``proc`` (killed after ``timeout_s``) and give its peak resident memory [MiB]: the rusage of
    that child alone (``os.wait4``), not the largest of every child this process had (a simulation's forked
    workers hold a copy of this process's memory). It counts the image the child replaced too: a child
    started by :class:`Launcher` gives its own."""
    end = time.monotonic() + timeout_s
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if time.monotonic() > end:
            proc.kill()
            _, status, usage = os.wait4(proc.pid, 0)
            break
        time.sleep(0.05)
    proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait for it again
    return usage.ru_maxrss / 1024


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", nargs="?", help="log folder (default: a simulated one, --simulate)")
    ap.add_argument("--simulate", type=float, default=60.0, metavar="S", help="simulated log length [s] at 500 Hz")
    ap.add_argument("--seconds", type=float, default=None, help="replay only the first S s")
    ap.add_argument("--lag-s", type=float, default=0.2)
    ap.add_argument("--speed", type=float, default=1.0, help="replay speed (1: the recorded rate)")
    ap.add_argument("--cell", default=None, help="replay the log of this regime-matrix cell (e.g. impacts-20kHz)")
    ap.add_argument("--duration-s", type=float, default=None, help="with --cell: its length [s] (default: the cell's)")
    ap.add_argument("--queue", type=int, default=None, metavar="N",
                    help="gfimu live --queue N: samples that may wait while the smoother is busy (default: live's)")
    ap.add_argument("-O", dest="options", action="append", default=[], metavar="KEY=VALUE",
                    help="an option of gfimu live (-O key=value), repeatable")
    args = ap.parse_args(argv)
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    launcher = Launcher(env=env, cwd=str(REPO))  # before the log is held: gfimu live's peak is then its own
    try:
        return _replay(args, ap, launcher)
    finally:
        if launcher.proc.stdin is not None:  # not started (an error before): the launcher ends on its closed input
            launcher.proc.stdin.close()
            launcher.proc.wait()


def _replay(args, ap, launcher: Launcher) -> int:
    from gfimu import io as gio

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.cell:
            import regime_matrix

            cell = regime_matrix.named_cell(args.cell, args.duration_s)
            if cell is None:
                ap.error(f"no cell {args.cell!r}; tools/regime_matrix.py --help lists them")
            log_dir, _ = regime_matrix.build_log(cell, tmp)
        elif args.log:
            log_dir = Path(args.log).resolve()
        else:
            from gfimu.simulate import simulate

            log_dir = tmp / "log"
            gio.write_log(simulate("random3d", duration_s=args.simulate, seed=0), log_dir)
        lines = (log_dir / "imu.csv").read_text().splitlines()[1:]
        stamps = [int(line.split(",", 1)[0]) for line in lines]
        if args.seconds is not None:
            n = sum(1 for t in stamps if t - stamps[0] <= args.seconds * 1e9)
            lines, stamps = lines[:n], stamps[:n]
        rate_hz = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) * 1e-9)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        options = [a for o in args.options for a in ("-O", o)] + (["--queue", str(args.queue)] if args.queue else [])
        # this checkout's gfimu (the launcher runs in it), whatever the caller's folder
        proc = launcher.start([sys.executable, "-m", "gfimu", "live", "--array", str(log_dir / "array.toml"),
                               "--rate-hz", f"{rate_hz:.6f}", "--source", f"udp://127.0.0.1:{port}",
                               "--out", "-", "--lag-s", str(args.lag_s), "--quiet", *options])
        sent_at: dict[int, float] = {}
        seen: list[tuple[int, float]] = []

        def read_rows() -> None:
            for line in proc.stdout:
                now = time.perf_counter()
                if line[:1].isdigit() or line[:1] == "-":
                    seen.append((int(line.split(",", 1)[0]), now))

        reader = threading.Thread(target=read_rows, daemon=True)
        reader.start()
        _wait_bound(port, proc)  # the command starts and binds its socket
        start = time.perf_counter()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 22)
            for line, t in zip(lines, stamps):
                due = start + (t - stamps[0]) * 1e-9 / args.speed
                delay = due - time.perf_counter()
                if delay > 0.0005:
                    time.sleep(delay)
                sent_at[t] = time.perf_counter()
                s.sendto(line.encode(), ("127.0.0.1", port))
            sent_s = time.perf_counter() - start
            time.sleep(args.lag_s + 0.5)
            s.sendto(b"EOF", ("127.0.0.1", port))
        errors: list[str] = []
        err_reader = threading.Thread(target=lambda: errors.append(proc.stderr.read()), daemon=True)
        err_reader.start()
        peak_mib = _wait_peak_mib(proc, timeout_s=600.0)
        reader.join(timeout=30)
        err_reader.join(timeout=30)
        err = "".join(errors)
        done_s = (seen[-1][1] - start) if seen else float("nan")
    latency = [(t, now - sent_at[t]) for t, now in seen if t in sent_at]
    steady = [d for t, d in latency if (t - stamps[0]) * 1e-9 >= STEADY_AFTER_S]
    recorded_s = (stamps[-1] - stamps[0]) * 1e-9
    print(f"# {time.strftime('%Y-%m-%d')}, {platform.node()}, {os.cpu_count()} cores: {len(lines)} samples at "
          f"{rate_hz:.1f} Hz ({recorded_s:.1f} s) sent in {sent_s:.1f} s (speed {args.speed:g}), lag {args.lag_s} s")
    print(f"rows out {len(seen)} of {len(lines)}; last row {done_s - recorded_s / args.speed:+.2f} s after the last "
          f"sample was due; latency datagram -> row on stdout {_percentiles([d for _, d in latency])}; past the first "
          f"{STEADY_AFTER_S:g} s {_percentiles(steady)}; peak memory of gfimu live {peak_mib:.0f} MiB (its own; the "
          f"replay tool's peak {_own_peak_mib():.0f} MiB, {launcher.floor_mib:.0f} MiB when it started the launcher)")
    print(err.strip().splitlines()[-1] if err.strip() else "(no summary from gfimu live)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
