#!/usr/bin/env python3
"""Speed and memory of every estimation method, for several log lengths.

For each method and log length (simulated, fixed seed): median wall time over
the repeats, throughput in samples per second, and peak traced memory
(tracemalloc, one extra run, so tracing does not slow the timed runs),
after one untimed warm-up run on the first 200 samples. Runs shorter than
0.3 s are repeated (up to 50 times) so that their median is stable. The
batch smoother's numbers come from ``tools/bench_smoother.py`` and the
fixed-lag update latency (median, 99th percentile) from
``tools/bench_fixed_lag.py``. Prints a table and writes JSON.

    python3 tools/bench.py [--quick] [--durations 10 30 100] [--repeats 3] [--json bench.json]

Arrays: the 5 cm cube of four triads (0.07 m/s²) at 500 Hz for the
accelerometer-only methods, Lu, Tsai & Lin 2010's nine-axis array with a gyro for
``gyro-aided``, McGinnis, Perkins & King 2012's single triad in free flight (1 kHz) for ``free-flight``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import platform
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from gfimu.array import cube_array, paper001_array  # noqa: E402
from gfimu.methods import METHODS, make_estimator  # noqa: E402
from gfimu.simulate import simulate  # noqa: E402

MAX_REPEATS = 50
PER_SAMPLE = ["inversion", "integration", "pure-integration", "imm", "ml", "gyro-aided", "free-flight"]


def bench_log(method: str, duration_s: float, seed: int = 0):
    """The simulated log a method is timed on."""
    if method == "free-flight":
        return simulate("freeflight-major", duration_s=duration_s, seed=seed)
    array = paper001_array() if method == "gyro-aided" else cube_array(0.05, 0.07)
    return simulate("random3d", array, rate_hz=500.0, duration_s=duration_s, seed=seed)


def time_method(method: str, log, repeats: int) -> dict:
    """Median time, throughput and peak traced memory of ``method`` on ``log``."""
    est = make_estimator(method)
    reason = est.applicable(log.array)
    if reason:
        return {"method": method, "samples": len(log), "status": f"not applicable: {reason}"}
    est.estimate(log.select(slice(0, min(len(log), 200)))).motion  # warm-up: imports and caches, not timed
    times = []
    n_runs = max(repeats, 1)
    while len(times) < n_runs:
        t0 = time.perf_counter()
        est.estimate(log).motion
        times.append(time.perf_counter() - t0)
        if len(times) == 1:  # fast methods: repeat until about 0.3 s in all, so the median is stable
            n_runs = max(n_runs, min(MAX_REPEATS, math.ceil(0.3 / max(times[0], 1e-6))))
    tracemalloc.start()
    est.estimate(log).motion
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    median = statistics.median(times)
    return {"method": method, "samples": len(log), "status": "ok", "median_time_s": median,
            "samples_per_s": len(log) / median, "peak_memory_mb": peak / 2**20, "repeats": len(times)}


def smoother_rows(durations, repeats: int) -> list[dict]:
    """Batch smoother throughput and memory from tools/bench_smoother.py."""
    import bench_smoother

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "smoother.json"
        with contextlib.redirect_stdout(io.StringIO()):
            bench_smoother.main(["--durations", *map(str, durations), "--repeats", str(repeats), "--json", str(out)])
        doc = json.loads(out.read_text())
    rows = doc["results"]
    return [{"method": "smoother", "samples": r["samples"], "status": "ok", "median_time_s": r["median_time_s"],
             "samples_per_s": r["samples_per_s"], "peak_memory_mb": r["peak_memory_mb"], "repeats": r["repeats"]}
            for r in rows]


def fixed_lag_latency(duration_s: float, lag_s: float = 0.2) -> dict:
    """Push latency of the streaming fixed-lag smoother from tools/bench_fixed_lag.py."""
    import bench_fixed_lag

    args = argparse.Namespace(rate_hz=500.0, duration_s=duration_s, lag_s=lag_s)
    with contextlib.redirect_stdout(io.StringIO()):
        return bench_fixed_lag.latency_run(args)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--durations", type=float, nargs="+", default=[10.0, 30.0, 100.0], help="log lengths [s]")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per point (median reported)")
    ap.add_argument("--methods", default=",".join(PER_SAMPLE + ["smoother", "fixed-lag"]),
                    help="comma-separated methods")
    ap.add_argument("--latency-duration-s", type=float, default=30.0, help="length of the fixed-lag latency run [s]")
    ap.add_argument("--quick", action="store_true", help="short logs, one repeat: a check that everything runs")
    ap.add_argument("--json", default="bench.json", help="where to write the results")
    args = ap.parse_args(argv)
    if args.quick:
        args.durations, args.repeats, args.latency_duration_s = [1.0, 4.0], 1, 2.0
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        ap.error(f"unknown methods {unknown}; choose among {list(METHODS)}")

    cpus = os.cpu_count()
    print(f"machine: {platform.platform()}, {cpus} CPUs, Python {platform.python_version()}; seed 0, "
          f"median of {args.repeats} run(s)", flush=True)
    rows = []
    for method in methods:
        if method in ("smoother", "fixed-lag"):
            continue
        for duration in args.durations:
            try:
                row = time_method(method, bench_log(method, duration), args.repeats)
            except Exception as exc:  # noqa: BLE001 - report and go on
                row = {"method": method, "status": f"failed: {type(exc).__name__}: {exc}"}
            row["duration_s"] = duration
            rows.append(row)
            print(f"  {method:18s} {duration:7g} s  {row.get('samples_per_s', float('nan')):12.0f} samples/s  "
                  f"{row['status']}", flush=True)
    if "smoother" in methods:
        for row, duration in zip(smoother_rows(args.durations, args.repeats), args.durations):
            row["duration_s"] = duration
            rows.append(row)
    latency = fixed_lag_latency(args.latency_duration_s) if "fixed-lag" in methods else None

    print()
    print("| method | log length | samples | median time [s] | samples/s | peak traced memory [MB] |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        if r["status"] != "ok":
            print(f"| {r['method']} | {r['duration_s']:g} s | – | – | – | {r['status']} |")
            continue
        print(f"| {r['method']} | {r['duration_s']:g} s | {r['samples']} | {r['median_time_s']:.4f} | "
              f"{r['samples_per_s']:.0f} | {r['peak_memory_mb']:.1f} |")
    if latency:
        print()
        print(f"fixed-lag (lag {latency['lag_s']:g} s, {latency['samples']} samples at {latency['rate_hz']:g} Hz): "
              f"push latency median {latency['latency_median_ms']:.3f} ms, p99 {latency['latency_p99_ms']:.3f} ms, "
              f"max {latency['latency_max_ms']:.1f} ms; {latency['samples_per_s']:.0f} samples/s")
    doc = {"platform": platform.platform(), "python": platform.python_version(), "cpu_count": cpus,
           "repeats": args.repeats, "durations_s": args.durations, "rows": rows, "fixed_lag_latency": latency}
    Path(args.json).write_text(json.dumps(doc, indent=2))
    print(f"\nresults written to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
