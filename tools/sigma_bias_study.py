#!/usr/bin/env python3
"""Why σ is too small on two cells of tools/sigma_coverage.py: the figures behind docs/uncertainty.md.

1. **foreign-ff-impact-4kHz-noise** (tools/foreign_sim.py through ``gfimu convert csv --map``): its
   readings are in g of 9.8 m/s² read as g of 9.80665, a common gain k = 9.80665 / 9.8 that scales f,
   ω̇ and q(ω) alike; the estimate then carries ω (√k − 1). Printed per stretch of the log: the mean
   error against (√k − 1) ω; the coverage of the errors less that bias; the same log with its readings
   in the file's own g (× 9.8 / 9.80665): ω RMSE and coverage; |f̂| while the body rests on its
   support (k g0 where the readings carry the gain).
2. **20kHz-0.5s**: a short log whose error is nearly constant over it. Printed, over ``--draws``
   independent draws of the cell (seeds 1 … N) pooled per stretch of time: the coverage and NEES, for
   the log as it is and for the same log reversed in time (readings in reverse order; ω(t) of the
   reversed log is −ω(T − t)), each sample scored in its original time: a start transient of a
   smoother shows at the start of either log, a property of the motion at the same samples in both.

    python3 tools/sigma_bias_study.py [--draws 16] [--methods smoother,fixed-lag] [--only foreign|short]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import foreign_sim  # noqa: E402
import sigma_coverage as sc  # noqa: E402


def _cell(name: str) -> sc.MisfitCell:
    return next(c for c in sc.CELLS if c.name == name)


def _shares(z: np.ndarray) -> str:
    z = z.reshape(-1, 3)
    one, two = (np.abs(z) < 1).mean(axis=0), (np.abs(z) < 2).mean(axis=0)
    return (f"1σ {'/'.join(f'{100 * v:.0f}' for v in one)} %, 2σ {'/'.join(f'{100 * v:.0f}' for v in two)} %, "
            f"NEES {np.mean(np.sum(z * z, axis=-1)):.2f}")


def foreign(methods, folder: Path) -> None:
    k = foreign_sim.G0 / foreign_sim.FILE_G
    log, omega = sc.read_cell(_cell("foreign-ff-impact-4kHz-noise"), folder)
    t = (log.timestamps_ns - log.timestamps_ns[0]) * 1e-9
    bias = (np.sqrt(k) - 1.0) * omega
    cfg = foreign_sim.Config()
    contact = t > cfg.impact_time_s + cfg.impact_duration_s
    print(f"## foreign-ff-impact-4kHz-noise: gain k = {k:.6f}, √k − 1 = {np.sqrt(k) - 1:.3e}")
    edges = [0.0, 0.1, 0.2, 0.3, cfg.impact_time_s, cfg.impact_time_s + 0.01, 0.5, 0.7, 1.0, t[-1] + 1e-9]
    rescaled = replace(log, accel_mps2=log.accel_mps2 / k)
    for method in methods:
        motion, _ = sc.run_both(log, method)
        err, sd = motion.omega_b_radps - omega, motion.sigma["omega_b_radps"]
        print(f"\n{method}: as converted: ω RMSE {np.round(np.sqrt(np.mean(err ** 2, axis=0)) * 1e3, 2)} mrad/s; {_shares(err / sd)}")
        print("stretch [s] | mean error [mrad/s] | (√k − 1) ω [mrad/s] | less that bias")
        for a, b in zip(edges[:-1], edges[1:]):
            s = (t >= a) & (t < b)
            print(f"{a:.3f}-{min(b, t[-1]):.3f} | {np.round(err[s].mean(axis=0) * 1e3, 2)} | "
                  f"{np.round(bias[s].mean(axis=0) * 1e3, 2)} | {np.round((err - bias)[s].mean(axis=0) * 1e3, 2)}")
        print(f"less the bias (√k − 1) ω: {_shares((err - bias) / sd)}")
        f = np.linalg.norm(motion.specific_force_b_mps2[contact], axis=1)
        print(f"|f̂| on the support: {f.mean():.5f} ± {f.std():.5f} m/s² (k g0 = {k * foreign_sim.G0:.5f}, "
              f"g0 = {foreign_sim.G0})")
        motion, _ = sc.run_both(rescaled, method)
        err, sd = motion.omega_b_radps - omega, motion.sigma["omega_b_radps"]
        print(f"readings × 9.8/9.80665: ω RMSE {np.round(np.sqrt(np.mean(err ** 2, axis=0)) * 1e3, 2)} mrad/s, mean error "
              f"{np.round(err.mean(axis=0) * 1e3, 2)} mrad/s; {_shares(err / sd)}")


def short(methods, draws: int, folder: Path) -> None:
    mc = _cell("20kHz-0.5s")
    print(f"\n## {mc.name}: {draws} draws pooled, forward and reversed in time")
    z = {(m, d): [] for m in methods for d in ("forward", "reversed")}
    for i, cell in enumerate(sc.draws(mc, draws)):
        sub = folder / f"short{i}"
        sub.mkdir(parents=True, exist_ok=True)
        log, omega = sc.read_cell(cell, sub)
        back = replace(log, accel_mps2=log.accel_mps2[::-1].copy())
        for method in methods:
            motion, _ = sc.run_both(log, method)
            z[method, "forward"].append((motion.omega_b_radps - omega) / motion.sigma["omega_b_radps"])
            motion, _ = sc.run_both(back, method)
            z[method, "reversed"].append((-motion.omega_b_radps[::-1] - omega) / motion.sigma["omega_b_radps"][::-1])
        del log, back
    t = np.arange(len(omega)) / mc.cell.rate_hz
    edges = [0.0, 0.1, 0.2, 0.3, 0.4, t[-1] + 1e-9]
    for (method, direction), parts in z.items():
        Z = np.stack(parts)
        print(f"{method}, {direction}: all {_shares(Z)}")
        for a, b in zip(edges[:-1], edges[1:]):
            s = (t >= a) & (t < b)
            print(f"  {a:.1f}-{min(b, t[-1]):.1f} s (original time): {_shares(Z[:, s])}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=16)
    ap.add_argument("--methods", default="smoother,fixed-lag")
    ap.add_argument("--only", choices=("foreign", "short"), default=None)
    args = ap.parse_args(argv)
    methods = args.methods.split(",")
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if args.only in (None, "foreign"):
            foreign(methods, Path(tmp))
        if args.only in (None, "short"):
            short(methods, args.draws, Path(tmp))
    return 0


if __name__ == "__main__":
    sys.exit(main())
