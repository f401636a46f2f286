#!/usr/bin/env python3
"""Throughput and peak memory of the batch smoother (method "smoother").

Simulated random 3-D motion, cube array (half edge 0.05 m, 0.07 m/s²),
500 Hz; for each log length, over the repeats, the median wall time and the
median CPU time of the process (``time.process_time``: the time this process
computed, which the other work on a shared machine does not inflate), samples
per second of each, and the peak memory traced (tracemalloc) during one extra run.

With ``--command`` the log is written to a folder and the whole command
``python -m gfimu estimate LOG --method smoother --out est.csv`` is timed
instead, each repeat its own process (start-up, reading and writing included):
wall time, CPU time of the child and its workers (user + system, ``os.wait4``) and
its peak resident memory. Both run with one BLAS thread (OMP_NUM_THREADS=1, as
the command line sets it), the command with Python's bytecode cache on (``tools/bench_env.py``).

    python3 tools/bench_smoother.py [--durations 10 60 600] [--repeats 3] [--json bench_smoother.json]
    python3 tools/bench_smoother.py --command --durations 20 60 200 600 --repeats 3
    python3 tools/bench_smoother.py --command --baseline ../old --durations 20 60 --repeats 5

``--baseline DIR`` times another checkout (``git worktree add ../old COMMIT``) in the same loop, its runs
alternating with these: on a machine whose speed drifts, only runs side by side compare.
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
import tracemalloc
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench_env import command_env  # noqa: E402
from gfimu.array import cube_array  # noqa: E402
from gfimu.simulate import simulate  # noqa: E402
from gfimu.smoother.batch.engine import BatchSmootherEstimator  # noqa: E402


def in_process(log, est, repeats: int) -> dict:
    walls, cpus = [], []
    for _ in range(max(repeats, 1)):
        c0, t0 = time.process_time(), time.perf_counter()
        est.estimate(log).motion
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    tracemalloc.start()
    est.estimate(log).motion
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {"median_time_s": statistics.median(walls), "median_cpu_s": statistics.median(cpus),
            "times_s": walls, "cpu_s": cpus, "peak_memory_mb": peak / 2**20}


def run_once(cmd: list, env: dict) -> tuple[float, float, float]:
    """Wall time, CPU time (user + system, its worker processes included) and peak resident memory
    [MB] of one run of ``cmd``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read()
    proc.stderr.close()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{err}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


def whole_command(log, repeats: int, sigma: bool, baseline: str | None = None) -> tuple[dict, dict | None]:
    """The command's figures over ``repeats`` runs; with ``baseline`` (another checkout of the package)
    its runs alternate with the baseline's, so that both see the same machine, and the baseline's
    figures come second."""
    from gfimu import io as gio

    def env_of(root):
        return command_env(Path(root))

    trees = [("this", env_of(REPO))] + ([("baseline", env_of(Path(baseline).resolve()))] if baseline else [])
    runs = {name: [] for name, _ in trees}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "log"
        gio.write_log(log, folder)
        cmd = [sys.executable, "-m", "gfimu", "estimate", str(folder), "--method", "smoother",
               "--out", str(Path(tmp) / "est.csv"), "--no-progress"] + (["--sigma"] if sigma else [])
        for _ in range(max(repeats, 1)):
            for name, env in trees:
                runs[name].append(run_once(cmd, env))

    def summary(rs):
        walls, cpus, rss = zip(*rs)
        return {"median_time_s": statistics.median(walls), "median_cpu_s": statistics.median(cpus),
                "times_s": list(walls), "cpu_s": list(cpus), "peak_memory_mb": max(rss)}

    return summary(runs["this"]), (summary(runs["baseline"]) if baseline else None)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--durations", type=float, nargs="+", default=[10.0, 60.0, 600.0], help="log lengths [s]")
    ap.add_argument("--rate-hz", type=float, default=500.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sigma", action="store_true", help="also compute the marginal uncertainties")
    ap.add_argument("--command", action="store_true",
                    help="time the whole command `python -m gfimu estimate LOG --method smoother` per repeat")
    ap.add_argument("--baseline", default=None, metavar="DIR",
                    help="with --command: also time another checkout of the package (its root folder, e.g. a "
                         "`git worktree` of an earlier version), its runs alternating with these")
    ap.add_argument("--json", default="bench_smoother.json", help="where to write the results")
    args = ap.parse_args(argv)
    if args.baseline and not args.command:
        ap.error("--baseline needs --command")
    est = BatchSmootherEstimator(compute_sigma=args.sigma)
    memory = "peak resident memory of the command" if args.command else "peak traced memory"
    rows = []
    for duration in args.durations:
        log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=args.rate_hz, duration_s=duration, seed=0)
        base = None
        if args.command:
            r, base = whole_command(log, args.repeats, args.sigma, args.baseline)
        else:
            r = in_process(log, est, args.repeats)
        for x in (r, base):
            if x is not None:
                x.update({"duration_s": duration, "samples": len(log), "repeats": max(args.repeats, 1),
                          "samples_per_s": len(log) / x["median_time_s"], "samples_per_cpu_s": len(log) / x["median_cpu_s"]})
        if base is not None:
            r["baseline"] = base
        rows.append(r)
        print(f"{duration:7.0f} s {r['samples']:8d} samples  wall {r['median_time_s']:7.2f} s "
              f"({r['samples_per_s']:7.0f} samples/s)  CPU {r['median_cpu_s']:7.2f} s "
              f"({r['samples_per_cpu_s']:7.0f} samples/s)  {memory} {r['peak_memory_mb']:7.1f} MB", flush=True)
    print()
    what = "`python -m gfimu estimate LOG --method smoother`" if args.command else "in process"
    print(f"{what}, median of {max(args.repeats, 1)}, load average {os.getloadavg()[0]:.1f} at the end")
    print()
    print(f"| log length | samples | wall [s] | samples/s (wall) | CPU [s] | samples/s (CPU) | {memory} [MB] |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['duration_s']:g} s | {r['samples']} | {r['median_time_s']:.2f} | {r['samples_per_s']:.0f} | "
              f"{r['median_cpu_s']:.2f} | {r['samples_per_cpu_s']:.0f} | {r['peak_memory_mb']:.1f} |")
    if args.baseline:
        print(f"\nthe baseline {args.baseline}, its runs alternating with these:\n")
        print(f"| log length | samples | wall [s] | samples/s (wall) | CPU [s] | samples/s (CPU) | {memory} [MB] | "
              "wall, this / baseline |")
        print("|---|---|---|---|---|---|---|---|")
        for r in rows:
            b = r["baseline"]
            print(f"| {b['duration_s']:g} s | {b['samples']} | {b['median_time_s']:.2f} | {b['samples_per_s']:.0f} | "
                  f"{b['median_cpu_s']:.2f} | {b['samples_per_cpu_s']:.0f} | {b['peak_memory_mb']:.1f} | "
                  f"{r['median_time_s'] / b['median_time_s']:.2f} |")
    out = {"method": "smoother", "baseline": args.baseline, "array": "cube half edge 0.05 m", "rate_hz": args.rate_hz, "sigma": args.sigma,
           "command": args.command, "python": platform.python_version(), "machine": platform.machine(),
           "results": rows}
    Path(args.json).write_text(json.dumps(out, indent=2))
    print(f"\nwritten {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
