#!/usr/bin/env python3
"""Accuracy of the streaming fixed-lag smoother against the batch smoother.

Simulated logs (cube array of half edge ``--half-edge-m``, 0.07 m/s² per
axis, ``--rate-hz``, ``--duration-s``, ``--seed``) of each scenario; the batch
smoother (method "smoother", process noise tuned on the whole log) and the
fixed-lag smoother (method "fixed-lag", ``--lag-s``, process noise tuned on the
first ``--tune-window-s``). Prints the ω RMSE of both and their ratio, over the
whole log and over the streamed part only (after the tuning stretch, whose
states the fixed-lag smoother takes from the batch solution of the stretch);
"causal" is the batch smoother on the data up to t + lag only, at
``--causal-points`` times of the streamed part, with the fixed-lag smoother's
densities, and again choosing its own model (the oscillator included) on those
data: the best any estimator with that lag can do under that model (the
fixed-lag smoother should match it). Sign errors: the share of samples with
ω_est · ω_true < 0 among all samples ("flipped, all") and among those with
|ω_true| > 0.1 rad/s (gfimu.evaluation's ``flipped_share``).

    python3 tools/fixed_lag_accuracy.py [--duration-s 10] [--scenarios random3d,turntable,reversal]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gfimu.array import cube_array  # noqa: E402
from gfimu.evaluation import evaluate  # noqa: E402
from gfimu.simulate import simulate  # noqa: E402
from gfimu.smoother.batch.engine import BatchSmootherEstimator  # noqa: E402
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator  # noqa: E402


def rmse(est_b_radps: np.ndarray, true_b_radps: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((est_b_radps - true_b_radps) ** 2, axis=1))))


def causal_rmse(log, tuning, lag_s: float, indices) -> float:
    """ω RMSE at ``indices`` of the batch smoother given the data up to each index + lag: with the
    fixed densities of ``tuning`` or, with ``tuning=None``, choosing its own model (oscillator
    included) on those data."""
    if tuning is None:
        batch = BatchSmootherEstimator()
    else:
        batch = BatchSmootherEstimator(tune_process_noise=False, omega_dot_random_walk_radps2_per_sqrt_s=tuning.density,
                                       process_axis_factors=tuning.axis_factors,
                                       process_axis_frequencies_hz=tuning.axis_frequencies_hz,
                                       specific_force_random_walk_mps2_per_sqrt_s=tuning.specific_force_density)
    lag_n = int(round(lag_s * log.rate_hz))
    err = []
    for k in indices:
        est = batch.estimate(log.select(slice(0, min(k + lag_n + 1, len(log))))).motion
        err.append(est.omega_b_radps[k] - log.truth.omega_b_radps[k])
    return float(np.sqrt(np.mean(np.sum(np.square(err), axis=1))))


def run(scenario: str, args) -> dict:
    log = simulate(scenario, cube_array(args.half_edge_m, 0.07), rate_hz=args.rate_hz, duration_s=args.duration_s,
                   seed=args.seed)
    truth = log.truth.omega_b_radps
    t0 = time.perf_counter()
    batch = BatchSmootherEstimator().estimate(log).motion
    t_batch = time.perf_counter() - t0
    fixed_est = FixedLagEstimator(lag_s=args.lag_s, tune_window_s=args.tune_window_s)
    t0 = time.perf_counter()
    fixed_run = fixed_est.estimate(log)
    fixed, fixed_tunings = fixed_run.motion, fixed_run.report.tunings
    t_fixed = time.perf_counter() - t0
    n_tune = int(round(args.tune_window_s * args.rate_hz))
    streamed = slice(min(n_tune, len(log) - 1), len(log))
    row = {
        "scenario": scenario,
        "batch": rmse(batch.omega_b_radps, truth), "fixed": rmse(fixed.omega_b_radps, truth),
        "batch_streamed": rmse(batch.omega_b_radps[streamed], truth[streamed]),
        "fixed_streamed": rmse(fixed.omega_b_radps[streamed], truth[streamed]),
        "flipped_all": float(np.mean(np.sum(fixed.omega_b_radps * truth, axis=1) < 0)),
        "flipped_all_batch": float(np.mean(np.sum(batch.omega_b_radps * truth, axis=1) < 0)),
        "flipped_share": evaluate(fixed, log.truth)["omega_b_radps"].signs.flipped_share,
        "time_batch_s": t_batch, "time_fixed_s": t_fixed,
    }
    if args.causal_points > 0 and fixed_tunings and streamed.stop - streamed.start > 2:
        idx = np.linspace(streamed.start, streamed.stop - 1, args.causal_points).astype(int)
        row["causal_points"] = rmse(batch.omega_b_radps[idx], truth[idx]), rmse(fixed.omega_b_radps[idx], truth[idx]), \
            causal_rmse(log, fixed_tunings[0], args.lag_s, idx), causal_rmse(log, None, args.lag_s, idx)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="random3d,turntable,reversal")
    ap.add_argument("--duration-s", type=float, default=10.0)
    ap.add_argument("--rate-hz", type=float, default=500.0)
    ap.add_argument("--half-edge-m", type=float, default=0.025, help="cube half edge [m] (0.025: the 5 cm cube)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--lag-s", type=float, default=0.2)
    ap.add_argument("--tune-window-s", type=float, default=FixedLagEstimator.tune_window_s)
    ap.add_argument("--causal-points", type=int, default=0,
                    help="times of the streamed part at which to solve the causal batch problem (0: skip)")
    args = ap.parse_args(argv)
    print(f"cube half edge {args.half_edge_m:g} m, {args.rate_hz:g} Hz, {args.duration_s:g} s, seed {args.seed}, "
          f"lag {args.lag_s:g} s, tuning stretch {args.tune_window_s:g} s")
    head = ("| scenario | batch ω RMSE | fixed-lag | ratio | streamed part: batch | fixed-lag | ratio | "
            "flipped, all (batch) | flipped, abs(ω) > 0.1 | time batch / fixed-lag |")
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    rows = []
    for scenario in args.scenarios.split(","):
        r = run(scenario.strip(), args)
        rows.append(r)
        print(f"| {r['scenario']} | {r['batch']:.4f} | {r['fixed']:.4f} | {r['fixed'] / r['batch']:.2f} | "
              f"{r['batch_streamed']:.4f} | {r['fixed_streamed']:.4f} | {r['fixed_streamed'] / r['batch_streamed']:.2f} | "
              f"{r['flipped_all']:.4f} ({r['flipped_all_batch']:.4f}) | {r['flipped_share']:.4f} | "
              f"{r['time_batch_s']:.1f} s / {r['time_fixed_s']:.1f} s |", flush=True)
    if any("causal_points" in r for r in rows):
        print(f"\nAt {args.causal_points} times of the streamed part (ω RMSE): batch on the whole log | fixed-lag | "
              "batch on the data up to t + lag (fixed-lag's densities) | the same, choosing its own model")
        for r in rows:
            if "causal_points" in r:
                b, f, c, c2 = r["causal_points"]
                print(f"| {r['scenario']} | {b:.4f} | {f:.4f} | {c:.4f} | {c2:.4f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
