#!/usr/bin/env python3
"""Replay a log over UDP at its own rate into ``gfimu live`` and print its latency summary.

Starts ``gfimu live --source udp://127.0.0.1:PORT`` on the log's array, sends each
imu.csv row as one datagram at the time it was recorded (1x, or ``--speed``), then
an ``EOF`` datagram; ``gfimu live`` measures, per sample, the time from the
datagram's arrival to its estimate row being written (the lag + the smoother's
processing) and prints p50/p99/max with its counts (dropped, late, processing time
per sample).

    python3 tools/replay_udp.py LOG [--seconds 60] [--lag-s 0.2] [--speed 1]
    python3 tools/replay_udp.py --simulate 60        # a simulated 500 Hz random3d log
"""

from __future__ import annotations

import argparse
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", nargs="?", help="log folder (default: a simulated one, --simulate)")
    ap.add_argument("--simulate", type=float, default=60.0, metavar="S", help="simulated log length [s] at 500 Hz")
    ap.add_argument("--seconds", type=float, default=None, help="replay only the first S s")
    ap.add_argument("--lag-s", type=float, default=0.2)
    ap.add_argument("--speed", type=float, default=1.0, help="replay speed (1: the recorded rate)")
    args = ap.parse_args(argv)
    from gfimu import io as gio

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        log_dir = Path(args.log) if args.log else tmp / "log"
        if not args.log:
            from gfimu.simulate import simulate

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
        env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
        proc = subprocess.Popen([sys.executable, "-m", "gfimu", "live", "--array", str(log_dir / "array.toml"),
                                 "--rate-hz", f"{rate_hz:.6f}", "--source", f"udp://127.0.0.1:{port}",
                                 "--out", str(tmp / "live.csv"), "--lag-s", str(args.lag_s), "--quiet"],
                                env=env, stderr=subprocess.PIPE, text=True)
        time.sleep(3.0)  # the command starts and binds its socket
        start = time.perf_counter()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for line, t in zip(lines, stamps):
                due = start + (t - stamps[0]) * 1e-9 / args.speed
                delay = due - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
                s.sendto(line.encode(), ("127.0.0.1", port))
            sent_s = time.perf_counter() - start
            time.sleep(args.lag_s + 0.5)
            s.sendto(b"EOF", ("127.0.0.1", port))
        try:
            _, err = proc.communicate(timeout=300)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
    print(f"# {time.strftime('%Y-%m-%d')}, {platform.node()}, {os.cpu_count()} cores: {len(lines)} samples at "
          f"{rate_hz:.1f} Hz sent in {sent_s:.1f} s (speed {args.speed:g}), lag {args.lag_s} s")
    print(err.strip().splitlines()[-1] if err.strip() else "(no summary from gfimu live)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
