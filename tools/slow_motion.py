#!/usr/bin/env python3
"""Slow motion: ω accuracy of every method on a slow random 3-D rotation (|ω| at most 1 rad/s).

The readings see ω through q(ω) ~ |ω|², small against the noise, so the sign and size of ω are told
by the ω̇ the readings give and the motion model over seconds, not by one sample (a hovering drone, a
slow hand). One log of the ``slow3d`` scenario (gfimu.simulate) on the cube array of four triads
(``--half-edge-m``, 0.07 m/s² per axis, ``--rate-hz``, ``--duration-s``, ``--seed``); each method runs
in this process, one after the other. Prints per method the ω RMSE over the whole log, over the first
``--first-s`` seconds and after, the share of those first samples (with |ω_true| > 0.1 rad/s) whose
estimate points against the truth, and the ratio of the whole-log RMSE to the batch smoother's.

    python3 tools/slow_motion.py [--half-edge-m 0.05] [--rate-hz 500] [--duration-s 20] [--seed 0] [--lag-s 0.2]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gfimu.array import cube_array  # noqa: E402
from gfimu.methods import make_estimator  # noqa: E402
from gfimu.simulate import simulate  # noqa: E402

METHODS = ("inversion", "integration", "imm", "ml", "smoother", "fixed-lag")


def motion_of(estimator, log):
    """The estimator's ω, ω̇, f over ``log`` (a gfimu.motion.Motion)."""
    if hasattr(estimator, "result"):
        return estimator.result(log).motion
    return estimator.estimate_motion(log)


def scores(omega: np.ndarray, truth: np.ndarray, first: np.ndarray) -> dict:
    err2 = np.sum((omega - truth) ** 2, axis=1)
    moving = np.linalg.norm(truth, axis=1) > 0.1
    wrong = np.sum(omega * truth, axis=1) < 0
    return {"whole": float(np.sqrt(np.mean(err2))), "first": float(np.sqrt(np.mean(err2[first]))),
            "after": float(np.sqrt(np.mean(err2[~first]))) if (~first).any() else float("nan"),
            "wrong_first": float(np.mean(wrong[first & moving])) if (first & moving).any() else 0.0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--half-edge-m", type=float, default=0.05)
    ap.add_argument("--rate-hz", type=float, default=500.0)
    ap.add_argument("--duration-s", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--lag-s", type=float, default=0.2, help="the fixed-lag smoother's lag [s]")
    ap.add_argument("--first-s", type=float, default=2.0, help="length of the start scored apart [s]")
    ap.add_argument("--methods", default=",".join(METHODS))
    args = ap.parse_args(argv)
    log = simulate("slow3d", array=cube_array(args.half_edge_m, noise_std_mps2=0.07), rate_hz=args.rate_hz,
                   duration_s=args.duration_s, seed=args.seed)
    truth = log.truth.omega_b_radps
    first = log.times_s - log.times_s[0] < args.first_s
    speed = np.linalg.norm(truth, axis=1)
    print(f"slow3d: cube half edge {args.half_edge_m:g} m, {args.rate_hz:g} Hz, {args.duration_s:g} s, seed "
          f"{args.seed}, 0.07 m/s²; |ω| median {np.median(speed):.2f}, 90th percentile "
          f"{np.percentile(speed, 90):.2f}, max {speed.max():.2f} rad/s; fixed-lag lag {args.lag_s:g} s\n")
    print(f"| method | ω RMSE whole | first {args.first_s:g} s | after | wrong sign, first {args.first_s:g} s | "
          "whole / batch | time |")
    print("|---|---|---|---|---|---|---|")
    rows = {}
    for name in [m.strip() for m in args.methods.split(",") if m.strip()]:
        estimator = make_estimator(name, **({"lag_s": args.lag_s} if name == "fixed-lag" else {}))
        t0 = time.perf_counter()
        rows[name] = scores(motion_of(estimator, log).omega_b_radps, truth, first)
        rows[name]["seconds"] = time.perf_counter() - t0
    batch = rows.get("smoother", {}).get("whole", float("nan"))
    for name, r in rows.items():
        print(f"| {name} | {r['whole']:.4f} | {r['first']:.4f} | {r['after']:.4f} | {100 * r['wrong_first']:.1f} % | "
              f"{r['whole'] / batch:.2f} | {r['seconds']:.1f} s |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
