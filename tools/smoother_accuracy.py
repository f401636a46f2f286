#!/usr/bin/env python3
"""Accuracy of the batch smoother against the per-sample methods on simulated logs.

Cube array of half edge 0.025 m (5 cm edge), 0.07 m/s² per axis, 500 Hz;
an arbitrary array (five triads at random positions within ±3 cm, each
rotated at random); the near-planar MIMU4444 layout; McGinnis, Perkins & King 2012's block in
free flight (one triad, 1 kHz). Prints ω RMSE (norm), share of sign errors
(|ω| > 0.1 rad/s), the gain over the best per-sample method, and the
smoother's efficiency (RMSE / bound of its own graph, with the process noise it
chose from the data, linearised at the truth) and that choice (jerk density
per body axis x, y, z, and the frequency of the oscillator model where chosen)
for the first window.

    python3 tools/smoother_accuracy.py [--duration-s 10] [--half-edge-m 0.025] [--no-tuning] [--json smoother_accuracy.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gfimu.array import SensorArray, cube_array, mimu4444_array, random_array  # noqa: E402
from gfimu.methods import make_estimator  # noqa: E402
from gfimu.simulate import simulate  # noqa: E402
from gfimu.smoother.batch.engine import BatchSmootherEstimator  # noqa: E402
from gfimu.smoother.batch.bound import efficiency, smoother_bound  # noqa: E402
from gfimu.smoother.solve.initialise import initial_states  # noqa: E402

PER_SAMPLE = ("inversion", "integration", "imm", "ml", "free-flight")


def omega_errors(motion, truth):
    e = motion.omega_b_radps - truth.omega_b_radps
    w = truth.omega_b_radps
    big = np.abs(w) > 0.1
    return {
        "rmse_radps": float(np.sqrt(np.mean(np.sum(e**2, axis=1)))),
        "relative_rms": float(np.sqrt(np.mean(np.sum(e**2, axis=1)) / np.mean(np.sum(w**2, axis=1)))),
        "sign_errors": float(np.mean(np.sign(motion.omega_b_radps[big]) != np.sign(w[big]))),
    }


def band_limited_wiener_bound(array: SensorArray, omega_b_radps: np.ndarray, rate_hz: float,
                              band_hz: tuple[float, float] = (0.1, 2.0)) -> tuple[np.ndarray, float]:
    """ω RMSE (per axis, norm) of the Wiener smoother that knows the motion's spectrum: each ω
    component a stationary process with a flat spectrum over ``band_hz`` (random3d draws its sines
    uniformly there) and the RMS of ``omega_b_radps``; measurements of ω and ω̇ per sample with the
    time-averaged Fisher information of the array (Ho & Lin 2009's model, f known to the estimator and
    the other axes too: optimistic). MSE = ∫ S N / (S + N) df with the noise spectrum of ω
    ``N(f) = h / (I_ω + I_ω̇ (2π f)²)``. No estimator that uses only that knowledge does better."""
    from gfimu.crb import axis_noise_std, fisher_information

    J = fisher_information(array.structure_matrix(), axis_noise_std(array), omega_b_radps).mean(axis=0)
    h = 1.0 / rate_hz
    f = np.linspace(-rate_hz / 2, rate_hz / 2, 400001)
    df = f[1] - f[0]
    lo, hi = band_hz
    mse = np.zeros(3)
    for a in range(3):
        var = float(np.var(omega_b_radps[:, a]))
        S = np.where((np.abs(f) > lo) & (np.abs(f) < hi), var / (2 * (hi - lo)), 0.0)
        N = h / (J[6 + a, 6 + a] + J[3 + a, 3 + a] * (2 * np.pi * f) ** 2)
        mse[a] = np.sum(S * N / (S + N + 1e-300)) * df
    return np.sqrt(mse), float(np.sqrt(mse.sum()))


def arbitrary_array(seed: int = 7) -> SensorArray:
    return random_array(5, half_extent_m=0.03, noise_std_mps2=0.07, seed=seed)


def cases(duration_s: float, half_edge_m: float = 0.025):
    cube = cube_array(half_edge_m, 0.07)
    for sc in ("random3d", "turntable", "reversal"):
        yield sc, simulate(sc, cube, rate_hz=500.0, duration_s=duration_s, seed=1), {}
    yield "random3d, arbitrary array", simulate("random3d", arbitrary_array(), rate_hz=500.0, duration_s=duration_s, seed=1), {}
    yield "random3d, mimu4444", simulate("random3d", mimu4444_array(0.05), rate_hz=500.0, duration_s=duration_s, seed=1), {}
    for sc in ("freeflight-major", "freeflight-intermediate", "freeflight-minor"):
        yield sc, simulate(sc, seed=1, duration_s=min(duration_s, 2.0)), {"free_flight": True}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=10.0)
    ap.add_argument("--half-edge-m", type=float, default=0.025, help="cube half edge (0.025: 5 cm edge)")
    ap.add_argument("--no-tuning", action="store_true", help="fixed process densities (tune_process_noise=False)")
    ap.add_argument("--only-cube", action="store_true", help="only the three cube scenarios")
    ap.add_argument("--json", default="smoother_accuracy.json")
    args = ap.parse_args(argv)
    rows = []
    print(f"cube half edge {args.half_edge_m} m, {args.duration_s:g} s logs, process noise {'fixed' if args.no_tuning else 'chosen from the data'}\n")
    print("| case | best per-sample (ω RMSE rad/s) | smoother ω RMSE rad/s | gain | sign errors | rel. RMS (eq. 7) per-sample → smoother | RMSE / bound | initialisation ω RMSE, sign errors | jerk density x, y, z | oscillator x, y, z (Hz) | time s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for i, (name, log, opts) in enumerate(cases(args.duration_s, args.half_edge_m)):
        if args.only_cube and i >= 3:
            break
        per = {}
        for meth in PER_SAMPLE:
            est = make_estimator(meth)
            if est.applicable(log.array):
                continue
            try:
                per[meth] = omega_errors(est.estimate(log).motion, log.truth)
            except Exception as exc:  # a per-sample method failing is reported, not fatal
                per[meth] = {"error": str(exc)}
        ok = {k: v for k, v in per.items() if "rmse_radps" in v}
        best = min(ok, key=lambda k: ok[k]["rmse_radps"])
        if args.no_tuning:
            opts = dict(opts, tune_process_noise=False)
        smoother = BatchSmootherEstimator(**opts)
        t0 = time.perf_counter()
        run = smoother.estimate(log)
        elapsed = time.perf_counter() - t0
        m, tunings = run.motion, run.report.tunings
        err = omega_errors(m, log.truth)
        tuning = tunings[0] if tunings else None
        bound_groups = tuning.apply(smoother.model_groups) if tuning else smoother.model_groups
        eff = efficiency(m, log.truth, smoother_bound(log, bound_groups, smoother.batch)).ratio["omega_b_radps"]
        bound_model = bound_groups.model
        q = (bound_model.omega_dot_random_walk_radps2_per_sqrt_s * np.asarray(bound_model.process_axis_factors)
             if bound_model.motion_model == "jerk" else None)
        gain = ok[best]["rmse_radps"] / err["rmse_radps"]
        x0 = initial_states(log, smoother.model_groups)
        init = omega_errors(type(m)(log.timestamps_ns, omega_b_radps=x0[:, :3]), log.truth)
        rows.append({"case": name, "per_sample": per, "best_per_sample": best, "smoother": err, "gain": gain,
                     "efficiency": eff, "initialisation": init, "time_s": elapsed, "samples": len(log),
                     "tuning": [t.as_dict() for t in tunings]})
        print(f"| {name} | {best} {ok[best]['rmse_radps']:.4g} | {err['rmse_radps']:.4g} | {gain:.1f}x | "
              f"{err['sign_errors']:.2%} (best per-sample {ok[best]['sign_errors']:.1%}) | "
              f"{ok[best]['relative_rms']:.2e} → {err['relative_rms']:.2e} | {eff:.2f} | {init['rmse_radps']:.3g}, {init['sign_errors']:.2%} | "
              f"{'-' if q is None else ', '.join(f'{v:.3g}' for v in q)} | "
              f"{', '.join(f'{v:.4g}' if v else '-' for v in bound_model.process_axis_frequencies_hz)} | {elapsed:.1f} |", flush=True)
    cube = cube_array(args.half_edge_m, 0.07)
    log = simulate("random3d", cube, rate_hz=500.0, duration_s=args.duration_s, seed=1)
    per_axis, norm = band_limited_wiener_bound(cube, log.truth.omega_b_radps, 500.0)
    print(f"\nrandom3d on the cube: ω RMSE of the Wiener smoother knowing the motion's band-limited spectrum "
          f"(0.1-2 Hz, flat): {norm:.4f} rad/s (per axis {', '.join(f'{v:.4f}' for v in per_axis)})")
    rows.append({"case": "random3d band-limited Wiener bound", "rmse_radps": norm, "per_axis_radps": per_axis.tolist()})
    Path(args.json).write_text(json.dumps(rows, indent=2))
    print(f"\nwritten {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
