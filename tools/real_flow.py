#!/usr/bin/env python3
"""The plain command flow on real recordings, as a new user runs it, timed and scored.

For each MIMU4444 recording (``data.bin``) given, in a temporary folder::

    gfimu convert mimu4444 data.bin --out LOG
    gfimu calibrate LOG --out cal.toml
    gfimu estimate LOG --method smoother --calibration cal.toml --out est.csv

each as its own process (start-up included), wall time, CPU time (user + system)
and peak resident memory of each step (``os.wait4``: its worker processes included); then the estimate is scored
against the board's gyro reference (mean of its gyros) on the moving, unsaturated
samples (|ω_ref| > 2 rad/s, reference valid): RMSE of the ω error norm, its median
and the share of samples with ``ω · ω_ref < 0`` (wrong sign). ``--option`` passes
``-O KEY=VALUE`` to the estimate (e.g. to compare with a preset: ``--preset NAME``).

    python3 tools/real_flow.py ../shared/data/mimu4444/exp_*/data.bin
    python3 tools/real_flow.py DATA.bin --preset hand-held-low-rate --json flow.json
    python3 tools/real_flow.py ../shared/data/mimu4444/exp_*/data.bin --baseline ../old

``--baseline DIR`` runs the same flow with another checkout (``git worktree add ../old COMMIT``) right
after this one's on each recording: on a machine whose speed drifts, only runs side by side compare.

The scoring uses the same library function as ``gfimu evaluate``; the real-flow figures of
docs/benchmarks.md come from this script (``tools/benchmarks.py --only real-flow``).
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
import warnings
from pathlib import Path

from bench_env import command_env

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

MOVING_RADPS = 2.0


def run_step(args: list[str], env: dict) -> tuple[float, float, float]:
    """(wall time [s], CPU time [s], peak RSS [MB]) of ``python -m gfimu ARGS``, its worker processes
    included (``os.wait4``); exits on failure."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "gfimu", *args], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.stderr.close()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"gfimu {' '.join(args)} failed ({proc.returncode}):\n{err.strip()}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


def score(log_dir: Path, estimate_csv: Path) -> dict:
    from gfimu import io as gio

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = gio.read_log(log_dir)
        est = gio.read_motion_csv(estimate_csv)
    ref = log.reference.omega_b_radps
    valid = ~log.invalid_reference if log.invalid_reference is not None else np.ones(len(log), bool)
    moving = valid & (np.linalg.norm(ref, axis=1) > MOVING_RADPS)
    err = est.omega_b_radps[moving] - ref[moving]
    norm = np.linalg.norm(err, axis=1)
    return {"samples": len(log), "moving": int(moving.sum()),
            "rmse_radps": float(np.sqrt(np.mean(norm**2))), "median_radps": float(np.median(norm)),
            "wrong_sign_share": float(np.mean(np.sum(est.omega_b_radps[moving] * ref[moving], axis=1) < 0))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("recordings", nargs="+", type=Path, help="MIMU4444 data.bin files")
    ap.add_argument("--preset", default=None, help="smoother preset to pass to the estimate (default: none)")
    ap.add_argument("--option", "-O", action="append", default=[], help="-O KEY=VALUE for the estimate")
    ap.add_argument("--baseline", type=Path, default=None, metavar="DIR",
                    help="also run the flow with another checkout of the package (its root folder, e.g. a `git "
                         "worktree` of an earlier version), right after this one's on each recording")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows as JSON here")
    args = ap.parse_args(argv)
    trees = [("this", command_env(REPO, threads=None))]
    if args.baseline:
        trees.append(("baseline", command_env(args.baseline.resolve(), threads=None)))
    rows = []
    print(f"# {time.strftime('%Y-%m-%d')}, {platform.node()}, {os.cpu_count()} cores, {platform.processor() or platform.machine()}")
    print("| recording | samples | moving | convert s | calibrate s | estimate s | total s | total CPU s | peak MB | RMSE rad/s "
          "| median rad/s | wrong sign |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for rec in args.recordings:
        for name, env in trees:  # with a baseline: its flow right after this one's, on the same recording
            with tempfile.TemporaryDirectory() as tmp:
                tmp = Path(tmp)
                log, cal, est = tmp / "log", tmp / "cal.toml", tmp / "est.csv"
                t_conv, c1, m1 = run_step(["convert", "mimu4444", str(rec), "--out", str(log)], env)
                t_cal, c2, m2 = run_step(["calibrate", str(log), "--out", str(cal)], env)
                extra = (["--preset", args.preset] if args.preset else []) + [x for o in args.option for x in ("-O", o)]
                t_est, c3, m3 = run_step(["estimate", str(log), "--method", "smoother", "--calibration", str(cal),
                                          "--out", str(est), "--no-progress", *extra], env)
                row = {"recording": str(rec), "tree": name, **score(log, est), "convert_s": t_conv, "calibrate_s": t_cal,
                       "estimate_s": t_est, "total_s": t_conv + t_cal + t_est, "peak_mb": max(m1, m2, m3),
                       "convert_cpu_s": c1, "calibrate_cpu_s": c2, "estimate_cpu_s": c3, "total_cpu_s": c1 + c2 + c3}
            rows.append(row)
            label = (rec.parent.name or rec.name) + ("" if name == "this" else " (baseline)")
            print(f"| {label} | {row['samples']} | {row['moving']} | {t_conv:.1f} | {t_cal:.1f} | {t_est:.1f} | "
                  f"{row['total_s']:.1f} | {row['total_cpu_s']:.1f} | {row['peak_mb']:.0f} | {row['rmse_radps']:.2f} | "
                  f"{row['median_radps']:.2f} | {100 * row['wrong_sign_share']:.2f} % |", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
