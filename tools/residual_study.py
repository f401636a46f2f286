#!/usr/bin/env python3
"""What the rigid-body residual of a real array is made of (MIMU4444 recordings).

For each recording: decode with the gyros, calibrate on its own still periods (as
``gfimu calibrate`` does), keep the moving, unsaturated samples (|ω_ref| > 2 rad/s,
reference valid) and look at the readings' disagreement with a rigid body:

- ``R6``: ω from the gyro reference (the study only; the estimator never reads it),
  f and ω̇ fitted per sample (6 unknowns, 18 residual degrees of freedom of 24);
- ``R12``: the 12 linear unknowns [f, ω̇, q(ω)] free per sample (no gyro; 12 dof).

Each candidate cause is fitted and its *share* of the residual variance is reported
(1 − variance after / variance before, degrees of freedom of the added unknowns
accounted for by fitting on the first half of the moving samples and scoring on the
second):

- per-sensor sample-time offsets and first-order lags (DLPF differences): the residual
  regressed on each sensor's reading rate (to first order a delay τ and a lag of time
  constant τ add the same ``-τ ẏ``);
- per-sensor dynamic gains (3×3, misalignment and cross-axis, plus bias) fitted jointly
  with the motion, without gyros (alternating with the 12-unknown per-sample fit);
- sensor positions (lever arms), with the gyro's ω;
- a scale error of the gyro reference: the ω scale that minimises R6, and the scale the
  accelerometers' own quadratic terms imply;
- motion-dependent noise: the variance model ``E[r²] = σ₀² + (s |ω|)² + (τ |ẏ|)²`` per
  axis (|ẏ| the axis's own reading rate: random sample-time jitter of size τ), compared by
  Gaussian log-likelihood, by the share of the residual variance the motion-dependent
  terms carry and by the tails of the whitened residual;
- aliasing: the residual's spectrum (share of its power above half the Nyquist rate;
  white noise puts half there) and the readings' spectrum near Nyquist.

    python3 tools/residual_study.py --data ../shared/data/mimu4444   # exp_1 (study), exp_2, exp_3 (checked)
    python3 tools/residual_study.py --experiments 1 --json out.json
    python3 tools/residual_study.py --experiments 1 --estimate est1.csv   # + where an estimate's errors are

``--estimate`` (one ω estimate per experiment, e.g. the ``est.csv`` of ``gfimu estimate``) adds
where its errors sit against the gyro reference on the moving, unsaturated samples: by |ω_ref|,
by distance to the nearest clipped gyro sample, the share of the squared error in the largest
1 % and 5 %, the wrong-sign share by |ω_ref|, along / across ω_ref, and the part a constant
delay of the reference explains (reported only; the scoring never shifts the reference).

The findings are in docs/rigid-body-residual.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gfimu import calibration as calib  # noqa: E402
from gfimu.io.readers.mimu4444 import read_mimu4444  # noqa: E402
from gfimu.rigid_body import quadratic_terms  # noqa: E402
from gfimu.rotations import skew  # noqa: E402

DEFAULT_DATA = REPO.parent / "shared" / "data" / "mimu4444"
MOVING_RADPS = 2.0


def load(data: Path, exp: int) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = read_mimu4444(data / f"exp_{exp}" / "data.bin", with_gyro=True)
        log = calib.apply_calibration(log, calib.fit(log))
    n = len(log)
    t = log.times_s
    w = log.reference.omega_b_radps
    ok = ~log.invalid_reference
    ok[1:] &= ok[:-1].copy()
    ok[:-1] &= ok[1:].copy()
    ok[[0, -1]] = False
    idx = np.nonzero((np.linalg.norm(w, axis=1) > MOVING_RADPS) & ok)[0]
    y_all = log.accel_mps2.reshape(n, -1, 3)
    ydot = np.gradient(y_all, t, axis=0)
    pos = np.array([a.position_m for a in log.array.accelerometers])
    S = log.array.structure_matrix()
    return dict(t=t, w_all=w, idx=idx, y_all=y_all, y=y_all[idx], w=w[idx], ydot=ydot[idx], pos=pos, S=S,
                stated=float(np.mean(log.array.noise_std_per_axis_mps2)), log=log)


# --- residuals --------------------------------------------------------------------

def residual6(y, omega, pos):
    """(N, k, 3) residual with ω given, f and ω̇ fitted per sample; (residual, f, ω̇)."""
    k = pos.shape[0]
    z = y - np.einsum("nij,kj->nki", skew(omega) @ skew(omega), pos)
    h = np.concatenate([np.tile(np.eye(3), (k, 1, 1)), -np.stack([skew(p) for p in pos])], 2).reshape(3 * k, 6)
    sol = np.linalg.lstsq(h, z.reshape(len(z), 3 * k).T, rcond=None)[0].T
    return (z.reshape(len(z), 3 * k) - sol @ h.T).reshape(z.shape), sol[:, :3], sol[:, 3:]


def residual12(y, S):
    """(N, k, 3) residual with all 12 linear unknowns free per sample; (residual, x (N, 12))."""
    yy = y.reshape(len(y), -1)
    x = np.linalg.lstsq(S, yy.T, rcond=None)[0].T
    return (yy - x @ S.T).reshape(y.shape), x


def var(r) -> float:
    return float(np.mean(np.square(r)))


def halves(n):
    h = n // 2
    return np.arange(h), np.arange(h, n)


# --- candidate causes -------------------------------------------------------------

def time_offsets(res, ydot, fit=None):
    """Per-sensor τ_i of ``res ≈ -τ_i ẏ_i`` (least squares on ``fit``); (τ (k,), residual)."""
    sel = slice(None) if fit is None else fit
    tau = np.array([-np.sum(res[sel, i] * ydot[sel, i]) / np.sum(ydot[sel, i] ** 2) for i in range(res.shape[1])])
    return tau, res + tau[None, :, None] * ydot


def projected(res, S):
    """The part of a per-axis correction the 12-unknown fit cannot absorb (project out S's span)."""
    yy = res.reshape(len(res), -1)
    P = np.eye(S.shape[0]) - S @ np.linalg.pinv(S)
    return (yy @ P.T).reshape(res.shape)


def dynamic_gains(y, S, fit, iterations=8):
    """Per-sensor 3×3 gain + bias fitted jointly with the 12 per-sample unknowns (no gyro) on ``fit``;
    mean gain held at identity and mean bias at zero (else absorbed by the motion). Returns the
    correction function ``y -> corrected``."""
    k = y.shape[1]
    G = np.tile(np.eye(3), (k, 1, 1))
    b = np.zeros((k, 3))
    for _ in range(iterations):
        yc = np.einsum("kij,nkj->nki", G, y[fit]) + b
        _, x = residual12(yc, S)
        pred = (x @ S.T).reshape(yc.shape)
        for i in range(k):
            a = np.column_stack([y[fit, i], np.ones(len(fit))])
            sol = np.linalg.lstsq(a, pred[:, i], rcond=None)[0]
            G[i], b[i] = sol[:3].T, sol[3]
        Gm = np.linalg.inv(G.mean(axis=0))
        G = Gm[None] @ G
        b = b @ Gm.T
        b -= b.mean(axis=0)
    return G, b, (lambda yy: np.einsum("kij,nkj->nki", G, yy) + b)


def fit_positions(y, omega, pos0, fit, iterations=20):
    r = pos0.copy()
    w2 = skew(omega[fit]) @ skew(omega[fit])
    for _ in range(iterations):
        _, f, dw = residual6(y[fit], omega[fit], r)
        a = (skew(dw) + w2).reshape(-1, 3)
        for i in range(r.shape[0]):
            r[i] = np.linalg.lstsq(a, (y[fit, i] - f).reshape(-1), rcond=None)[0]
        r += pos0.mean(axis=0) - r.mean(axis=0)
    return r


def gyro_scale(d, fit):
    """(scale minimising R6 on ``fit``, scale implied by the accelerometers' quadratic terms)."""
    scales = np.linspace(0.9, 1.1, 41)
    v = [var(residual6(d["y"][fit], s * d["w"][fit], d["pos"])[0]) for s in scales]
    i = int(np.argmin(v))
    lo, hi = max(i - 2, 0), min(i + 3, len(scales))
    c = np.polyfit(scales[lo:hi], v[lo:hi], 2)
    best = float(-c[1] / (2 * c[0])) if c[0] > 0 else float(scales[i])
    # q(ω) from the 12-unknown fit against q(ω_ref): the diagonal terms scale with k²
    _, x = residual12(d["y"][fit], d["S"])
    q_ref = quadratic_terms(d["w"][fit])[:, :3]
    q_acc = x[:, 6:9]
    k2 = float(np.sum(q_acc * q_ref) / np.sum(q_ref**2))
    return best, float(np.sqrt(max(k2, 0.0)))


def variance_models(res, omega, ydot, nyquist, dof_factor, fit, test):
    """Per-axis variance models E[r²]·dof = a + b|ω|² + c ẏ² + e |Δ²ȳ|², fitted by least squares on r²
    over ``fit`` (ẏ: the axis's own reading rate; Δ²ȳ: second difference of the array-mean reading, the
    readings' content near the Nyquist rate), scored by mean Gaussian log-likelihood per axis on
    ``test``, the share of the motion-dependent terms in the residual variance and the whitened
    residual's tail share (beyond 4) and kurtosis."""
    r2 = res**2 * dof_factor
    wn2 = np.broadcast_to((np.linalg.norm(omega, axis=1) ** 2)[:, None, None], res.shape)
    yd2 = ydot**2
    ny2 = np.broadcast_to((nyquist**2)[:, None, None], res.shape)
    cols = {"constant": [], "omega": [wn2], "reading rate": [yd2], "near Nyquist": [ny2],
            "omega + reading rate": [wn2, yd2], "omega + near Nyquist": [wn2, ny2]}
    out = {}
    for name, extra in cols.items():
        A = np.column_stack([np.ones(r2[fit].size)] + [e[fit].ravel() for e in extra])
        coef = np.linalg.lstsq(A, r2[fit].ravel(), rcond=None)[0]
        coef = np.maximum(coef, 0.0)
        coef[0] = max(coef[0], 1e-6)

        def model(sel):
            return coef[0] + sum(c * e[sel] for c, e in zip(coef[1:], extra))

        v = model(test)
        z = res[test] * np.sqrt(dof_factor) / np.sqrt(v)
        ll = float(np.mean(-0.5 * np.log(2 * np.pi * v) - 0.5 * z**2))
        motion_share = float(1.0 - coef[0] / np.mean(v))
        out[name] = dict(coef=coef.tolist(), loglik=ll, motion_share=motion_share,
                         tail=float(np.mean(np.abs(z) > 4.0)), kurtosis=float(np.mean(z**4) / np.mean(z**2) ** 2))
    return out


def spectra(d, res, fs):
    """Share of the residual's power above fs/4 (white: 0.5) and of the readings' rate-of-change power
    above fs/4, on the contiguous moving stretches."""
    idx = d["idx"]
    breaks = np.nonzero(np.diff(idx) != 1)[0] + 1
    segs = np.split(np.arange(len(idx)), breaks)
    n = 32
    pr = np.zeros(n // 2 + 1)
    py = np.zeros(n // 2 + 1)
    win = np.hanning(n)
    ym = d["y"] - d["y"].mean(axis=1, keepdims=True)  # per-sensor departure from the array mean
    for s in segs:
        for start in range(0, len(s) - n + 1, n // 2):
            j = s[start:start + n]
            pr += np.sum(np.abs(np.fft.rfft(res[j] * win[:, None, None], axis=0)) ** 2, axis=(1, 2))
            py += np.sum(np.abs(np.fft.rfft(d["y"][j].mean(axis=1) * win[:, None], axis=0)) ** 2, axis=1)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    hi = f > fs / 4
    return dict(residual_high_share=float(pr[hi].sum() / pr.sum()), readings_high_share=float(py[hi].sum() / py.sum()),
                residual_psd=(pr / pr.sum()).round(4).tolist(), freq_hz=f.round(2).tolist(), departures_rms=var(ym) ** 0.5)


def study(d, fs) -> dict:
    y, w, pos, S, ydot = d["y"], d["w"], d["pos"], d["S"], d["ydot"]
    n = len(y)
    fit, test = halves(n)
    r6, _, _ = residual6(y, w, pos)
    r12, _ = residual12(y, S)
    v6, v12 = var(r6[test]), var(r12[test])
    out = dict(moving=n, rms_r6=np.sqrt(var(r6)), rms_r12=np.sqrt(var(r12)))
    wn = np.linalg.norm(w, axis=1)
    edges = [2, 5, 10, 20, 30, 60]
    out["rms_r12_by_omega"] = {f"{a}-{b}": np.sqrt(var(r12[(wn >= a) & (wn < b)])) for a, b in zip(edges[:-1], edges[1:])}
    # per-sensor time offsets / first-order lags
    tau6, c6 = time_offsets(r6, ydot, fit)
    tau12, _ = time_offsets(r12, ydot, fit)
    c12 = projected(r12 + tau12[None, :, None] * ydot, S)
    out["time_offsets_ms"] = (1e3 * tau6).round(3).tolist()
    out["share_time_offsets_r6"] = 1 - var(c6[test]) / v6
    out["share_time_offsets_r12"] = 1 - var(c12[test]) / v12
    u = ydot / np.maximum(np.linalg.norm(ydot, axis=2, keepdims=True), 1e-12)
    out["share_along_rate"] = float(np.sum(np.sum(r12 * u, 2) ** 2) / np.sum(r12**2))
    # dynamic gains, no gyro
    G, b, corr = dynamic_gains(y, S, fit)
    out["gain_deviation_max"] = float(np.max(np.abs(G - np.eye(3))))
    out["share_dynamic_gains_r12"] = 1 - var(residual12(corr(y[test]), S)[0]) / v12
    # positions (gyro ω)
    p = fit_positions(y, w, pos, fit)
    out["position_change_mm"] = float(1e3 * np.max(np.linalg.norm(p - pos, axis=1)))
    out["share_positions_r6"] = 1 - var(residual6(y[test], w[test], p)[0]) / v6
    # gyro scale
    k_fit, k_acc = gyro_scale(d, fit)
    out["gyro_scale_minimising_r6"] = k_fit
    out["gyro_scale_from_accelerometers"] = k_acc
    out["share_gyro_scale_r6"] = 1 - var(residual6(y[test], k_fit * w[test], pos)[0]) / v6
    # accelerometer/gyro lag
    from scipy.interpolate import CubicSpline
    spl = CubicSpline(d["t"], d["w_all"])
    lags = np.arange(-4.0, 4.01, 0.5)
    vl = [var(residual6(y, spl(d["t"][d["idx"]] + 1e-3 * lag), pos)[0][test]) for lag in lags]
    out["gyro_lag_ms"] = float(lags[int(np.argmin(vl))])
    out["share_gyro_lag_r6"] = 1 - min(vl) / v6
    # motion-dependent noise (on the gyro-free residual)
    ym = d["y_all"].mean(axis=1)
    i = d["idx"]
    nyq = np.linalg.norm(ym[i + 1] - 2 * ym[i] + ym[i - 1], axis=1)
    out["variance_models_r12"] = variance_models(r12, w, ydot, nyq, 24 / 12, fit, test)
    # the whitened residual's law: Student-t by maximum likelihood (the robust loss it implies)
    from scipy import stats
    coef = out["variance_models_r12"]["omega"]["coef"]
    z = (r12 * np.sqrt(2.0) / np.sqrt(coef[0] + coef[1] * wn**2)[:, None, None]).ravel()
    nu, _, scale = stats.t.fit(z, floc=0)
    out["student_t_nu"], out["student_t_scale"] = float(nu), float(scale)
    out["correlation_log_power"] = {name: float(np.corrcoef(np.log(np.mean(r12**2, axis=(1, 2))), np.log(v + 1e-12))[0, 1])
                                    for name, v in (("|ω|", wn), ("|Δ²ȳ| near Nyquist", nyq),
                                                    ("|ẏ| reading rate", np.linalg.norm(ydot, axis=(1, 2))))}
    # aliasing / content near Nyquist
    out["spectra"] = spectra(d, r12, fs)
    # at equal |ω|, residual against the reading-rate content
    rate = np.sqrt(np.mean(ydot**2, axis=(1, 2)))
    ps = np.sqrt(np.mean(r12**2, axis=(1, 2)))
    split = {}
    for lo, hi in ((2, 10), (10, 20), (20, 60)):
        sel = (wn >= lo) & (wn < hi)
        med = np.median(rate[sel])
        split[f"{lo}-{hi}"] = (float(np.sqrt(np.mean(ps[sel & (rate < med)] ** 2))), float(np.sqrt(np.mean(ps[sel & (rate >= med)] ** 2))))
    out["r12_low_high_rate_at_equal_omega"] = split
    sel = np.argsort(rate)
    q = len(sel) // 4
    # structure across the axes: principal components of the residual whitened by its |ω| model
    coef = out["variance_models_r12"]["omega"]["coef"]
    rw = r12.reshape(n, -1) / np.sqrt(coef[0] + coef[1] * wn**2)[:, None]
    sv = np.linalg.svd(rw, compute_uv=False) ** 2
    out["principal_shares"] = (sv[:12] / sv.sum()).tolist()
    nxt = np.nonzero(np.diff(d["idx"]) == 1)[0]
    rf = r12.reshape(n, -1)
    out["lag1_autocorrelation"] = float(np.sum(rf[nxt] * rf[nxt + 1]) / np.sqrt(np.sum(rf[nxt] ** 2) * np.sum(rf[nxt + 1] ** 2)))
    out["r12_by_rate_quartile"] = [float(np.sqrt(np.mean(ps[sel[i * q:(i + 1) * q]] ** 2))) for i in range(4)]
    out["stated_noise"] = d["stated"]
    # per-sample conditioning of the layout: std of each linear unknown per unit axis noise
    out["unknown_std_per_unit_noise"] = np.sqrt(np.diag(np.linalg.pinv(S.T @ S))).tolist()
    return out


def error_breakdown(d, estimate_csv: Path) -> dict:
    """Where the errors of an ω estimate sit (see the module docstring)."""
    from gfimu import io as gio

    log = d["log"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = gio.read_motion_csv(estimate_csv).omega_b_radps
    ref = log.reference.omega_b_radps
    inv = log.invalid_reference
    mov = ~inv & (np.linalg.norm(ref, axis=1) > MOVING_RADPS)
    E = est - ref
    err2 = np.sum(E**2, axis=1)
    total = float(np.sum(err2[mov]))
    out = {"rmse": float(np.sqrt(np.mean(err2[mov]))), "median": float(np.median(np.sqrt(err2[mov])))}
    srt = np.sort(err2[mov])[::-1]
    out["top1_share"] = float(srt[: max(len(srt) // 100, 1)].sum() / total)
    out["top5_share"] = float(srt[: max(len(srt) // 20, 1)].sum() / total)
    wn = np.linalg.norm(ref, axis=1)
    wrong = np.sum(est * ref, axis=1) < 0
    out["by_omega"] = {}
    for lo, hi in ((2, 5), (5, 10), (10, 20), (20, 30), (30, 40)):
        sel = mov & (wn >= lo) & (wn < hi)
        out["by_omega"][f"{lo}-{hi}"] = dict(n=int(sel.sum()), rmse=float(np.sqrt(np.mean(err2[sel]))),
                                              share=float(np.sum(err2[sel]) / total), wrong=float(np.mean(wrong[sel])))
    clipped = np.nonzero(inv)[0]
    k = np.arange(len(ref))
    if clipped.size:
        p = np.searchsorted(clipped, k)
        dist = np.minimum(np.abs(k - clipped[np.clip(p - 1, 0, clipped.size - 1)]),
                          np.abs(clipped[np.clip(p, 0, clipped.size - 1)] - k))
    else:
        dist = np.full(len(ref), 10**9)
    out["by_distance_to_clipped"] = {}
    for lo, hi in ((1, 2), (2, 4), (4, 8), (8, 10**9)):
        sel = mov & (dist >= lo) & (dist < hi)
        out["by_distance_to_clipped"][f"{lo}-{hi if hi < 10**9 else 'inf'}"] = dict(
            n=int(sel.sum()), rmse=float(np.sqrt(np.mean(err2[sel]))) if sel.any() else float("nan"),
            share=float(np.sum(err2[sel]) / total))
    u = ref[mov] / wn[mov, None]
    along = np.sum(E[mov] * u, axis=1)
    out["rms_along_ref"] = float(np.sqrt(np.mean(along**2)))
    out["rms_across_ref"] = float(np.sqrt(np.mean(np.sum((E[mov] - along[:, None] * u) ** 2, axis=1))))
    # a constant delay of the reference: E ≈ τ ω̇_ref (samples with valid neighbours)
    wd = np.gradient(ref, log.times_s, axis=0)
    m = mov.copy()
    m[[0, -1]] = False
    m[1:] &= ~inv[:-1]
    m[:-1] &= ~inv[1:]
    tau = float(np.sum(E[m] * wd[m]) / np.sum(wd[m] ** 2))
    out["reference_delay_ms"] = 1e3 * tau
    out["rmse_with_neighbours"] = float(np.sqrt(np.mean(err2[m])))
    out["rmse_reference_delay_removed"] = float(np.sqrt(np.mean(np.sum((E[m] - tau * wd[m]) ** 2, axis=1))))
    return out


def report_errors(exp, b) -> None:
    print(f"  estimate: RMSE {b['rmse']:.2f}, median {b['median']:.2f} rad/s; largest 1 % of the errors carry "
          f"{100 * b['top1_share']:.0f} % of the squared error, largest 5 % {100 * b['top5_share']:.0f} %")
    print("    by |ω_ref| [rad/s]: " + "; ".join(f"{k}: n {v['n']}, RMSE {v['rmse']:.2f}, share {100 * v['share']:.0f} %, "
                                                 f"wrong sign {100 * v['wrong']:.1f} %" for k, v in b["by_omega"].items()))
    print("    by distance to the nearest clipped gyro sample [samples]: " + "; ".join(
        f"{k}: n {v['n']}, RMSE {v['rmse']:.2f}, share {100 * v['share']:.0f} %" for k, v in b["by_distance_to_clipped"].items()))
    print(f"    along ω_ref {b['rms_along_ref']:.2f}, across {b['rms_across_ref']:.2f} rad/s; the reference lags by "
          f"{-b['reference_delay_ms']:.2f} ms: RMSE {b['rmse_with_neighbours']:.2f} -> {b['rmse_reference_delay_removed']:.2f} "
          "with that delay removed (samples with valid neighbours; reported only)")


def report(exp, r) -> None:
    print(f"\nexp_{exp}: {r['moving']} moving samples; RMS per axis [m/s²]: R6 (gyro ω) {r['rms_r6']:.3f}, "
          f"R12 (12 unknowns, no gyro) {r['rms_r12']:.3f}; stated noise {r['stated_noise']:.3f}")
    print("  R12 by |ω| [rad/s]: " + ", ".join(f"{k}: {v:.2f}" for k, v in r["rms_r12_by_omega"].items()))
    print("  share of the residual variance explained (fitted on the first half, scored on the second):")
    print(f"    per-sensor time offsets / first-order lags: R6 {100 * r['share_time_offsets_r6']:.1f} %, "
          f"R12 {100 * r['share_time_offsets_r12']:.1f} % (τ {r['time_offsets_ms']} ms); "
          f"share along the reading rate {r['share_along_rate']:.3f} (1/3 if unrelated)")
    print(f"    per-sensor dynamic 3x3 gains + bias, no gyro: R12 {100 * r['share_dynamic_gains_r12']:.1f} % "
          f"(largest gain deviation {r['gain_deviation_max']:.4f})")
    print(f"    sensor positions: R6 {100 * r['share_positions_r6']:.1f} % (largest move {r['position_change_mm']:.2f} mm)")
    print(f"    gyro scale: R6 {100 * r['share_gyro_scale_r6']:.2f} % at scale {r['gyro_scale_minimising_r6']:.4f}; "
          f"the accelerometers' quadratic terms imply {r['gyro_scale_from_accelerometers']:.4f}")
    print(f"    accelerometer/gyro lag: R6 {100 * r['share_gyro_lag_r6']:.1f} % at {r['gyro_lag_ms']:+.1f} ms")
    print("  variance models of R12 (held-out mean log-likelihood per axis; motion share; |z| > 4; kurtosis):")
    for k, v in r["variance_models_r12"].items():
        print(f"    {k:22s} {v['loglik']:+.3f}  {100 * v['motion_share']:5.1f} %  {100 * v['tail']:.2f} %  "
              f"{v['kurtosis']:.1f}   coef {np.round(v['coef'], 6).tolist()}")
    print(f"  whitened by the |ω| model, the residual is Student-t with ν = {r['student_t_nu']:.2f}, scale "
          f"{r['student_t_scale']:.2f} (a Cauchy-form loss at √(ν+1) = {np.sqrt(r['student_t_nu'] + 1):.2f} of "
          f"σ' = scale·√(ν/(ν+1)) = {r['student_t_scale'] * np.sqrt(r['student_t_nu'] / (r['student_t_nu'] + 1)):.2f})")
    print("  correlation of the log residual power with the log of: "
          + ", ".join(f"{k} {v:.2f}" for k, v in r["correlation_log_power"].items()))
    sd = r["unknown_std_per_unit_noise"]
    print("  per-sample std of the 12 unknowns per 1 m/s² of axis noise: f " + ", ".join(f"{v:.2f}" for v in sd[:3])
          + "; ω̇ " + ", ".join(f"{v:.0f}" for v in sd[3:6]) + "; q(ω) [xx+yy, xx+zz, yy+zz, xy, xz, yz] "
          + ", ".join(f"{v:.0f}" for v in sd[6:]))
    print(f"  principal components of R12 (12 dims, isotropic 8.3 % each): largest "
          + ", ".join(f"{100 * v:.1f} %" for v in r["principal_shares"][:3]) + f", smallest {100 * r['principal_shares'][-1]:.1f} %; "
          f"lag-1 autocorrelation {r['lag1_autocorrelation']:.3f}")
    s = r["spectra"]
    print(f"  spectra: residual power above fs/4 {100 * s['residual_high_share']:.0f} % (white 50 %); "
          f"array-mean reading power above fs/4 {100 * s['readings_high_share']:.1f} %")
    print("  residual PSD share by bin: " + ", ".join(f"{f:.0f} Hz {100 * p:.0f}%" for f, p in zip(s["freq_hz"], s["residual_psd"])))
    print("  R12 at equal |ω|, samples with slower / faster reading change: "
          + ", ".join(f"{k}: {a:.2f} / {b:.2f}" for k, (a, b) in r["r12_low_high_rate_at_equal_omega"].items()))
    print("  R12 by quartile of the reading rate: " + ", ".join(f"{v:.2f}" for v in r["r12_by_rate_quartile"]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--experiments", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--estimate", type=Path, nargs="*", default=[],
                    help="ω estimates (CSV), one per experiment in the order given: adds where their errors are")
    args = ap.parse_args(argv)
    rows = {}
    for exp in args.experiments:
        path = args.data / f"exp_{exp}" / "data.bin"
        if not path.is_file():
            print(f"{path} not found, skipped")
            continue
        d = load(args.data, exp)
        fs = 1.0 / float(np.median(np.diff(d["t"])))
        rows[exp] = study(d, fs)
        report(exp, rows[exp])
        k = args.experiments.index(exp)
        if k < len(args.estimate):
            rows[exp]["errors"] = error_breakdown(d, args.estimate[k])
            report_errors(exp, rows[exp]["errors"])
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
