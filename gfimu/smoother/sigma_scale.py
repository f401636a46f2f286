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
- **Variance factor** s² = Σ_i |p_i|² / Σ_i (m − rank J_i): the realised misfit against the assumed
  noise (1 when the noise is as stated).
- **Correlation in time.** ρ_k = Σ_i p_i · p_{i−k} / Σ_i |p_i|², k = 1 … :data:`MAX_LAG`. A state the
  smoother estimates from L samples' worth of readings has, under an error of this correlation, the
  variance of white noise times τ(L) = 1 + 2 Σ_{k<L} (1 − k/L) ρ_k (the mean of L correlated samples
  against that of L independent ones; linear between whole L), taken at least 1.
- **Span.** L_ij = σ²_single,ij / σ²_ij: the variance of state j from sample i's readings alone
  ((J_iᵀ J_i)⁺, infinite along directions one sample does not see, such as ω at rest) over the
  smoother's; at most :data:`MAX_LAG`.

The reported σ_ij becomes σ_ij √(s² τ(L_ij)). The batch smoother takes s² and ρ over the whole log
(:func:`calibrated_sigma`); the fixed-lag smoother, which writes σ as it goes, over the samples emitted
so far (:class:`RunningSigmaScale`: causal). The estimates themselves are not touched.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..rigid_body import quadratic_terms, quadratic_terms_jacobian

MAX_LAG = 64
"""Longest lag [samples] of the residual's autocorrelation, and longest span L taken."""
RANK_TOLERANCE = 1e-6
"""A direction of the whitened Jacobian counts (rank, single-sample variance) when its singular value
exceeds this times the largest."""
MIN_SAMPLES = 16
"""The running factor stays 1 until this many samples' residuals are in."""


def _geometry(array):
    S = array.structure_matrix()
    return S[:, 0:3], S[:, 3:6], S[:, 6:12]


def parity(array, accel_mps2: np.ndarray, states: np.ndarray, noise_std_mps2: np.ndarray, robust=None):
    """(p (N, m), rank (N,), single-sample variances (N, 9)) of the readings ``accel_mps2`` (N, m) at the
    estimates ``states`` (N, ≥9: ω, ω̇, f) with the noise std ``noise_std_mps2`` (N, m) or (m,): the parity
    residual, the rank of the whitened Jacobian and the variance of each state from that sample alone
    (module docstring). ``robust``: (loss, threshold) of the smoother's robust re-weighting of the
    accelerometer axes, or None: each axis' std is then the one the re-weighting gives at the estimate,
    ``std / √w(r/std)`` (:func:`gfimu.smoother.graph.robust_weight`), the noise the smoother's σ assumed."""
    S_f, S_dw, S_q = _geometry(array)
    X = np.asarray(states, dtype=float)
    w, dw, f = X[:, 0:3], X[:, 3:6], X[:, 6:9]
    y = np.asarray(accel_mps2, dtype=float)
    inv = 1.0 / np.broadcast_to(np.asarray(noise_std_mps2, dtype=float), y.shape)
    z = (y - f @ S_f.T - dw @ S_dw.T - quadratic_terms(w) @ S_q.T) * inv
    if robust is not None and robust[1] > 0:
        from .graph import robust_weight

        weight = np.sqrt(robust_weight(z, float(robust[1]), robust[0]))
        z, inv = z * weight, inv * weight
    J = np.concatenate([np.einsum("mk,nkj->nmj", S_q, quadratic_terms_jacobian(w)),
                        np.broadcast_to(S_dw, (len(X),) + S_dw.shape), np.broadcast_to(S_f, (len(X),) + S_f.shape)],
                       axis=2) * inv[:, :, None]
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    keep = s > RANK_TOLERANCE * s[:, :1]
    Uk = U * keep[:, None, :]
    p = z - np.einsum("nmr,nr->nm", Uk, np.einsum("nmr,nm->nr", Uk, z))
    with np.errstate(divide="ignore"):
        inv_s2 = np.where(keep, 1.0 / np.where(keep, s, 1.0) ** 2, np.inf)
    Vt2 = Vt ** 2
    with np.errstate(invalid="ignore"):
        single = np.einsum("nrj,nr->nj", np.where(Vt2 > 0, Vt2, 0.0), np.where(np.isinf(inv_s2), 0.0, inv_s2))
        unseen = np.any((Vt2 > 1e-12) & ~keep[:, :, None], axis=1)
    single = np.where(unseen, np.inf, single)
    return p, keep.sum(axis=1), single


def long_run_factors(rho: np.ndarray) -> np.ndarray:
    """τ(L) for L = 0 … len(rho) (``rho[k-1]``: the autocorrelation at lag k), each at least 1."""
    K = len(rho)
    out = np.ones(K + 1)
    k = np.arange(1, K + 1)
    for L in range(2, K + 1):
        out[L] = 1.0 + 2.0 * float(np.sum((1.0 - k[:L - 1] / L) * rho[:L - 1]))
    return np.maximum(out, 1.0)


def scale_factors(sd: np.ndarray, single: np.ndarray, variance_factor: float, tau: np.ndarray) -> np.ndarray:
    """(N, 9) factors on σ: √(s² τ(L_ij)), L_ij = single_ij / sd_ij² within 0 … len(tau) − 1 (τ linear
    between whole spans)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        span = single / (sd * sd)
    span = np.where(np.isfinite(span), span, np.inf)
    L = np.clip(np.nan_to_num(span, nan=0.0, posinf=len(tau) - 1), 0, len(tau) - 1)
    return np.sqrt(variance_factor * np.interp(L, np.arange(len(tau)), tau))


class RunningSigmaScale:
    """The factor on σ from the residuals seen so far (the fixed-lag smoother's, causal): :meth:`scaled`
    takes one emitted state with its reading, adds its parity residual to the running sums and returns
    its σ scaled by the factor of those sums."""

    def __init__(self, array, max_lag: int = MAX_LAG):
        self.array = array
        self.robust = None
        """(loss, threshold) of the robust re-weighting in use (:func:`parity`), or None."""
        self.max_lag = int(max_lag)
        self._recent: deque = deque(maxlen=self.max_lag)  # the newest parity residuals, newest last
        self._power = 0.0
        self._dof = 0.0
        self._lagged = np.zeros(self.max_lag)
        self.samples = 0

    def reset(self) -> None:
        """A new segment: the lagged products do not reach across it (the sums so far are kept)."""
        self._recent.clear()

    @property
    def variance_factor(self) -> float:
        return self._power / self._dof if self._dof > 0 and self.samples >= MIN_SAMPLES else 1.0

    def tau(self) -> np.ndarray:
        if self.samples < MIN_SAMPLES or self._power <= 0:
            return np.ones(self.max_lag + 1)
        return long_run_factors(self._lagged / self._power)

    def scaled(self, accel_mps2: np.ndarray, state: np.ndarray, sd: np.ndarray, noise_std_mps2: np.ndarray) -> np.ndarray:
        """``sd`` (9,) of ``state`` (9,: ω, ω̇, f) scaled by the factor with this sample's residual included."""
        p, rank, single = parity(self.array, np.asarray(accel_mps2, dtype=float)[None], np.asarray(state)[None, :9],
                                 np.asarray(noise_std_mps2, dtype=float)[None], self.robust)
        p = p[0]
        if np.all(np.isfinite(p)):
            self._power += float(p @ p)
            self._dof += float(len(p) - rank[0])
            if self._recent:
                past = np.array(self._recent)[::-1]  # lag 1 first
                self._lagged[:len(past)] += past @ p
            self._recent.append(p)
            self.samples += 1
        return np.asarray(sd, dtype=float) * scale_factors(np.asarray(sd, dtype=float)[None], single,
                                                           self.variance_factor, self.tau())[0]


def calibrated_sigma(array, accel_mps2: np.ndarray, states: np.ndarray, sd: np.ndarray, noise_std_mps2: np.ndarray,
                     robust=None, max_lag: int = MAX_LAG) -> np.ndarray:
    """``sd`` (N, ≥9) with its first nine columns (ω, ω̇, f) scaled by the factors of the whole log's
    residuals (the batch smoother's; module docstring). Rows with a non-finite residual do not count."""
    p, rank, single = parity(array, accel_mps2, states[:, :9], noise_std_mps2, robust)
    ok = np.all(np.isfinite(p), axis=1)
    out = np.array(sd, dtype=float)
    if np.count_nonzero(ok) < MIN_SAMPLES:
        return out
    q = np.where(ok[:, None], p, 0.0)
    power = float(np.sum(q * q))
    dof = float(np.sum((p.shape[1] - rank)[ok]))
    if power <= 0 or dof <= 0:
        return out
    n = len(q)
    lags = min(max_lag, n - 1)
    lagged = np.array([float(np.sum(q[k:] * q[:n - k])) for k in range(1, lags + 1)])
    tau = long_run_factors(lagged / power)
    out[:, :9] = out[:, :9] * scale_factors(out[:, :9], single, power / dof, tau)
    return out


def calibrates_stream(array, options) -> bool:
    """Whether the fixed-lag smoother scales σ (the accelerometers alone as they are: no gyroscope or
    calibration variables the residual would leave out)."""
    return (options.measurement == "accelerometer" and not (options.self_calibrate_bias or options.self_calibrate_scale)
            and not (options.use_gyro and array.gyroscope is not None))
