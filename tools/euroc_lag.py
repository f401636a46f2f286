#!/usr/bin/env python3
"""The fixed-lag smoother on the demo's EuRoC log, against ``imm`` and the batch smoother.

The log is ``gfimu demo``'s second one: the real EuRoC V1_01_easy motion (shipped with GTSAM)
through the default cube array, 500 Hz, 10 s, seed 0 (:func:`gfimu.cli.demo.demo_logs`). Each
variant's ω error is printed as the RMSE per axis, the RMS over the axes (``axes``) and the RMSE of
the error norm (``norm``, the demo's ‖ω‖ column), plus the share of that error's power below 2 Hz
(a slow bias or a fast noise). The variants: ``imm`` (starts at rest by default), the batch smoother,
the fixed-lag smoother at each lag of ``--lags``, and with ``--no-still-start`` also the fixed-lag
smoother without its still start (``FixedLagSmoother._still_start`` giving None: the start from the
batch initialiser's ω, held until its sign is decided), to show what the start prior ω = 0 does.

    python3 tools/euroc_lag.py                    # imm, smoother, fixed-lag at 0.2 s
    python3 tools/euroc_lag.py --lags 0.2,1,3 --no-still-start
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
import types
from pathlib import Path
from unittest import mock

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def euroc_log(duration_s: float, rate_hz: float, seed: int):
    from gfimu.cli.demo import demo_logs
    from gfimu.simulate import defaults

    args = types.SimpleNamespace(half_edge_m=defaults.CUBE_HALF_EDGE_M, noise_std_mps2=defaults.ACCEL_NOISE_STD_MPS2,
                                 rate_hz=rate_hz, duration_s=duration_s, seed=seed, no_progress=True)
    for title, log in demo_logs(args):
        if title.startswith("euroc"):
            return log
    raise SystemExit("the demo has no euroc log")


def scores(omega: np.ndarray, truth: np.ndarray, rate_hz: float) -> dict:
    e = omega - truth
    per_axis = np.sqrt(np.mean(e * e, axis=0))
    spec = np.abs(np.fft.rfft(e - e.mean(axis=0), axis=0)) ** 2
    freq = np.fft.rfftfreq(len(e), 1.0 / rate_hz)
    slow = float(spec[freq < 2.0].sum() / max(spec.sum(), 1e-300))
    return {"x": per_axis[0], "y": per_axis[1], "z": per_axis[2], "axes": float(np.sqrt(np.mean(per_axis ** 2))),
            "norm": float(np.sqrt(np.mean(np.sum(e * e, axis=1)))), "slow": slow}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lags", default="0.2", help="comma-separated lags of the fixed-lag smoother [s] (default 0.2)")
    ap.add_argument("--duration-s", type=float, default=10.0)
    ap.add_argument("--rate-hz", type=float, default=500.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-still-start", action="store_true",
                    help="also run the fixed-lag smoother with still_start=False")
    ap.add_argument("--no-batch", action="store_true", help="skip the batch smoother")
    args = ap.parse_args(argv)
    from gfimu.methods import make_estimator

    log = euroc_log(args.duration_s, args.rate_hz, args.seed)
    truth = log.truth.omega_b_radps
    variants = [("imm", "imm", {})]
    if not args.no_batch:
        variants.append(("smoother", "smoother", {}))
    for lag in (float(v) for v in args.lags.split(",") if v.strip()):
        variants.append((f"fixed-lag {lag:g} s", "fixed-lag", {"lag_s": lag}))
        if args.no_still_start:
            variants.append((f"fixed-lag {lag:g} s, no still start", "fixed-lag", {"lag_s": lag, "_no_still": True}))
    print(f"EuRoC demo log: {len(log)} samples, {args.rate_hz:g} Hz, {args.duration_s:g} s, seed {args.seed}; ω RMSE [rad/s]\n")
    print("| variant | x | y | z | axes | norm | power < 2 Hz | time [s] |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, method, opts in variants:
        no_still = opts.pop("_no_still", False)
        t0 = time.perf_counter()
        with contextlib.ExitStack() as stack:
            if no_still:
                from gfimu.smoother.stream.fixed_lag import FixedLagSmoother

                stack.enter_context(mock.patch.object(FixedLagSmoother, "_still_start", lambda self, *a: None))
            est = make_estimator(method, **opts).estimate(log)
        dt = time.perf_counter() - t0
        s = scores(np.asarray(est.motion.omega_b_radps), truth, args.rate_hz)
        print(f"| {name} | {s['x']:.4f} | {s['y']:.4f} | {s['z']:.4f} | {s['axes']:.4f} | {s['norm']:.4f} | "
              f"{100 * s['slow']:.1f} % | {dt:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
