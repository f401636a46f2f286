#!/usr/bin/env python3
"""Where the time of ``gfimu estimate LOG --method smoother`` goes on one log, and how fast the estimation
would have to be for a given whole-command throughput.

The log is the simulated cube log of ``tools/bench_smoother.py`` (random 3-D motion, cube array, 500 Hz,
``--duration-s`` long). Each part is timed on its own, the best of ``--repeats`` runs:

- start: a Python process that imports nothing of ours (``python -c pass``);
- imports: a fresh process importing what the command imports (``gfimu.cli`` and the smoother);
- reading ``LOG`` (``gfimu.io.read_log`` as the command calls it) and screening its readings;
- writing an estimate of the log's length (the truth's ω, ω̇ and acceleration: the columns the smoother
  writes) through the command's CSV writer;
- the whole command, each run its own process.

The processes run with Python's bytecode cache on (``tools/bench_env.py``). The estimation is the
whole command less these parts. For ``--target`` samples/s the command may take
samples / target seconds; the parts above take what they take whatever the estimation does, and the
rest is the estimation's budget: the table gives the estimation throughput that budget asks for,
against the one measured here and the one ``tools/bench_smoother.py`` measures on long logs.

    python3 tools/bench_floor.py [--duration-s 60] [--target 30000] [--repeats 5] [--json bench_floor.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench_env import command_env  # noqa: E402


def best_of_processes(argv: list[str], repeats: int, env: dict) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(argv, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        times.append(time.perf_counter() - t0)
    return min(times)


def best_in_process(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=60.0, help="length of the cube log [s] (default 60)")
    ap.add_argument("--target", type=float, default=30000.0, help="whole-command throughput to budget for [samples/s] (default 30000)")
    ap.add_argument("--repeats", type=int, default=5, help="runs of each part; the best is kept (default 5)")
    ap.add_argument("--json", default="bench_floor.json", help="where to write the results")
    args = ap.parse_args(argv)

    from gfimu import io as gio
    from gfimu.array import cube_array
    from gfimu.io.atomic import atomic_write
    from gfimu.io.tables import motion_csv_chunks
    from gfimu.readings import screen_log
    from gfimu.simulate import simulate

    env = command_env(REPO)
    r = args.repeats
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "log"
        log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=500.0, duration_s=args.duration_s, seed=0)
        gio.write_log(log, folder)
        n = len(log)
        truth = log.truth
        estimate = truth.replace(quaternion_wb=None, specific_force_b_mps2=None)
        parts = {
            "start": best_of_processes([sys.executable, "-c", "pass"], r, env),
            "imports": best_of_processes([sys.executable, "-c", "import gfimu.cli, gfimu.cli.estimate, gfimu.io, "
                                          "gfimu.pipeline, gfimu.smoother.batch"], r, env),
            "read": best_in_process(lambda: gio.read_log(folder, truth=False), r),
            "screen": best_in_process(lambda: screen_log(log), r),
            "write": best_in_process(lambda: atomic_write(Path(tmp) / "est.csv", motion_csv_chunks(estimate)), r),
        }
        command = best_of_processes([sys.executable, "-m", "gfimu", "estimate", str(folder), "--method", "smoother",
                                     "--out", str(Path(tmp) / "cmd.csv"), "--no-progress"], r, env)
    floor = sum(parts.values())
    estimation = command - floor
    budget = n / args.target
    print(f"# {time.strftime('%Y-%m-%d')}, {platform.node() or 'this machine'}, {os.cpu_count()} CPUs; cube log "
          f"{args.duration_s:g} s at 500 Hz = {n} samples; best of {r} runs each")
    print("| part | s |")
    print("|---|---:|")
    for name, s in parts.items():
        print(f"| {name} | {s:.3f} |")
    print(f"| everything but the estimation | {floor:.3f} |")
    print(f"| the whole command | {command:.3f} ({n / command:,.0f} samples/s) |")
    print(f"| the estimation (the rest) | {estimation:.3f} ({n / max(estimation, 1e-9):,.0f} samples/s) |")
    left = budget - floor
    if left > 0:
        need = f"{n / left:,.0f} samples/s, {estimation / left:.1f}× the estimation measured here"
    else:
        need = "impossible: the parts other than the estimation already take longer"
    print(f"\n{args.target:,.0f} samples/s for the whole command allows {budget:.3f} s; the estimation would have "
          f"{max(left, 0):.3f} s: {need}.")
    Path(args.json).write_text(json.dumps({
        "date": time.strftime("%Y-%m-%d %H:%M %Z"), "platform": platform.platform(), "cpus": os.cpu_count(),
        "samples": n, "repeats": r, "parts_s": parts, "floor_s": floor, "command_s": command,
        "estimation_s": estimation, "target_samples_per_s": args.target, "budget_s": budget,
        "estimation_budget_s": left}, indent=2))
    print(f"results written to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
