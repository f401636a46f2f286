#!/usr/bin/env python3
"""Search or model? The default smoother's own objective at its solution and at the solution
started from the gyro reference, on real MIMU4444 recordings.

For each recording (``data.bin``): convert and calibrate it as the plain flow does
(``gfimu convert mimu4444``, ``gfimu calibrate``, in a temporary folder), screen and calibrate the
readings as ``gfimu estimate`` does, and build the default batch smoother's model exactly as
:func:`gfimu.smoother.batch.engine.smooth` builds it for an inconsistent log (the model check of
:mod:`gfimu.smoother.tuning.model_choice`, the per-window problem of ``moment_problem``: the same windows, noise
floor and slope, Cauchy thresholds, process densities and local density factors). Per solve window:

- **default**: the production window solve (:func:`gfimu.smoother.solve.banded.solve_reweighted`) from
  the production start (the per-sample ML estimate with its sign chain), before the branch restarts
  (:mod:`gfimu.smoother.solve.restarts`; ``--restarts runs`` adds them as a third solution);
- **reference start**: the same model, ω started at the gyro reference (where it is valid; at
  saturated samples the default start's ω turned to the reference's side), ω̇ and f from the default
  start, solved by the re-weighted Levenberg-Marquardt straight away (the plain first iterations of
  the production schedule would pull the start off the reference before the robust weights act).

Both are then compared under ONE objective, the robust cost the re-weighting minimises, with the
accelerometer noise frozen: ``J = Σ_axes ρ(r/σ_k) + Σ_steps 6 ρ(|e|/√6) + ½ Σ (other whitened rows)²``,
``ρ(u) = c²/2 log(1 + u²/c²)`` (the Cauchy loss whose IRLS weight is the smoother's), ``σ_k`` the
motion-dependent noise ``√(σ₀² + (s |ω_k|)²)`` evaluated at ONE trajectory for both solutions (``--sigma-from
default``, the default; ``reference`` for the reference-started solution's ω). Each solution is also
re-solved to convergence under that frozen model (IRLS with the noise fixed: monotone in J), from
its own solution, so both costs are local minima of the same function.

Reported per recording: J of both (per term: accelerometer axes, motion-model steps, the rest),
ω RMSE against the gyro mean on moving unsaturated samples (|ω_ref| > 2 rad/s), and per 2 s segment
the cost difference against the squared-error difference: where the reference start is much better
(its squared error lower by more than ``--segment-gain`` rad²/s² per moving sample), is its cost
lower too? The gyro reference is used for the start and the scoring only.

    python3 tools/branch_cost_study.py ../shared/data/mimu4444/exp_*/data.bin
    python3 tools/branch_cost_study.py ../shared/data/mimu4444/exp_*/data.bin --reference-shift-ms -1.6
    python3 tools/branch_cost_study.py ../shared/data/mimu4444/exp_*/data.bin --restarts runs
    python3 tools/branch_cost_study.py ../shared/data/mimu4444/exp_1/data.bin --sigma-from reference --json out.json

A third solution, **pinned**, holds ω at the reference (its delay removed with ``--reference-shift-ms``)
and lets the model choose ω̇ and f: J of the reference trajectory itself.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gfimu import io as gio  # noqa: E402
from gfimu.calibration import apply_calibration, read_calibration  # noqa: E402
from gfimu.factors import accelerometer  # noqa: E402
from gfimu.readings import screen_log  # noqa: E402
from gfimu.smoother.solve.banded import reweighting, solve, solve_reweighted  # noqa: E402
from gfimu.smoother.model.problem import robust_loss  # noqa: E402
from gfimu.smoother.batch.engine import BatchSmootherEstimator, chosen_model, moment_problem, window_slices  # noqa: E402
from gfimu.smoother.model.option_groups import ModelGroups, with_groups  # noqa: E402
from gfimu.smoother.model.groups import AccelerometerGroup, FactorGroup, MotionModelGroup, Term  # noqa: E402
from gfimu.smoother.model.layout import OMEGA, OMEGA_DOT, SPECIFIC_FORCE  # noqa: E402
from gfimu.smoother.solve.restarts import BRANCHES, branch_restarts, plane_normal  # noqa: E402

MOVING_RADPS = 2.0


def prepare(recording: Path, folder: Path):
    """The calibrated, screened log of ``recording`` as the plain flow's estimate step reads it."""
    log_dir, cal = folder / "log", folder / "cal.toml"
    for args in (["convert", "mimu4444", str(recording), "--out", str(log_dir)], ["calibrate", str(log_dir), "--out", str(cal)]):
        proc = subprocess.run([sys.executable, "-m", "gfimu", *args], capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(REPO)})
        if proc.returncode:
            raise SystemExit(f"gfimu {' '.join(args)} failed:\n{proc.stderr}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = screen_log(gio.read_log(log_dir))
        return apply_calibration(log, read_calibration(cal))


class FrozenModel:
    """The objective of one solve window with the accelerometer noise frozen at one trajectory's |ω|
    and the robust losses as functions (not as weights): :meth:`parts` per sample, :meth:`resolve`."""

    def __init__(self, problem, omega_b_radps: np.ndarray):
        self.problem = problem
        opt = problem.batch_model
        self.slope = opt.accel_noise_slope_mps2_per_radps
        wn = np.linalg.norm(omega_b_radps, axis=1)
        self.sigma = np.sqrt(problem.noise.accel.sigma[None, :] ** 2 + (self.slope * wn[:, None]) ** 2)
        self.base = (problem.noise.motion.trapezoid_sigma.copy(), problem.noise.motion.omega_dot_step_sigma.copy())
        self.rows = problem.all_rows

    def parts(self, X: np.ndarray) -> dict:
        """Per-sample contributions (N,) to J: 'accelerometer', 'motion' (step k -> k+1 on sample k), 'other'."""
        p, opt = self.problem, self.problem.batch_model
        n = p.n
        r = (accelerometer.accelerometer_prediction(X[:, OMEGA], X[:, OMEGA_DOT], X[:, SPECIFIC_FORCE], self.rows)
             - p.log.accel_mps2) / self.sigma
        acc = np.sum(robust_loss(r * r, opt.accel_robust_threshold, opt.robust_loss), axis=1)
        e = p.group(MotionModelGroup).step_residual(p, X, self.base)
        rows = e.shape[1]
        motion = np.zeros(n)
        motion[:-1] = rows * robust_loss(np.mean(e * e, axis=1), opt.process_robust_threshold, opt.robust_loss)
        other = np.zeros(n)
        P = np.zeros(p.n_global)
        for g in p.groups:
            if isinstance(g, (AccelerometerGroup, MotionModelGroup, PinOmega)):
                continue
            for t in g.terms(p, X, P):
                v = 0.5 * np.sum(t.residual.reshape(t.residual.shape[0], -1) ** 2, axis=1)
                if t.kind == "unary":
                    other[t.first:t.first + v.size] += v
                elif t.kind == "binary":
                    other[:-1] += v
                else:
                    other[0] += float(np.sum(v))
        return {"accelerometer": acc, "motion": motion, "other": other}

    def cost(self, X: np.ndarray) -> float:
        return float(sum(np.sum(v) for v in self.parts(X).values()))

    def resolve(self, X: np.ndarray):
        """Robust re-weighted Levenberg-Marquardt under the frozen noise (each step lowers J), from X."""
        p = self.problem.with_noise(accel=self.problem.noise.accel.with_base(self.sigma),
                                    motion=self.problem.noise.motion.with_steps(*self.base))
        reweight = reweighting(replace(p.batch_model, accel_noise_slope_mps2_per_radps=0.0))
        return solve(p, X, reweight=reweight, max_iterations=100)


class PinOmega(FactorGroup):
    """ω held at the log's reference (std ``sigma_radps`` where it is valid, free elsewhere): the best the
    model can do with ω on the reference, for the diagnosis only (never part of J)."""

    name = "pin omega"
    per_sample = False

    def __init__(self, sigma_radps: float = 0.01):
        self.sigma_radps = sigma_radps

    def terms(self, problem, states, params):
        log = problem.log
        ok = ~log.invalid_reference if log.invalid_reference is not None else np.ones(problem.n, bool)
        w = np.where(ok, 1.0 / self.sigma_radps, 0.0)[:, None]
        r = (states[:, OMEGA] - np.nan_to_num(log.reference.omega_b_radps)) * w
        J = np.zeros((problem.n, 3, problem.state_size))
        J[:, :, OMEGA] = np.eye(3)[None] * w[:, :, None]
        return [Term("unary", r, {"x": J})]

    def log_normaliser(self, problem):
        return 0.0


def reference_start(x0: np.ndarray, part) -> np.ndarray:
    """x0 with ω from the reference where it is valid; elsewhere x0's ω turned to the reference's side."""
    x = x0.copy()
    ref = part.reference.omega_b_radps
    ok = ~part.invalid_reference if part.invalid_reference is not None else np.ones(len(part), bool)
    w = x[:, OMEGA].copy()
    w[ok] = ref[ok]
    w[~ok & (np.sum(w * ref, axis=1) < 0)] *= -1.0
    x[:, OMEGA] = w
    return x


def segment_restarts(model: FrozenModel, X: np.ndarray, normal: np.ndarray, width: int) -> tuple[np.ndarray, int, int]:
    """Local restarts on other branches: for every stretch of ``width`` samples whose own |ω| is
    above the moving threshold (from the solution, not the reference), move ω there to each branch
    (:data:`gfimu.smoother.solve.restarts.BRANCHES`: sign flipped; mirrored through the array's plane), re-solve
    the window under the frozen model and keep the result only when J falls. Returns (states,
    restarts tried, restarts kept)."""
    best = model.cost(X)
    tried = kept = 0
    speed = np.linalg.norm(X[:, OMEGA], axis=1)
    for a in range(0, len(X), width):
        sl = slice(a, min(a + width, len(X)))
        if np.median(speed[sl]) <= MOVING_RADPS:
            continue
        base = X
        for branch in BRANCHES:
            start = base.copy()
            start[sl] = branch(base[sl], normal)
            tried += 1
            Y = model.resolve(start).states
            c = model.cost(Y)
            if c < best:
                X, best = Y, c
        kept += X is not base
    return X, tried, kept


def study(log, sigma_from: str, segment_s: float, segment_gain: float, resolve: bool,
          reference_shift_ms: float = 0.0, restarts: str | None = None) -> dict:
    est = BatchSmootherEstimator()
    given = est
    chosen, auto = chosen_model(log, ModelGroups.of(given), False)
    opt = with_groups(given, *chosen)
    if auto is None or auto[0].consistent:
        raise SystemExit(f"{log.source}: the model check finds the log consistent; this study is about the robust model")
    aligned = log
    if reference_shift_ms:
        from gfimu.io.readers.mimu4444 import shift_reference

        aligned = shift_reference(log, reference_shift_ms)
    n = len(log)
    windows = window_slices(n, log.rate_hz, opt.window_s, opt.overlap_s)
    names = ("default", "reference", "pinned") + (("restarted",) if restarts else ())
    normal = plane_normal(log.array.axis_positions_m)
    width = max(int(round(segment_s * log.rate_hz)), 1)
    restart_counts = [0, 0]
    omega = {k: np.zeros((n, 3)) for k in names}
    parts = {k: {t: np.zeros(n) for t in ("accelerometer", "motion", "other")} for k in names}
    totals = {k: 0.0 for k in names}
    production = {k: 0.0 for k in names}
    seconds = {k: 0.0 for k in names}
    pinned_opt = replace(opt, factor_groups=(PinOmega(),))
    for solve_sl, keep_log, keep_win in windows:
        part, part_ref = log.select(solve_sl), aligned.select(solve_sl)
        sols = {}
        problem, x0 = moment_problem(part, opt.model_groups, auto, solve_sl, [])
        t0 = time.perf_counter()
        sols["default"] = solve_reweighted(problem, x0, opt.batch, compute_sigma=False)
        seconds["default"] += time.perf_counter() - t0
        problem_r, _ = moment_problem(part, opt.model_groups, auto, solve_sl, [])
        t0 = time.perf_counter()
        sols["reference"] = solve_reweighted(problem_r, reference_start(x0, part_ref), opt.batch,
                                             compute_sigma=False, warm=True)
        seconds["reference"] += time.perf_counter() - t0
        frozen_at = sols["default" if sigma_from == "default" else "reference"].states[:, OMEGA]
        for k in names:
            if k == "pinned":  # ω held at the reference, ω̇ and f the model's best under the frozen noise
                fresh, _ = moment_problem(part_ref, pinned_opt.model_groups, auto, solve_sl, [])
                model = FrozenModel(fresh, frozen_at)
                res = model.resolve(reference_start(x0, part_ref))
                X = res.states
            elif k == "restarted":  # the default's frozen solution with local restarts on the other branches
                fresh, _ = moment_problem(part, opt.model_groups, auto, solve_sl, [])
                model = FrozenModel(fresh, frozen_at)
                if restarts == "runs":  # the library's restarts (what the default smoother now does)
                    model.resolve(default_states)  # the frozen noise and base weights on the problem
                    X, tried, kept = branch_restarts(model.problem, default_states)
                else:
                    X, tried, kept = segment_restarts(model, default_states, normal, width)
                restart_counts[0] += tried
                restart_counts[1] += kept
            else:
                production[k] += float(sols[k].cost)
                fresh, _ = moment_problem(part, opt.model_groups, auto, solve_sl, [])
                model = FrozenModel(fresh, frozen_at)
                X = model.resolve(sols[k].states).states if resolve else sols[k].states
            if k == "default":
                default_states = X
            p = model.parts(X)
            totals[k] += float(sum(np.sum(v) for v in p.values()))
            omega[k][keep_log] = X[keep_win, OMEGA]
            for t, v in p.items():
                parts[k][t][keep_log] = v[keep_win]
    ref = log.reference.omega_b_radps
    valid = ~log.invalid_reference if log.invalid_reference is not None else np.ones(n, bool)
    moving = valid & (np.linalg.norm(ref, axis=1) > MOVING_RADPS)
    err2 = {k: np.where(moving, np.sum((omega[k] - ref) ** 2, axis=1), 0.0) for k in names}
    out = {"samples": n, "moving": int(moving.sum()), "windows": len(windows), "sigma_from": sigma_from,
           "resolved": resolve, "reference_shift_ms": reference_shift_ms, "seconds": seconds,
           "restarts_tried": restart_counts[0], "restarts_kept": restart_counts[1],
           "_arrays": {**{f"omega_{k}": omega[k] for k in names}, "omega_ref": ref, "moving": moving,
                       **{f"J_{t}_{k}": parts[k][t] for k in names for t in parts[k]}}}
    for k in names:
        mirror = omega[k] - 2.0 * np.outer(omega[k] @ normal, normal)  # ω mirrored through the board's plane
        closer = np.linalg.norm(mirror - ref, axis=1) < np.linalg.norm(omega[k] - ref, axis=1) - 2.0
        out[k] = {"rmse_radps": float(np.sqrt(np.sum(err2[k]) / moving.sum())),
                  "cost_stitched": float(sum(np.sum(v) for v in parts[k].values())),
                  "cost_windows": totals[k], "production_cost": production[k],
                  "terms": {t: float(np.sum(v)) for t, v in parts[k].items()},
                  "mirror_closer_share": float(np.mean(closer[moving]))}
    # segments: cost difference against squared-error difference
    seg = np.arange(n) // width
    S = seg[-1] + 1
    m_count = np.bincount(seg, moving.astype(float), S)
    has = m_count >= 10
    out["segments"] = {"width_s": segment_s, "gain_rad2ps2_per_sample": segment_gain, "with_motion": int(has.sum())}
    for other in names[1:]:
        dJ = {t: np.bincount(seg, parts[other][t] - parts["default"][t], S) for t in parts["default"]}
        dJ_total = sum(dJ.values())
        dE = np.bincount(seg, err2[other] - err2["default"], S)
        better = has & (dE < -segment_gain * m_count)
        worse = has & (dE > segment_gain * m_count)
        same = has & ~better & ~worse

        def summary(mask, dJ=dJ, dJ_total=dJ_total, dE=dE):
            return {"segments": int(mask.sum()),
                    "cost_lower": int(np.sum(dJ_total[mask] < 0)),
                    "sum_dJ": float(np.sum(dJ_total[mask])),
                    "sum_dJ_terms": {t: float(np.sum(v[mask])) for t, v in dJ.items()},
                    "sum_d_sq_error": float(np.sum(dE[mask])),
                    "median_dJ": float(np.median(dJ_total[mask])) if mask.any() else float("nan")}

        # the better of the two per segment by the objective (what a cost-driven local restart could
        # reach with this candidate at most), and by the error (an oracle)
        pick_cost = np.repeat(dJ_total < 0, width)[:n]
        pick_error = np.repeat(dE < 0, width)[:n]
        rm = {name: float(np.sqrt(np.sum(np.where(pick, err2[other], err2["default"])) / moving.sum()))
              for name, pick in (("by_cost", pick_cost), ("by_error", pick_error))}
        order = [s_ for s_ in np.argsort(dE) if has[s_]][:10]
        out["segments"][other] = {
            "better": summary(better), "similar": summary(same), "worse": summary(worse),
            "spearman_dJ_dE": spearman(dJ_total[has], dE[has]),
            "rmse_segment_pick_by_cost": rm["by_cost"], "rmse_segment_pick_by_error": rm["by_error"],
            "largest_gains": [{"t_s": float(s_ * width / log.rate_hz), "d_sq_error_per_sample": float(dE[s_] / m_count[s_]),
                               "dJ": float(dJ_total[s_]), **{f"dJ_{t}": float(v[s_]) for t, v in dJ.items()}} for s_ in order]}
    return out


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    if a.size < 3:
        return float("nan")
    ra, rb = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    return float(np.corrcoef(ra, rb)[0, 1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "),
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n", 1)[1])
    ap.add_argument("recordings", nargs="+", type=Path, help="MIMU4444 data.bin files")
    ap.add_argument("--sigma-from", choices=("default", "reference"), default="default",
                    help="trajectory whose |ω| sets the frozen motion-dependent accelerometer noise (default: default)")
    ap.add_argument("--segment-s", type=float, default=2.0, help="segment length [s] of the comparison (default 2)")
    ap.add_argument("--segment-gain", type=float, default=1.0,
                    help="a segment counts as better/worse when the squared ω error changes by more than this "
                         "many rad²/s² per moving sample (default 1)")
    ap.add_argument("--no-resolve", action="store_true",
                    help="evaluate J at the production solutions as they are, without re-solving under the frozen noise")
    ap.add_argument("--reference-shift-ms", type=float, default=0.0,
                    help="start (and pin) at the reference re-sampled at t + this [ms] (e.g. -1.6: its own delay "
                         "removed); the scoring keeps the recorded reference (default 0)")
    ap.add_argument("--restarts", choices=("segments", "runs"), default=None,
                    help="also try local restarts of the default's solution on the other branches (ω sign-flipped, "
                         "ω mirrored through the array's plane), kept when J falls: 'segments' every moving segment with "
                         "a window re-solve (slow), 'runs' the short runs between outlying motion-model steps with a "
                         "local re-solve (gfimu.smoother.solve.restarts, as the default smoother does)")
    ap.add_argument("--save-arrays", type=Path, default=None,
                    help="folder for one .npz per recording: ω of every solution, the reference, the moving mask and "
                         "the per-sample parts of J")
    ap.add_argument("--json", type=Path, default=None, help="also write the results as JSON here")
    args = ap.parse_args(argv)
    rows = {}
    for rec in args.recordings:
        with tempfile.TemporaryDirectory() as tmp:
            log = prepare(rec, Path(tmp))
        t0 = time.perf_counter()
        r = study(log, args.sigma_from, args.segment_s, args.segment_gain, not args.no_resolve, args.reference_shift_ms,
                  args.restarts)
        r["elapsed_s"] = time.perf_counter() - t0
        name = rec.parent.name or rec.name
        arrays = r.pop("_arrays")
        if args.save_arrays:
            args.save_arrays.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(args.save_arrays / f"{name}.npz", **arrays)
        rows[name] = r
        print(f"\n## {name}: {r['moving']} moving samples, {r['windows']} windows, noise frozen at the {r['sigma_from']} "
              f"solution's |ω|{'' if r['resolved'] else ' (not re-solved)'}, {r['elapsed_s']:.0f} s")
        print("| start | RMSE rad/s | J (stitched) | J accel | J motion | J other | J (windows) | production cost "
              "| mirrored closer by > 2 rad/s |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for k in ("default", "reference", "pinned", "restarted"):
            if k not in r:
                continue
            s = r[k]
            print(f"| {k} | {s['rmse_radps']:.3f} | {s['cost_stitched']:.1f} | {s['terms']['accelerometer']:.1f} | "
                  f"{s['terms']['motion']:.1f} | {s['terms']['other']:.1f} | {s['cost_windows']:.1f} | "
                  f"{s['production_cost']:.1f} | {100 * s['mirror_closer_share']:.2f} % |")
        sg = r["segments"]
        if "restarted" in r:
            print(f"\nlocal restarts on the other branches: {r['restarts_kept']} of {r['restarts_tried']} kept (J lower)")
        for other in [k for k in ("reference", "pinned", "restarted") if k in r["segments"]]:
            sg = r["segments"][other]
            print(f"\n{r['segments']['width_s']:g} s segments with motion, {other} against default (ΔJ = J_{other} - J_default; "
                  f"Δe² in rad²/s² summed over moving samples; Spearman(ΔJ, Δe²) = {sg['spearman_dJ_dE']:.2f}; "
                  f"RMSE taking the lower-J solution per segment {sg['rmse_segment_pick_by_cost']:.3f}, "
                  f"the lower-error one {sg['rmse_segment_pick_by_error']:.3f}):")
            print(f"| segments where {other} is | n | its J lower in | ΣΔJ | ΔJ accel | ΔJ motion | ΔJ other | median ΔJ | ΣΔe² |")
            print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
            for label in ("better", "similar", "worse"):
                s = sg[label]
                t = s["sum_dJ_terms"]
                print(f"| {label} | {s['segments']} | {s['cost_lower']} | {s['sum_dJ']:.1f} | {t['accelerometer']:.1f} | "
                      f"{t['motion']:.1f} | {t['other']:.1f} | {s['median_dJ']:.2f} | {s['sum_d_sq_error']:.0f} |")
            print(f"largest gains of {other} (segment start, Δe² per moving sample, ΔJ = accel + motion + other):")
            for g in sg["largest_gains"][:5]:
                print(f"  t {g['t_s']:6.1f} s  Δe² {g['d_sq_error_per_sample']:8.1f}  ΔJ {g['dJ']:8.1f} = "
                      f"{g['dJ_accelerometer']:.1f} + {g['dJ_motion']:.1f} + {g['dJ_other']:.1f}")
        sys.stdout.flush()
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
