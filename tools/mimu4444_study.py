#!/usr/bin/env python3
"""Accelerometer-only angular velocity on the real MIMU4444 recordings.

For each recording (exp_1..3): decode, calibrate (fitted on the same
recording's still periods — "within" — and/or on another recording's —
"cross"), run every applicable accelerometer-only method, and compare ω with
the gyro reference (mean of the board's eight gyros) on the moving,
unsaturated samples (|ω_ref| > 2 rad/s, reference valid) with
:func:`gfimu.evaluation.evaluate`.

``--residual`` adds the investigation of the rigid-body model residual: with
ω from the gyro reference, how far do the calibrated accelerometer readings
stand from the rigid-body model, and how much of it do a lag between the
accelerometer and gyro channels, per-sensor time offsets, fitted sensor
positions, per-sensor dynamic gains or the full 12-unknown linear model take
away (fitted on one recording, checked on another).

Examples::

    python3 tools/mimu4444_study.py                       # all methods, within calibration, exp_1..3
    python3 tools/mimu4444_study.py --methods ml smoother --calibration within cross --fit-on 1
    python3 tools/mimu4444_study.py --residual --methods  # residual study only

The smoother set up for these recordings is the preset ``hand-held-low-rate``
(:mod:`gfimu.smoother.model.presets`; settings chosen on exp_1): per-sample ML initialisation with its
sign chain (a fast rotation slowing through zero and reversing is otherwise taken as a bounce),
fixed jerk density 3000 rad/s²/√s and specific-force density 300 m/s²/√s for hand motion at
62.5 Hz, accelerometer noise growing by 0.03 m/s² per rad/s, and a Cauchy loss at 2 σ on the
accelerometer axes and on the motion-model steps (heavy-tailed rigid-body residual, sudden hand
jerks), re-weighted over 5 solves; ``--option smoother:KEY=VALUE`` overrides single settings,
``--breakdown`` prints where the remaining error sits, ``--start-at-reference`` starts the
smoother's ω at the gyro reference (other states from the ML initialisation) and ``--bound``
adds the smoother's own bound at the reference trajectory (:mod:`gfimu.smoother.batch.bound`, with the
noise slope, without the robust weights)::

    python3 tools/mimu4444_study.py --experiments 1 2 3 --methods smoother --calibration within cross \
        --fit-on 1 --reference-shift-ms -1.5 --breakdown --preset hand-held-low-rate
    python3 tools/mimu4444_study.py --methods smoother --reference-shift-ms -1.5 \
        --preset hand-held-low-rate --start-at-reference --bound

Measured (shifted reference, within calibration, moving valid samples; RMSE of the ω error norm /
median / share with ω·ω_ref < 0), with the preset: exp_1 3.13 / 1.90 / 1.57 %, exp_2 3.61 / 1.99 /
0.31 %, exp_3 4.03 / 2.11 / 1.25 %. With the sign chain's plain squared steps (before its Cauchy
loss, :func:`gfimu.smoother.solve.initialise.sign_chain`): 3.15 / 1.91 / 2.01 %, 4.58 / 2.01 / 0.73 %,
5.54 / 2.13 / 1.68 %, the largest 1 % of the errors carrying 53 % (exp_2) and 64 % (exp_3) of the
squared error: runs of 4-5 samples on the wrong sign branch after a single sample with a reading
spike (per-sample ω̇ off by thousands of rad/s²) at the fastest rotations; now 29 % and 38 %.
Before the sign chain and the robust loss: 3.58 / 2.23 / 1.88 %, 4.94 / 2.43 / 1.59 %,
5.84 / 2.42 / 1.77 %. Started at the reference: 3.04 / 1.86 / 0.28 %, 3.33 / 1.98 / 0.15 %,
3.30 / 2.04 / 0.13 %. The smoother's own bound at the reference (RMS of the ω bound's norm):
1.55, 1.54, 1.54 rad/s: even on the right sign branch the error is twice what the model's
noise allows, the rigid-body residual of the board (``--residual``) not being white noise.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gfimu import calibration as calib  # noqa: E402
from gfimu.io.readers.mimu4444 import read_mimu4444, shift_reference  # noqa: E402
from gfimu.methods import METHODS, make_estimator  # noqa: E402
from gfimu.smoother.solve.initialise import initial_estimate  # noqa: E402
from gfimu.evaluation import evaluate  # noqa: E402
from gfimu.array import mimu4444_array  # noqa: E402
from gfimu.rotations import skew  # noqa: E402

DEFAULT_DATA = REPO.parent / "shared" / "data" / "mimu4444"
MOVING_RADPS = 2.0
NEEDS_GYRO = {"gyro-aided"}  # the gyro is the reference here: methods that read it are not compared


# --- data ----------------------------------------------------------------------

def load(data_dir: Path, exp: int, with_gyro: bool):
    path = data_dir / f"exp_{exp}" / "data.bin"
    if not path.is_file():
        raise SystemExit(f"{path} not found (pass --data)")
    return read_mimu4444(path, with_gyro=with_gyro)


def moving_mask(log, threshold_radps: float = MOVING_RADPS) -> np.ndarray:
    w = np.linalg.norm(log.reference.omega_b_radps, axis=1)
    return (w > threshold_radps) & ~log.invalid_reference


# --- method comparison ------------------------------------------------------------

def run_method(name: str, log, options: dict, progress: bool, start_at_reference: bool = False):
    est = make_estimator(name, **options)
    reason = est.applicable(log.array)
    if reason:
        return None, reason, 0.0
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if start_at_reference and name == "smoother":
            motion = est.result(log, progress=progress, initial=started_at_reference).motion
        else:
            motion = est.estimate(log, progress=progress).motion
    return motion, None, time.perf_counter() - t0


def started_at_reference(part, groups):
    """Initial states of a batch-smoother window from ω of the log's reference (where the reference
    is valid; at saturated-gyro samples from the own initialisation's ω, turned to the reference's
    side), its other states from its own initialisation: how far the accelerometer-only solution
    stands from the gyro's when started on the right sign branch."""
    x = initial_estimate(part, groups)
    ref = part.reference.omega_b_radps
    ok = ~part.invalid_reference if part.invalid_reference is not None else np.ones(len(part), bool)
    w = x[:, 0:3].copy()
    w[ok] = ref[ok]
    w[~ok & (np.sum(w * ref, axis=1) < 0)] *= -1.0
    x[:, 0:3] = w
    return x


def reference_bound(log, options: dict, mask) -> dict:
    """The smoother's own bound (:mod:`gfimu.smoother.batch.bound`: its graph linearised, here at the
    reference trajectory) with the accelerometer noise the options model, including the noise
    growing with |ω| of the reference (``accel_noise_slope_mps2_per_radps``); the robust weights,
    which depend on the residuals of a solution, are left out. RMS of the norm of the one-sigma ω
    bound over ``mask``, and by |ω_ref| band."""
    from dataclasses import fields

    from gfimu.rigid_body import quadratic_terms
    from gfimu.smoother.solve.banded import factorise, marginal_covariances, normal_equations
    from gfimu.smoother.batch.engine import window_slices
    from gfimu.smoother.model.problem import SmootherOptions
    from gfimu.smoother.tuning.evidence import make_problem

    opt = SmootherOptions(**{k: v for k, v in options.items() if k in {f.name for f in fields(SmootherOptions)}})
    if opt.tune_process_noise or opt.motion_model != "jerk" or opt.measurement != "accelerometer":
        raise SystemExit("--bound needs fixed process noise, the jerk model and the accelerometer factors "
                         "(e.g. --preset hand-held-low-rate)")
    omega = log.reference.omega_b_radps
    omega_dot = np.gradient(omega, log.times_s, axis=0)
    # specific force at the origin by least squares given the reference ω, ω̇ (the bound's Jacobians
    # do not depend on it: the model is linear in f)
    s = log.array.structure_matrix()
    rest = np.hstack([omega_dot, quadratic_terms(omega)]) @ s[:, 3:].T
    f = np.linalg.lstsq(s[:, :3], (log.accel_mps2 - rest).T, rcond=None)[0].T
    states = np.hstack([omega, omega_dot, f])
    sd = np.zeros((len(log), 3))
    for solve_sl, keep_log, keep_win in window_slices(len(log), log.rate_hz, opt.window_s, opt.overlap_s):
        part = log.select(solve_sl)
        problem = make_problem(part, opt.model_groups, 1.0, omega[solve_sl])
        ne = normal_equations(problem, states[solve_sl], np.zeros(problem.n_global))
        cov, _ = marginal_covariances(ne, factorise(ne, 0.0))
        sd[keep_log] = np.sqrt(np.einsum("nii->ni", cov[:, 0:3, 0:3]))[keep_win]
    b2 = np.sum(sd**2, axis=1)
    wn = np.linalg.norm(omega, axis=1)
    out = {"rms_bound_norm": float(np.sqrt(np.mean(b2[mask]))), "median_bound_norm": float(np.median(np.sqrt(b2[mask])))}
    out["by_omega_radps"] = {f"{a}-{b}": float(np.sqrt(np.mean(b2[mask & (wn >= a) & (wn < b)])))
                             for a, b in ((2, 10), (10, 20), (20, 30), (30, 40)) if np.any(mask & (wn >= a) & (wn < b))}
    return out


def metrics_row(motion, log, mask) -> dict:
    """ω metrics from :func:`gfimu.evaluation.evaluate`, plus the share pointing to the other hemisphere."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = evaluate(motion.replace(omega_dot_b_radps2=None, accel_b_mps2=None, specific_force_b_mps2=None,
                                      quaternion_wb=None, sigma={}),
                       log.reference, valid=mask)
    row = next(r for r in res.rows if r["quantity"] in ("omega", "omega_b_radps"))
    est, ref = motion.omega_b_radps[mask], log.reference.omega_b_radps[mask]
    return {
        "n": row.get("n_samples", row.get("n")),
        "rmse_x": row["rmse_x"], "rmse_y": row["rmse_y"], "rmse_z": row["rmse_z"],
        "rmse_norm": row["rmse_norm"], "median_norm": row["median_norm"],
        "large_error": row.get("share_off_5radps", row.get("large_error")),
        "wrong_sign": row.get("flipped_share", row.get("wrong_sign")),
        # the accelerometer-only sign ambiguity: estimate in the opposite half-space of the reference
        "opposite": float(np.mean(np.sum(est * ref, axis=1) < 0)),
    }


def compare(args) -> list[dict]:
    rows = []
    cals = {}
    for exp in set(args.experiments) | ({args.fit_on} if "cross" in args.calibration else set()):
        glog, _ = load(args.data, exp, with_gyro=True)
        if args.calibration_until_s is not None:
            glog = glog.select(slice(0, int(np.sum(glog.times_s <= args.calibration_until_s))))
        cals[exp] = calib.fit(glog)
        i = cals[exp].info
        print(f"exp_{exp}: calibration from {i['still_periods']} still periods, spread {i['spread_before_mps2']:.3f} -> "
              f"{i['spread_after_mps2']:.4f} m/s² (norm), {i['spread_per_axis_before_mps2']:.3f} -> "
              f"{i['spread_per_axis_after_mps2']:.4f} m/s² (per axis)", flush=True)
    for exp in args.experiments:
        raw, report = load(args.data, exp, with_gyro=False)
        references = {"recorded": raw.reference}
        mask = moving_mask(raw)
        if args.reference_shift_ms:
            shifted = shift_reference(raw, args.reference_shift_ms)
            references[f"shifted {args.reference_shift_ms:+g} ms"] = shifted.reference
            mask &= moving_mask(shifted)  # the same samples for both references
        print(f"exp_{exp}: {report.n_packets} samples, {int(mask.sum())} moving and valid "
              f"(|ω_ref| > {MOVING_RADPS} rad/s), {report.invalid_reference_samples} with a saturated gyro", flush=True)
        for cal_mode in args.calibration:
            if cal_mode == "none":
                log = raw
            else:
                c = cals[exp] if cal_mode == "within" else cals[args.fit_on]
                log = calib.apply_calibration(raw, c)
            if args.noise_std is not None:
                log = log.replace(array=mimu4444_array(noise_std_mps2=args.noise_std))
            if args.seconds is not None:
                log = log.select(slice(0, int(np.sum(log.times_s <= args.seconds))))
                m = mask[: len(log)]
            else:
                m = mask
            if args.start_at_reference or args.bound:  # the aligned reference, for the start and the bound
                aligned = references[list(references)[-1]]
                log = log.replace(reference=aligned if len(aligned) == len(log) else aligned.select(slice(0, len(log))))
            if args.bound:
                b = reference_bound(log, args.options.get("smoother", {}), m)
                rows.append({"exp": exp, "calibration": cal_mode, "method": "smoother bound at the reference", **b})
                print(f"  {cal_mode:>14} smoother bound at the reference: RMS of the ω bound norm {b['rms_bound_norm']:.3f} rad/s, "
                      f"median {b['median_bound_norm']:.3f}; by |ω| " +
                      ", ".join(f"{k}: {v:.2f}" for k, v in b["by_omega_radps"].items()), flush=True)
            for name in args.methods:
                opts = dict(args.options.get(name, {}))
                motion, reason, elapsed = run_method(name, log, opts, args.progress, args.start_at_reference)
                label = f"{cal_mode}" + (f" (exp_{args.fit_on})" if cal_mode == "cross" else "")
                if motion is None:
                    print(f"  {name}: not applicable: {reason}", flush=True)
                    rows.append({"exp": exp, "calibration": label, "method": name, "skipped": reason})
                    continue
                if motion.omega_b_radps is None:
                    print(f"  {name}: gives no angular velocity", flush=True)
                    continue
                for ref_name, reference in references.items():
                    if len(reference) != len(log):  # --seconds
                        reference = reference.select(slice(0, len(log)))
                    row = metrics_row(motion, log.replace(reference=reference), m)
                    row.update(exp=exp, calibration=label, method=name, seconds=elapsed, options=opts, reference=ref_name)
                    if args.breakdown and (ref_name != "recorded" or len(references) == 1):
                        row["breakdown"] = error_breakdown(motion, log.replace(reference=reference), m)
                    rows.append(row)
                    print(f"  {label:>14} {name:>16} (ref {ref_name}): ω RMSE norm {row['rmse_norm']:.3f} rad/s, median {row['median_norm']:.3f}, "
                          f"> 5 rad/s {100 * row['large_error']:.1f} %, some axis wrong sign {100 * row['wrong_sign']:.2f} %, "
                          f"ω·ω_ref < 0 {100 * row['opposite']:.2f} % "
                          f"({elapsed:.1f} s)", flush=True)
                    if "breakdown" in row:
                        print_breakdown(row["breakdown"])
    return rows


def error_breakdown(motion, log, mask) -> dict:
    """Where the ω error sits: share of the squared error (and RMSE of the norm) by distance to the
    nearest saturated-gyro sample, by |ω_ref|, by |ω̇_ref| quantile; opposite-sign share by |ω_ref|."""
    ref = log.reference.omega_b_radps
    err2 = np.sum((motion.omega_b_radps - ref) ** 2, axis=1)
    wn = np.linalg.norm(ref, axis=1)
    k = np.arange(len(log))
    sat = np.nonzero(log.invalid_reference)[0]
    if sat.size:
        j = np.clip(np.searchsorted(sat, k), 1, sat.size) - 1
        dist = np.minimum(np.abs(k - sat[j]), np.abs(sat[np.clip(j + 1, 0, sat.size - 1)] - k))
    else:
        dist = np.full(len(log), 10**9)
    wd = np.linalg.norm(np.gradient(ref, log.times_s, axis=0), axis=1)
    total = float(np.sum(err2[mask]))
    opposite = np.sum(motion.omega_b_radps * ref, axis=1) < 0

    def cell(sel):
        sel = sel & mask
        n = int(sel.sum())
        return {"n": n, "rmse_norm": float(np.sqrt(np.mean(err2[sel]))) if n else float("nan"),
                "share_sse": float(np.sum(err2[sel]) / total), "opposite": float(np.mean(opposite[sel])) if n else float("nan")}

    out = {"by_distance_to_saturation": {f"{a}-{b}": cell((dist >= a) & (dist < b)) for a, b in ((1, 4), (4, 10), (10, 30), (30, 10**9))},
           "by_omega_radps": {f"{a}-{b}": cell((wn >= a) & (wn < b)) for a, b in ((2, 5), (5, 10), (10, 20), (20, 30), (30, 40))}}
    q = np.quantile(wd[mask], [0.0, 0.5, 0.9, 0.99, 1.0])
    out["by_omega_dot_quantile"] = {f"{lo:.0f}-{hi:.0f}": cell((wd >= lo) & (wd <= hi)) for lo, hi in zip(q[:-1], q[1:])}
    e = np.sort(err2[mask])[::-1]
    out["top_1pc_share_sse"] = float(e[: max(len(e) // 100, 1)].sum() / total)
    out["top_5pc_share_sse"] = float(e[: max(len(e) // 20, 1)].sum() / total)
    return out


def print_breakdown(b: dict, indent: str = "    ") -> None:
    for key in ("by_distance_to_saturation", "by_omega_radps", "by_omega_dot_quantile"):
        print(f"{indent}{key}: " + "; ".join(f"{k}: n {c['n']}, RMSE {c['rmse_norm']:.2f}, SSE {100 * c['share_sse']:.0f} %, "
                                            f"opp {100 * c['opposite']:.1f} %" for k, c in b[key].items()))
    print(f"{indent}largest 1 % / 5 % of errors carry {100 * b['top_1pc_share_sse']:.0f} % / {100 * b['top_5pc_share_sse']:.0f} % "
          "of the squared error", flush=True)


def table(rows: list[dict]) -> str:
    head = ("| exp | calibration | reference | method | n | RMSE x | RMSE y | RMSE z | RMSE norm | median | > 5 rad/s | wrong sign (any axis) "
            "| ω·ω_ref < 0 | time |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        if "rms_bound_norm" in r:
            lines.append(f"| {r['exp']} | {r['calibration']} | | {r['method']} | | | | | {r['rms_bound_norm']:.3f} (RMS) | "
                         f"{r['median_bound_norm']:.3f} | | | | |")
            continue
        if "skipped" in r:
            lines.append(f"| {r['exp']} | {r['calibration']} | | {r['method']} | not applicable: {r['skipped']} ||||||||||")
            continue
        lines.append(
            f"| {r['exp']} | {r['calibration']} | {r['reference']} | {r['method']} | {r['n']} | {r['rmse_x']:.3f} | {r['rmse_y']:.3f} | "
            f"{r['rmse_z']:.3f} | {r['rmse_norm']:.3f} | {r['median_norm']:.3f} | {100 * r['large_error']:.1f} % | "
            f"{100 * r['wrong_sign']:.2f} % | {100 * r['opposite']:.2f} % | {r['seconds']:.1f} s |"
        )
    return "\n".join(lines)


# --- rigid-body residual investigation ------------------------------------------------

def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def rigid_residual(y: np.ndarray, omega: np.ndarray, positions: np.ndarray, omega_dot: np.ndarray | None = None):
    """Residual (N, k, 3) of triad readings y (N, k, 3) in B against the rigid-body model.

    ω is given; f (and ω̇ unless given) are fitted per sample by least
    squares. Returns ``(residual, f, omega_dot)``.
    """
    w2 = skew(omega) @ skew(omega)
    k = positions.shape[0]
    if omega_dot is not None:
        pred = np.einsum("nij,kj->nki", skew(omega_dot) + w2, positions)
        f = (y - pred).mean(axis=1)
        return y - pred - f[:, None], f, omega_dot
    z = y - np.einsum("nij,kj->nki", w2, positions)
    h = np.concatenate([np.tile(np.eye(3), (k, 1, 1)), -np.stack([skew(p) for p in positions])], 2).reshape(3 * k, 6)
    sol = np.linalg.lstsq(h, z.reshape(len(z), 3 * k).T, rcond=None)[0].T
    res = (z.reshape(len(z), 3 * k) - sol @ h.T).reshape(len(z), k, 3)
    return res, sol[:, :3], sol[:, 3:]


def fit_positions(y, omega, positions0, iterations: int = 30):
    """Sensor positions by alternating least squares (f, ω̇ per sample; centroid held at the nominal one)."""
    r = positions0.copy()
    w2 = skew(omega) @ skew(omega)
    for _ in range(iterations):
        _, f, dw = rigid_residual(y, omega, r)
        a = (skew(dw) + w2).reshape(-1, 3)
        for i in range(r.shape[0]):
            r[i] = np.linalg.lstsq(a, (y[:, i] - f).reshape(-1), rcond=None)[0]
        r += positions0.mean(axis=0) - r.mean(axis=0)
    return r


def residual_study(args) -> dict:
    """Residual of the rigid-body model with the gyro's ω, and what the candidate causes explain."""
    from scipy.interpolate import CubicSpline

    fit_exp = args.fit_on
    test_exp = next((e for e in args.experiments if e != fit_exp), fit_exp)
    data = {}
    for exp in sorted({fit_exp, test_exp}):
        glog, _ = load(args.data, exp, with_gyro=True)
        glog = calib.apply_calibration(glog, calib.fit(glog))
        n = len(glog)
        t = glog.times_s
        w = glog.reference.omega_b_radps
        valid = ~glog.invalid_reference
        ok = valid.copy()
        ok[1:] &= valid[:-1]
        ok[:-1] &= valid[1:]
        idx = np.nonzero((np.linalg.norm(w, axis=1) > MOVING_RADPS) & ok)[0]
        data[exp] = dict(t=t, w=w, idx=idx, y=glog.accel_mps2.reshape(n, 8, 3), spline=CubicSpline(t, w))
    pos0 = np.array([a.position_m for a in glog.array.accelerometers])
    out = {"fit_on": fit_exp, "checked_on": test_exp}
    d = data[fit_exp]
    idx, y, w = d["idx"], d["y"][d["idx"]], d["w"][d["idx"]]
    out["moving_samples"] = int(idx.size)
    dw_gyro = np.gradient(d["w"], d["t"], axis=0)[idx]
    out["residual_gyro_omega_dot"] = _rms(rigid_residual(y, w, pos0, dw_gyro)[0])
    res, _, _ = rigid_residual(y, w, pos0)
    out["residual_free_omega_dot"] = _rms(res)
    wn = np.linalg.norm(w, axis=1)
    edges = [2, 5, 10, 15, 20, 25, 30, 35, 60]
    out["residual_by_omega"] = {f"{lo}-{hi}": _rms(res[(wn >= lo) & (wn < hi)]) for lo, hi in zip(edges[:-1], edges[1:])}
    # lag between accelerometer and gyro channels: ω taken at t + lag
    lags_ms = np.arange(-5.0, 5.01, 0.5)
    by_lag = [_rms(rigid_residual(y, d["spline"](d["t"][idx] + 1e-3 * lag), pos0)[0]) for lag in lags_ms]
    best = int(np.argmin(by_lag))
    out["lag_scan_ms"] = {f"{lag:+.1f}": v for lag, v in zip(lags_ms, by_lag)}
    out["best_lag_ms"] = float(lags_ms[best])
    out["residual_best_lag"] = by_lag[best]
    # per-sensor time offsets: residual regressed on each sensor's reading rate
    dy = np.gradient(d["y"], d["t"], axis=0)[idx]
    taus = np.array([np.sum(res[:, i] * dy[:, i]) / np.sum(dy[:, i] ** 2) for i in range(8)])
    out["sensor_time_offsets_ms"] = (1e3 * taus).tolist()
    out["residual_sensor_time_offsets"] = _rms(res - taus[None, :, None] * dy)
    # share of the residual along each sensor's reading rate (1/3 if unrelated to timing)
    u = dy / np.maximum(np.linalg.norm(dy, axis=2, keepdims=True), 1e-12)
    out["residual_share_along_rate"] = float(np.sum(np.sum(res * u, 2) ** 2) / np.sum(res**2))
    # sensor positions
    pos = fit_positions(y, w, pos0)
    out["fitted_positions_mm"] = (1e3 * pos).round(3).tolist()
    out["residual_fitted_positions"] = _rms(rigid_residual(y, w, pos)[0])
    # per-sensor dynamic gain (3x3 + bias) against the rigid-body prediction
    _, f, dw = rigid_residual(y, w, pos0)
    pred = f[:, None, :] + np.einsum("nij,kj->nki", skew(dw) + skew(w) @ skew(w), pos0)
    rg = np.empty_like(res)
    for i in range(8):
        x = np.column_stack([pred[:, i], np.ones(len(pred))])
        rg[:, i] = y[:, i] - x @ np.linalg.lstsq(x, y[:, i], rcond=None)[0]
    out["residual_dynamic_gains"] = _rms(rg)
    # dependence on the readings' content near the Nyquist rate (second difference of the array mean), at equal |ω|
    ym = d["y"].mean(axis=1)
    d2 = np.zeros_like(ym)
    d2[1:-1] = ym[2:] - 2 * ym[1:-1] + ym[:-2]
    hf = np.linalg.norm(d2, axis=1)[idx]
    per_sample = np.sqrt(np.mean(np.sum(res**2, axis=2), axis=1) / 3)
    split = {}
    for lo, hi in ((2, 10), (10, 20), (20, 30), (30, 60)):
        sel = (wn >= lo) & (wn < hi)
        med = np.median(hf[sel])
        split[f"{lo}-{hi}"] = (_rms(per_sample[sel & (hf < med)]), _rms(per_sample[sel & (hf >= med)]))
    out["residual_low_high_nyquist_content"] = split
    # full 12-unknown linear model (absorbs any rigid-body error in ω, ω̇, f)
    s = mimu4444_array().structure_matrix()
    yy = y.reshape(len(y), 24)
    out["residual_full_linear_model"] = _rms(yy - (s @ np.linalg.lstsq(s, yy.T, rcond=None)[0]).T)
    # time correlation and cross-sensor correlation of the residual
    rf = res.reshape(len(res), 24)
    nxt = np.nonzero(np.diff(idx) == 1)[0]
    out["residual_lag1_autocorrelation"] = float(np.sum(rf[nxt] * rf[nxt + 1]) / np.sqrt(np.sum(rf[nxt] ** 2) * np.sum(rf[nxt + 1] ** 2)))
    # held-out check on another recording: fitted lag and positions
    if test_exp != fit_exp:
        e = data[test_exp]
        iy, yt, wt = e["idx"], e["y"][e["idx"]], e["w"][e["idx"]]
        out["checked_residual_free_omega_dot"] = _rms(rigid_residual(yt, wt, pos0)[0])
        out["checked_residual_fitted_positions"] = _rms(rigid_residual(yt, wt, pos)[0])
        out["checked_residual_best_lag"] = _rms(rigid_residual(yt, e["spline"](e["t"][iy] + 1e-3 * out["best_lag_ms"]), pos0)[0])
        out["checked_residual_lag_and_positions"] = _rms(
            rigid_residual(yt, e["spline"](e["t"][iy] + 1e-3 * out["best_lag_ms"]), pos)[0])
    return out


def print_residual(r: dict) -> None:
    print(f"\nRigid-body residual with ω from the gyro reference (exp_{r['fit_on']}, {r['moving_samples']} moving samples, "
          "calibrated, RMS per axis, m/s²):")
    print(f"  ω̇ from gyro differences:           {r['residual_gyro_omega_dot']:.3f}")
    print(f"  ω̇ (and f) fitted per sample:        {r['residual_free_omega_dot']:.3f}")
    print(f"  + accel/gyro lag {r['best_lag_ms']:+.1f} ms (best):    {r['residual_best_lag']:.3f}")
    print(f"  + per-sensor time offsets:          {r['residual_sensor_time_offsets']:.3f}  "
          f"(offsets {np.round(r['sensor_time_offsets_ms'], 2).tolist()} ms)")
    print(f"  + fitted sensor positions:          {r['residual_fitted_positions']:.3f}")
    print(f"  + per-sensor dynamic 3x3 gains:     {r['residual_dynamic_gains']:.3f}")
    print(f"  full 12-unknown linear model:       {r['residual_full_linear_model']:.3f}  (floor for any rigid-body fix)")
    print(f"  lag-1 autocorrelation {r['residual_lag1_autocorrelation']:.3f}; share along the reading rate "
          f"{r['residual_share_along_rate']:.3f} (1/3 if unrelated)")
    print("  by |ω| (rad/s): " + ", ".join(f"{k}: {v:.2f}" for k, v in r["residual_by_omega"].items()))
    print("  at equal |ω|, samples with less / more content near Nyquist (2nd difference of the array mean): "
          + ", ".join(f"{k}: {a:.2f} / {b:.2f}" for k, (a, b) in r["residual_low_high_nyquist_content"].items()))
    print("  fitted positions (mm): " + "; ".join(", ".join(f"{c:+.2f}" for c in p) for p in r["fitted_positions_mm"]))
    if "checked_residual_free_omega_dot" in r:
        print(f"  held out (exp_{r['checked_on']}): nominal {r['checked_residual_free_omega_dot']:.3f}, fitted positions "
              f"{r['checked_residual_fitted_positions']:.3f}, lag {r['checked_residual_best_lag']:.3f}, both "
              f"{r['checked_residual_lag_and_positions']:.3f}")


def parse_method_options(items: list[str]) -> dict:
    from gfimu.cli.options import parse_options

    out: dict = {}
    for item in items:
        if ":" not in item:
            raise SystemExit(f"--option expects METHOD:KEY=VALUE, got {item!r}")
        method, pair = item.split(":", 1)
        out.setdefault(method, {}).update(parse_options([pair]))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder holding exp_1..3/data.bin")
    p.add_argument("--experiments", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--methods", nargs="*", default=[m for m in METHODS if m not in NEEDS_GYRO],
                   help="methods to compare (default: every accelerometer-only method)")
    p.add_argument("--calibration", nargs="+", choices=["none", "within", "cross"], default=["within"])
    p.add_argument("--fit-on", type=int, default=1, help="recording whose still periods give the 'cross' calibration")
    p.add_argument("--calibration-until-s", type=float, default=None,
                   help="fit calibrations on the first seconds only (the static phase)")
    p.add_argument("--seconds", type=float, default=None, help="estimate only the first SECONDS of each recording")
    p.add_argument("--reference-shift-ms", type=float, default=0.0,
                   help="evaluate against the gyro reference re-sampled at t + SHIFT (-1.5 aligns it with the accelerometers)")
    p.add_argument("--noise-std", type=float, default=None,
                   help="accelerometer noise std (m/s²) written into the array model (default: the layout's 0.05)")
    p.add_argument("--option", action="append", default=[], metavar="METHOD:KEY=VALUE", help="method option, repeatable")
    p.add_argument("--preset", default=None, metavar="NAME",
                   help="named smoother settings (gfimu.smoother.model.presets); --option smoother:KEY=VALUE wins over it")
    p.add_argument("--start-at-reference", action="store_true",
                   help="start the smoother's ω at the gyro reference (other states from its initialisation)")
    p.add_argument("--bound", action="store_true",
                   help="also print the smoother's own bound at the reference trajectory (with the noise slope)")
    p.add_argument("--residual", action="store_true", help="also run the rigid-body residual investigation")
    p.add_argument("--breakdown", action="store_true",
                   help="print where the ω error sits (distance to gyro saturation, |ω|, |ω̇|) for each method")
    p.add_argument("--json", type=Path, default=None, help="write all numbers to this JSON file")
    p.add_argument("--progress", action="store_true")
    args = p.parse_args(argv)
    args.options = parse_method_options(args.option)
    if args.preset is not None:
        from gfimu.smoother.model.presets import apply_preset

        try:
            args.options["smoother"] = apply_preset(args.preset, args.options.get("smoother", {}))
        except ValueError as exc:
            raise SystemExit(str(exc)) from None
    result: dict = {}
    if args.methods:
        rows = compare(args)
        print()
        print(table(rows))
        result["methods"] = rows
    if args.residual:
        r = residual_study(args)
        print_residual(r)
        result["residual"] = r
    if args.json:
        args.json.write_text(json.dumps(result, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
