#!/usr/bin/env python3
"""Does σ mean what it says? The smoothers' ω σ against the truth, per regime.

For each cell (every cell of the regime matrix, tools/regime_matrix.py, with noise, and cells whose
readings disagree with the model in ways array.toml does not state, built from the physics: noise above
the stated level, a slowly varying error per axis, sensor positions off, per-axis gains off, each sensor
shaken by its own mount, a MIMU-like mix of them), the batch smoother and the
fixed-lag smoother run with σ, and the table gives per axis the share of samples with |error| < 1σ
(Gaussian: 68.3 %) and < 2σ (95.4 %), and the mean NEES (3 when σ is right), for the σ the smoothers
report ("scaled": by the readings' own misfit and the path's own trapezoid level, and widened by a common
gain the log's stretches of gravity alone show, :mod:`gfimu.smoother.solve.sigma_scale`) and for the white-noise
σ before that scaling ("white", the earlier behaviour). The target: < 1σ within 60-76 %, < 2σ within
90-98 % on every axis.

MIMU4444 recordings given as arguments (``data.bin``) are converted with ``gfimu convert mimu4444`` and
scored as ``gfimu evaluate LOG EST --moving-threshold-radps 2`` scores them: against the mean of the
board's gyros, on the rows whose reference is valid and turns faster than 2 rad/s.

    python3 tools/sigma_coverage.py [--cells PATTERN] [--methods smoother,fixed-lag] [--no-cells] [--all] [--draws N|auto] [data.bin ...]

Noise-free cells are left out (the errors there are rounding, σ ~ 0), and cells over 10,000 samples
unless ``--all`` (time). Each row's ± is the spread of its 1σ share from the count of independent
samples: N / (1 + 2 Σ ρ_k) with ρ_k the autocorrelation of the indicator |e| < σ (summed while
positive), a binomial std √(c (1 − c) / N_eff) of share c, the largest over the axes. Recordings give a
third row: the scaled σ against the reference lined up in time (the offset that best lines |ω| up, as
``gfimu evaluate --estimate-time-offset``: the board's gyros lag its accelerometers by about 1.3 ms, an
error of the reference, not of the estimate).
Each simulated cell is drawn again (seeds 1, 2, … of its motion, noise and misfit), its draws pooled, until
every method's scaled σ has :data:`MIN_INDEPENDENT` independent samples on every axis, or
:data:`MAX_DRAWS` draws: a short cell's error is correlated over most of its length (20kHz-0.5s: a few
independent samples per axis, ± 26 %), so one draw cannot tell a σ that is right from one that is not; the
pooled draws hold the sum of their independent samples, and ± shrinks as 1/√N. A cell with sensor positions or
gains off makes one fixed calibration error per draw, which the count of a draw's samples does not see: it is
drawn :data:`MAX_DRAWS` times. ``--draws N`` pools exactly N draws. The foreign cells' draws vary the triads'
layout and the noise only: the motion, and with it the bias of their unstated gain, is the same in every
draw, which ± does not count. A run that fails prints its error in the table.
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
    readings are those of the true positions: a misfit that grows with ω̇ and ω²); each axis' gain off 1 by
    a normal error of std ``scale_error`` (a misfit proportional to the reading); each sensor shaken by its
    own mount at ``vibration_hz`` (a sine of random phase and direction, amplitude ``vibration_mps2``, not a
    motion of the body: a misfit that the rigid-body equation cannot explain)."""

    cell: rm.Cell
    misfit_mps2: float = 0.0
    misfit_corr: float = 0.0
    position_error_m: float = 0.0
    scale_error: float = 0.0
    vibration_mps2: float = 0.0
    vibration_hz: float = 0.0

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


LONG_SAMPLES = 10000
"""Cells of more samples run with ``--all`` only (time)."""
MIN_INDEPENDENT = 100
"""Independent samples per axis a simulated cell's pooled draws reach before the drawing stops (``--draws auto``):
the 1σ share of a right σ then scatters by at most √(0.68 · 0.32 / 100) ≈ 5 %."""
MAX_DRAWS = 5
"""... or this many draws (time)."""

MATRIX = tuple(MisfitCell(c) for c in rm.CELLS if c.noise_mps2 > 0)
CELLS = MATRIX + (
    MisfitCell(rm.Cell("unstated-noise-x5", "handheld", 200.0, 10.0, 0.025, 0.05, 0.01)),
    MisfitCell(rm.Cell("misfit-ar0.95-200Hz", "handheld", 200.0, 10.0, 0.025, 0.01, 0.01), 0.05, 0.95),
    MisfitCell(rm.Cell("misfit-ar0.99-62Hz-0.1m", "handheld", 62.5, 30.0, 0.1, 0.05, 0.05), 0.3, 0.99),
    MisfitCell(rm.Cell("positions-2mm-off-500Hz", "handheld", 500.0, 10.0, 0.05, 0.01, 0.01), position_error_m=0.002),
    MisfitCell(rm.Cell("scale-1pc-200Hz", "handheld", 200.0, 10.0, 0.025, 0.01, 0.01), scale_error=0.01),
    MisfitCell(rm.Cell("vibration-37Hz-200Hz", "handheld", 200.0, 10.0, 0.025, 0.01, 0.01), vibration_mps2=0.05,
               vibration_hz=37.0),
    MisfitCell(rm.Cell("mimu-like-62Hz", "handheld", 62.5, 30.0, 0.03, 0.02, 0.02,
                       motion_options={"omega_rms_radps": 4.0}), position_error_m=0.001, scale_error=0.005),
)


def build(mc: MisfitCell, folder: Path):
    path, omega = rm.build_log(mc.cell, folder)
    if mc.misfit_mps2 > 0 or mc.position_error_m > 0 or mc.scale_error > 0 or mc.vibration_mps2 > 0:
        log = gio.read_log(path)
        rng = np.random.default_rng(mc.cell.seed + 100)
        if mc.misfit_mps2 > 0:
            log = replace(log, accel_mps2=log.accel_mps2 + ar1(rng, log.accel_mps2.shape, mc.misfit_mps2,
                                                               mc.misfit_corr))
        if mc.position_error_m > 0:
            log = replace(log, array=log.array.with_accelerometers(
                replace(a, position_m=np.asarray(a.position_m) + rng.normal(0.0, mc.position_error_m, 3))
                for a in log.array.accelerometers))
        if mc.scale_error > 0:
            log = replace(log, accel_mps2=log.accel_mps2 * (1.0 + rng.normal(0.0, mc.scale_error, log.accel_mps2.shape[1])))
        if mc.vibration_mps2 > 0:
            t = (log.timestamps_ns - log.timestamps_ns[0]) * 1e-9
            m = log.accel_mps2.shape[1]
            phase = rng.uniform(0.0, 2 * np.pi, m // 3)
            shake = np.repeat(np.sin(2 * np.pi * mc.vibration_hz * t[:, None] + phase), 3, axis=1)
            direction = rng.normal(size=m)
            direction /= np.repeat(np.linalg.norm(direction.reshape(-1, 3), axis=1), 3)
            log = replace(log, accel_mps2=log.accel_mps2 + mc.vibration_mps2 * shake * direction)
        path = folder / f"{mc.name}-misfit"
        gio.write_log(log, path)
    return path, omega


MOVING_RADPS = 2.0


def moving_recording(rec: Path, folder: Path, seconds: float | None = None):
    """A MIMU4444 recording as σ is measured on it: converted into ``folder`` (its first ``seconds`` when
    given) and screened as ``gfimu estimate`` screens it; (log, reference, the rows whose reference is valid
    and turns faster than :data:`MOVING_RADPS`), or the converter's message (a str) where it failed."""
    from gfimu.readings import screen_log

    out = folder / rec.parent.name
    done = subprocess.run([sys.executable, "-m", "gfimu", "convert", "mimu4444", str(rec), "--out", str(out)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        return done.stderr.strip()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = gio.read_log(out)
        if seconds:
            log = log.select(slice(0, int(round(seconds * log.rate_hz))))
        reference, invalid = log.reference, log.invalid_reference
        log, _ = screen_log(log)
    valid = np.ones(len(log), bool) if invalid is None else ~np.asarray(invalid, bool)
    valid &= np.linalg.norm(reference.omega_b_radps, axis=1) > MOVING_RADPS
    return log, reference, valid


def run_both(log, method: str):
    """(motion, white σ of ω (N, 3)) of ``method`` on ``log`` (screened) in one run: the σ the smoother
    reports, and the one it had before the scaling (recorded where the scaling takes it in)."""
    from gfimu.methods import make_estimator
    from gfimu.smoother.batch import engine as batch
    from gfimu.smoother.solve import sigma_scale

    seen = []
    calibrated, scaled = batch.calibrated_sigma, sigma_scale.RunningSigmaScale.scaled

    def batch_in(array, accel, states, sd, *args, **kwargs):
        seen.append(np.array(sd[:, :3]))
        return calibrated(array, accel, states, sd, *args, **kwargs)

    def stream_in(self, accel, state, sd, noise, *args, **kwargs):
        seen.append(np.array(sd[:3])[None, :])
        return scaled(self, accel, state, sd, noise, *args, **kwargs)

    batch.calibrated_sigma, sigma_scale.RunningSigmaScale.scaled = batch_in, stream_in
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            motion = make_estimator(method, compute_sigma=True).estimate(log).motion
    finally:
        batch.calibrated_sigma, sigma_scale.RunningSigmaScale.scaled = calibrated, scaled
    reported = motion.sigma["omega_b_radps"]
    white = np.vstack(seen) if seen else reported  # not scaled (a gyroscope, self-calibration): the same σ
    if len(white) != len(reported):
        raise RuntimeError(f"{len(white)} white σ rows for {len(reported)} samples")
    return motion, white


def aligned(motion, sigma: np.ndarray, reference, valid: np.ndarray):
    """(ω, σ) of ``motion`` on ``reference``'s rows after the time offset that best lines |ω| up with it
    (:func:`gfimu.evaluation.estimate_time_offset_s`, as ``gfimu evaluate --estimate-time-offset``), and
    that offset [s]."""
    from gfimu.evaluation import estimate_time_offset_s

    offset = estimate_time_offset_s(motion, reference, valid)
    t = reference.timestamps_ns.astype(float)
    ts = motion.timestamps_ns + offset * 1e9
    interp = lambda v: np.column_stack([np.interp(t, ts, v[:, i], left=np.nan, right=np.nan) for i in range(3)])
    return interp(motion.omega_b_radps), interp(sigma), offset


def independent_counts(err: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """(axes, 2): per axis, the samples with |e| < σ and the effective count of independent samples
    N / (1 + 2 Σ ρ_k) (module docstring; NaN below 2 samples). An indicator that does not change over the
    draw shows no time over which it decorrelates: it counts as one independent sample."""
    ok = np.all(np.isfinite(err) & np.isfinite(sigma) & (sigma > 0), axis=1)
    out = np.full((err.shape[1], 2), np.nan)
    for j in range(err.shape[1]):
        x = (np.abs(err[ok, j]) < sigma[ok, j]).astype(float)
        n = len(x)
        if n < 2:
            continue
        d = x - x.mean()
        var = float(d @ d)
        if var == 0:
            out[j] = (x.sum(), 1.0)
            continue
        tau = 1.0
        for k in range(1, min(n - 1, 2000)):
            rho = float(d[k:] @ d[:-k]) / var
            if rho <= 0:
                break
            tau += 2 * rho
        out[j] = (x.sum(), n / tau)
    return out


def spread(err: np.ndarray, sigma: np.ndarray, more=()) -> float:
    """The largest over the axes of the binomial std of the 1σ share from the effective count of
    independent samples (module docstring); ``more``: further independent draws (err, sigma) of the same
    cell, pooled with the first (shares over all samples, counts of independent samples summed)."""
    out = 0.0
    parts = [(err, sigma)] + list(more)
    counts = np.array([independent_counts(e, s) for e, s in parts])  # (draws, axes, 2)
    n = np.array([np.all(np.isfinite(e) & np.isfinite(s) & (s > 0), axis=1).sum() for e, s in parts], float)
    if np.isnan(counts).any():
        return float("nan")
    for j in range(counts.shape[1]):
        c = counts[:, j, 0].sum() / n.sum()
        out = max(out, float(np.sqrt(c * (1 - c) / counts[:, j, 1].sum())))
    return out


def in_target(m: dict, slack: float = 0.0) -> bool:
    """Every axis' 1σ share within 60-76 % and 2σ share within 90-98 %, each bound widened by ``slack``."""
    return (all(0.60 - slack <= v <= 0.76 + slack for v in m.coverage_1sigma)
            and all(0.90 - slack <= v <= 0.98 + slack for v in m.coverage_2sigma))


def row(name: str, method: str, kind: str, err: np.ndarray, sigma: np.ndarray, more=()) -> str:
    """One line of the table; ``more``: further independent draws (err, sigma), pooled (:func:`spread`)."""
    m = sigma_metrics(np.vstack([err] + [e for e, _ in more]), np.vstack([sigma] + [s for _, s in more]))
    cov = m.coverage_1sigma + m.coverage_2sigma
    sp = spread(err, sigma, more)
    verdict = "yes" if in_target(m) else "within ±" if in_target(m, 2 * sp) else "no"
    return (f"| {name} | {method} | {kind} | " + " | ".join(f"{100 * v:.0f} %" for v in cov)
            + f" | ±{100 * sp:.0f} % | {m.mean_nees:.3g} | {verdict} |")


def rows_for(name: str, log, omega_true, methods, valid=None, reference=None) -> None:
    """Rows of ``log`` for each method: white and scaled σ; with ``reference`` (a recording's), also the
    scaled σ against the reference lined up in time."""
    rows = np.ones(len(log), bool) if valid is None else valid
    for method in methods:
        try:
            motion, white = run_both(log, method)
            err = motion.omega_b_radps - omega_true
            print(row(name, method, "white", err[rows], white[rows]), flush=True)
            print(row(name, method, "scaled", err[rows], motion.sigma["omega_b_radps"][rows]), flush=True)
            if reference is not None:
                w, sd, offset = aligned(motion, motion.sigma["omega_b_radps"], reference, rows)
                print(row(name, method, f"scaled, reference {offset * 1e3:+.2f} ms", (w - omega_true)[rows], sd[rows]),
                      flush=True)
        except Exception as exc:  # reported, not fatal to the table
            print(f"| {name} | {method} | | error: {type(exc).__name__}: {exc} ||||||||", flush=True)


def draws(mc: MisfitCell, n: int) -> list[MisfitCell]:
    """``n`` independent draws of ``mc``: its cell with seeds ``seed`` … ``seed + n − 1`` (the first is ``mc``)."""
    return [replace(mc, cell=replace(mc.cell, seed=mc.cell.seed + k)) for k in range(int(n))]


def read_cell(mc: MisfitCell, folder: Path):
    """(screened log, true ω) of ``mc`` built in ``folder``."""
    from gfimu.readings import screen_log

    path, omega = build(mc, folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = screen_log(gio.read_log(path, truth=False))
    return log, omega


def independent_samples(err: np.ndarray, sigma: np.ndarray) -> float:
    """The fewest independent samples over the axes of one draw's 1σ indicator (:func:`independent_counts`)."""
    counts = independent_counts(err, sigma)
    return float(np.min(counts[:, 1])) if np.all(np.isfinite(counts)) else 0.0


def pooled_rows_for(mc: MisfitCell, n: int | None, methods, folder: Path) -> None:
    """Rows of independent draws of ``mc`` pooled (:func:`draws`, :func:`spread`), for each method: ``n``
    draws, or (None) draws until every method's scaled σ holds :data:`MIN_INDEPENDENT` independent samples
    on every axis, at most :data:`MAX_DRAWS` (and :data:`MAX_DRAWS` of a cell whose sensor positions or gains are
    off: one such error per draw, which makes each draw's errors one sample however many it holds)."""
    runs = {m: [] for m in methods}  # (err, white, scaled) per draw
    held = {m: 0.0 for m in methods}  # independent samples of the scaled σ's indicator, summed over the draws
    failed = {}
    if n is None and (mc.position_error_m > 0 or mc.scale_error > 0):
        n = MAX_DRAWS  # one calibration error per draw, which its samples' count does not see: every draw
    for k, cell in enumerate(draws(mc, n or MAX_DRAWS)):
        sub = folder / f"{mc.name}-draw{k}"
        sub.mkdir(parents=True, exist_ok=True)
        log, omega = read_cell(cell, sub)
        for method in methods:
            if method in failed:
                continue
            try:
                motion, white = run_both(log, method)
                err = motion.omega_b_radps - omega
                runs[method].append((err, white, motion.sigma["omega_b_radps"]))
                held[method] += independent_samples(err, motion.sigma["omega_b_radps"])
            except Exception as exc:  # reported, not fatal to the table
                failed[method] = f"seed {cell.cell.seed}: {type(exc).__name__}: {exc}"
        del log
        if n is None and all(held[m] >= MIN_INDEPENDENT for m in methods if m not in failed):
            break
    for method in methods:
        if method in failed:
            print(f"| {mc.name} | {method} | | error: {failed[method]} ||||||||", flush=True)
            continue
        drawn = len(runs[method])
        name = mc.name if drawn == 1 else f"{mc.name} ({drawn} draws)"
        (e0, w0, s0), rest = runs[method][0], runs[method][1:]
        print(row(name, method, "white", e0, w0, [(e, w) for e, w, _ in rest]), flush=True)
        print(row(name, method, "scaled", e0, s0, [(e, s) for e, _, s in rest]), flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recordings", nargs="*", type=Path, help="MIMU4444 data.bin files")
    ap.add_argument("--cells", default=None, help="comma-separated names or glob patterns")
    ap.add_argument("--no-cells", action="store_true", help="the recordings only")
    ap.add_argument("--all", action="store_true", help=f"cells over {LONG_SAMPLES} samples too")
    ap.add_argument("--methods", default="smoother,fixed-lag")
    ap.add_argument("--draws", default="auto",
                    help="independent draws of each simulated cell, pooled: a number, or auto (until every method's "
                         f"scaled σ holds {MIN_INDEPENDENT} independent samples per axis, at most {MAX_DRAWS}; "
                         "default: auto)")
    args = ap.parse_args(argv)
    methods = args.methods.split(",")
    if args.draws == "auto":
        n_draws = None
    elif args.draws.isdigit() and int(args.draws) >= 1:
        n_draws = int(args.draws)
    else:
        ap.error(f"--draws: a number of draws (1 or more) or auto, not {args.draws!r}")
    cells = [] if args.no_cells else [c for c in CELLS if args.all or c.cell.duration_s * c.cell.rate_hz <= LONG_SAMPLES]
    if args.cells:
        import fnmatch

        pats = [p.strip() for p in args.cells.split(",") if p.strip()]
        cells = [c for c in cells if any(fnmatch.fnmatch(c.name, p if any(ch in p for ch in "*?[") else f"*{p}*")
                                         for p in pats)]
    print("| log | method | σ | < 1σ x | < 1σ y | < 1σ z | < 2σ x | < 2σ y | < 2σ z | ± | mean NEES | in target |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for mc in cells:
            pooled_rows_for(mc, n_draws, methods, Path(tmp))
        for rec in args.recordings:
            name = f"{rec.parent.name} (MIMU4444)"
            got = moving_recording(rec, Path(tmp))
            if isinstance(got, str):
                print(f"| {name} | | | convert failed: {got} ||||||||")
                continue
            log, reference, valid = got
            rows_for(name, log, reference.omega_b_radps, methods, valid, reference)
    print(f"\nShares of samples with |ω error| < 1σ and < 2σ per axis (a Gaussian error of that σ: 68.3 %, 95.4 %); "
          "±: the spread of a 1σ share from the count of independent samples (of all draws, pooled: N draws); "
          "mean NEES Σ_j (e_j/σ_j)² (3 when σ is right); in target: every axis within 60-76 % and 90-98 % (yes), or "
          "within those bounds widened by twice ± (within ±), or not (no). "
          "white: the σ of the white-noise model alone; scaled: the σ the smoothers report, scaled by the "
          "readings' own misfit (under a robust model, the M-estimator's sandwich), following the path's own "
          "trapezoid level and widened by the common gain gravity shows. "
          f"Recordings: moving samples (|ω_ref| > {MOVING_RADPS:g} rad/s, reference valid) "
          "against the mean of the board's gyros.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
