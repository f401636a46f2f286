"""Fixed-lag smoothing of the window in numpy: a Kalman filter that carries cross-covariances.

The factors of :mod:`gfimu.smoother._fixed_lag_model` written as a state-space
model of the state ``x = [ω, ω̇, f]`` (9 values, body frame):

- process: the trapezoid ``ω_{k+1} = ω_k + h/2 (ω̇_k + ω̇_{k+1}) + n_int`` and the
  random walk ``ω̇_{k+1} = ω̇_k + n_ω̇`` are, substituting the second in the first,
  ``ω_{k+1} = ω_k + h ω̇_k + h/2 n_ω̇ + n_int``: ``x_{k+1} = F x_k + n`` with
  ``Q_ωω = σ_int² + h²/4 σ_ω̇²``, ``Q_ωω̇ = h/2 σ_ω̇²``, ``Q_ω̇ω̇ = σ_ω̇²`` per body axis
  (the change of variables has unit Jacobian, so the density of the factor graph
  and of this model are the same); f is a random walk; with
  ``process_axis_frequencies_hz`` the exact oscillator step (Φ, its covariance);
- measurement (paper 000, eq. 6): ``y = S_f f + S_ω̇ ω̇ + S_q q(ω) + v``, and the
  gyroscope ``ω + v_g``; priors on the first state of a segment; the whitened rows
  of the factor groups given in the options (:meth:`ArrayModel.sample_terms`:
  "readings" 0 with unit noise).

The measurement is linearised by a Gauss-Newton (iterated extended Kalman) update
of the newest state, started from the prediction, or from the sign-resolving
initial values during the warm-up of a segment. Every state ``i`` of the window
keeps its mean given all data so far, its marginal variances and
``C_i = Cov(x_i, x_newest)``; one measurement of the newest state moves them all
by ``m_i += C_i Hᵀ S⁻¹ ν``, ``C_i ← C_i (I - Hᵀ S⁻¹ H P)``: the fixed-lag
smoother as a Kalman filter on the state augmented with the window, keeping only
the cross-covariances the newest measurement needs (O(window) 9×9 products, all
vectorised). For a linear measurement this is exactly the minimum of the
window's least-squares problem given the marginalised past (what gtsam's
fixed-lag smoother solves); with the quadratic term, each measurement keeps the
linearisation of its own update (gtsam relinearises ω when it moves by more
than its threshold, 0.1 rad/s by default).

The window lives in preallocated arrays; states leave from the old end
(exact marginalisation: the filter already carries the marginal), and the
arrays are compacted when the new end reaches their capacity.
"""

from __future__ import annotations

import numpy as np

from ..factors import kinematics, process
from ._fixed_lag_model import ArrayModel


class FilterFailure(RuntimeError):
    """A numerical failure of an update (a singular innovation covariance, non-finite values)."""


class WindowFilter:
    """The window of one segment: means, marginal variances and cross-covariances with the newest state."""

    def __init__(self, model: ArrayModel, capacity: int = 256, iterations: int = 2,
                 step_tolerance_radps: float = 1e-6) -> None:
        self.model = model
        self.iterations = int(iterations)
        self.step_tolerance_radps = float(step_tolerance_radps)
        o = model.options
        self._prior_var = np.repeat(np.array([o.initial_omega_std_radps, o.initial_omega_dot_std_radps2,
                                              o.initial_specific_force_std_mps2], dtype=float) ** 2, 3)
        self._R = model.accel_sigma_mps2 ** 2
        self._gyro_var = model.gyro_sigma_radps ** 2
        self._cap = max(int(capacity), 8)
        self._mean = np.zeros((self._cap, 9))
        self._var = np.zeros((self._cap, 9))
        self._cross = np.zeros((self._cap, 9, 9))
        self._tmp = np.empty((self._cap, 9, 9))
        self._lo = self._hi = 0
        self._base = 0  # index k of slot 0
        self._P = np.zeros((9, 9))  # covariance of the newest state
        self._process_cache: dict = {}
        self.n_updates = 0
        m = model.S_q.shape[0]
        # Jacobian buffers: the ω̇ and f columns are constant; the gyroscope rows select ω
        self._H = np.zeros((m, 9))
        self._H[:, 3:6], self._H[:, 6:] = model.S_dw, model.S_f
        self._Hg = np.zeros((m + 3, 9))
        self._Hg[:m] = self._H
        self._Hg[m + np.arange(3), np.arange(3)] = 1.0
        self._Rg = np.concatenate([self._R, np.full(3, self._gyro_var)])
        self._diag = (np.arange(m), np.arange(m))
        self._diag_g = (np.arange(m + 3), np.arange(m + 3))

    # --- window -------------------------------------------------------------------------
    def __len__(self) -> int:
        return self._hi - self._lo

    @property
    def capacity(self) -> int:
        return self._cap

    def _slot(self, k: int) -> int:
        s = k - self._base
        if not self._lo <= s < self._hi:
            raise KeyError(f"state {k} is not in the window")
        return s

    def mean(self, k: int) -> np.ndarray:
        return self._mean[self._slot(k)]

    def sigma(self, k: int) -> np.ndarray:
        return np.sqrt(np.clip(self._var[self._slot(k)], 0.0, None))

    def drop_oldest(self) -> None:
        if self._hi > self._lo:
            self._lo += 1

    def _make_room(self) -> None:
        if self._hi < self._cap:
            return
        n = self._hi - self._lo
        if n >= self._cap // 2:  # a window longer than expected (irregular steps): grow
            cap = 2 * self._cap
            for name in ("_mean", "_var", "_cross"):
                old = getattr(self, name)
                new = np.zeros((cap,) + old.shape[1:])
                new[:n] = old[self._lo:self._hi]
                setattr(self, name, new)
            self._tmp = np.empty((cap, 9, 9))
            self._cap = cap
        else:
            for arr in (self._mean, self._var, self._cross):
                arr[:n] = arr[self._lo:self._hi]
        self._base += self._lo
        self._lo, self._hi = 0, n

    # --- model --------------------------------------------------------------------------
    def _process(self, h: float):
        key = round(h * 1e9)
        cached = self._process_cache.get(key)
        if cached is not None:
            return cached
        m, o = self.model, self.model.options
        q_dw = o.omega_dot_random_walk_radps2_per_sqrt_s
        F = np.eye(9)
        Q = np.zeros((9, 9))
        if m.oscillator:
            phi = process.oscillator_transition(h, m.natural_frequency_radps)[0]
            cov = process.oscillator_step_covariance(q_dw, h, m.natural_frequency_radps, m.axis_factors)[0]
            for i in range(3):
                F[i, i], F[i, 3 + i], F[3 + i, i], F[3 + i, 3 + i] = phi[i, 0, 0], phi[i, 0, 1], phi[i, 1, 0], phi[i, 1, 1]
            Q[:6, :6] = cov
        else:
            s_int = float(kinematics.trapezoid_sigma(q_dw, h)) * m.axis_factors
            s_dw = float(process.random_walk_sigma(q_dw, h)) * m.axis_factors
            for i in range(3):
                F[i, 3 + i] = h
                Q[i, i] = s_int[i] ** 2 + 0.25 * h * h * s_dw[i] ** 2
                Q[i, 3 + i] = Q[3 + i, i] = 0.5 * h * s_dw[i] ** 2
                Q[3 + i, 3 + i] = s_dw[i] ** 2
        s_f = float(process.random_walk_sigma(o.specific_force_random_walk_mps2_per_sqrt_s, h))
        Q[6:, 6:] = s_f * s_f * np.eye(3)
        if len(self._process_cache) > 64:  # irregular timestamps: keep the cache bounded
            self._process_cache.clear()
        cached = (F, np.ascontiguousarray(F.T), Q)
        self._process_cache[key] = cached
        return cached

    def _measure(self, x: np.ndarray, gyro):
        """Prediction ``h(x)`` and Jacobian H of the readings (and gyroscope) at ``x``."""
        m = self.model
        wx, wy, wz = x[0], x[1], x[2]
        q = np.array([wx * wx + wy * wy, wx * wx + wz * wz, wy * wy + wz * wz, wx * wy, wx * wz, wy * wz])
        dq = np.array([[2 * wx, 2 * wy, 0.0], [2 * wx, 0.0, 2 * wz], [0.0, 2 * wy, 2 * wz],
                       [wy, wx, 0.0], [wz, 0.0, wx], [0.0, wz, wy]])
        H = self._H if gyro is None else self._Hg
        n = m.S_q.shape[0]
        H[:n, :3] = m.S_q @ dq
        pred = H[:n, 3:] @ x[3:] + m.S_q @ q
        if gyro is None:
            return pred, H
        return np.concatenate([pred, x[:3]]), H

    # --- updates ------------------------------------------------------------------------
    def start(self, k: int) -> None:
        """First state of a segment, index ``k``: the weak zero-mean priors."""
        self._lo = self._hi = 0
        self._base = k
        self._mean[0] = 0.0
        self._var[0] = self._prior_var
        self._P = np.diag(self._prior_var)
        self._cross[0] = self._P
        self._hi = 1

    def predict(self, k: int, h: float) -> None:
        """Append state ``k`` one step of ``h`` seconds after the newest."""
        if k != self._base + self._hi:
            raise ValueError(f"state {k} does not follow the window's newest state")
        F, FT, Q = self._process(h)
        self._make_room()
        lo, hi = self._lo, self._hi
        x = F @ self._mean[hi - 1]
        P = F @ self._P @ FT + Q
        P = 0.5 * (P + P.T)
        n = hi - lo
        tmp = np.matmul(self._cross[lo:hi].reshape(9 * n, 9), FT, out=self._tmp[lo:hi].reshape(9 * n, 9))
        self._cross[lo:hi] = tmp.reshape(n, 9, 9)
        self._mean[hi] = x
        self._var[hi] = np.diagonal(P)
        self._cross[hi] = P
        self._P = P
        self._hi = hi + 1

    def measure(self, y: np.ndarray, gyro=None, start=None, extra=None) -> None:
        """Gauss-Newton update of the newest state with its readings, moving every state of the window.

        ``extra``: the factor groups' rows at this sample (:meth:`ArrayModel.sample_terms`), or None."""
        lo, hi = self._lo, self._hi
        xp = self._mean[hi - 1].copy()
        P = self._P
        if gyro is not None:
            y = np.concatenate([y, gyro])
            R, diag = self._Rg, self._diag_g
        else:
            R, diag = self._R, self._diag
        x = xp if start is None else np.asarray(start, dtype=float)
        rhs = np.empty((R.size, 10))
        extended = False
        for _ in range(max(self.iterations, 1)):
            pred, H = self._measure(x, gyro)
            if extra is not None:  # the groups' whitened rows: readings 0, prediction r(x), unit noise
                r_e, J_e = extra(x)
                H = np.vstack([H, J_e])
                pred = np.concatenate([pred, r_e])
                if not extended:
                    y, R = np.concatenate([y, np.zeros(r_e.size)]), np.concatenate([R, np.ones(r_e.size)])
                    diag = (np.arange(R.size), np.arange(R.size))
                    rhs = np.empty((R.size, 10))
                    extended = True
            rhs[:, :9] = H
            rhs[:, 9] = y - pred + H @ (x - xp)  # innovation of the linearisation at x
            PHt = P @ H.T
            S = H @ PHt
            S[diag] += R
            try:
                Z = np.linalg.solve(S, rhs)  # S⁻¹ [H, ν]
            except np.linalg.LinAlgError as err:
                raise FilterFailure(f"singular innovation covariance ({err})") from err
            x_new = xp + PHt @ Z[:, -1]
            step = abs(x_new[0] - x[0]) + abs(x_new[1] - x[1]) + abs(x_new[2] - x[2])
            x = x_new
            if step < self.step_tolerance_radps:
                break
        # the last linearisation moves the whole window
        g = H.T @ Z[:, -1]  # Hᵀ S⁻¹ ν
        A = H.T @ Z[:, :-1]  # Hᵀ S⁻¹ H
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(A))):
            raise FilterFailure("non-finite values in the update")
        n = hi - lo
        cross = self._cross[lo:hi].reshape(9 * n, 9)  # the stack as one matrix: one BLAS call per product
        # (einsum, not BLAS gemv: OpenBLAS threads a gemv this size, and on a busy machine waiting for its
        # second thread costs milliseconds)
        self._mean[lo:hi] += np.einsum("lij,j->li", cross.reshape(n, 9, 9), g)
        CA = np.matmul(cross, A, out=self._tmp[lo:hi].reshape(9 * n, 9))
        self._var[lo:hi] -= np.einsum("lij,lij->li", CA.reshape(n, 9, 9), cross.reshape(n, 9, 9))
        # C_i (I - A P) = C_i - (C_i A) P
        cross -= CA @ P
        P_new = P - P @ A @ P
        P_new = 0.5 * (P_new + P_new.T)
        self._P = P_new
        self._cross[hi - 1] = P_new
        self._var[hi - 1] = np.diagonal(P_new)
        self.n_updates += 1
