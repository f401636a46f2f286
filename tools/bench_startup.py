#!/usr/bin/env python3
"""Start-up time of the ``gfimu`` command: ``--help``, ``--version`` and a few command helps.

Each command line runs ``--repeats`` times in a fresh process (``python -m gfimu ...``); prints the
median and the worst wall-clock time and whether numpy, scipy, gtsam, matplotlib, numba or pandas
were imported on the way (``-X importtime``).

    python3 tools/bench_startup.py [--repeats 7] [--json bench_startup.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

from bench_env import command_env

ROOT = Path(__file__).resolve().parents[1]
COMMAND_LINES = (["--help"], ["--version"], ["estimate", "--help"], ["simulate", "--help"])
HEAVY = ("numpy", "scipy", "gtsam", "matplotlib", "numba", "pandas")


def run(args: list[str], repeats: int) -> dict:
    env = command_env(ROOT, threads=None)
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "gfimu", *args], capture_output=True, env=env)
        walls.append(time.perf_counter() - t0)
        if done.returncode != 0:
            raise SystemExit(f"gfimu {' '.join(args)} exited {done.returncode}: {done.stderr.decode().strip()}")
    trace = subprocess.run([sys.executable, "-X", "importtime", "-m", "gfimu", *args], capture_output=True, env=env,
                           text=True).stderr
    imported = sorted({line.split("|")[-1].strip() for line in trace.splitlines() if "|" in line}
                      & set(HEAVY))
    return {"args": args, "median_s": statistics.median(walls), "max_s": max(walls), "heavy_imports": imported}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7, help="runs per command line (default 7)")
    ap.add_argument("--json", default="bench_startup.json", help="where to write the results")
    args = ap.parse_args(argv)
    rows = [run(a, args.repeats) for a in COMMAND_LINES]
    load = os.getloadavg()[0]
    print(f"gfimu start-up, {args.repeats} runs each, {os.cpu_count()} CPUs, 1-min load average {load:.1f}")
    print("| command | median | worst | heavy modules imported |")
    print("|---|---|---|---|")
    for r in rows:
        print(f"| gfimu {' '.join(r['args'])} | {r['median_s']:.3f} s | {r['max_s']:.3f} s | "
              f"{', '.join(r['heavy_imports']) or 'none'} |")
    Path(args.json).write_text(json.dumps({"platform": platform.platform(), "python": platform.python_version(),
                                           "date": time.strftime("%Y-%m-%d %H:%M %Z"), "load_average_1min": load,
                                           "cpus": os.cpu_count(), "runs": rows}, indent=2))
    print(f"\nresults written to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
