#!/usr/bin/env python3
"""Peak memory of reading a log's ``imu.csv`` (and the whole log folder), against the CSV's size.

Writes a ``--minutes`` long log at ``--rate-hz`` from an array of ``--triads`` three-axis
accelerometers (default: 30 min, 500 Hz, 8 triads: the corners of a 10 cm cube) with the library's
own writer, then reads it in a fresh process for each reader and prints the peak resident memory
above the process's memory just before reading (``ru_maxrss`` against ``/proc/self/statm``), as MB
and as a multiple of the CSV's size, the read time, and the peak resident memory of the largest
worker process that parsed blocks of the file (forked from the reader: its count includes the
pages it shares with the reader at the fork).

    python3 tools/bench_reader_memory.py [--minutes 30] [--rate-hz 500] [--triads 8] [--json bench_reader_memory.json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, {root!r})
import numpy as np
from gfimu import io as gio
from gfimu.io.tables import read_imu_csv

def rss_mb():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * resource.getpagesize() / 2**20

folder = {folder!r}
array = gio.load_array_toml(folder + "/array.toml")[0] if {what!r} == "imu.csv" else None
before = rss_mb()
t0 = time.perf_counter()
if {what!r} == "imu.csv":
    out = read_imu_csv(folder + "/imu.csv", array)
    n = len(out[0])
else:
    out = gio.read_log(folder)
    n = len(out)
wall = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
workers = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
print(json.dumps({{"before_mb": before, "peak_mb": peak, "after_mb": rss_mb(), "rows": n, "read_s": wall,
                  "worker_peak_mb": workers}}))
"""


def eight_corner_array(n_triads: int):
    import numpy as np

    from gfimu.array import Accelerometer, SensorArray

    corners = [np.array(c, dtype=float) * 0.05 for c in itertools.product((1, -1), repeat=3)]
    extra = [np.array([0.1 * (k + 1), 0.0, 0.0]) for k in range(max(0, n_triads - 8))]
    positions = (corners + extra)[:n_triads]
    return SensorArray(tuple(Accelerometer(f"a{i + 1}", p, noise_std_mps2=0.07) for i, p in enumerate(positions)),
                       name=f"{n_triads}-triad bench array")


def write_log(folder: Path, minutes: float, rate_hz: float, n_triads: int) -> None:
    """A log written in one-minute pieces of random readings through the library's writer."""
    import numpy as np

    from gfimu import io as gio
    from gfimu.log import Log

    array = eight_corner_array(n_triads)
    n = int(round(minutes * 60 * rate_hz))
    rng = np.random.default_rng(0)
    t = np.arange(n, dtype=np.int64) * int(round(1e9 / rate_hz)) + 1_700_000_000_000_000_000
    accel = rng.normal(0.0, 3.0, (n, array.n_axes))
    accel[:, 2::3] += 9.81
    gio.write_log(Log(array, t, accel, source="bench"), folder)


def measure(folder: Path, what: str) -> dict:
    code = CHILD.format(root=str(ROOT), folder=str(folder), what=what)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"reading {what} failed: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=30.0, help="length of the log [min] (default 30)")
    ap.add_argument("--rate-hz", type=float, default=500.0, help="sample rate [Hz] (default 500)")
    ap.add_argument("--triads", type=int, default=8, help="three-axis accelerometers (default 8)")
    ap.add_argument("--json", default="bench_reader_memory.json", help="where to write the results")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "log"
        t0 = time.perf_counter()
        write_log(folder, args.minutes, args.rate_hz, args.triads)
        size_mb = (folder / "imu.csv").stat().st_size / 2**20
        print(f"log: {args.minutes:g} min at {args.rate_hz:g} Hz, {args.triads} triads; imu.csv {size_mb:.0f} MB "
              f"(written in {time.perf_counter() - t0:.0f} s)")
        rows = {what: measure(folder, what) for what in ("imu.csv", "log folder")}
    print("| read | rows | peak RSS above start | × CSV size | time | largest worker's peak RSS |")
    print("|---|---|---|---|---|---|")
    for what, r in rows.items():
        extra = r["peak_mb"] - r["before_mb"]
        r["peak_above_start_mb"] = extra
        r["ratio_to_csv"] = extra / size_mb
        print(f"| {what} | {r['rows']} | {extra:.0f} MB | {extra / size_mb:.2f} | {r['read_s']:.1f} s | "
              f"{r['worker_peak_mb']:.0f} MB |")
    Path(args.json).write_text(json.dumps({"platform": platform.platform(), "date": time.strftime("%Y-%m-%d %H:%M %Z"),
                                           "csv_mb": size_mb, "minutes": args.minutes, "rate_hz": args.rate_hz,
                                           "triads": args.triads, "reads": rows}, indent=2))
    print(f"\nresults written to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
