"""Constant errors of an array's calibration, read off the rigid-body residual of a per-sample fit.

A sensor whose true position is its stated one plus δr reads, on axis a of direction d_a,
``d_aᵀ ([ω̇]× + [ω]×²) δr`` more than the rigid body of the stated positions predicts (Ho & Lin 2009, eq. 6
with r + δr); an axis whose gain is 1 + δg reads δg times its value more. Such an error is the same at every
sample: the part of it the per-sample fit absorbs moves every estimate along the states, a bias that the
smoothers' σ, scaled by the residual the states cannot fit (:mod:`gfimu.smoother.solve.sigma_scale`), does not
include. :func:`calibration_errors` fits the errors to the residual over a whole log; ``gfimu diagnose`` reports
them, and the smoothers' σ comes with a warning where they are most of the misfit (:func:`misfit_warning`).
Pure computation, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rigid_body import quadratic_terms, quadratic_terms_jacobian
from .rotations import skew

CALIBRATION_SHARE = 0.5
"""Constant position and gain errors are reported when they explain at least half of the residual's power,
on a log whose readings disagree with a rigid body beyond white noise (the model check): the misfit is then
mostly a calibration error, not noise, vibration or an error that changes with time. (On a consistent log
the share means nothing: near rest the per-sample fit cannot follow the noise of the quadratic terms,
q(ω) = q(−ω) ≥ 0 along some directions, and leaves a constant residual that the gains take up: 20-30 % on the
slow cells of the regime matrix.)"""
CALIBRATION_MIN_Z = 5.0
"""... and a sensor's position (or an axis' gain) when its error is 5 standard errors from zero."""
CALIBRATION_CHUNK = 4096
"""Samples whose regressors :func:`calibration_errors` holds at once."""
MISFIT_SAMPLES = 10_000
"""At most this many samples, evenly spread, give :func:`misfit_warning` its share (a ratio of powers: a
subsample estimates it without bias, to about 1 % with this many)."""


@dataclass(frozen=True)
class CalibrationFit:
    """Constant calibration errors fitted to the rigid-body residual (:func:`calibration_errors`): per sensor its
    position error [m] (S, 3) and standard errors, per axis its gain error (m,) and standard errors, the share
    of the residual's power they explain and the rank of the fit (of 3 S + m unknowns)."""

    position_m: np.ndarray
    position_std_m: np.ndarray
    gain: np.ndarray
    gain_std: np.ndarray
    share: float
    rank: int


def calibration_errors(log, motion, sigma_axes: np.ndarray, residual: np.ndarray,
                       use: np.ndarray | None = None) -> CalibrationFit:
    """Constant errors of the array's calibration fitted to the per-sample fit's ``residual`` (N, m) [m/s²]
    (``motion`` its ω, ω̇; ``sigma_axes`` (m,) the noise that whitens it; ``use`` (N,) the samples, default
    all finite ones), by least squares over the whole log.

    A sensor whose true position is its stated one plus δr reads, on axis a of direction d_a,
    ``d_aᵀ ([ω̇]× + [ω]×²) δr`` more than the rigid body of the stated positions predicts; an axis whose gain
    is 1 + δg reads δg times its value more. The per-sample fit absorbs what of that lies in the tangent
    space of the model (the columns of ``D = [S_f, S_ω̇, S_q ∂q/∂ω]``, as
    :func:`gfimu.diagnose.sensor_skews`), so its whitened residual is the regressors projected off D times
    (δr, δg), plus noise. Some errors are changes of the
    states and never show: a common shift of every position (f absorbs it), a common scale of the positions
    (ω̇ / c, ω / √c) and a common gain (f, ω̇, ω² scaled alike): the fit gives the least-squares errors of
    least size, the part the readings tell (its ``rank``; 3 S + m − 5 for an array that sees ω in full).
    Standard errors from the residual left after the fit. (Pure: no I/O.)"""
    array = log.array
    S = array.structure_matrix()
    m = array.n_axes
    owner = np.asarray(array.axis_owner)
    sensors = len(array.accelerometers)
    n_par = 3 * sensors + m
    w = 1.0 / np.asarray(sigma_axes, dtype=float)
    omega, omega_dot = np.asarray(motion.omega_b_radps), np.asarray(motion.omega_dot_b_radps2)
    ok = (np.all(np.isfinite(residual), axis=1) & np.all(np.isfinite(omega), axis=1)
          & np.all(np.isfinite(omega_dot), axis=1))
    if use is not None:
        ok &= use
    rows = np.nonzero(ok)[0]
    directions = np.asarray(array.axis_directions_b, dtype=float)
    A = np.zeros((n_par, n_par))
    b = np.zeros(n_par)
    power = 0.0
    for start in range(0, rows.size, CALIBRATION_CHUNK):
        idx = rows[start:start + CALIBRATION_CHUNK]
        n = idx.size
        wv, dw = omega[idx], omega_dot[idx]
        D = np.concatenate([np.broadcast_to(S[:, :6], (n,) + S[:, :6].shape),
                            np.einsum("aj,njk->nak", S[:, 6:], quadratic_terms_jacobian(wv))], axis=2)
        D *= w[None, :, None]
        q, _ = np.linalg.qr(D)
        lever = skew(dw) + skew(wv) @ skew(wv)  # (n, 3, 3): δf = lever δr
        G = np.zeros((n, m, n_par))
        per_axis = np.einsum("aj,njk->nak", directions, lever)  # (n, m, 3)
        for a in range(m):
            G[:, a, 3 * owner[a]:3 * owner[a] + 3] = per_axis[:, a]
        G[:, np.arange(m), 3 * sensors + np.arange(m)] = log.accel_mps2[idx] - residual[idx]  # the fitted readings
        G *= w[None, :, None]
        # projected off q's columns: Gᵀ (I − q qᵀ) G = GᵀG − (qᵀG)ᵀ(qᵀG), and the same for r
        qt = q.transpose(0, 2, 1)
        r = (residual[idx] * w[None, :])[:, :, None]
        H, h = (qt @ G).reshape(n * 9, n_par), (qt @ r).reshape(n * 9)
        G, r = G.reshape(n * m, n_par), r.reshape(n * m)
        A += G.T @ G - H.T @ H
        b += G.T @ r - H.T @ h
        power += float(r @ r - h @ h)
    nan = np.full(n_par, np.nan)
    theta, std, share, rank = nan, nan, float("nan"), 0
    scale = np.sqrt(np.diag(A))
    if rows.size and power > 0 and np.all(scale > 0):
        As = A / np.outer(scale, scale)  # (the unknowns made alike: metres and gains)
        lam, V = np.linalg.eigh(0.5 * (As + As.T))
        keep = lam > 1e-9 * lam[-1]
        rank = int(np.count_nonzero(keep))
        pinv = (V[:, keep] / lam[keep]) @ V[:, keep].T
        theta = pinv @ (b / scale) / scale
        fitted = float(theta @ b)
        dof = max(rows.size * (m - 9) - rank, 1)
        s2 = max(power - fitted, 0.0) / dof
        std = np.sqrt(np.clip(np.diag(pinv), 0.0, None) * s2) / scale
        share = fitted / power
    return CalibrationFit(theta[:3 * sensors].reshape(sensors, 3), std[:3 * sensors].reshape(sensors, 3),
                          theta[3 * sensors:], std[3 * sensors:], share, rank)


def rigid_body_residual(array, accel_mps2: np.ndarray, motion) -> np.ndarray:
    """(N, m) readings ``accel_mps2`` less the rigid-body prediction ``S [f, ω̇, q(ω)]`` of ``motion``
    (Ho & Lin 2009, eq. 6) [m/s²]."""
    S = array.structure_matrix()
    x = np.hstack([motion.specific_force_b_mps2, motion.omega_dot_b_radps2, quadratic_terms(motion.omega_b_radps)])
    return np.asarray(accel_mps2, dtype=float) - x @ S.T


def misfit_warning(log, motion) -> str | None:
    """The warning that ``log``'s misfit is mostly a calibration error (:data:`CALIBRATION_SHARE` of the residual's
    power of the per-sample fit ``motion``, on at most :data:`MISFIT_SAMPLES` of its samples), which the
    smoothers' σ does not include; None otherwise."""
    from .noise import accel_noise_std

    stride = max(1, -(-len(log) // MISFIT_SAMPLES))
    part = log.select(slice(0, len(log), stride)) if stride > 1 else log
    picked = motion if stride == 1 else motion.select(slice(0, len(log), stride))
    fit = calibration_errors(part, picked, accel_noise_std(log.array),
                             rigid_body_residual(log.array, part.accel_mps2, picked))
    if not fit.share >= CALIBRATION_SHARE:
        return None
    return ("sigma does not cover an error of the array's calibration: the readings' misfit is "
            f"{100 * fit.share:.0f} % that of constant sensor position and gain errors, which bias the estimate "
            "alike at every sample "
            f"(`gfimu diagnose {log.source}` names the sensors and their offsets)")
