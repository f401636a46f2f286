"""The smoothers' one-sigma values scaled to what the readings show: the misfit the model did not state.

Both smoothers compute σ from the noise their model assumes: white accelerometer noise of the stated
(or measured, or tuned) level, growing with |ω| under the robust model. A real array's readings also
disagree with a rigid body in ways that are neither white nor of that level (sensor positions and
alignment, scale errors, vibration, timing), and the smoother averages such an error over neighbouring
samples as if it were white. This module measures both from the readings themselves and scales σ by
them:

- **Parity residual.** At sample i the whitened reading residual z_i = W_i (y_i − h(x̂_i)) (W_i: the
  inverse of the noise std the model assumed) is projected onto the orthogonal complement of the
  columns of the whitened measurement Jacobian J_i = W_i ∂h/∂x (x = [ω, ω̇, f]): p_i = (I − J_i J_i⁺) z_i.
  To first order p_i = (I − J_i J_i⁺) W_i e_i, the reading error alone: whatever the smoother made of the
  states, this part of the residual cannot be fitted by them. Under the model it has
  E|p_i|² = m − rank J_i (m: accelerometer axes).
- **Variance factor** s_i² = Σ_k |p_k|² / Σ_k (m − rank_k) over the samples k of a window around
  sample i (:func:`local_window`: :data:`LOCAL_WINDOW` samples at least, :data:`LOCAL_DOF` degrees of
  freedom at least) (the batch smoother: centred on i; the fixed-lag smoother: the newest ones, i included): the
  realised misfit against the assumed noise (1 when the noise is as stated). Local, not one number for
  the log: a real array's misfit grows and shrinks with the motion (lever-arm, scale and alignment errors
  scale with ω̇, ω² and f; vibration comes and goes), and a factor of the whole log would give the fast
  stretches σ too small (the short tails of the error) and the quiet ones σ too large.
- **Robust sandwich.** Under the robust loss a misfitting log gets, the smoother's P is the inverse of the
  information its re-weighting states; the spread of an M-estimate is the sandwich (Huber 1981): s² is then
  the parity level counted by each axis' weight, over β², β the leverage-weighted ψ'/w (:func:`robust_slope`,
  :func:`sandwich_factor`).
- **Correlation in time.** ρ_k = Σ_i p_i · p_{i−k} / Σ_i |p_i|², k = 1 … :data:`MAX_LAG` (whole log, or the
  samples emitted so far). A state the smoother estimates from L samples' worth of readings has, under an
  error of this correlation, the variance of white noise times τ(L) = 1 + 2 Σ_{k<L} (1 − k/L) ρ_k (the
  mean of L correlated samples against that of L independent ones; linear between whole L), taken at
  least :data:`TAU_FLOOR`: below 1 where the misfit alternates faster than the state changes (a
  vibration, which the motion model averages away), above 1 where it drifts (a slowly varying error the
  smoother cannot tell from the motion).
- **Span.** L_ij = σ²_single,ij / σ²_ij: the variance of state j from sample i's readings alone
  ((J_iᵀ J_i)⁺, infinite along directions one sample does not see, such as ω at rest) over the
  smoother's; at most :data:`MAX_LAG`.

- **Trapezoid level.** The motion model ties ω_{k+1} to ω_k and the two ω̇ by the trapezoid rule, with the std of
  a white jerk within the step; half or so of ω's variance under the model comes from those rows
  (:func:`kinematic_shares`: the share, under a local stationary model of each axis). A path whose jerk is
  continuous has a trapezoid residual far below that std, and its smoother's error lacks that part (the
  sandwich P (JᵀR⁻¹J) P + λ P Aᵀ Q⁻¹ A P, λ the path's level). λ is measured from the estimate's own whitened
  trapezoid residuals r̂ over the window of s_i², less the readings' noise in them (:func:`trapezoid_level`:
  E r̂² = λ a + s² b), within 0 … 1.

- **Common gain.** A gain k common to every accelerometer axis (readings in a g other than the one the
  converter assumed, an array calibrated against another gravity) is a change of the states, not a misfit:
  ω → √k ω, ω̇ → k ω̇, f → k f explain the readings exactly, and no residual sees it. Gravity is the one
  absolute scale a log holds: on stretches where f̂ is constant in the world (ḟ + ω × f ≈ 0: gravity
  alone, told from a steady linear acceleration by the body turning across it) and within 1 % of the
  standard gravity, |f̂| = k g (:func:`gravity_windows`). The gain's variance is
  (k̂ − 1)² less the scatter of k̂ itself (:func:`common_gain_variance`), k̂ = the mean |f̂| of those
  stretches over the standard gravity: the readings' scale is known to no better than they read gravity
  (which also differs from the standard one by up to 0.3 % with the place); ω's variance gains
  var_k ω² / 4, ω̇'s var_k ω̇², f's var_k f² (:func:`common_gain_sd`). None without such a stretch, and
  none for linear acceleration (no gravity in the readings).

The reported σ_ij becomes σ_ij √(s_i² τ(L_ij)), ω's √(s_i² τ(L_ij) (1 − share) + λ share) where the motion
model is the white jerk or the driven oscillator: a function of the log's own residuals only, nothing
fitted to a recording. The batch smoother takes s_i² over the window around each sample and ρ over the
whole log (:func:`calibrated_sigma`); the fixed-lag smoother, which writes σ as it goes, over the samples
emitted so far (:class:`RunningSigmaScale`: causal). The estimates themselves are not touched.
"""

from __future__ import annotations

import numpy as np

from ...rigid_body import quadratic_terms, quadratic_terms_jacobian

MAX_LAG = 64
"""Longest lag [samples] of the residual's autocorrelation, and longest span L taken."""
LOCAL_WINDOW = 2 * MAX_LAG
"""Fewest samples whose parity residuals give one sample's variance factor s_i²: twice the longest span a
state draws on, so that s_i² covers the readings the state averaged."""
LOCAL_DOF = 1024
"""... and at least this many degrees of freedom (m − rank a sample: 3 for four triads, 15 for eight): the
factor √s_i² of white residuals then scatters by √(1 / (2 · 1024)) ≈ 2.2 % about 1."""


def local_window(dof_per_sample: float) -> int:
    """Samples of the window of s_i² for residuals of ``dof_per_sample`` degrees of freedom each:
    :data:`LOCAL_WINDOW` at least, more until they hold :data:`LOCAL_DOF`."""
    if not dof_per_sample > 0:
        return LOCAL_WINDOW
    return max(LOCAL_WINDOW, int(np.ceil(LOCAL_DOF / dof_per_sample)))
TAU_FLOOR = 1.0 / MAX_LAG
"""Least long-run factor τ(L): the variance of a mean of :data:`MAX_LAG` samples cannot be told, from lags
up to :data:`MAX_LAG`, to be smaller than that of one sample over :data:`MAX_LAG`."""
RANK_TOLERANCE = 1e-6
"""A direction of the whitened Jacobian counts (rank, single-sample variance) when its singular value
exceeds this times the largest."""
CHUNK = 20000
"""Samples whose Jacobians the batch smoother's factor takes at once."""
MIN_SAMPLES = 16
"""The running factor stays 1 until this many samples' residuals are in."""


def _geometry(array):
    S = array.structure_matrix()
    return np.ascontiguousarray(S[:, 0:3]), np.ascontiguousarray(S[:, 3:6]), np.ascontiguousarray(S[:, 6:12])


def parity(array, accel_mps2: np.ndarray, states: np.ndarray, noise_std_mps2: np.ndarray, robust=None,
           geometry=None, slopes: bool = False):
    """(p (N, m), rank (N,), single-sample variances (N, 9)) of the readings ``accel_mps2`` (N, m) at the
    estimates ``states`` (N, ≥9: ω, ω̇, f) with the noise std ``noise_std_mps2`` (N, m) or (m,): the parity
    residual, the rank of the whitened Jacobian and the variance of each state from that sample alone
    (module docstring). ``robust``: (loss, threshold) of the smoother's robust re-weighting of the
    accelerometer axes, or None: each axis' std is then the one the re-weighting gives at the estimate,
    ``std / √w(r/std)`` (:func:`gfimu.smoother.model.problem.robust_weight`), the noise the smoother's σ assumed.
    ``slopes``: a fourth array (N, 3), the sums over the sample's axes a of the sandwich's parts under the robust
    loss (:func:`robust_slope`): Σ w_a p_a², Σ w_a (1 − h_a) and Σ h_a ψ'(z_a)/w(z_a) (w_a the IRLS weight,
    h_a the axis' leverage on the states, which sum to the rank); without ``robust``: |p|², m − rank, rank."""
    S_f, S_dw, S_q = _geometry(array) if geometry is None else geometry
    X = np.asarray(states, dtype=float)
    w, dw, f = X[:, 0:3], X[:, 3:6], X[:, 6:9]
    y = np.asarray(accel_mps2, dtype=float)
    inv = 1.0 / np.broadcast_to(np.asarray(noise_std_mps2, dtype=float), y.shape)
    z = (y - f @ S_f.T - dw @ S_dw.T - quadratic_terms(w) @ S_q.T) * inv
    slope = None
    if robust is not None and robust[1] > 0:
        from ..model.problem import robust_weight

        weight = robust_weight(z, float(robust[1]), robust[0])
        slope = robust_slope(z, weight, float(robust[1]), robust[0])
        weight = np.sqrt(weight)
        z, inv = z * weight, inv * weight
    J = np.concatenate([np.einsum("mk,nkj->nmj", S_q, quadratic_terms_jacobian(w)),
                        np.broadcast_to(S_dw, (len(X),) + S_dw.shape), np.broadcast_to(S_f, (len(X),) + S_f.shape)],
                       axis=2) * inv[:, :, None]
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    keep = s > RANK_TOLERANCE * s[:, :1]
    Uk = U * keep[:, None, :]
    p = z - np.einsum("nmr,nr->nm", Uk, np.einsum("nmr,nm->nr", Uk, z))
    inv_s2 = np.where(keep, 1.0 / np.where(keep, s, 1.0) ** 2, 0.0)
    Vt2 = Vt ** 2
    single = np.einsum("nrj,nr->nj", Vt2, inv_s2)
    unseen = np.any((Vt2 > 1e-12) & ~keep[:, :, None], axis=1)
    single[unseen] = np.inf
    rank = keep.sum(axis=1)
    if not slopes:
        return p, rank, single
    if slope is None:
        return p, rank, single, np.column_stack([np.sum(p * p, axis=1), p.shape[1] - rank, rank])
    leverage = np.einsum("nmr,nmr->nm", Uk, Uk)
    w = weight * weight
    return p, rank, single, np.column_stack([np.sum(w * p * p, axis=1), np.sum(w * (1.0 - leverage), axis=1),
                                             np.sum(leverage * slope, axis=1)])


def robust_slope(z: np.ndarray, weight: np.ndarray, threshold: float, loss: str) -> np.ndarray:
    """ψ'(z) / w(z) of whitened residuals ``z`` with their IRLS weights ``weight`` = ψ(z)/z under the robust
    ``loss`` of ``threshold`` c: Cauchy 2w − 1 (ψ = z/(1 + z²/c²)), Huber 1 within c and 0 beyond.

    The robust smoother's P is the inverse of the information JᵀWJ its re-weighting states; the estimate's
    spread under the readings' errors is the M-estimator's sandwich (Huber 1981, *Robust Statistics*,
    §6.2 and §7.6): (Jᵀ Ψ' J)⁻¹ (Jᵀ diag(ψ²) J) (Jᵀ Ψ' J)⁻¹, Ψ' = diag(ψ'). In the weighted frame
    (J̃ = √W J, z̃ = √w z) the middle is J̃ᵀ diag(w z̃²) J̃ and the outer factors J̃ᵀ diag(ψ'/w) J̃: against
    P = (J̃ᵀ J̃)⁻¹, the variance factor s² = Σ w p² / Σ w (1 − h) (the parity residual's level, each
    axis counted by its weight, as it counts in the states) over β² = (Σ h ψ'/w / Σ h)²: the
    information the re-weighting states, less what the residuals beyond the loss' bend lend the estimate's
    stability (:func:`calibrated_sigma`, :class:`RunningSigmaScale`; tests/test_sigma_scale.py checks the
    factor against the spread of a robust regression's estimates over many draws)."""
    if loss == "cauchy":
        return 2.0 * weight - 1.0
    return (np.abs(z) <= threshold).astype(float)


SLOPE_FLOOR = 0.25
"""Least local robust slope β (:func:`robust_slope`, averaged by leverage over the window of s²): below it
most of the readings' leverage lies beyond the loss' bend, where the sandwich is no first-order
description; σ's variance is then widened 1/β² = 16 times, not more."""


def sandwich_factor(weighted, weighted_dof, slope, rank):
    """The variance factor s² / β² of a robust solution (:func:`robust_slope`) from sums over its readings
    (parity's ``slopes``): ``weighted`` Σ w p², ``weighted_dof`` Σ w (1 − h), ``slope`` Σ h ψ'/w and ``rank`` Σ h,
    numbers or arrays alike."""
    with np.errstate(divide="ignore", invalid="ignore"):
        beta = np.clip(np.asarray(slope, dtype=float) / np.asarray(rank, dtype=float), SLOPE_FLOOR, 1.0)
        return np.asarray(weighted, dtype=float) / np.asarray(weighted_dof, dtype=float) / beta ** 2


def long_run_factors(rho: np.ndarray) -> np.ndarray:
    """τ(L) for L = 0 … len(rho) (``rho[k-1]``: the autocorrelation at lag k), each at least :data:`TAU_FLOOR`
    (τ(0) = τ(1) = 1)."""
    rho = np.asarray(rho, dtype=float)
    K = len(rho)
    out = np.ones(K + 1)
    if K:
        c1 = np.cumsum(rho)[:K - 1]  # Σ_{k<L} ρ_k for L = 2 … K
        c2 = np.cumsum(np.arange(1, K + 1) * rho)[:K - 1]  # Σ_{k<L} k ρ_k
        L = np.arange(2, K + 1)
        out[2:] = 1.0 + 2.0 * (c1 - c2 / L)
    return np.maximum(out, TAU_FLOOR)


def local_sums(values: np.ndarray, window: int) -> np.ndarray:
    """Sums of ``values`` (N,) over the ``window`` samples centred on each (fewer at the ends): samples
    ``i - window // 2`` to ``i + (window - 1) // 2``, the window of ``numpy.convolve(values, numpy.ones(window),
    "same")`` (``window`` ≤ N), by cumulative sums: O(N) rather than O(N · window), the same sums to rounding
    (exactly for integer values)."""
    c = np.concatenate([[0.0], np.cumsum(np.asarray(values, dtype=float))])
    i = np.arange(len(values))
    half = int(window) // 2
    return c[np.minimum(len(values), i + window - half)] - c[np.maximum(0, i - half)]


def scale_factors(sd: np.ndarray, single: np.ndarray, variance_factor, tau: np.ndarray, kinematic=None) -> np.ndarray:
    """(N, 9) factors on σ: √(s² τ(L_ij)), L_ij = single_ij / sd_ij² within 0 … len(tau) − 1 (τ linear
    between whole spans); ``variance_factor`` s² one number or one per row (N, 1). ``kinematic``: (share,
    level) (N, 3) of :func:`kinematic_shares` and :func:`trapezoid_level`, or None: ω's factor is then
    √(s² τ(L) (1 − share) + level share) (module docstring, *trapezoid level*)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        span = single / (sd * sd)
    top = len(tau) - 1
    L = np.where(np.isnan(span), 0.0, np.minimum(span, top))  # nothing known (σ 0 or NaN): no span
    factor = variance_factor * np.interp(L, np.arange(len(tau)), tau)
    if kinematic is not None:
        share, level = kinematic
        factor = np.array(factor, dtype=float)
        factor[..., 0:3] = factor[..., 0:3] * (1.0 - share) + level * share
    return np.sqrt(factor)


QUADRATURE_POINTS = 32
"""Points of the quadrature over frequency in :func:`kinematic_shares` (θ = π u³, u uniform: dense near θ = 0,
where a weakly observed ω draws on many samples)."""


_QUADRATURES: dict = {}


def _quadrature(points: int):
    """(weights, cos θ − 1, 1 + cos θ, sin θ) of the frequency quadrature of :func:`kinematic_shares`:
    θ = π u³ at the midpoints u of ``points`` equal parts of 0 … 1, weights (1/π) dθ."""
    if points not in _QUADRATURES:
        u = (np.arange(points) + 0.5) / points
        theta = np.pi * u ** 3
        _QUADRATURES[points] = (3.0 * u ** 2 / points, np.cos(theta) - 1.0, 1.0 + np.cos(theta), np.sin(theta))
    return _QUADRATURES[points]


def kinematic_shares(single: np.ndarray, trapezoid_var: np.ndarray, step_var: np.ndarray, dt_s,
                     points: int = QUADRATURE_POINTS):
    """(share, a, b), each (N, 3), of the white-jerk motion model's trapezoid rows under a local stationary
    model of each body axis: ω and ω̇ observed every sample with the variances one sample's readings give
    them (``single`` (N, ≥6): :func:`parity`), tied by the trapezoid rows (variance ``trapezoid_var``
    (N, 3)) and the ω̇ steps (``step_var`` (N, 3)) of ``dt_s`` (N,) seconds, over an infinite run of samples.
    In the frequency domain (x_k = X e^{ikθ}) the information is H(θ) = diag(1/σ²_ω, 1/σ²_ω̇) + uᴴu / t +
    vᴴv / s with u = [e^{iθ} − 1, −h/2 (1 + e^{iθ})], v = [0, e^{iθ} − 1], and (1/π)∫₀^π dθ of:

    - share: [H⁻¹ uᴴu H⁻¹]_ωω / t over [H⁻¹]_ωω — the part of ω's variance that the trapezoid rows' noise
      makes (P Aᵀ Q⁻¹ A P over P for the rows A), the part a path whose trapezoid residual is smaller than
      the model's (any motion whose jerk is continuous, sampled well above its bandwidth) does not have;
    - a, b: the expected square of a whitened trapezoid residual at the estimate from the rows' own noise,
      (1 − u H⁻¹ uᴴ / t)², and from the readings' noise, u H⁻¹ D H⁻¹ uᴴ / t (D the readings' information):
      the realised E r̂² = λ a + b for a path of trapezoid level λ (1: the model's)."""
    sw = np.asarray(single, dtype=float)[:, 0:3]
    sdd = np.asarray(single, dtype=float)[:, 3:6]
    with np.errstate(divide="ignore"):
        aw = np.where(np.isfinite(sw) & (sw > 0), 1.0 / sw, 0.0)[..., None]
        ad = np.where(np.isfinite(sdd) & (sdd > 0), 1.0 / sdd, 0.0)[..., None]
    t = np.asarray(trapezoid_var, dtype=float)[..., None]
    s = np.asarray(step_var, dtype=float)[..., None]
    h = np.broadcast_to(np.asarray(dt_s, dtype=float), (len(sw),))[:, None, None]
    weight, cm, cp, sn = _quadrature(int(points))  # cos θ − 1, 1 + cos θ, sin θ
    # in real arithmetic: u = [cm + i sn, −h/2 (cp + i sn)], |u₀|² = −2 cm, |u₁|² = h²/4 · 2 cp, H₀₁ = i g
    H00 = aw - 2.0 * cm / t
    H11 = ad + 0.5 * h * h * cp / t - 2.0 * cm / s
    g = h * sn / t
    hh = 0.5 * h
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_det = 1.0 / (H00 * H11 - g * g)
        c0r = (H11 * cm + g * hh * sn) * inv_det  # H⁻¹ uᴴ, ω row
        c0i = (-H11 * sn + g * hh * cp) * inv_det
        c1r = (g * sn - H00 * hh * cp) * inv_det  # ... ω̇ row
        c1i = (g * cm + H00 * hh * sn) * inv_det
        c0 = c0r * c0r + c0i * c0i
        c1 = c1r * c1r + c1i * c1i
        p_w = np.sum(weight * H11 * inv_det, axis=-1)
        d_w = np.sum(weight * c0 / t, axis=-1)
        hat = (cm * c0r - sn * c0i - hh * (cp * c1r - sn * c1i)) / t
        a = np.sum(weight * (1.0 - hat) ** 2, axis=-1)
        b = np.sum(weight * (aw * c0 + ad * c1) / t, axis=-1)
        share = np.clip(d_w / p_w, 0.0, 1.0)
    bad = ~(np.isfinite(share) & np.isfinite(a) & np.isfinite(b))
    return np.where(bad, 0.0, share), np.where(bad, 1.0, a), np.where(bad, 0.0, b)


def jerk_steps(density: np.ndarray, natural_frequency_radps, dt_s):
    """(trapezoid variance, step variance, coefficient, transition) of the motion model's steps: ``density``
    (K, 3) the white-jerk density of each step per body axis, ``natural_frequency_radps`` (3,) the driven
    oscillator's Ω per axis (0: the white jerk), ``dt_s`` (K,). The step's noise [e_ω, e_ω̇] per axis has the
    covariance C of :func:`gfimu.factors.process.oscillator_covariance`; its *trapezoid* part e_ω − (C_ωω̇ / C_ω̇ω̇)
    e_ω̇ (the white jerk's ω_{k+1} − ω_k − h/2 (ω̇_k + ω̇_{k+1})) has the variance C_ωω − C_ωω̇² / C_ω̇ω̇ (h³/12 q²
    for the white jerk) and is independent of the ω̇ step's e_ω̇ (variance C_ω̇ω̇); the transition Φ (K, 3, 2, 2)."""
    from ...factors.process import oscillator_covariance, oscillator_transition

    q = np.asarray(density, dtype=float)
    dt = np.asarray(dt_s, dtype=float)
    cov = oscillator_covariance(1.0, dt, natural_frequency_radps) * (q * q)[:, :, None, None]
    coef = cov[..., 0, 1] / cov[..., 1, 1]
    return cov[..., 0, 0] - cov[..., 0, 1] * coef, cov[..., 1, 1], coef, oscillator_transition(dt, natural_frequency_radps)


def trapezoid_residuals(states: np.ndarray, steps) -> np.ndarray:
    """(N − 1, 3) whitened trapezoid residuals of ``states`` (N, ≥6) over the steps ``steps`` of :func:`jerk_steps`."""
    X = np.asarray(states, dtype=float)
    var, _, coef, phi = steps
    w0, w1, d0, d1 = X[:-1, 0:3], X[1:, 0:3], X[:-1, 3:6], X[1:, 3:6]
    e_w = w1 - phi[..., 0, 0] * w0 - phi[..., 0, 1] * d0
    e_d = d1 - phi[..., 1, 0] * w0 - phi[..., 1, 1] * d0
    return (e_w - coef * e_d) / np.sqrt(var)


def trapezoid_level(r2, a, b, variance_factor):
    """λ = (Σ r̂² − s² Σ b) / Σ a within 0 … 1: the trapezoid level of the path from the realised whitened trapezoid
    residuals' sum of squares ``r2`` and the sums of :func:`kinematic_shares`' ``a``, ``b`` over the same
    samples (the readings' part b scaled by their misfit s², ``variance_factor``)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        level = (np.asarray(r2, dtype=float) - variance_factor * np.asarray(b, dtype=float)) / np.asarray(a, dtype=float)
    return np.where(np.isfinite(level), np.clip(level, 0.0, 1.0), 1.0)


GRAVITY_WINDOW_S = 0.25
"""Length of the stretches tested for gravity alone [s] (as :data:`gfimu.io.plausibility.STILL_WINDOW_S`)."""
GRAVITY_DRIFT = 0.03
"""A stretch holds gravity alone when f̂, carried into the world by ω̂, moves by less than this share of |f̂|
over it (as :data:`gfimu.io.plausibility.STILL_TIME_SPREAD`, the still stretches' 3 %)."""
GRAVITY_BAND = 0.01
"""... and its mean |f̂| lies within this share of the standard gravity: the Earth's gravity lies within 0.3 % of
it everywhere, so a stretch further off carries a steady linear acceleration (a vehicle's) rather than a gain,
and one within it can add at most (0.5 %)² of ω² to ω's variance."""


def gravity_steps(states: np.ndarray, dt_s: np.ndarray):
    """(|f̂| (N − 1,), change (N − 1, 3), turn (N − 1,)) over the steps of ``states`` (N, ≥9: ω, ω̇, f), ``dt_s``
    (N − 1,) [s]: the specific force's size over the step (the mean of its ends'), its change in the world frame
    over the step, in body axes, f_{k+1} − f_k + h ω̄ × f̄ (bars: the ends' mean; 0 for gravity alone, to
    O(h³ |ω|³ |f|)), and the angle [rad] the body turns about axes across f̄, h |ω̄ × f̄| / |f̄| (how far a
    vector fixed in the world turns in the body, and one fixed in the body in the world)."""
    X = np.asarray(states, dtype=float)
    h = np.asarray(dt_s, dtype=float)
    size = np.linalg.norm(X[:, 6:9], axis=1)
    f = 0.5 * (X[1:, 6:9] + X[:-1, 6:9])
    w = 0.5 * (X[1:, 0:3] + X[:-1, 0:3])
    spin = h[:, None] * np.cross(w, f)
    with np.errstate(divide="ignore", invalid="ignore"):
        turn = np.linalg.norm(spin, axis=1) / np.linalg.norm(f, axis=1)
    return 0.5 * (size[1:] + size[:-1]), (X[1:, 6:9] - X[:-1, 6:9]) + spin, turn


def gravity_windows(norm: np.ndarray, change: np.ndarray, turn: np.ndarray, steps: int) -> np.ndarray:
    """(K, 2): per whole stretch of ``steps`` consecutive steps of ``norm``, ``change``, ``turn``
    (:func:`gravity_steps`) that holds gravity alone, the mean |f̂| and the variance of that mean (the steps'
    variance over their count). Gravity alone: f̂ carried into the world moves from where it was at the
    stretch's start by less than :data:`GRAVITY_DRIFT` of its mean size anywhere in it, while the body turns
    across f̂ by at least twice that angle in all (so that a specific force fixed in the body, a steady
    linear acceleration at rest, would have moved by more), its mean size lies within :data:`GRAVITY_BAND` of
    the standard gravity, every value finite. A trailing part shorter than ``steps`` is not a stretch."""
    from ...io.units import STANDARD_GRAVITY_MPS2

    steps = int(steps)
    K = len(norm) // steps if steps > 0 else 0
    if K == 0:
        return np.zeros((0, 2))
    n = np.asarray(norm, dtype=float)[:K * steps].reshape(K, steps)
    c = np.asarray(change, dtype=float)[:K * steps].reshape(K, steps, 3)
    a = np.asarray(turn, dtype=float)[:K * steps].reshape(K, steps)
    finite = np.all(np.isfinite(n) & np.isfinite(a), axis=1) & np.all(np.isfinite(c), axis=(1, 2))
    with np.errstate(invalid="ignore", over="ignore"):
        level = n.mean(axis=1)
        moved = np.max(np.linalg.norm(np.cumsum(c, axis=1), axis=2), axis=1)
        ok = (finite & (level > 0) & (moved <= GRAVITY_DRIFT * level) & (a.sum(axis=1) >= 2.0 * GRAVITY_DRIFT)
              & (np.abs(level / STANDARD_GRAVITY_MPS2 - 1.0) <= GRAVITY_BAND))
    return np.column_stack([level[ok], n[ok].var(axis=1) / steps])


def common_gain_variance(windows: np.ndarray) -> float:
    """var_k = (k̂ − 1)² less the variance of k̂ (at least 0) from the stretches ``windows`` (K, 2) of
    :func:`gravity_windows`: k̂ their mean |f̂| over the standard gravity, its variance the larger of their
    scatter over K and their own mean variance over K; 0 without a stretch."""
    from ...io.units import STANDARD_GRAVITY_MPS2

    W = np.asarray(windows, dtype=float).reshape(-1, 2)
    K = len(W)
    if K == 0:
        return 0.0
    k = float(W[:, 0].mean()) / STANDARD_GRAVITY_MPS2
    spread = max(float(W[:, 0].var(ddof=1)) / K if K > 1 else 0.0, float(W[:, 1].mean()) / K)
    return max(0.0, (k - 1.0) ** 2 - spread / STANDARD_GRAVITY_MPS2 ** 2)


def common_gain_sd(states: np.ndarray, variance: float) -> np.ndarray:
    """(N, 9) σ of ω, ω̇, f from a common gain of variance ``variance`` (:func:`common_gain_variance`) at
    ``states`` (N, ≥9): |ω| √var / 2, |ω̇| √var, |f| √var per component."""
    X = np.atleast_2d(np.asarray(states, dtype=float))[:, :9]
    sd = np.sqrt(max(float(variance), 0.0))
    return np.abs(X) * np.concatenate([np.full(3, 0.5 * sd), np.full(6, sd)])


def _gravity_window_steps(dt_s) -> int:
    """Steps per stretch of :data:`GRAVITY_WINDOW_S` at the median step ``dt_s`` (at least 4)."""
    h = float(np.median(dt_s)) if np.size(dt_s) else 0.0
    return max(4, int(round(GRAVITY_WINDOW_S / h))) if h > 0 else 4


class RunningGain:
    """The common gain's variance (:func:`common_gain_variance`) from the stretches of gravity alone among the states
    taken so far, one after the other (causal, :meth:`take`), and among a stretch of states given at once
    (:meth:`seed`: the batch solution of a stream's first stretch, available before its rows are given out; those
    rows, taken again as they are given out, are not counted twice)."""

    def __init__(self, array):
        self.applies = getattr(array, "readings", "specific_force") == "specific_force"
        """Only readings of specific force show gravity's size."""
        self.block: list = []  # (time [s], state (9,)) of the current stretch, from the one before its first step
        self.steps: int | None = None  # steps of a stretch (:func:`_gravity_window_steps` of the first step)
        self.windows: list = []  # (mean |f̂|, its variance) of the stretches of gravity alone so far
        self.counted_until_s = -np.inf  # the stretches up to this time are counted already (a seed's)
        self.variance = 0.0
        """The variance from the stretches found so far."""

    def reset(self) -> None:
        """A new segment: a stretch does not reach across it."""
        self.block = []
        self.counted_until_s = -np.inf

    def _found(self, windows: np.ndarray) -> None:
        if len(windows):
            self.windows.extend(windows)
            self.variance = common_gain_variance(np.array(self.windows))

    def seed(self, times_s: np.ndarray, states: np.ndarray) -> None:
        """The stretches of ``states`` (N, ≥9) at ``times_s`` (N,) [s], the first of a segment, counted at once
        (cut from its first state, as :meth:`take` cuts them)."""
        t = np.asarray(times_s, dtype=float)
        if not self.applies or len(t) < 2:
            return
        dt = np.round(np.diff(t) * 1e9) * 1e-9
        if self.steps is None:
            self.steps = _gravity_window_steps(dt[:1])
        self._found(gravity_windows(*gravity_steps(np.asarray(states, dtype=float)[:, :9], dt), self.steps))
        self.counted_until_s = float(t[-1])

    def take(self, state: np.ndarray, t_s) -> None:
        """``state`` at ``t_s`` [s] into the current stretch; a whole stretch (the steps from the state before its
        first) tested for gravity alone (:func:`gravity_steps`, :func:`gravity_windows`) unless a seed counted it."""
        if t_s is None or not self.applies:
            return
        block = self.block
        entry = (float(t_s), np.array(state, dtype=float))
        if block and not entry[0] > block[-1][0]:  # no step: the state taken instead of the one before
            block[-1] = entry
            return
        block.append(entry)
        if len(block) < 2:
            return
        if self.steps is None:
            self.steps = _gravity_window_steps(np.round(np.array([block[1][0] - block[0][0]]) * 1e9) * 1e-9)
        if len(block) <= self.steps:
            return
        times = np.array([t for t, _ in block])
        self.block = [block[-1]]
        if times[-1] <= self.counted_until_s:
            return
        self._found(gravity_windows(*gravity_steps(np.vstack([x for _, x in block]),
                                                   np.round(np.diff(times) * 1e9) * 1e-9), self.steps))


class RunningTrapezoid:
    """The path's trapezoid level (:func:`trapezoid_level`) over the newest steps between the states taken one
    after the other (causal): each step's whitened trapezoid residual under the motion model and the shares
    of :func:`kinematic_shares`, summed over a ring of the newest steps."""

    def __init__(self):
        self.ring: np.ndarray | None = None  # |r̂|², Σ a, Σ b of the newest steps, row i % length of step i
        self.steps = 0
        self.previous: tuple | None = None  # (time [s], state (9,)) of the newest state taken
        self.jerk_steps: tuple | None = None  # (step [s], density, Ω) and their jerk_steps, the newest

    def reset(self) -> None:
        """A new segment: no step reaches across it (the sums so far are kept)."""
        self.previous = None

    def level(self, state: np.ndarray, single: np.ndarray, jerk, t_s, length: int, variance_factor: float):
        """(share (3,), level) of :func:`scale_factors` for ``state`` at ``t_s`` [s] under the motion model
        ``jerk`` (:func:`jerk_density`): its step from the state before it added to the newest ``length`` steps'
        sums, the level at the readings' ``variance_factor``; or None (no jerk model, no earlier state in the
        segment yet, fewer than :data:`MIN_SAMPLES` steps)."""
        if jerk is None or t_s is None:
            return None
        previous, self.previous = self.previous, (float(t_s), np.array(state[:9], dtype=float))
        if previous is None or not t_s > previous[0]:
            return None
        h = np.array([round((float(t_s) - previous[0]) * 1e9) * 1e-9])  # whole nanoseconds, as the timestamps
        key = (float(h[0]), tuple(np.asarray(jerk[0], dtype=float)), tuple(np.asarray(jerk[1], dtype=float)))
        if self.jerk_steps is None or self.jerk_steps[0] != key:  # the same step and model: the same rows
            self.jerk_steps = (key, jerk_steps(np.asarray(jerk[0], dtype=float)[None, :], jerk[1], h))
        steps = self.jerk_steps[1]
        share, a, b = self.shares(single, steps[0][0], steps[1][0], float(h[0]))
        r = trapezoid_residuals(np.vstack([previous[1], state[:9]]), steps)
        if not np.all(np.isfinite(r)):
            return None
        if self.ring is None:
            self.ring = np.zeros((length, 3))
        self.ring[self.steps % len(self.ring)] = (float(np.sum(r * r)), float(a.sum()), float(b.sum()))
        self.steps += 1
        if self.steps < MIN_SAMPLES:
            return None
        r2, a_sum, b_sum = self.ring.sum(axis=0)
        return share, float(trapezoid_level(r2, a_sum, b_sum, variance_factor))

    @staticmethod
    def shares(single: np.ndarray, trapezoid_var: np.ndarray, step_var: np.ndarray, h: float):
        """(share, a, b) (3,) of :func:`kinematic_shares` for one state, by its compiled row
        (:func:`gfimu.smoother.solve.sigma_kernels.kinematic_shares_row`: the same numbers to rounding)."""
        from .sigma_kernels import kinematic_shares_row

        share, a, b = np.empty(3), np.empty(3), np.empty(3)
        kinematic_shares_row(np.ascontiguousarray(single, dtype=float), np.ascontiguousarray(trapezoid_var, dtype=float),
                             np.ascontiguousarray(step_var, dtype=float), h, *_quadrature(QUADRATURE_POINTS),
                             share, a, b)
        return share, a, b


class RunningSigmaScale:
    """The factor on σ from the residuals seen so far (the fixed-lag smoother's, causal): :meth:`scaled`
    takes one emitted state with its reading, adds its parity residual to the running sums and returns
    its σ scaled by the factor of those sums (s² of the newest ``window`` samples, ρ of all)."""

    def __init__(self, array, max_lag: int = MAX_LAG, window: int | None = None):
        self.array = array
        self._geometry = _geometry(array)
        self.robust = None
        """(loss, threshold) of the robust re-weighting in use (:func:`parity`), or None."""
        self.max_lag = int(max_lag)
        self._ring: np.ndarray | None = None  # the newest parity residuals, row i % max_lag of sample i
        self._held = 0  # rows of the ring filled since the last reset
        self._power = 0.0
        self._dof = 0.0
        self._lagged = np.zeros(self.max_lag)
        self.samples = 0
        self.window = None if window is None else int(window)
        """Samples of s²'s window (:func:`local_window` of the first sample's degrees of freedom when None)."""
        # |p|², m − rank, the robust sandwich's three sums (parity's ``slopes``) and the rank of the newest samples,
        # row i % window of sample i
        self._recent: np.ndarray | None = None
        self.trapezoid = RunningTrapezoid()
        """The path's trapezoid level over the newest steps (the same window as s²)."""
        self.gain = RunningGain(array)
        """The common gain the stretches of gravity alone so far show."""

    def reset(self) -> None:
        """A new segment: the lagged products and the trapezoid residuals do not reach across it (the sums so far
        are kept)."""
        self._held = 0
        self.trapezoid.reset()
        self.gain.reset()

    @property
    def variance_factor(self) -> float:
        """s² over the newest :attr:`window` samples (1 before :data:`MIN_SAMPLES`), over the square of their
        robust slope under a robust loss (:func:`robust_slope`; :func:`calibrated_sigma`)."""
        if self._recent is None:
            return 1.0
        power, dof, weighted, weighted_dof, slope, rank = self._recent.sum(axis=0)
        if not (dof > 0 and self.samples >= MIN_SAMPLES):
            return 1.0
        if self.robust is None or not self.robust[1] > 0 or not (weighted_dof > 0 and rank > 0):
            return power / dof
        return float(sandwich_factor(weighted, weighted_dof, slope, rank))

    def tau(self) -> np.ndarray:
        if self.samples < MIN_SAMPLES or self._power <= 0:
            return np.ones(self.max_lag + 1)
        return long_run_factors(self._lagged / self._power)

    def _parity(self, y: np.ndarray, x: np.ndarray, std: np.ndarray):
        """:func:`parity` of one sample (the same numbers to rounding, by its compiled row
        :func:`gfimu.smoother.solve.sigma_kernels.parity_row`)."""
        from .sigma_kernels import parity_row

        S_f, S_dw, S_q = self._geometry
        c, cauchy = 0.0, False
        if self.robust is not None and self.robust[1] > 0:
            c, cauchy = float(self.robust[1]), self.robust[0] == "cauchy"
        p, single, sandwich = np.empty(len(y)), np.empty(9), np.empty(3)
        rank = parity_row(np.ascontiguousarray(y, dtype=float), np.ascontiguousarray(x, dtype=float),
                          np.ascontiguousarray(std, dtype=float), S_f, S_dw, S_q, c, cauchy, RANK_TOLERANCE, p, single,
                          sandwich)
        return p, int(rank), single, sandwich

    def scaled(self, accel_mps2: np.ndarray, state: np.ndarray, sd: np.ndarray, noise_std_mps2: np.ndarray,
               jerk=None, t_s: float | None = None) -> np.ndarray:
        """``sd`` (9,) of ``state`` (9,: ω, ω̇, f) scaled by the factor with this sample's residual included;
        ``jerk``: the motion model's (density (3,), Ω (3,)) (:func:`jerk_density`; None: white snap), ``t_s``
        the state's time [s]: ω's σ then also follows the path's trapezoid level (:func:`calibrated_sigma`'s
        ``process``), over the newest steps between the states taken."""
        sd = np.asarray(sd, dtype=float)
        x = np.asarray(state, dtype=float)[:9]
        p, rank, single, sandwich = self._parity(np.asarray(accel_mps2, dtype=float), x,
                                              np.asarray(noise_std_mps2, dtype=float))
        if np.all(np.isfinite(p)):
            self._power += float(p @ p)
            self._dof += float(len(p) - rank)
            if self._ring is None:
                self._ring = np.zeros((self.max_lag, len(p)))
            K = self.max_lag
            held = min(self._held, K)
            if held:
                rows = (self._held - np.arange(1, held + 1)) % K  # lag 1 first
                self._lagged[:held] += self._ring[rows] @ p
            self._ring[self._held % K] = p
            self._held += 1
            if self._recent is None:
                if self.window is None:
                    self.window = local_window(len(p) - rank)
                self._recent = np.zeros((self.window, 6))
            self._recent[self.samples % self.window] = (float(p @ p), float(len(p) - rank), *sandwich, float(rank))
            self.samples += 1
        variance_factor = self.variance_factor
        kinematic = self.trapezoid.level(x, single, jerk, t_s, self.window or LOCAL_WINDOW, variance_factor)
        out = sd * scale_factors(sd, single, variance_factor, self.tau(), kinematic)
        self.gain.take(x, t_s)
        if self.gain.variance > 0:
            out = np.sqrt(out ** 2 + common_gain_sd(x[None, :], self.gain.variance)[0] ** 2)
        return out


def calibrated_sigma(array, accel_mps2: np.ndarray, states: np.ndarray, sd: np.ndarray, noise_std_mps2: np.ndarray,
                     robust=None, max_lag: int = MAX_LAG, window: int | None = None, process=None,
                     dt_s: np.ndarray | None = None) -> np.ndarray:
    """``sd`` (N, ≥9) with its first nine columns (ω, ω̇, f) scaled by the factors of the log's residuals
    (the batch smoother's; module docstring): s² over the ``window`` samples centred on each row
    (:func:`local_window` of the median degrees of freedom when None), ρ over the whole log. Rows with a
    non-finite residual do not count.
    ``process``: (jerk density (N − 1, 3) of each step per body axis, the driven oscillator's Ω (3,), steps [s]
    (N − 1,)) of the motion model the solution assumed (:func:`jerk_steps`), or None; given, ω's σ also follows
    the path's own trapezoid level over the same window (:func:`kinematic_shares`, :func:`trapezoid_level`).
    ``dt_s``: the steps [s] (N − 1,), or None: given, and the readings specific force, σ also carries the
    common gain the log's stretches of gravity alone show (:func:`common_gain_variance`, over the whole log)."""
    n = len(states)
    noise = np.broadcast_to(np.asarray(noise_std_mps2, dtype=float), np.shape(accel_mps2))
    geometry = _geometry(array)
    parts = [parity(array, accel_mps2[i:i + CHUNK], states[i:i + CHUNK, :9], noise[i:i + CHUNK], robust, geometry,
                    slopes=True) for i in range(0, n, CHUNK)]  # in blocks: the Jacobians of a long log at once would not fit
    p, rank, single, sandwich = (np.concatenate([part[j] for part in parts]) for j in range(4))
    ok = np.all(np.isfinite(p), axis=1)
    out = np.array(sd, dtype=float)
    if np.count_nonzero(ok) < MIN_SAMPLES:
        return out
    q = np.where(ok[:, None], p, 0.0)
    power = float(np.sum(q * q))
    dof = float(np.sum((p.shape[1] - rank)[ok]))
    if power <= 0 or dof <= 0:
        return out
    lags = min(max_lag, n - 1)
    lagged = np.array([float(np.sum(q[k:] * q[:n - k])) for k in range(1, lags + 1)])
    tau = long_run_factors(lagged / power)
    if window is None:
        window = local_window(float(np.median((p.shape[1] - rank)[ok])))
    local_dof = local_sums(np.where(ok, p.shape[1] - rank, 0), window)
    with np.errstate(divide="ignore", invalid="ignore"):
        s2 = np.where(local_dof > 0, local_sums(np.sum(q * q, axis=1), window) / local_dof, power / dof)
    if robust is not None and robust[1] > 0:  # the M-estimator's sandwich (robust_slope)
        part = [local_sums(np.where(ok, sandwich[:, j], 0.0), window) for j in range(3)]
        leverage = local_sums(np.where(ok, rank, 0), window)
        s2 = np.where((part[1] > 0) & (leverage > 0), sandwich_factor(*part, leverage), s2)
    kinematic = None
    if process is not None and n > 2:
        density, natural, dt = process
        steps = jerk_steps(density, natural, dt)
        share, a, b = kinematic_shares(single, np.vstack([steps[0], steps[0][-1:]]), np.vstack([steps[1], steps[1][-1:]]),
                                       np.append(dt, dt[-1]))
        r = trapezoid_residuals(states, steps)
        fine = np.all(np.isfinite(r), axis=1) & ok[:-1] & ok[1:]
        r2 = np.append(np.where(fine, np.sum(np.where(fine[:, None], r, 0.0) ** 2, axis=1), 0.0), 0.0)
        use = np.append(fine, False)
        level = trapezoid_level(local_sums(r2, window), local_sums(np.where(use, a.sum(axis=1), 0.0), window),
                                local_sums(np.where(use, b.sum(axis=1), 0.0), window), s2)
        kinematic = (share, level[:, None])
    out[:, :9] = out[:, :9] * scale_factors(out[:, :9], single, s2[:, None], tau, kinematic)
    if dt_s is not None and n > 2 and getattr(array, "readings", "specific_force") == "specific_force":
        gain = common_gain_variance(gravity_windows(*gravity_steps(states, dt_s), _gravity_window_steps(dt_s)))
        if gain > 0:
            out[:, :9] = np.sqrt(out[:, :9] ** 2 + common_gain_sd(states, gain) ** 2)
    return out


def calibrates_stream(array, groups) -> bool:
    """Whether the fixed-lag smoother scales σ under the option ``groups`` of its model (its model, batch model
    and self-calibration): the accelerometers alone as they are, no gyroscope or calibration variables the
    residual would leave out."""
    return (groups.batch_model.measurement == "accelerometer" and not groups.self_calibration.calibrates
            and not (groups.model.use_gyro and array.gyroscope is not None))


def jerk_density(model):
    """(white-jerk density per body axis (3,) [rad/s²/√s], the driven oscillator's Ω per axis (3,) [rad/s]) of
    the ``model``'s (option group) motion model (Ω = 0: the white jerk), or None (white snap)."""
    if model.motion_model != "jerk":
        return None
    return (float(model.omega_dot_random_walk_radps2_per_sqrt_s) * np.asarray(model.process_axis_factors, dtype=float),
            2.0 * np.pi * np.asarray(model.process_axis_frequencies_hz, dtype=float))
