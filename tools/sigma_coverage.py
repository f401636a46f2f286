#!/usr/bin/env python3
"""Does σ mean what it says? The smoothers' ω σ against the truth, per regime.

For each cell (the regime matrix's cells of tools/regime_matrix.py, and cells whose readings disagree
with the model in ways array.toml does not state: noise above the stated level, a slowly varying
error per axis as a real array's misalignment and scale errors give), the batch smoother and the
fixed-lag smoother run with σ, and the table gives per axis the share of samples with |error| < 1σ
(Gaussian: 68.3 %) and < 2σ (95.4 %), and the mean NEES (3 when σ is right), for the σ the smoothers
report ("scaled": by the readings' own misfit, :mod:`gfimu.smoother.solve.sigma_scale`) and for the white-noise
σ before that scaling ("white", the earlier behaviour). The target: < 1σ within 60-76 %, < 2σ within
90-98 % on every axis.

MIMU4444 recordings given as arguments (``data.bin``) are converted with ``gfimu convert mimu4444`` and
scored as ``gfimu evaluate LOG EST --moving-threshold-radps 2`` scores them: against the mean of the
board's gyros, on the rows whose reference is valid and turns faster than 2 rad/s.

    python3 tools/sigma_coverage.py [--cells PATTERN] [--methods smoother,fixed-lag] [--no-cells] [data.bin ...]

Noise-free cells are left out (the errors there are rounding, σ ~ 0), and cells over 10,000 samples (time).
A run that fails prints its error in the table.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import regime_matrix as rm  # noqa: E402
from gfimu import io as gio  # noqa: E402
from gfimu.evaluation import sigma_metrics  # noqa: E402


@dataclass(frozen=True)
class MisfitCell:
    """A regime-matrix cell plus an error the model does not state: on every axis, AR(1) noise of std
    ``misfit_mps2`` and correlation ``misfit_corr`` from one sample to the next; each sensor's position
    in array.toml off its true one by a normal error of std ``position_error_m`` per coordinate (the
    readings are those of the true positions: a misfit that grows with ω̇ and ω²)."""

    cell: rm.Cell
    misfit_mps2: float = 0.0
    misfit_corr: float = 0.0
    position_error_m: float = 0.0

    @property
    def name(self) -> str:
        return self.cell.name


def ar1(rng, shape, std: float, corr: float) -> np.ndarray:
    out = np.empty(shape)
    e = rng.standard_normal(shape) * std * np.sqrt(1.0 - corr * corr)
    out[0] = rng.standard_normal(shape[1:]) * std
    for i in range(1, shape[0]):
        out[i] = corr * out[i - 1] + e[i]
    return out


CELLS = tuple(MisfitCell(c) for c in rm.CELLS if c.noise_mps2 > 0 and not c.foreign
              and c.duration_s * c.rate_hz <= 10000) + (
    MisfitCell(rm.Cell("unstated-noise-x5", "handheld", 200.0, 10.0, 0.025, 0.05, 0.01)),
    MisfitCell(rm.Cell("misfit-ar0.95-200Hz", "handheld", 200.0, 10.0, 0.025, 0.01, 0.01), 0.05, 0.95),
    MisfitCell(rm.Cell("misfit-ar0.99-62Hz-0.1m", "handheld", 62.5, 30.0, 0.1, 0.05, 0.05), 0.3, 0.99),
    MisfitCell(rm.Cell("positions-2mm-off-500Hz", "handheld", 500.0, 10.0, 0.05, 0.01, 0.01), position_error_m=0.002),
)


def build(mc: MisfitCell, folder: Path):
    path, omega = rm.build_log(mc.cell, folder)
    if mc.misfit_mps2 > 0 or mc.position_error_m > 0:
        log = gio.read_log(path)
        rng = np.random.default_rng(mc.cell.seed + 100)
        if mc.misfit_mps2 > 0:
            log = replace(log, accel_mps2=log.accel_mps2 + ar1(rng, log.accel_mps2.shape, mc.misfit_mps2,
                                                               mc.misfit_corr))
        if mc.position_error_m > 0:
            log = replace(log, array=log.array.with_accelerometers(
                replace(a, position_m=np.asarray(a.position_m) + rng.normal(0.0, mc.position_error_m, 3))
                for a in log.array.accelerometers))
        path = folder / f"{mc.name}-misfit"
        gio.write_log(log, path)
    return path, omega


MOVING_RADPS = 2.0


def coverage(log, omega_true: np.ndarray, method: str, white: bool, valid: np.ndarray | None = None) -> dict:
    """σ metrics of ``method``'s ω on ``log`` (screened) against ``omega_true`` over the rows ``valid``;
    ``white``: without the scaling."""
    from gfimu.methods import make_estimator
    from gfimu.smoother.batch import engine as batch
    from gfimu.smoother.stream import fixed_lag

    saved = batch._calibrates_sigma, fixed_lag.calibrates_stream
    if white:
        batch._calibrates_sigma = fixed_lag.calibrates_stream = lambda *a: False
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            motion = make_estimator(method, compute_sigma=True).estimate(log).motion
    finally:
        batch._calibrates_sigma, fixed_lag.calibrates_stream = saved
    rows = np.ones(len(log), bool) if valid is None else valid
    return sigma_metrics((motion.omega_b_radps - omega_true)[rows], motion.sigma["omega_b_radps"][rows])


def row(name: str, method: str, kind: str, m: dict) -> str:
    cov = m["coverage_1sigma"] + m["coverage_2sigma"]
    ok = all(0.60 <= v <= 0.76 for v in m["coverage_1sigma"]) and all(0.90 <= v <= 0.98 for v in m["coverage_2sigma"])
    return (f"| {name} | {method} | {kind} | " + " | ".join(f"{100 * v:.0f} %" for v in cov)
            + f" | {m['mean_nees']:.3g} | {'yes' if ok else 'no'} |")


def rows_for(name: str, log, omega_true, methods, valid=None) -> None:
    for method in methods:
        for white in (True, False):
            kind = "white" if white else "scaled"
            try:
                print(row(name, method, kind, coverage(log, omega_true, method, white, valid)), flush=True)
            except Exception as exc:  # reported, not fatal to the table
                print(f"| {name} | {method} | {kind} | error: {type(exc).__name__}: {exc} ||||||||", flush=True)


def main(argv=None) -> int:
    from gfimu.readings import screen_log

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recordings", nargs="*", type=Path, help="MIMU4444 data.bin files")
    ap.add_argument("--cells", default=None, help="comma-separated names or glob patterns")
    ap.add_argument("--no-cells", action="store_true", help="the recordings only")
    ap.add_argument("--methods", default="smoother,fixed-lag")
    args = ap.parse_args(argv)
    methods = args.methods.split(",")
    cells = [] if args.no_cells else list(CELLS)
    if args.cells:
        import fnmatch

        pats = [p.strip() for p in args.cells.split(",") if p.strip()]
        cells = [c for c in cells if any(fnmatch.fnmatch(c.name, p if any(ch in p for ch in "*?[") else f"*{p}*")
                                         for p in pats)]
    print("| log | method | σ | < 1σ x | < 1σ y | < 1σ z | < 2σ x | < 2σ y | < 2σ z | mean NEES | in target |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for mc in cells:
            path, omega = build(mc, Path(tmp))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                log, _ = screen_log(gio.read_log(path, truth=False))
            rows_for(mc.name, log, omega, methods)
        for rec in args.recordings:
            name = f"{rec.parent.name} (MIMU4444)"
            out = Path(tmp) / rec.parent.name
            done = subprocess.run([sys.executable, "-m", "gfimu", "convert", "mimu4444", str(rec), "--out", str(out)],
                                  capture_output=True, text=True)
            if done.returncode != 0:
                print(f"| {name} | | | convert failed: {done.stderr.strip()} ||||||||")
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                log = gio.read_log(out)
                reference, invalid = log.reference, log.invalid_reference
                log, _ = screen_log(log)
            valid = np.ones(len(log), bool) if invalid is None else ~np.asarray(invalid, bool)
            valid &= np.linalg.norm(reference.omega_b_radps, axis=1) > MOVING_RADPS
            rows_for(name, log, reference.omega_b_radps, methods, valid)
    print(f"\nShares of samples with |ω error| < 1σ and < 2σ per axis (a Gaussian error of that σ: 68.3 %, 95.4 %); "
          "mean NEES Σ_j (e_j/σ_j)² (3 when σ is right); in target: every axis within 60-76 % and 90-98 %. "
          "white: the σ of the white-noise model alone; scaled: the σ the smoothers report, scaled by the "
          f"readings' own misfit. Recordings: moving samples (|ω_ref| > {MOVING_RADPS:g} rad/s, reference valid) "
          "against the mean of the board's gyros.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
