#!/usr/bin/env python3
"""Throughput and peak memory of the batch smoother (method "smoother").

Simulated random 3-D motion, cube array (half edge 0.05 m, 0.07 m/s²),
500 Hz; for each log length: median wall time of the repeats, samples per
second, and the peak memory traced (tracemalloc) during one extra run.

    python3 tools/bench_smoother.py [--durations 10 60 600] [--repeats 3] [--json bench_smoother.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gfimu.array import cube_array  # noqa: E402
from gfimu.simulate import simulate  # noqa: E402
from gfimu.smoother.batch import BatchSmootherEstimator  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--durations", type=float, nargs="+", default=[10.0, 60.0, 600.0], help="log lengths [s]")
    ap.add_argument("--rate-hz", type=float, default=500.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sigma", action="store_true", help="also compute the marginal uncertainties")
    ap.add_argument("--json", default="bench_smoother.json", help="where to write the results")
    args = ap.parse_args(argv)
    est = BatchSmootherEstimator(compute_sigma=args.sigma)
    rows = []
    for duration in args.durations:
        log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=args.rate_hz, duration_s=duration, seed=0)
        times = []
        for _ in range(max(args.repeats, 1)):
            t0 = time.perf_counter()
            est.estimate(log)
            times.append(time.perf_counter() - t0)
        tracemalloc.start()
        est.estimate(log)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        median = statistics.median(times)
        rows.append({"duration_s": duration, "samples": len(log), "median_time_s": median,
                     "samples_per_s": len(log) / median, "peak_memory_mb": peak / 2**20, "repeats": len(times)})
        r = rows[-1]
        print(f"{duration:7.0f} s {r['samples']:8d} samples  {median:8.2f} s  {r['samples_per_s']:9.0f} samples/s  "
              f"peak {r['peak_memory_mb']:7.1f} MB", flush=True)
    print()
    print("| log length | samples | median time [s] | samples/s | peak traced memory [MB] |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['duration_s']:g} s | {r['samples']} | {r['median_time_s']:.2f} | {r['samples_per_s']:.0f} | {r['peak_memory_mb']:.1f} |")
    out = {"method": "smoother", "array": "cube half edge 0.05 m", "rate_hz": args.rate_hz, "sigma": args.sigma,
           "python": platform.python_version(), "machine": platform.machine(), "results": rows}
    Path(args.json).write_text(json.dumps(out, indent=2))
    print(f"\nwritten {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
