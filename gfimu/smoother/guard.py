"""The smoothers' guard: where the smoother fits the readings clearly worse than the per-sample
maximum-likelihood estimate, find it, say it, and (by default) use the per-sample answer there.

A smoother trades fit for smoothness: its states follow the motion model, so they leave a larger
rigid-body residual than the per-sample fit (:class:`gfimu.estimators.ml.MLEstimator`), which
minimises each sample's residual alone. How much larger is bounded by the model. Take the
residual ``r_k = y_k - S [f_k, ω̇_k, q(ω_k)]`` (Ho & Lin 2009, eq. 6; :func:`gfimu.smoother.tuning.model_choice.rigid_body_residual`)
whitened by the noise of the model check, ``σ_k² = σ₀² + (s |ω_k|)²`` (floor and slope of
:class:`gfimu.smoother.tuning.model_choice.ModelCheck`), and the excess of the smoother's whitened squared
residual over the per-sample one,

    Δ_k = |r_k(smoother)|² / σ_k² - |r_k(per sample)|² / σ_k².

Linearised at the per-sample fit, whose residual is orthogonal to the span of the 9 unknowns of a
sample (f, ω̇, ω), ``Δ_k = |J_k (x_k - x̂_k)|² / σ_k²``. A smoother that estimated the truth itself would
have ``Δ_k ~ χ²₉`` (the per-sample estimate's own error); an optimal smoother, whose error is
uncorrelated with the difference to the per-sample estimate, has ``E Δ_k ≤ 9``. So over a sliding
window of :data:`WINDOW_S` (m usable samples) a smoother consistent with its model keeps ``ΣΔ``
below the χ² quantile of ``9 m`` degrees of freedom at :data:`FALSE_ALARM`; a window beyond it
fits the readings worse than the model allows. Within such windows the samples whose own ``Δ_k``
exceeds the per-sample χ²₉ quantile at :data:`SAMPLE_FALSE_ALARM` mark the span, gaps shorter
than :data:`MERGE_GAP_S` are bridged and spans shorter than :data:`MIN_SAMPLES` samples dropped.

Only samples where the per-sample fit is well determined count: its |ω| at least
:data:`DETERMINED_FACTOR` times the std of its ω (the Cramér-Rao bound at that ω with the noise σ_k,
:func:`gfimu.crb.crb_per_sample`; it falls as 1/|ω|, so this asks |ω|² above a multiple of σ_k over
the lever arms, the |ω| the noise alone gives), and its own whitened residual within the χ²_ν
quantile at :data:`OUTLIER_FALSE_ALARM` (ν = axes - 9): where the readings themselves disagree with a rigid body, neither fit says which
answer is right.

The readings fix ω only up to its sign (q(ω) = q(-ω)): a smoother whose ω has the wrong sign fits
them exactly as well, and no residual can see it. The guard therefore never judges the sign; when
it replaces a span, the per-sample ω takes the signs that best follow the trapezoid of ω̇ from the
smoother's neighbouring samples (:func:`gfimu.smoother.solve.initialise.sign_chain`), so that the
replacement does not flip the sign the smoother chose around it.

Pure computation: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri  # the χ² inverse survival function (scipy.stats.chi2.isf's own)

from .. import rigid_body
from ..crb import crb_per_sample
from ..log import Log
from ..motion import Motion
from .tuning.model_choice import ModelCheck, rigid_body_residual
from .solve.initialise import sign_chain, sign_chain_scale
from .solve.sigma_scale import local_sums

DOF = 9
"""Unknowns of one sample fitted by the per-sample estimate (f, ω̇, ω): the degrees of freedom of Δ_k."""
WINDOW_S = 0.25
"""Length of the sliding window over which Δ is summed [s]."""
FALSE_ALARM = 1e-4
"""Probability that a window of a smoother consistent with its model exceeds its χ²₉ₘ allowance."""
SAMPLE_FALSE_ALARM = 0.01
"""Within a window beyond its allowance, a sample belongs to the span when its own Δ_k exceeds the χ²₉
quantile at this probability."""
OUTLIER_FALSE_ALARM = 1e-3
"""A per-sample fit is an outlier when its whitened residual exceeds the χ²_ν quantile at this probability."""
DETERMINED_FACTOR = 3.0
"""A per-sample fit is well determined where its |ω| is at least this many times the std of its ω (three
sigma from zero: the factor :data:`gfimu.smoother.stream.model_choice.STILL_OMEGA_NOISE` tells rest from turning by)."""
MERGE_GAP_S = 0.05
"""Marked samples closer than this [s] belong to one span."""
MIN_SAMPLES = 3
"""Spans of fewer samples are ignored."""


@dataclass(frozen=True)
class GuardSpan:
    """One stretch where the smoother fits the readings worse than its model allows."""

    start: int
    """First sample (index into the log)."""
    stop: int
    """Last sample (inclusive)."""
    start_s: float
    """Time of the first sample from the log's first [s]."""
    end_s: float
    """Time of the last sample from the log's first [s]."""
    excess: float
    """Mean Δ_k per usable sample of the span (a smoother consistent with its model: at most 9)."""
    rms_ratio: float
    """RMS whitened residual of the smoother over that of the per-sample fit, on the span's usable samples."""

    @property
    def samples(self) -> int:
        return self.stop - self.start + 1

    @property
    def seconds(self) -> float:
        return self.end_s - self.start_s

    def as_dict(self) -> dict:
        return {"start_s": self.start_s, "end_s": self.end_s, "first_sample": self.start, "last_sample": self.stop,
                "samples": self.samples, "excess_chi2_per_sample": self.excess, "rms_ratio": self.rms_ratio}


@dataclass(frozen=True)
class GuardResult:
    """What the guard found on one estimate (:func:`check`) and what it did (``mode``)."""

    mode: str
    spans: tuple[GuardSpan, ...] = ()
    usable: int = 0
    """Samples where the per-sample fit is well determined and not an outlier (the only ones judged)."""
    samples: int = 0
    note: str = ""
    """Why the estimate was not checked (empty when it was)."""

    @property
    def seconds(self) -> float:
        return float(sum(s.seconds for s in self.spans))

    def summary(self) -> str | None:
        """The spans in a few words, e.g. ``fits the readings worse than the per-sample estimate over 2 span(s),
        0.40 s in all (0.60-0.80 s, 2.48-2.68 s)`` (None without any)."""
        if not self.spans:
            return None
        listed = ", ".join(f"{s.start_s:.2f}-{s.end_s:.2f} s" for s in self.spans[:5])
        if len(self.spans) > 5:
            listed += f", ... {len(self.spans) - 5} more"
        return (f"fits the readings worse than the per-sample estimate over {len(self.spans)} span(s), "
                f"{self.seconds:.2f} s in all ({listed})")

    def message(self) -> str | None:
        """The one warning line on the spans and what was done (None without any); the caller names the
        method before it."""
        head = self.summary()
        if head is None:
            return None
        if self.mode == "replace":
            return head + (": the per-sample answer is used there, its sign following the smoother's around it "
                           "(-O guard=warn keeps the smoother's)")
        return head + ": the smoother's answer is kept (guard=warn; -O guard=replace uses the per-sample answer there)"

    def as_dict(self) -> dict:
        return {"mode": self.mode, "samples": self.samples, "usable_samples": self.usable,
                "seconds": self.seconds, "spans": [s.as_dict() for s in self.spans], "note": self.note}


def noise_variance(check: ModelCheck, omega_b_radps: np.ndarray) -> np.ndarray:
    """(N,) σ_k² = σ₀² + (s |ω_k|)² of the model check [m²/s⁴]."""
    wn = np.linalg.norm(omega_b_radps, axis=1)
    return check.noise_floor_mps2**2 + (check.noise_slope_mps2_per_radps * wn) ** 2


def omega_noise(array, omega_b_radps: np.ndarray, var: np.ndarray) -> np.ndarray:
    """(N,) std of the per-sample fit's ω [rad/s] at ``omega_b_radps`` for noise variances ``var``: the
    root of the trace of the Cramér-Rao bound's ω block (:func:`gfimu.crb.crb_per_sample`, which falls as
    1/|ω|: the readings see ω through q(ω)); inf where the information is singular.

    The ω block of the inverse of the information ``[[A, B_k], [B_kᵀ, C_k]]`` is the inverse of its Schur
    complement ``C_k - B_kᵀ A⁻¹ B_k = D_kᵀ P D_k``, with ``D_k = S_q ∂q/∂ω(ω_k)`` and the one projection
    ``P = I - L (LᵀL)⁻¹ Lᵀ`` off the linear columns ``L`` of the structure matrix (unit noise): a 3×3 matrix per
    sample instead of a 9×9 eigen-decomposition. Where that 3×3 is nearly singular (its determinant, scaled
    to a unit diagonal, at most 1e-6), and on an array whose ``L`` is nearly rank-deficient, the bound itself
    gives the trace and says whether the sample is singular."""
    w = np.asarray(omega_b_radps, dtype=float).reshape(-1, 3)
    S = np.asarray(array.structure_matrix(), dtype=float)
    lin, Sq = S[:, :6], S[:, 6:]
    A = lin.T @ lin
    d = np.sqrt(np.diagonal(A))
    if w.shape[0] == 0:
        return np.zeros(0)
    if S.shape[0] < 9:  # fewer readings than unknowns: singular everywhere
        return np.full(w.shape[0], np.inf)
    va = np.linalg.eigvalsh(A / d[:, None] / d[None, :]) if np.all(d > 0) else np.zeros(1)
    if va[0] <= 1e-8 * va[-1]:  # L (nearly) rank-deficient: the projection would lose the digits
        bound = crb_per_sample(array, w, noise_std_mps2=1.0)
        trace = np.trace(bound.covariance[:, 6:9, 6:9], axis1=1, axis2=2)
        singular = bound.singular
    else:
        P = np.eye(S.shape[0]) - lin @ np.linalg.solve(A, lin.T)
        Dq = rigid_body.quadratic_terms_jacobian(w)  # (N, 6, 3)
        M = np.swapaxes(Dq, 1, 2) @ ((Sq.T @ P @ Sq) @ Dq)  # D_kᵀ P D_k, (N, 3, 3)
        m00, m11, m22 = M[:, 0, 0], M[:, 1, 1], M[:, 2, 2]
        m01 = 0.5 * (M[:, 0, 1] + M[:, 1, 0])
        m02 = 0.5 * (M[:, 0, 2] + M[:, 2, 0])
        m12 = 0.5 * (M[:, 1, 2] + M[:, 2, 1])
        # the principal 2×2 minors and the determinant: trace(M⁻¹) = their sum over it (the adjugate)
        c0, c1, c2 = m11 * m22 - m12**2, m00 * m22 - m02**2, m00 * m11 - m01**2
        det = m00 * c0 - m01 * (m01 * m22 - m12 * m02) + m02 * (m01 * m12 - m11 * m02)
        with np.errstate(divide="ignore", invalid="ignore"):
            trace = (c0 + c1 + c2) / det
            scaled_det = det / (m00 * m11 * m22)
        # nearly singular (scaled to a unit diagonal, a determinant this small): the bound itself decides there
        singular = np.zeros(w.shape[0], bool)
        near = np.flatnonzero(~(scaled_det > 1e-6))
        if near.size:
            bound = crb_per_sample(array, w[near], noise_std_mps2=1.0)
            trace[near] = np.trace(bound.covariance[:, 6:9, 6:9], axis1=1, axis2=2)
            singular[near] = bound.singular
    with np.errstate(invalid="ignore"):
        out = np.sqrt(np.maximum(trace, 0.0) * var)
    return np.where(np.isfinite(out) & ~singular, out, np.inf)


def usable_samples(log: Log, per_sample: Motion, check: ModelCheck, z_per_sample: np.ndarray,
                   var: np.ndarray) -> np.ndarray:
    """(N,) bool: where the per-sample fit is well determined (|ω| at least :data:`DETERMINED_FACTOR` times
    its own std, :func:`omega_noise`) and its whitened residual ``z_per_sample`` is no outlier (see the
    module docstring)."""
    wn = np.linalg.norm(per_sample.omega_b_radps, axis=1)
    ok = np.isfinite(z_per_sample) & np.isfinite(wn) & (wn > 0) & (var > 0)
    nu = log.array.structure_matrix().shape[0] - DOF
    if nu > 0:
        ok &= z_per_sample <= chdtri(nu, OUTLIER_FALSE_ALARM)
    if ok.any():  # the bound only where it can decide
        ok[ok] = wn[ok] >= DETERMINED_FACTOR * omega_noise(log.array, per_sample.omega_b_radps[ok], var[ok])
    return ok


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) of each run of True."""
    if not mask.any():
        return []
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1))


def check(log: Log, smoothed: Motion, per_sample: Motion, model_check: ModelCheck, mode: str = "replace") -> GuardResult:
    """Where ``smoothed`` fits ``log``'s readings worse than ``per_sample`` (the per-sample ML estimate) beyond
    what the smoother's model allows (module docstring); ``mode`` is only recorded."""
    n = len(log)
    var = noise_variance(model_check, per_sample.omega_b_radps)
    with np.errstate(divide="ignore", invalid="ignore"):
        z_m = np.sum(rigid_body_residual(log, per_sample.omega_b_radps, per_sample.omega_dot_b_radps2,
                                         per_sample.specific_force_b_mps2) ** 2, axis=1) / var
        z_s = np.sum(rigid_body_residual(log, smoothed.omega_b_radps, smoothed.omega_dot_b_radps2,
                                         smoothed.specific_force_b_mps2) ** 2, axis=1) / var
    ok = usable_samples(log, per_sample, model_check, z_m, var) & np.isfinite(z_s)
    delta = np.where(ok, z_s - z_m, 0.0)
    if n < MIN_SAMPLES or not ok.any():
        return GuardResult(mode, (), int(ok.sum()), n)
    dt = log.nominal_dt_s
    width = max(int(round(WINDOW_S / dt)), MIN_SAMPLES) if np.isfinite(dt) and dt > 0 else MIN_SAMPLES
    width = min(width, n)
    # sums over the window centred on each sample (numpy's "same" convolution with ``width`` ones), by cumulative
    # sums: O(n) where the convolution is O(n · width), 5,000 samples wide at 20 kHz
    total = local_sums(delta, width)
    m = np.rint(local_sums(ok, width)).astype(int)
    allowance = np.full(n, np.inf)
    has = m >= MIN_SAMPLES
    counts, which = np.unique(m[has], return_inverse=True)  # the quantile once per count (a window's m), not per sample
    allowance[has] = chdtri(DOF * counts, FALSE_ALARM)[which.reshape(-1)]
    beyond = total > allowance
    # the samples of windows beyond their allowance, each window spreading over its own samples
    in_flagged = local_sums(beyond, width) > 0
    marked = in_flagged & ok & (delta > chdtri(DOF, SAMPLE_FALSE_ALARM))
    gap = max(int(round(MERGE_GAP_S / dt)), 1) if np.isfinite(dt) and dt > 0 else 1
    t = log.times_s
    spans, current = [], None
    for a, b in _runs(marked):
        if current is not None and a - current[1] - 1 <= gap:
            current = (current[0], b)
        else:
            if current is not None:
                spans.append(current)
            current = (a, b)
    if current is not None:
        spans.append(current)
    out = []
    for a, b in spans:
        sel = slice(a, b + 1)
        use = ok[sel]
        if np.count_nonzero(marked[sel]) < MIN_SAMPLES:
            continue
        excess = float(np.mean(delta[sel][use]))
        ratio = float(np.sqrt(np.sum(z_s[sel][use]) / max(np.sum(z_m[sel][use]), 1e-300)))
        out.append(GuardSpan(int(a), int(b), float(t[a]), float(t[b]), excess, ratio))
    return GuardResult(mode, tuple(out), int(ok.sum()), n)


def _unknown_sigma(n: int) -> dict[str, np.ndarray]:
    """σ of ω, ω̇ and f unknown (NaN) at ``n`` samples."""
    return {k: np.full((n, 3), np.nan) for k in ("omega_b_radps", "omega_dot_b_radps2", "specific_force_b_mps2")}


def per_sample_sigma(array, per_sample: Motion, model_check: ModelCheck, rows: np.ndarray) -> dict[str, np.ndarray]:
    """The one-sigma values of the per-sample fit at ``rows`` (indices): the Cramér-Rao bound at its ω
    (:func:`gfimu.crb.crb_per_sample`, unit noise) times the noise of the model check there, σ_k² = σ₀² + (s |ω_k|)²
    (:func:`noise_variance`, measured on the log's own residual), per axis of ω, ω̇ and f; NaN where the
    bound is singular (|ω| too small for the readings to fix it: the quadratic terms vanish there)."""
    rows = np.asarray(rows, dtype=int)
    out = _unknown_sigma(rows.size)
    w = np.asarray(per_sample.omega_b_radps, dtype=float)[rows]
    good = np.all(np.isfinite(w), axis=1)
    if not good.any():
        return out
    bound = crb_per_sample(array, w[good], noise_std_mps2=1.0)
    var = noise_variance(model_check, w[good])
    with np.errstate(invalid="ignore"):
        sd = np.sqrt(np.diagonal(bound.covariance, axis1=1, axis2=2) * var[:, None])  # (n, 9): f, ω̇, ω
    sd[bound.singular | ~np.all(np.isfinite(sd), axis=1)] = np.nan
    out["specific_force_b_mps2"][good] = sd[:, 0:3]
    out["omega_dot_b_radps2"][good] = sd[:, 3:6]
    out["omega_b_radps"][good] = sd[:, 6:9]
    return out


def replaced(smoothed: Motion, per_sample: Motion, result: GuardResult, model_check: ModelCheck | None = None,
             array=None) -> Motion:
    """``smoothed`` with the per-sample ω, ω̇ and f over ``result``'s spans (the gravity-free
    acceleration, where present, moved by the same change of f; the attitude kept). Where ``smoothed``
    carries σ, the replaced rows carry the per-sample fit's own (:func:`per_sample_sigma`, with the
    ``model_check`` and ``array`` given; else, and where that bound is singular, NaN: unknown), the
    gravity-free acceleration's widened by it. ω takes the signs of
    :func:`gfimu.smoother.solve.initialise.sign_chain` over the span and the
    smoother's samples next to it, the chain as a whole oriented to agree most with the smoother's ω
    there (Σ ω_chain · ω_smoother over the span and its two neighbours: where the motion starts or
    stops next to the span, the neighbours turn too slowly to tell the sign, the span's own samples do).
    Without spans: ``smoothed`` itself."""
    if not result.spans:
        return smoothed
    n = len(smoothed)
    w = np.array(smoothed.omega_b_radps, dtype=float)
    wd = np.array(smoothed.omega_dot_b_radps2, dtype=float)
    f = np.array(smoothed.specific_force_b_mps2, dtype=float)
    t = smoothed.timestamps_ns
    scale = sign_chain_scale(per_sample.omega_b_radps, per_sample.omega_dot_b_radps2, np.diff(t) * 1e-9)
    sigma = {k: np.array(v, dtype=float) for k, v in smoothed.sigma.items()}
    for span in result.spans:
        a, b = span.start, span.stop
        idx = np.arange(max(a - 1, 0), min(b + 1, n - 1) + 1)
        # a sample of the span without a per-sample answer (not finite) keeps the smoother's
        inner = (idx >= a) & (idx <= b) & np.all(np.isfinite(per_sample.omega_b_radps[idx]), axis=1) \
            & np.all(np.isfinite(per_sample.omega_dot_b_radps2[idx]), axis=1) \
            & np.all(np.isfinite(per_sample.specific_force_b_mps2[idx]), axis=1)
        seq_w = np.where(inner[:, None], per_sample.omega_b_radps[idx], w[idx])
        seq_wd = np.where(inner[:, None], per_sample.omega_dot_b_radps2[idx], wd[idx])
        signs = sign_chain(seq_w, seq_wd, np.diff(t[idx]) * 1e-9, scale)
        if np.sum(signs[:, None] * seq_w * w[idx]) < 0:  # the orientation that agrees most with the smoother's ω
            signs = -signs
        sel = idx[inner]
        w[sel] = per_sample.omega_b_radps[sel] * signs[inner][:, None]
        wd[sel] = per_sample.omega_dot_b_radps2[sel]
        f[sel] = per_sample.specific_force_b_mps2[sel]
        if sigma and model_check is not None and array is not None:
            own = per_sample_sigma(array, per_sample, model_check, sel)
        else:
            own = _unknown_sigma(sel.size)
        if "accel_b_mps2" in sigma:  # the attitude's share kept, the change of f's added
            sigma["accel_b_mps2"][sel] = np.hypot(sigma["accel_b_mps2"][sel], own["specific_force_b_mps2"])
        for k, v in own.items():
            if k in sigma:
                sigma[k][sel] = v
    changes = {"omega_b_radps": w, "omega_dot_b_radps2": wd, "specific_force_b_mps2": f, "sigma": sigma}
    if smoothed.accel_b_mps2 is not None:
        changes["accel_b_mps2"] = smoothed.accel_b_mps2 + (f - smoothed.specific_force_b_mps2)
    return smoothed.replace(**changes)
