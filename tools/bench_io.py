#!/usr/bin/env python3
"""Reading and writing a log's tables, and the screening's rolling median, timed on their own.

Writes the simulated cube log (random 3-D motion, 500 Hz, ``--duration-s`` long, with its truth),
then, each part in a fresh process and ``--repeats`` times (with ``--baseline DIR``, another
checkout's runs alternating with these):

- read: ``gfimu.io.read_log`` of the folder, imu.csv and truth.csv;
- write: the truth's ω, ω̇ and acceleration (the columns of an estimate) through the estimate writer;
- median: the screening's rolling median of five over the readings.

Wall times in seconds, the median of the repeats.

    python3 tools/bench_io.py [--duration-s 600] [--repeats 3] [--baseline ../old] [--json bench_io.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench_env import command_env  # noqa: E402

CHILD = """
import json, sys, time
from gfimu import io as gio
from gfimu.io.atomic import atomic_write
from gfimu.io.tables import motion_csv_chunks
from gfimu.readings import _rolling_median
folder, out = sys.argv[1], sys.argv[2]
t0 = time.perf_counter(); log = gio.read_log(folder, check=False); t1 = time.perf_counter()
est = log.truth.replace(quaternion_wb=None, specific_force_b_mps2=None)
t2 = time.perf_counter(); atomic_write(out, motion_csv_chunks(est)); t3 = time.perf_counter()
t4 = time.perf_counter(); _rolling_median(log.accel_mps2, 2); t5 = time.perf_counter()
print(json.dumps({"read": t1 - t0, "write": t3 - t2, "median": t5 - t4}))
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=600.0, help="length of the cube log [s] (default 600)")
    ap.add_argument("--repeats", type=int, default=3, help="runs of each version (default 3)")
    ap.add_argument("--baseline", type=Path, default=None, metavar="DIR",
                    help="another checkout of the package (its root folder), its runs alternating with these")
    ap.add_argument("--json", default="bench_io.json", help="where to write the results")
    args = ap.parse_args(argv)

    from gfimu import io as gio
    from gfimu.array import cube_array
    from gfimu.simulate import simulate

    trees = [("this", command_env(REPO))] + ([("baseline", command_env(args.baseline.resolve()))] if args.baseline else [])
    runs: dict = {name: [] for name, _ in trees}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "log"
        log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=500.0, duration_s=args.duration_s, seed=0)
        gio.write_log(log, folder)
        n = len(log)
        for _ in range(max(args.repeats, 1)):
            for name, env in trees:
                done = subprocess.run([sys.executable, "-c", CHILD, str(folder), str(Path(tmp) / "est.csv")], env=env,
                                      capture_output=True, text=True, check=True)
                runs[name].append(json.loads(done.stdout.strip().splitlines()[-1]))
    print(f"# {time.strftime('%Y-%m-%d %H:%M')}, {platform.node()}, {os.cpu_count()} CPUs; cube log "
          f"{args.duration_s:g} s at 500 Hz = {n} rows; median of {max(args.repeats, 1)} runs [s]")
    print("| version | read imu.csv + truth.csv | write the estimate | rolling median of five |")
    print("|---|---:|---:|---:|")
    summary = {}
    for name, rs in runs.items():
        med = {k: statistics.median(r[k] for r in rs) for k in ("read", "write", "median")}
        summary[name] = {"median_s": med, "runs": rs}
        print(f"| {name} | {med['read']:.2f} | {med['write']:.2f} | {med['median']:.2f} |")
    Path(args.json).write_text(json.dumps({"date": time.strftime("%Y-%m-%d %H:%M %Z"), "platform": platform.platform(),
                                           "rows": n, "baseline": str(args.baseline) if args.baseline else None,
                                           "results": summary}, indent=2))
    print(f"results written to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
