"""Factors and initial values of the fixed-lag smoother (paper 000, eq. 6).

Variables of sample k (gtsam vectors, body frame B): ``W(k)`` = ω [rad/s],
``D(k)`` = ω̇ [rad/s²], ``F(k)`` = f [m/s²].

- measurement: ``r = S [f, ω̇, q(ω)] - y`` (Python factor; Jacobian
  ``[S_f, S_ω̇, S_q ∂q/∂ω]``);
- ω integration (trapezoid) ``r = ω_{k+1} - ω_k - h (ω̇_k + ω̇_{k+1}) / 2`` with
  variance ``q_ω̈ h³ / 12`` (white angular jerk), a linear factor evaluated by
  gtsam itself;
- random walks ``ω̇_{k+1} - ω̇_k`` (variance ``q_ω̈ h``) and ``f_{k+1} - f_k``
  (variance ``q_f h``): gtsam ``BetweenFactorVector``;
- priors on the first state of a segment, optional gyroscope on ω.
"""

from __future__ import annotations

import gtsam
import numpy as np

from .. import rigid_body
from ..array import SensorArray

_W, _D, _F = (ord(c) << 56 for c in "wdf")  # gtsam.Symbol layout: char in the top byte


def keys(k: int) -> tuple[int, int, int]:
    """gtsam keys of ω, ω̇ and f of sample k."""
    return _W | k, _D | k, _F | k


def insert_state(values: gtsam.Values, k: int, omega, omega_dot, f) -> None:
    kw, kd, kf = keys(k)
    values.insert(kw, np.asarray(omega, dtype=float))
    values.insert(kd, np.asarray(omega_dot, dtype=float))
    values.insert(kf, np.asarray(f, dtype=float))


class ArrayModel:
    """Precomputed matrices and noise models of one array."""

    def __init__(self, array: SensorArray, options) -> None:
        self.array = array
        self.options = options
        S = array.structure_matrix()
        self.S_lin = np.ascontiguousarray(S[:, :6])  # [f, ω̇] columns
        self.S_q = np.ascontiguousarray(S[:, 6:])
        self.S_f = np.ascontiguousarray(S[:, :3])
        self.S_dw = np.ascontiguousarray(S[:, 3:6])
        sigma = array.noise_std_per_axis_mps2
        sigma = np.where(np.isfinite(sigma), sigma, options.accel_noise_std_mps2)
        sigma = np.where(sigma > 0, sigma, options.accel_noise_std_mps2)
        self.accel_sigma_mps2 = sigma
        self.accel_noise = gtsam.noiseModel.Diagonal.Sigmas(sigma)
        wS = S / sigma[:, None]
        self.pinv_w = np.linalg.pinv(wS) / sigma[None, :]  # weighted LS of all 12 unknowns
        wL = self.S_lin / sigma[:, None]
        self.pinv_lin_w = np.linalg.pinv(wL) / sigma[None, :]  # [f, ω̇] given q(ω)
        self._eye3 = np.eye(3)
        self._zero3 = np.zeros(3)
        self._noise_cache: dict = {}
        self.gyro_noise = gtsam.noiseModel.Isotropic.Sigma(
            3, array.gyroscope.noise_std_radps if array.gyroscope is not None and array.gyroscope.noise_std_radps
            else options.gyro_noise_std_radps)

    # --- factors ----------------------------------------------------------------
    def add_measurement(self, graph: gtsam.NonlinearFactorGraph, k: int, y: np.ndarray, gyro=None) -> None:
        kw, kd, kf = keys(k)
        S_lin, S_q, S_f, S_dw = self.S_lin, self.S_q, self.S_f, self.S_dw
        y = np.array(y, dtype=float)

        def error(this, values, jacobians):
            w = values.atVector(kw)
            x, yy, z = w
            q = np.array([x * x + yy * yy, x * x + z * z, yy * yy + z * z, x * yy, x * z, yy * z])
            r = S_lin[:, :3] @ values.atVector(kf) + S_lin[:, 3:] @ values.atVector(kd) + S_q @ q - y
            if jacobians is not None:
                dq = np.array([[2 * x, 2 * yy, 0.0], [2 * x, 0.0, 2 * z], [0.0, 2 * yy, 2 * z],
                               [yy, x, 0.0], [z, 0.0, x], [0.0, z, yy]])
                jacobians[0] = S_q @ dq
                jacobians[1] = S_dw
                jacobians[2] = S_f
            return r

        graph.add(gtsam.CustomFactor(self.accel_noise, [kw, kd, kf], error))
        if gyro is not None:
            graph.add(gtsam.PriorFactorVector(kw, np.asarray(gyro, dtype=float), self.gyro_noise))

    def _process_noises(self, h: float):
        key = round(h * 1e9)
        cached = self._noise_cache.get(key)
        if cached is None:
            o = self.options
            s_int = np.sqrt(o.angular_jerk_psd * h ** 3 / 12.0 + o.integration_floor_radps ** 2)
            cached = (
                gtsam.noiseModel.Isotropic.Sigma(3, s_int),
                gtsam.noiseModel.Isotropic.Sigma(3, np.sqrt(o.angular_jerk_psd * h)),
                gtsam.noiseModel.Isotropic.Sigma(3, np.sqrt(o.jerk_psd * h)),
            )
            if len(self._noise_cache) > 64:  # irregular timestamps: keep the cache bounded
                self._noise_cache.clear()
            self._noise_cache[key] = cached
        return cached

    def add_process(self, graph: gtsam.NonlinearFactorGraph, k0: int, k1: int, h: float) -> None:
        w0, d0, f0 = keys(k0)
        w1, d1, f1 = keys(k1)
        int_noise, dw_noise, f_noise = self._process_noises(h)
        # Trapezoid: r = (ω1 - ω0 - h/2 (ω̇0 + ω̇1)), constant Jacobians.
        half_h = 0.5 * h
        eye, neg, jd = self._eye3, -self._eye3, -half_h * self._eye3

        def error(this, values, jacobians):
            r = values.atVector(w1) - values.atVector(w0) - half_h * (values.atVector(d0) + values.atVector(d1))
            if jacobians is not None:
                jacobians[0] = neg
                jacobians[1] = eye
                jacobians[2] = jd
                jacobians[3] = jd
            return r

        graph.add(gtsam.CustomFactor(int_noise, [w0, w1, d0, d1], error))
        graph.add(gtsam.BetweenFactorVector(d0, d1, self._zero3, dw_noise))
        graph.add(gtsam.BetweenFactorVector(f0, f1, self._zero3, f_noise))

    def add_priors(self, graph: gtsam.NonlinearFactorGraph, k: int, omega, omega_dot, f) -> None:
        o = self.options
        kw, kd, kf = keys(k)
        graph.add(gtsam.PriorFactorVector(kw, np.asarray(omega, float), gtsam.noiseModel.Isotropic.Sigma(3, o.prior_omega_std_radps)))
        graph.add(gtsam.PriorFactorVector(kd, np.asarray(omega_dot, float),
                                          gtsam.noiseModel.Isotropic.Sigma(3, o.prior_omega_dot_std_radps2)))
        graph.add(gtsam.PriorFactorVector(kf, np.asarray(f, float),
                                          gtsam.noiseModel.Isotropic.Sigma(3, o.prior_specific_force_std_mps2)))

    # --- initial values ---------------------------------------------------------
    def predict(self, omega, omega_dot, f, h: float, y: np.ndarray):
        """Initial value of a new state: ω by one step of ω̇, then [f, ω̇] from y given q(ω)."""
        w = omega + h * omega_dot
        x6 = self.pinv_lin_w @ (y - self.S_q @ rigid_body.quadratic_terms(w))
        return w, x6[3:], x6[:3]


_SIGN_PATTERNS = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [1, -1, -1]], dtype=float)


def omega_up_to_sign(q: np.ndarray) -> np.ndarray:
    """ω from its quadratic terms up to one global sign, (N, 6) -> (N, 3).

    Magnitudes from the squares (paper 000, §IV); the relative signs are the
    pattern (first component positive) that best matches the products
    ωxωy, ωxωz, ωyωz.
    """
    mag = rigid_body.omega_from_quadratic_terms(q)
    cand = mag[:, None, :] * _SIGN_PATTERNS[None, :, :]  # (N, 4, 3)
    prods = np.stack([cand[..., 0] * cand[..., 1], cand[..., 0] * cand[..., 2], cand[..., 1] * cand[..., 2]], axis=-1)
    cost = np.sum((prods - q[:, None, 3:]) ** 2, axis=-1)
    best = np.argmin(cost, axis=1)
    return cand[np.arange(len(q)), best]


def track_sign(v: np.ndarray, omega_dot: np.ndarray, times_s: np.ndarray) -> np.ndarray:
    """Resolve the global sign of ω over a short run by following ω̇.

    Two tracks start from +v₀ and -v₀; each picks, sample by sample, the sign
    of ±v_k nearer to the previous choice plus the trapezoidal step of ω̇. The
    track whose choices agree better with the integrated ω̇ wins. (When ω̇
    carries no information the two tracks tie and the sign stays unresolved:
    the accelerometers cannot see it.)
    """
    n = len(v)
    best, best_cost = None, np.inf
    for s0 in (1.0, -1.0):
        out = np.empty_like(v)
        out[0] = s0 * v[0]
        cost = 0.0
        for k in range(1, n):
            pred = out[k - 1] + 0.5 * (times_s[k] - times_s[k - 1]) * (omega_dot[k - 1] + omega_dot[k])
            plus, minus = v[k], -v[k]
            ep, em = np.sum((plus - pred) ** 2), np.sum((minus - pred) ** 2)
            out[k] = plus if ep <= em else minus
            cost += min(ep, em)
        if cost < best_cost - 1e-12:
            best, best_cost = out, cost
    return best


def initial_states(array: SensorArray, times_ns: np.ndarray, accel: np.ndarray, m: ArrayModel):
    """Per-sample weighted least squares (paper 000, eq. 7) with the sign of ω tracked."""
    x = accel @ m.pinv_w.T
    f, omega_dot, q = x[:, :3], x[:, 3:6], x[:, 6:]
    v = omega_up_to_sign(q)
    times_s = (np.asarray(times_ns, dtype=np.int64) - int(times_ns[0])) * 1e-9
    omega = track_sign(v, omega_dot, times_s)
    return omega, omega_dot, f
