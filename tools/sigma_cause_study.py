#!/usr/bin/env python3
"""Why σ stays too small on some cells of tools/sigma_coverage.py: two causes no scaling of σ by the residuals'
level can see, with the figures behind docs/uncertainty.md.

1. **Calibration errors along the states** (``--only calibration``; positions-2mm-off-500Hz, mimu-like-62Hz and,
   for comparison, cells whose misfit is not a calibration error). The batch smoother's parity residuals p_i
   (:func:`gfimu.smoother.solve.sigma_scale.parity`) are fitted by least squares with a constant error of the
   array's calibration: each sensor's position (3 per sensor: a reading error R_sᵀ([ω̇]× + [ω]×²) δr_s) and
   each axis' gain (the predicted reading times δg_a), whitened and projected off the Jacobian's columns as p
   is. Printed: the fitted errors, the share of the parity power they explain, the state bias they imply
   (B_i δ̂ with B_i = (Σ_k J_kᵀ J_k)⁻¹ Σ_k J_kᵀ G_k over the 64 samples around i: the information-weighted
   mean of each sample's own bias), its correlation with the true error per axis, and the coverage of three
   candidate σ: today's (scaled), today's with that bias added in quadrature, and the level of the cleaned
   parity residual plus that bias; then the smoother's own bias: its estimate less the one on the log with the
   fitted errors taken out (:func:`corrected_log`). None of the σ is right on every cell (docs/uncertainty.md).
   MIMU4444 recordings given as arguments: the same on their moving rows, against the board's gyros.
2. **The fixed-lag smoother's hand-over** (``--only handover``; turntable-0.3m-unstated): the states of the
   first tuning stretch are the batch smoother's on it; at ``tune_window_s`` − lag the stream's own window
   takes over. Printed for three ``tune_window_s``: the largest step of the x error, where it sits, and σ_x.

    python3 tools/sigma_cause_study.py [--only calibration|handover] [--cells NAME,...] [data.bin ...]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import sigma_coverage as sc  # noqa: E402

CALIBRATION_CELLS = ("positions-2mm-off-500Hz", "mimu-like-62Hz", "scale-1pc-200Hz", "misfit-ar0.95-200Hz",
                     "vibration-37Hz-200Hz", "handheld-50radps")
SPAN = 64
"""Samples over which one sample's calibration bias is averaged (sigma_scale.MAX_LAG: the longest span)."""


def _cell(name: str) -> sc.MisfitCell:
    return next(c for c in sc.CELLS if c.name == name)


def _captured(log):
    """The inputs and output of the batch smoother's σ scaling on ``log`` (states, model σ, noise, robust)."""
    from gfimu.methods import make_estimator
    from gfimu.smoother.batch import engine as batch

    seen = {}
    original = batch.calibrated_sigma

    def hook(array, accel, states, sd, noise, robust=None, **kwargs):
        out = original(array, accel, states, sd, noise, robust, **kwargs)
        seen.update(states=np.array(states[:, :9]), noise=np.array(noise), robust=robust, scaled=np.array(out[:, :3]))
        return out

    batch.calibrated_sigma = hook
    try:
        make_estimator("smoother", compute_sigma=True).estimate(log)
    finally:
        batch.calibrated_sigma = original
    return seen


def _shares(e: np.ndarray, sd: np.ndarray) -> str:
    z = e / sd
    return (f"1σ {'/'.join(f'{100 * v:.0f}' for v in (np.abs(z) < 1).mean(axis=0))} %, "
            f"2σ {'/'.join(f'{100 * v:.0f}' for v in (np.abs(z) < 2).mean(axis=0))} %, NEES {np.mean(np.sum(z * z, axis=1)):.2f}")


def calibration_fit(array, accel: np.ndarray, states: np.ndarray, noise: np.ndarray, robust=None) -> dict:
    """The parity residuals of ``accel`` (N, m) at ``states`` (N, ≥9) with the noise std ``noise`` (N, m) or (m,)
    and the robust weights ``robust`` (as :func:`gfimu.smoother.solve.sigma_scale.parity`) fitted by least
    squares with constant errors of the positions (3 per triad, metres) and the gains (1 per axis): ``errors``
    (the fitted ones: positions first, then gains), ``explained`` (the share of the parity power they explain),
    ``level`` and ``cleaned`` (the parity power over its degrees of freedom, before and after), ``rank`` (of the
    fit), ``J`` (N, m, 9) and ``G`` (N, m, 3 triads + m) (the whitened Jacobians of the states and of the errors)."""
    from gfimu.rigid_body import quadratic_terms, quadratic_terms_jacobian
    from gfimu.rotations import skew
    from gfimu.smoother.model.problem import robust_weight

    y, X = np.asarray(accel, dtype=float), np.asarray(states, dtype=float)
    S = array.structure_matrix()
    S_f, S_dw, S_q = S[:, 0:3], S[:, 3:6], S[:, 6:12]
    n, m = y.shape
    w, dw, f = X[:, 0:3], X[:, 3:6], X[:, 6:9]
    predicted = f @ S_f.T + dw @ S_dw.T + quadratic_terms(w) @ S_q.T
    inv = 1.0 / np.broadcast_to(np.asarray(noise, dtype=float), y.shape)
    z = (y - predicted) * inv
    if robust is not None:
        weight = np.sqrt(robust_weight(z, float(robust[1]), robust[0]))
        z, inv = z * weight, inv * weight
    J = np.concatenate([np.einsum("mk,nkj->nmj", S_q, quadratic_terms_jacobian(w)), np.broadcast_to(S_dw, (n, m, 3)),
                        np.broadcast_to(S_f, (n, m, 3))], axis=2) * inv[:, :, None]
    U, s, _ = np.linalg.svd(J, full_matrices=False)
    keep = s > 1e-6 * s[:, :1]
    Uk = U * keep[:, None, :]
    project = lambda A: A - np.einsum("nmr,nr...->nm...", Uk, np.einsum("nmr,nm...->nr...", Uk, A))
    p = project(z)
    dof = float(m * n - np.count_nonzero(keep))
    owner = np.asarray(array.axis_owner)
    triads = int(owner.max()) + 1
    rows = np.einsum("ak,nkj->naj", array.axis_directions_b, skew(dw) + skew(w) @ skew(w))
    G = np.zeros((n, m, 3 * triads + m))
    for k in range(m):
        G[:, k, 3 * owner[k]:3 * owner[k] + 3] = rows[:, k]
    G[:, np.arange(m), 3 * triads + np.arange(m)] = predicted
    G *= inv[:, :, None]
    PG = project(G)
    ev, vec = np.linalg.eigh(np.einsum("nmp,nmq->pq", PG, PG))
    good = ev > 1e-8 * ev.max()
    d = vec[:, good] @ ((vec[:, good].T @ np.einsum("nmp,nm->p", PG, p)) / ev[good])
    rest = float(np.sum((p - PG @ d) ** 2))
    power = float(np.sum(p * p))
    return {"errors": d, "explained": 1.0 - rest / power if power > 0 else 0.0, "level": power / dof,
            "cleaned": rest / (dof - np.count_nonzero(good)), "rank": int(np.count_nonzero(good)), "J": J, "G": G,
            "triads": triads}


def implied_bias(fit: dict, span: int = SPAN) -> np.ndarray:
    """(N, 3) the bias of ω the fitted errors imply: B_i errors, B_i = (Σ_k J_kᵀ J_k)⁻¹ Σ_k J_kᵀ G_k over the ``span``
    samples around i (module docstring)."""
    J, G = fit["J"], fit["G"]
    n = len(J)

    def local(a):
        cs = np.concatenate([np.zeros((1,) + a.shape[1:]), np.cumsum(a, axis=0)])
        i = np.arange(n)
        return cs[np.minimum(n, i + span - span // 2)] - cs[np.maximum(0, i - span // 2)]

    B = np.linalg.solve(local(np.einsum("nmi,nmj->nij", J, J)), local(np.einsum("nmi,nmp->nip", J, G)))
    return np.einsum("nip,p->ni", B, fit["errors"])[:, 0:3]


def corrected_log(log, fit: dict):
    """``log`` with the fitted errors of :func:`calibration_fit` taken out: the triads moved by the fitted position
    errors, each axis' readings divided by 1 + its fitted gain error."""
    from dataclasses import replace

    d, triads = fit["errors"], fit["triads"]
    moved = d[:3 * triads].reshape(-1, 3)
    array = log.array.with_accelerometers(replace(a, position_m=np.asarray(a.position_m) + moved[i])
                                          for i, a in enumerate(log.array.accelerometers))
    return replace(log, array=array, accel_mps2=log.accel_mps2 / (1.0 + d[3 * triads:]))


def calibration(name: str, folder: Path, recording: Path | None = None) -> None:
    """The figures of item 1 for the cell ``name``, or for ``recording`` (a MIMU4444 ``data.bin``: its moving rows
    against the board's gyros, as tools/sigma_coverage.py scores it)."""
    if recording is None:
        log, omega = sc.read_cell(_cell(name), folder)
        rows = np.ones(len(log), bool)
    else:
        got = sc.moving_recording(recording, folder)
        if isinstance(got, str):
            print(f"\n## {name}: convert failed: {got}")
            return
        log, reference, rows = got
        omega = reference.omega_b_radps
    c = _captured(log)
    fit = calibration_fit(log.array, log.accel_mps2, c["states"], c["noise"], c["robust"])
    d, triads = fit["errors"], fit["triads"]
    bias = implied_bias(fit)[rows]
    e, sd = (c["states"][:, 0:3] - omega)[rows], c["scaled"][rows]
    print(f"\n## {name}: parity level s² {fit['level']:.2f}, {100 * fit['explained']:.0f} % of its power fitted by constant "
          f"position and gain errors (rank {fit['rank']} of {len(d)}), the rest's level {fit['cleaned']:.2f}")
    print(f"position errors [mm]: {np.array2string(d[:3 * triads].reshape(-1, 3) * 1e3, precision=2)}")
    print(f"gain errors [%]: {np.array2string(d[3 * triads:] * 100, precision=2)}")
    print(f"ω error RMS {np.round(np.sqrt(np.mean(e ** 2, axis=0)) * 1e3, 2)} mrad/s; implied bias RMS "
          f"{np.round(np.sqrt(np.mean(bias ** 2, axis=0)) * 1e3, 2)} mrad/s, correlation with the error "
          f"{np.round([np.corrcoef(e[:, j], bias[:, j])[0, 1] for j in range(3)], 2)}")
    print(f"σ today: {_shares(e, sd)}")
    print(f"σ today, bias added: {_shares(e, np.sqrt(sd ** 2 + bias ** 2))}")
    print(f"σ at the cleaned level, bias added: {_shares(e, np.sqrt(sd ** 2 * fit['cleaned'] / fit['level'] + bias ** 2))}")
    from gfimu.methods import make_estimator

    b = e - (make_estimator("smoother").estimate(corrected_log(log, fit)).motion.omega_b_radps - omega)[rows]
    print(f"the smoother's own bias (its estimate less the one with the fitted errors taken out of the log): RMS "
          f"{np.round(np.sqrt(np.mean(b ** 2, axis=0)) * 1e3, 2)} mrad/s, correlation with the error "
          f"{np.round([np.corrcoef(e[:, j], b[:, j])[0, 1] for j in range(3)], 2)}, the error less it "
          f"{np.round(np.sqrt(np.mean((e - b) ** 2, axis=0)) * 1e3, 2)} mrad/s RMS; σ today, that bias added: "
          f"{_shares(e, np.sqrt(sd ** 2 + b ** 2))}; the error less it against σ at the cleaned level: "
          f"{_shares(e - b, sd * np.sqrt(fit['cleaned'] / fit['level']))}")


def handover(folder: Path) -> None:
    from gfimu.methods import make_estimator

    log, omega = sc.read_cell(_cell("turntable-0.3m-unstated"), folder)
    t = (log.timestamps_ns - log.timestamps_ns[0]) * 1e-9
    print("\n## turntable-0.3m-unstated, fixed-lag: the hand-over from the tuning stretch's batch states")
    for window in (2.0, 3.0, 4.0):
        motion = make_estimator("fixed-lag", compute_sigma=True, tune_window_s=window).estimate(log).motion
        e, sd = motion.omega_b_radps - omega, motion.sigma["omega_b_radps"]
        j = int(np.argmax(np.abs(np.diff(e[:, 0]))))
        print(f"tune_window_s {window:g}: x error {e[j, 0] * 1e3:+.2f} → {e[j + 1, 0] * 1e3:+.2f} mrad/s at t = {t[j + 1]:.3f} s "
              f"(σ_x {sd[j + 1, 0] * 1e3:.2f} mrad/s); whole log {_shares(e, sd)}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=("calibration", "handover"), default=None)
    ap.add_argument("--cells", default=",".join(CALIBRATION_CELLS))
    ap.add_argument("recordings", nargs="*", type=Path, help="MIMU4444 data.bin files (item 1 on their moving rows)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if args.only in (None, "calibration"):
            for name in args.cells.split(","):
                calibration(name.strip(), Path(tmp))
            for rec in args.recordings:
                calibration(f"{rec.parent.name} (MIMU4444, moving rows against the board's gyros)", Path(tmp), rec)
        if args.only in (None, "handover"):
            handover(Path(tmp))
    return 0


if __name__ == "__main__":
    sys.exit(main())
