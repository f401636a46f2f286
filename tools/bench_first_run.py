#!/usr/bin/env python3
"""The first fixed-lag run on a machine: what compiling the stream's kernels costs, and what is left of it.

The fixed-lag smoother's per-sample arithmetic (``gfimu/smoother/stream/kernels.py``) and the per-sample ML
iterations its model choice runs (``gfimu/estimators/ml_kernels.py``) are compiled by numba the first time they
run and cached on disk. This script times ``gfimu estimate LOG --method fixed-lag`` on a short simulated log
(``gfimu simulate random3d``, 5 s, 500 Hz) in fresh processes:

- ``first run``: with an empty cache (``NUMBA_CACHE_DIR`` set to a new empty folder each time): what a user's
  first run after installing pays;
- ``cached``: with that cache filled: every later run;

alternating, medians of ``--runs``; their difference is the compilation. Then, in one more process with an
empty cache, each kernel's compilation time as numba reports it (its ``numba:compile`` events; a kernel's
time includes the kernels it calls that were not compiled before it).

With ``--baseline DIR`` (another checkout of gfimu) its package is timed the same way in the same loop.

    python3 tools/bench_first_run.py [--runs 3] [--baseline DIR]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_env import command_env  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

KERNEL_TIMES = r"""
import json, sys
from numba.core import event
from gfimu.cli import main
with event.install_recorder("numba:compile") as rec:
    code = main(sys.argv[1:])
start, out = {}, {}
for ts, ev in rec.buffer:
    d = ev.data.get("dispatcher")
    mod = getattr(getattr(d, "py_func", None), "__module__", "") or ""
    if not mod.startswith("gfimu."):
        continue
    key = d.py_func.__module__.rsplit(".", 1)[-1] + "." + d.py_func.__name__
    if ev.is_start:
        start[key] = ts
    elif key in start:
        out[key] = out.get(key, 0.0) + ts - start.pop(key)
print(json.dumps(out))
"""


def timed(env: dict, log: Path, out: Path, cache: Path) -> float:
    out.unlink(missing_ok=True)
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "gfimu", "estimate", str(log), "--method", "fixed-lag", "--out",
                           str(out), "-q"], env={**env, "NUMBA_CACHE_DIR": str(cache)}, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"gfimu estimate exited {done.returncode}: {done.stderr.strip()}")
    return time.perf_counter() - t0


def kernel_times(env: dict, log: Path, out: Path, cache: Path) -> dict:
    out.unlink(missing_ok=True)
    done = subprocess.run([sys.executable, "-c", KERNEL_TIMES, "estimate", str(log), "--method", "fixed-lag", "--out",
                           str(out), "-q"], env={**env, "NUMBA_CACHE_DIR": str(cache)}, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"the kernels' compilation could not be timed: {done.stderr.strip()}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3, help="rounds (each: a first run and a cached run per checkout)")
    ap.add_argument("--baseline", help="another checkout of gfimu, timed in the same loop")
    args = ap.parse_args()
    roots = {"now": ROOT}
    if args.baseline:
        roots["baseline"] = Path(args.baseline).resolve()
    envs = {name: command_env(root) for name, root in roots.items()}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        log = tmp / "log"
        subprocess.run([sys.executable, "-m", "gfimu", "simulate", "random3d", "--out", str(log), "--duration-s", "5",
                        "-q"], env=envs["now"], check=True)
        warm = {name: tmp / f"warm-{name}" for name in roots}
        for name in roots:  # the cached runs' cache, filled once
            timed(envs[name], log, tmp / "x.csv", warm[name])
        first = {name: [] for name in roots}
        cached = {name: [] for name in roots}
        for r in range(args.runs):
            for name in roots:
                first[name].append(timed(envs[name], log, tmp / "x.csv", tmp / f"cold-{name}-{r}"))
                cached[name].append(timed(envs[name], log, tmp / "x.csv", warm[name]))
        kernels = {name: kernel_times(envs[name], log, tmp / "x.csv", tmp / f"cold-k-{name}") for name in roots}
    print(f"gfimu estimate LOG --method fixed-lag on a 5 s, 500 Hz simulated log (2,500 samples); wall time, "
          f"medians of {args.runs} run(s)")
    print()
    names = list(roots)
    print("| run | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    rows = (("first run (empty kernel cache) [s]", first), ("cached [s]", cached))
    for label, values in rows:
        print(f"| {label} | " + " | ".join(f"{statistics.median(values[n]):.2f}" for n in names) + " |")
    print("| compilation (first run - cached) [s] | " + " | ".join(
        f"{statistics.median(first[n]) - statistics.median(cached[n]):.2f}" for n in names) + " |")
    print()
    print("Each kernel's compilation as numba reports it (a fresh process, an empty cache) [s]:")
    print()
    keys = sorted(set().union(*kernels.values()), key=lambda k: -kernels["now"].get(k, 0.0))
    print("| kernel | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for key in keys:
        print(f"| {key} | " + " | ".join(f"{kernels[n][key]:.2f}" if key in kernels[n] else "" for n in names) + " |")


if __name__ == "__main__":
    main()
