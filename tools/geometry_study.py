#!/usr/bin/env python3
"""ω accuracy of the methods as an array degenerates from a cube to a plane to a line.

The four triads of the 5 cm cube (alternate corners, half edge 5 cm, 0.07 m/s²) are squeezed along z by a factor ε
(ε = 1 the cube, ε = 0 a 10 cm square) and then, in the plane, along y by a factor η (η → 0: the triads close in on
the x axis, η = 0: on one line); plus all four at one point and the MIMU4444 board (eight triads on a 19 mm square,
±1 mm off its plane, 0.05 m/s²). Each layout sees the same random3d motion (seed 1, 500 Hz); for each method the
RMSE of the ω error norm over the log [rad/s] per seed against the per-sample Cramér-Rao bound (gfimu.crb, RMS of
√trace Cov(ω) along the true ω), the rank of S, the condition number of the unit-free linear block [f, ω̇]
(SensorArray.linear_condition_number) and that of the equations left for ω once f and ω̇ are eliminated
(SensorArray.omega_condition_number). The methods run without the geometry rule (it is switched off for the
study) so that the table shows what they would give; the column "rule" shows what the rule decides.

    python tools/geometry_study.py [--duration-s 5] [--methods inversion,ml,smoother]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gfimu.array import Accelerometer, SensorArray, cube_array, mimu4444_array  # noqa: E402
from gfimu.crb import crb_for_motion  # noqa: E402
from gfimu.methods import make_estimator  # noqa: E402
from gfimu.simulate import simulate  # noqa: E402


def squeezed(array: SensorArray, factors, name: str) -> SensorArray:
    accs = [Accelerometer(a.name, a.position_m * np.asarray(factors, float), noise_std_mps2=a.noise_std_mps2)
            for a in array.accelerometers]
    return SensorArray(tuple(accs), name)


def layouts() -> list[tuple[str, SensorArray]]:
    cube = cube_array()
    out = [(f"cube, z x {eps:g}", squeezed(cube, (1, 1, eps), "flat")) for eps in (1.0, 0.1, 0.01, 0.001, 0.0)]
    out += [(f"cube, y and z x {eta:g}", squeezed(cube, (1, eta, eta), "line")) for eta in
            (0.3, 0.1, 0.03, 0.01, 0.003, 0.001, 0.0)]
    out.append(("cube, one point", squeezed(cube, (0, 0, 0), "point")))
    board = mimu4444_array()
    out.append(("MIMU4444 board", board))
    out.append(("MIMU4444 board, z x 0", squeezed(board, (1, 1, 0), "flat board")))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=5.0, help="log length [s] (default 5 s)")
    ap.add_argument("--methods", default="inversion,ml,smoother", help="methods (default inversion,ml,smoother)")
    ap.add_argument("--seeds", default="1,2", help="motion seeds, comma-separated (default 1,2)")
    args = ap.parse_args(argv)
    methods = args.methods.split(",")
    rule = SensorArray.geometry_reason
    seeds = [int(s) for s in args.seeds.split(",")]
    print(f"random3d, seeds {args.seeds}, 500 Hz, {args.duration_s:g} s; ω RMSE [rad/s] per seed (largest RMSE / "
          "bound); 'refused': the method's own check, without the geometry rule\n")
    print("| layout | rank S | cond [f, ω̇] | cond ω | bound [rad/s] | " + " | ".join(methods) + " | rule (per-sample / smoothers) |")
    print("|---|---|---|---|---|" + "---|" * len(methods) + "---|")
    for name, array in layouts():
        decision = ["refused" if rule(array, several_solutions=k) else "accepted" for k in (False, True)]
        SensorArray.geometry_reason = lambda self, *a, **k: None  # measure without the rule
        try:
            logs = [simulate("random3d", array=array, duration_s=args.duration_s, seed=seed) for seed in seeds]
            bounds = []
            for log in logs:
                try:
                    bounds.append(crb_for_motion(array, log.truth).rmse_bound_omega())
                except ValueError:
                    bounds.append(float("inf"))
            bound = float(np.sqrt(np.mean(np.square(bounds))))
            cells = []
            for m in methods:
                est = make_estimator(m)
                if est.applicable(array):
                    cells.append("refused")
                    continue
                rmses = []
                t0 = time.perf_counter()
                for log in logs:
                    try:
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            w = est.estimate(log).motion.omega_b_radps
                        err = w - log.truth.omega_b_radps
                        rmses.append(float(np.sqrt(np.nanmean(np.sum(err**2, axis=1)))))
                    except Exception as exc:  # noqa: BLE001 - the table records a failure
                        rmses.append(f"failed ({type(exc).__name__})")
                text = " / ".join(r if isinstance(r, str) else f"{r:.3g}" for r in rmses)
                numbers = [r for r in rmses if not isinstance(r, str)]
                if numbers and np.isfinite(bound) and bound > 0:
                    text += f" ({max(numbers) / bound:.2g})"
                cells.append(text)
                print(f"  {name} {m}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        finally:
            SensorArray.geometry_reason = rule
        cond = array.linear_condition_number()
        print(f"| {name} | {array.rank()} | {cond:.3g} | {array.omega_condition_number():.3g} | {bound:.3g} | " + " | ".join(cells) + " | "
              + " / ".join(decision) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
