"""Compiled kernels of the fixed-lag window filter's update (:mod:`gfimu.smoother.stream.window_filter`).

The per-sample work of the numpy engine is a few dozen products of 9×9 and m×9 matrices: in numpy
each costs a call (microseconds of dispatch for nanoseconds of arithmetic), so the update is
written here once more as loops that numba compiles to machine code. Each kernel is the numpy
expression it replaces, term for term; the numpy expressions stay in the filter as the oracle the
tests compare these kernels with (``tests/test_filter_kernels.py``), and the filter falls back to
them where a kernel does not apply (gyroscope rows, factor groups' rows).

- :func:`solve` is :meth:`WindowFilter._solve <gfimu.smoother.stream.window_filter.WindowFilter._solve>`
  for the accelerometer readings alone: Gauss-Newton (iterated Kalman) on
  ``J(x) = ||y - h(x)||²_R + ||x - x̂||²_P`` with ``h(x) = S_ω̇ ω̇ + S_f f + S_q q(ω)``
  (Ho & Lin 2009, eq. 6), the accelerometer variances at ``x`` (motion-dependent, robust), each step
  solved in the state's nine dimensions (information form) rather than the m readings' (the same
  update to rounding, a 9 × 9 system instead of an m × m one);
- :func:`search` is the branch search of :meth:`WindowFilter.measure`: Gauss-Newton from the
  prediction and from the other three branches of its minimum (ω flipped, mirrored through the
  array's plane, both: :func:`gfimu.smoother.solve.restarts.branch`), keeping the lowest J;
- :func:`update_window` is :meth:`WindowFilter._update`: one update of the newest state moving
  every state of the window (means, marginal variances, cross-covariances);
- :func:`chain_step` is one step of :class:`gfimu.smoother.stream.model_choice.StreamSignChain`.

Compiled on first use and cached on disk (numba's ``cache=True``: beside this file, or in the user's
cache folder where that is not writable), so only the first run on a machine pays the compilation.
They run without Python's global lock (``nogil=True``; each works on arrays no other thread touches): a
live stream's reader thread takes datagrams in while an update runs, and a model choice in the worker
thread runs beside the stream.
"""

from __future__ import annotations

import numpy as np
from numba import njit

LOSS_NONE, LOSS_CAUCHY, LOSS_HUBER = 0, 1, 2

_TWO, _TRUE, _FALSE = np.int64(2), np.bool_(True), np.bool_(False)
"""Constants passed between kernels as typed values: a literal ``2`` or ``True`` in a call would make numba
compile the callee once more for that literal (one compilation of :func:`solve` per literal, seconds each on
a machine's first run); these share the callee's one compilation."""


def loss_code(c: float, loss: str) -> int:
    """The kernels' code of a robust loss of threshold ``c`` (:func:`gfimu.smoother.model.problem.robust_loss`)."""
    if c <= 0:
        return LOSS_NONE
    return LOSS_CAUCHY if loss == "cauchy" else LOSS_HUBER


@njit(cache=True, nogil=True, inline="always")
def _weight(e: float, c: float, loss: int) -> float:
    """:func:`gfimu.smoother.model.problem.robust_weight` of one whitened residual."""
    e = abs(e)
    if loss == LOSS_CAUCHY:
        return 1.0 / (1.0 + (e / c) ** 2)
    if e <= c:
        return 1.0
    return c / max(e, 1e-300)


@njit(cache=True, nogil=True)
def _eliminate(S, piv, B):
    """Gaussian elimination with partial pivoting of S, in place, with the columns of B (none: an (n, 0) array)
    eliminated along: U above the diagonal and on it, each row's multipliers below it (moved with the row by
    later swaps), the row each column swapped with in ``piv``; False where a pivot is exactly zero or not
    finite."""
    n = S.shape[0]
    k_rhs = B.shape[1]
    for c in range(n):
        p, best = c, abs(S[c, c])
        for r in range(c + 1, n):
            v = abs(S[r, c])
            if v > best:
                p, best = r, v
        if not best > 0.0 or not np.isfinite(best):
            return False
        piv[c] = p
        if p != c:
            for j in range(n):
                S[c, j], S[p, j] = S[p, j], S[c, j]
            for j in range(k_rhs):
                B[c, j], B[p, j] = B[p, j], B[c, j]
        inv = 1.0 / S[c, c]
        for r in range(c + 1, n):
            f = S[r, c] * inv
            S[r, c] = f
            if f != 0.0:
                for j in range(c + 1, n):
                    S[r, j] -= f * S[c, j]
                for j in range(k_rhs):
                    B[r, j] -= f * B[c, j]
    return True


@njit(cache=True, nogil=True)
def _back_substitute(S, B):
    """``B ← U⁻¹ B`` with U the upper triangle of an eliminated S (:func:`_eliminate`)."""
    n = S.shape[0]
    for c in range(n - 1, -1, -1):
        inv = 1.0 / S[c, c]
        for j in range(B.shape[1]):
            v = B[c, j]
            for i in range(c + 1, n):
                v -= S[c, i] * B[i, j]
            B[c, j] = v * inv


@njit(cache=True, nogil=True)
def _lu_solve(S, B):
    """``S⁻¹ B`` by Gaussian elimination with partial pivoting (LAPACK's getrf/getrs, unblocked), in place:
    S is overwritten, B becomes the solution; False where a pivot is exactly zero or not finite."""
    piv = np.empty(S.shape[0], dtype=np.int64)
    if not _eliminate(S, piv, B):
        return False
    _back_substitute(S, B)
    return True


@njit(cache=True, nogil=True)
def _lu_factor(S, piv):
    """:func:`_eliminate` of S alone: its factors for :func:`_lu_apply`, which then solves for any right-hand
    side with the numbers :func:`_lu_solve` gives (the swaps first, then the eliminations: each row receives the
    same updates from the same pivot rows, in the same order)."""
    return _eliminate(S, piv, np.empty((S.shape[0], 0)))


@njit(cache=True, nogil=True)
def _lu_apply(S, piv, B):
    """``B ← S⁻¹ B`` from :func:`_lu_factor`'s factors of S."""
    n = S.shape[0]
    k_rhs = B.shape[1]
    for c in range(n):
        p = piv[c]
        if p != c:
            for j in range(k_rhs):
                B[c, j], B[p, j] = B[p, j], B[c, j]
    for c in range(n):
        for r in range(c + 1, n):
            f = S[r, c]
            if f != 0.0:
                for j in range(k_rhs):
                    B[r, j] -= f * B[c, j]
    _back_substitute(S, B)


@njit(cache=True, nogil=True)
def _factored(P):
    """``(LU, piv, ok)``: :func:`_lu_factor` of a copy of P, for :func:`_factored_form_inverse`."""
    LU = P.copy()
    piv = np.empty(P.shape[0], dtype=np.int64)
    return LU, piv, _lu_factor(LU, piv)


@njit(cache=True, nogil=True)
def _factored_form_inverse(LU, piv, ok, d):
    """:func:`_quadratic_form_inverse` of the matrix :func:`_factored` factored: the same number."""
    if not ok:
        return -1.0
    n = d.shape[0]
    B = np.empty((n, 1))
    for i in range(n):
        B[i, 0] = d[i]
    _lu_apply(LU, piv, B)
    v = 0.0
    for i in range(n):
        v += d[i] * B[i, 0]
    return v


@njit(cache=True, nogil=True)
def _quadratic_form_inverse(P, d):
    """``dᵀ P⁻¹ d`` (the prior's cost), or -1 where P is singular."""
    n = d.shape[0]
    S = P.copy()
    B = np.empty((n, 1))
    for i in range(n):
        B[i, 0] = d[i]
    if not _lu_solve(S, B):
        return -1.0
    v = 0.0
    for i in range(n):
        v += d[i] * B[i, 0]
    return v


@njit(cache=True, nogil=True)
def _predict_readings(x, S_q, S_dw, S_f, pred, H):
    """``h(x)`` into ``pred`` and its Jacobian into H (the ω̇ and f columns are set once, here too)."""
    wx, wy, wz = x[0], x[1], x[2]
    q0, q1, q2 = wx * wx + wy * wy, wx * wx + wz * wz, wy * wy + wz * wz
    q3, q4, q5 = wx * wy, wx * wz, wy * wz
    m = S_q.shape[0]
    for i in range(m):
        a0, a1, a2, a3, a4, a5 = S_q[i, 0], S_q[i, 1], S_q[i, 2], S_q[i, 3], S_q[i, 4], S_q[i, 5]
        H[i, 0] = 2.0 * wx * (a0 + a1) + wy * a3 + wz * a4
        H[i, 1] = 2.0 * wy * (a0 + a2) + wx * a3 + wz * a5
        H[i, 2] = 2.0 * wz * (a1 + a2) + wx * a4 + wy * a5
        s = a0 * q0 + a1 * q1 + a2 * q2 + a3 * q3 + a4 * q4 + a5 * q5
        for j in range(3):
            H[i, 3 + j] = S_dw[i, j]
            H[i, 6 + j] = S_f[i, j]
            s += S_dw[i, j] * x[3 + j] + S_f[i, j] * x[6 + j]
        pred[i] = s


@njit(cache=True, nogil=True)
def _weighted_products(H, nu, R, AG, inv_r, hw):
    """``AG[:, :10] = Hᵀ R⁻¹ [H, ν]`` (``[G, b]`` of :func:`solve`, R diagonal), each reading's row of H
    weighed by 1/R once (``inv_r``, ``hw``: work arrays of the readings' length)."""
    m = H.shape[0]
    for i in range(m):
        inv_r[i] = 1.0 / R[i]
    for a in range(9):
        for i in range(m):
            hw[i] = H[i, a] * inv_r[i]
        for b in range(a, 9):
            s = 0.0
            for i in range(m):
                s += hw[i] * H[i, b]
            AG[a, b] = s
            AG[b, a] = s
        s = 0.0
        for i in range(m):
            s += hw[i] * nu[i]
        AG[a, 9] = s


@njit(cache=True, nogil=True)
def solve(y, xp, P, x, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance, with_cost):
    """:func:`_solve` with P factored here for the cost's prior term."""
    LU, piv, lu_ok = _factored(P)
    return _solve(y, xp, P, x, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance, with_cost, LU, piv,
                  lu_ok)


@njit(cache=True, nogil=True)
def _solve(y, xp, P, x, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance, with_cost, LU, piv, lu_ok):
    """:func:`_gauss_newton` with its ``AG`` solved: ``(x, H, AG, J, ok)``."""
    x, H, AG, M, piv_m, J, ok = _gauss_newton(y, xp, P, x, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations,
                                              tolerance, with_cost, LU, piv, lu_ok)
    if ok:
        _lu_apply(M, piv_m, AG)
    return x, H, AG, J, ok


@njit(cache=True, nogil=True)
def _gauss_newton(y, xp, P, x, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance, with_cost, LU, piv,
                  lu_ok):
    """Gauss-Newton on J from ``x``, at most ``iterations`` steps: ``(x, H, GB, M, piv_m, J, ok)``, with
    ``GB = Hᵀ R⁻¹ [H, ν]`` (9 × 10: ``[G, b]``) at the last linearisation and ``M = I + G P`` factored there
    (``(M, piv_m)``, :func:`_lu_factor`): ``_lu_apply(M, piv_m, GB)`` makes it ``Hᵀ S⁻¹ [H, ν]``, ``A = Hᵀ
    S⁻¹ H`` and ``g = Hᵀ S⁻¹ ν``, the update's information (:func:`_solve`; :func:`search` does it for the
    minimum it keeps alone); J at x (0 unless ``with_cost``); ``ok`` False where the update's system is
    singular or a reading's variance is not positive (the filter's ``FilterFailure``).

    The update is solved in the state's nine dimensions rather than the m readings': with ``G = Hᵀ R⁻¹ H``
    and ``b = Hᵀ R⁻¹ ν`` (R diagonal), ``Hᵀ S⁻¹ = (I + G P)⁻¹ Hᵀ R⁻¹`` (since ``Hᵀ R⁻¹ S = (G P + I) Hᵀ``
    for ``S = H P Hᵀ + R``), so ``[A, g] = (I + G P)⁻¹ [G, b]``, one 9 × 9 system whatever the number of
    axes, and the new state is ``x̂ + P g``: the numpy expression's ``S⁻¹ [H, ν]`` (an m × m system) to
    rounding. Each step solves for g alone; A, which only the last linearisation needs, is solved from
    the same factors by whoever keeps the result (the same numbers as solving both at every step: each
    column of a right-hand side is eliminated on its own). ``(LU, piv, lu_ok)``: P factored
    (:func:`_factored`), for the prior's cost."""
    m = y.shape[0]
    R = R0.copy()
    H = np.zeros((m, 9))
    pred = np.empty(m)
    nu = np.empty(m)
    AG = np.zeros((9, 10))
    M = np.empty((9, 9))
    piv_m = np.zeros(9, dtype=np.int64)
    g = np.empty((9, 1))
    x = x.copy()
    x_new = np.empty(9)
    inv_r = np.empty(m)
    hw = np.empty(m)
    adaptive = slope > 0.0 or c_robust > 0.0
    for it in range(iterations):
        if adaptive:
            w2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
            for i in range(m):
                R[i] = R0[i] + (slope * slope) * w2 if slope > 0.0 else R0[i]
            if c_robust > 0.0 and it > 0:
                _predict_readings(x, S_q, S_dw, S_f, pred, H)
                for i in range(m):
                    R[i] = R[i] / _weight((y[i] - pred[i]) / np.sqrt(R[i]), c_robust, loss)
        if not (adaptive and c_robust > 0.0 and it > 0):  # (else h(x) and H at this x are made just above)
            _predict_readings(x, S_q, S_dw, S_f, pred, H)
        for i in range(m):
            if not R[i] > 0.0:  # a reading without noise: the information form does not apply
                return x, H, AG, M, piv_m, 0.0, False
        for i in range(m):  # ν, the innovation of the linearisation at x
            s = 0.0
            for j in range(9):
                s += H[i, j] * (x[j] - xp[j])
            nu[i] = y[i] - pred[i] + s
        _weighted_products(H, nu, R, AG, inv_r, hw)
        for a in range(9):  # I + G P
            for b in range(9):
                s = 0.0
                for k in range(9):
                    s += AG[a, k] * P[k, b]
                M[a, b] = s
            M[a, a] += 1.0
            g[a, 0] = AG[a, 9]
        if not _lu_factor(M, piv_m):
            return x, H, AG, M, piv_m, 0.0, False
        _lu_apply(M, piv_m, g)  # g ← (I + G P)⁻¹ b = Hᵀ S⁻¹ ν
        for a in range(9):
            s = xp[a]
            for b in range(9):
                s += P[a, b] * g[b, 0]
            x_new[a] = s
        step = abs(x_new[0] - x[0]) + abs(x_new[1] - x[1]) + abs(x_new[2] - x[2])
        for a in range(9):
            x[a] = x_new[a]
        if step < tolerance and (c_robust <= 0.0 or it > 0):
            break
    if not with_cost:
        return x, H, AG, M, piv_m, 0.0, True
    H_last = H.copy()
    _predict_readings(x, S_q, S_dw, S_f, pred, H)
    cost = 0.0
    for i in range(m):
        r = y[i] - pred[i]
        cost += r * r / R[i]
    prior = _factored_form_inverse(LU, piv, lu_ok, x - xp)
    return x, H_last, AG, M, piv_m, cost + max(prior, 0.0), True


@njit(cache=True, nogil=True)
def branch_state(kind, x, normal):
    """x (9,) with its ω, ω̇ on branch ``kind`` (:func:`gfimu.smoother.solve.restarts.branch`)."""
    out = x.copy()
    if kind & 2:
        wn = x[0] * normal[0] + x[1] * normal[1] + x[2] * normal[2]
        nxw0 = normal[1] * x[2] - normal[2] * x[1]
        nxw1 = normal[2] * x[0] - normal[0] * x[2]
        nxw2 = normal[0] * x[1] - normal[1] * x[0]
        for j in range(3):
            out[j] = x[j] - 2.0 * wn * normal[j]
        out[3] = x[3] - 2.0 * wn * nxw0
        out[4] = x[4] - 2.0 * wn * nxw1
        out[5] = x[5] - 2.0 * wn * nxw2
    if kind & 1:
        for j in range(3):
            out[j] = -out[j]
    return out


@njit(cache=True, nogil=True)
def search(y, xp, P, start, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance, branches, normal,
           prior_margin, LU, piv, lu_ok):
    """The update's minimum: Gauss-Newton from ``start``, then (``branches``) from the other three branches
    of that minimum, each tried only when the prediction does not rule it out by more than
    ``prior_margin`` (squared, in P) beyond the minimum's cost; two steps tell a branch that loses, one
    that may win is solved to the end. ``(x, H, AG, J, ok)`` of the lowest J (its ``AG`` solved, as
    :func:`_solve` gives it). ``(LU, piv, lu_ok)``: P factored (:func:`_factored`; read only with
    ``branches``)."""
    x, H, AG, M, pm, J, ok = _gauss_newton(y, xp, P, start, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations,
                                           tolerance, branches, LU, piv, lu_ok)
    if not ok:
        return x, H, AG, J, ok
    if branches:
        x_first = x.copy()  # the branches of the first minimum are tried
        for kind in range(1, 4):
            b = branch_state(kind, x_first, normal)
            distance = _factored_form_inverse(LU, piv, lu_ok, b - xp)
            if distance > J + prior_margin:  # (P singular: -1, tried)
                continue
            cx, cH, cAG, cM, cpm, cJ, cok = _gauss_newton(y, xp, P, b, R0, S_q, S_dw, S_f, slope, c_robust, loss, _TWO,
                                                          tolerance, _TRUE, LU, piv, lu_ok)
            if not cok:
                return cx, cH, cAG, cJ, cok
            if cJ < J:
                cx, cH, cAG, cM, cpm, cJ, cok = _gauss_newton(y, xp, P, cx, R0, S_q, S_dw, S_f, slope, c_robust, loss,
                                                              iterations, tolerance, _TRUE, LU, piv, lu_ok)
                if not cok:
                    return cx, cH, cAG, cJ, cok
            if cJ < J:
                x, H, AG, M, pm, J = cx, cH, cAG, cM, cpm, cJ
    _lu_apply(M, pm, AG)
    return x, H, AG, J, True


@njit(cache=True, nogil=True)
def _mm(A, B):
    """A B of small matrices."""
    n, k = A.shape
    p = B.shape[1]
    out = np.zeros((n, p))
    for i in range(n):
        for c in range(k):
            a = A[i, c]
            if a != 0.0:
                for j in range(p):
                    out[i, j] += a * B[c, j]
    return out


@njit(cache=True, nogil=True)
def _plus(A, B, k):
    """``A + k B`` of two matrices of one shape, as a loop: the same numbers as the array expression
    (``k`` = 1 or -1 gives ``A + B`` and ``A - B`` exactly), which costs numba seconds more to compile."""
    out = np.empty_like(A)
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[i, j] = A[i, j] + k * B[i, j]
    return out


@njit(cache=True, nogil=True)
def _symmetrised(P):
    """``0.5 (P + Pᵀ)`` of a square matrix, as a loop (:func:`_plus`)."""
    out = np.empty_like(P)
    for i in range(P.shape[0]):
        for j in range(P.shape[1]):
            out[i, j] = 0.5 * (P[i, j] + P[j, i])
    return out


@njit(cache=True, nogil=True)
def _mv_plus(u, T, g):
    """``u + T g`` of a vector and a matrix times a vector, each sum in :func:`_mm`'s order."""
    out = np.empty(T.shape[0])
    for i in range(T.shape[0]):
        s = 0.0
        for k in range(T.shape[1]):
            a = T[i, k]
            if a != 0.0:
                s += a * g[k]
        out[i] = u[i] + s
    return out


@njit(cache=True, nogil=True)
def update_window(AG, P, T, u, W, mean, var, cross):
    """The update ``AG = Hᵀ S⁻¹ [H, ν]`` (9 × 10: ``A = Hᵀ S⁻¹ H``, ``g = Hᵀ S⁻¹ ν``) of the newest state
    (covariance P before it) on the window: the recent states ``mean``, ``var``, ``cross`` (n, ...) in
    place, the old ones' factors ``(T, u, W)`` returned new, with the newest state's covariance after it;
    ``ok`` False on non-finite values."""
    g = np.empty(9)
    A = np.empty((9, 9))
    for i in range(9):
        g[i] = AG[i, 9]
        for j in range(9):
            A[i, j] = AG[i, j]
    for i in range(9):
        if not np.isfinite(g[i]):
            return T, u, W, P, False
        for j in range(9):
            if not np.isfinite(A[i, j]):
                return T, u, W, P, False
    u = _mv_plus(u, T, g)
    TA = _mm(T, A)
    W = _plus(W, _mm(TA, np.ascontiguousarray(T.T)), 1.0)
    T = _plus(T, _mm(TA, P), -1.0)
    n = mean.shape[0]
    CA = np.empty((9, 9))
    for l in range(n):
        C = cross[l]
        for i in range(9):
            s = 0.0
            for j in range(9):
                s += C[i, j] * g[j]
            mean[l, i] += s
        for i in range(9):
            for j in range(9):
                s = 0.0
                for k in range(9):
                    s += C[i, k] * A[k, j]
                CA[i, j] = s
        for i in range(9):
            s = 0.0
            for j in range(9):
                s += CA[i, j] * C[i, j]
            var[l, i] -= s
        # C (I - A P) = C - (C A) P
        for i in range(9):
            for j in range(9):
                s = 0.0
                for k in range(9):
                    s += CA[i, k] * P[k, j]
                C[i, j] -= s
    P_new = _symmetrised(_plus(P, _mm(P, _mm(A, P)), -1.0))
    return T, u, W, P_new, True


@njit(cache=True, nogil=True)
def chain_step(prev_w, prev_dw, w, dw, normal, h, c2, cost, back):
    """One step of the streaming sign chain, in place: from the earlier state's (ω, ω̇) on each branch
    (``prev_w``, ``prev_dw``: (4, 3)) and the chain's costs ``cost`` (4,), the Cauchy loss of scale ``c2`` (c²)
    of each trapezoid misfit ``ω_b - ω_a - h/2 (ω̇_a + ω̇_b)`` to the newest state's (ω, ω̇) = (``w``, ``dw``) on
    each branch b: ``back`` (4,) gets the best earlier branch for each later one, ``cost`` the new costs (lowest
    0), ``prev_w`` and ``prev_dw`` the newest state's branches. Returns the branch of the lowest cost (the
    first of equals, as ``argmin``)."""
    nb = cost.shape[0]
    x = np.zeros(9)
    for j in range(3):  # (loops, not slice assignments: the same numbers, seconds less to compile)
        x[j], x[3 + j] = w[j], dw[j]
    cur_w = np.empty((nb, 3))
    cur_dw = np.empty((nb, 3))
    for b in range(nb):
        xb = branch_state(b, x, normal)
        for j in range(3):
            cur_w[b, j], cur_dw[b, j] = xb[j], xb[3 + j]
    new = np.empty(nb)
    for b in range(nb):
        best, arg = np.inf, 0
        for a in range(nb):
            e2 = 0.0
            for j in range(3):
                e = cur_w[b, j] - prev_w[a, j] - 0.5 * h * (prev_dw[a, j] + cur_dw[b, j])
                e2 += e * e
            total = cost[a] + c2 * np.log1p(e2 / c2)
            if total < best:
                best, arg = total, a
        back[b], new[b] = arg, best
    lowest = 0
    for b in range(1, nb):
        if new[b] < new[lowest]:
            lowest = b
    low = new[lowest]
    for b in range(nb):
        cost[b] = new[b] - low
        for j in range(3):
            prev_w[b, j], prev_dw[b, j] = cur_w[b, j], cur_dw[b, j]
    return lowest


@njit(cache=True, nogil=True, inline="always")
def _loss(e2: float, c: float, loss: int) -> float:
    """:func:`gfimu.smoother.model.problem.robust_loss` of one squared whitened residual."""
    if loss == LOSS_NONE:
        return 0.5 * e2
    if loss == LOSS_CAUCHY:
        return 0.5 * c * c * np.log1p(e2 / (c * c))
    e = np.sqrt(e2)
    return 0.5 * e2 if e <= c else c * e - 0.5 * c * c


@njit(cache=True, nogil=True)
def settle_path(X, F, Q_inv, Y, R0, slope, S_q, S_dw, S_f, normal, c_process, process_loss, c_accel, accel_loss):
    """The branch of each state after the oldest that :meth:`WindowFilter.settle
    <gfimu.smoother.stream.window_filter.WindowFilter.settle>` decides, in one call: the n states ``X`` (n, 9;
    the oldest first, held on its branch), the steps between them (``F``, ``Q_inv``: (n - 1, 6, 6), the ω, ω̇
    block of each step's transition and of its covariance's inverse) and the readings ``Y`` (n - 1, m) of the
    states after the oldest. The costs are those of :meth:`~gfimu.smoother.stream.window_filter.WindowFilter._step_costs`
    (the process loss of the RMS over the six rows of the step's whitened residual, times six, between each
    branch a of a state and b of the next) and :meth:`~gfimu.smoother.stream.window_filter.WindowFilter._readings_costs`
    (the accelerometer loss of each reading's squared residual over its variance at the state's |ω|, less
    branch 0's); the path is the Viterbi path from branch 0 of the oldest to branch 0 of the newest. Returns
    the branch (0-3) of each of the n - 1 states after the oldest."""
    n = X.shape[0]
    W = np.empty((4, n, 6))
    for b in range(4):
        for j in range(n):
            xb = branch_state(b, X[j], normal)
            for k in range(6):
                W[b, j, k] = xb[k]
    step = _branch_step_costs(W, F, Q_inv, c_process, process_loss)
    node = np.empty((4, n - 1))
    R = np.empty(Y.shape[1])
    pred = np.empty(Y.shape[1])
    H = np.empty((Y.shape[1], 9))
    for j in range(n - 1):  # the readings of the states after the oldest, on each branch
        x = X[j + 1]
        w2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
        for i in range(R.shape[0]):
            R[i] = R0[i] + (slope * slope) * w2
        for b in range(4):
            _predict_readings(branch_state(b, x, normal), S_q, S_dw, S_f, pred, H)  # (the filter's h(x))
            total = 0.0
            for i in range(R.shape[0]):
                r = Y[j, i] - pred[i]
                total += _loss(r * r / R[i], c_accel, accel_loss)
            node[b, j] = total
        base = node[0, j]
        for b in range(4):
            node[b, j] -= base
    return _viterbi(step, node)


@njit(cache=True, nogil=True)
def _branch_step_costs(W, F, Q_inv, c, loss):
    """(4, 4, n - 1) costs of the steps between the n states whose ω, ω̇ on each branch are ``W`` (4, n, 6),
    from branch a of state j to branch b of state j + 1: six times the loss of the RMS over the six rows of the
    step's whitened residual (``F``, ``Q_inv``: each step's ω, ω̇ block of the transition and of its
    covariance's inverse)."""
    n = W.shape[1]
    step = np.empty((4, 4, n - 1))
    pred = np.empty(6)
    d = np.empty(6)
    for j in range(n - 1):
        for a in range(4):
            for k in range(6):
                s = 0.0
                for l in range(6):
                    s += F[j, k, l] * W[a, j, l]
                pred[k] = s
            for b in range(4):
                for k in range(6):
                    d[k] = W[b, j + 1, k] - pred[k]
                e2 = 0.0
                for k in range(6):
                    s = 0.0
                    for l in range(6):
                        s += Q_inv[j, k, l] * d[l]
                    e2 += d[k] * s
                step[a, b, j] = 6.0 * _loss(e2 / 6.0, c, loss)
    return step


@njit(cache=True, nogil=True)
def _viterbi(step, node):
    """The lowest path through the chain of ``step`` (4, 4, n) transition costs and ``node`` (4, n) state
    costs, from branch 0 before the first state to branch 0 at the last (the first of equals, as ``argmin``):
    the branch of each of the n states."""
    n = node.shape[1]
    cost = np.empty(4)
    for b in range(4):
        cost[b] = step[0, b, 0] + node[b, 0]
    back = np.zeros((n, 4), dtype=np.int8)
    new = np.empty(4)
    for j in range(1, n):
        for b in range(4):
            best, arg = cost[0] + step[0, b, j], 0
            for a in range(1, 4):
                t = cost[a] + step[a, b, j]
                if t < best:
                    best, arg = t, a
            back[j, b] = arg
            new[b] = best + node[b, j]
        for b in range(4):
            cost[b] = new[b]
    path = np.zeros(n, dtype=np.int8)
    state = 0
    for j in range(n - 1, 0, -1):
        state = back[j, state]
        path[j - 1] = state
    return path


@njit(cache=True, nogil=True)
def local_density_push(t_ns, y, noise_var, pinv_dw, c_dw, prev_dw, ring_t, ring_s, state_i, state_f, period_ns,
                       resolved_factor):
    """One sample into :class:`gfimu.smoother.stream.model_choice.LocalDensity`: the per-sample inversion's ω̇
    ``pinv_dw y``, its step power from the previous sample's ω̇ (``prev_dw``) above the noise's, and the mean of
    both over the last ``period_ns``, kept in a ring (``ring_t`` the steps' times, ``ring_s`` their (step, noise)
    powers; ``state_i`` = [oldest slot, count, previous sample kept, its time], ``state_f`` = [Σ step, Σ noise,
    the previous sample's noise variance]), all updated in place. Returns ``(density, resolved, room)``: the
    local jerk density [rad/s²/√s] (-1: none yet), whether it is resolved, and False where the ring is full
    (nothing then changed: a larger ring is to be made and the sample given again)."""
    cap = ring_t.shape[0]
    if state_i[2] and state_i[1] == cap:
        return -1.0, False, False
    dw0 = dw1 = dw2 = 0.0
    for i in range(y.shape[0]):
        dw0 += pinv_dw[0, i] * y[i]
        dw1 += pinv_dw[1, i] * y[i]
        dw2 += pinv_dw[2, i] * y[i]
    var = c_dw * noise_var
    had, prev_t, prev_var = state_i[2], state_i[3], state_f[2]
    d0, d1, d2 = dw0 - prev_dw[0], dw1 - prev_dw[1], dw2 - prev_dw[2]
    prev_dw[0], prev_dw[1], prev_dw[2] = dw0, dw1, dw2
    state_i[2], state_i[3], state_f[2] = 1, t_ns, var
    if not had:
        return -1.0, False, True
    h = (t_ns - prev_t) * 1e-9
    if not h > 0:
        return -1.0, False, True
    step, noise = (d0 * d0 + d1 * d1 + d2 * d2) / h, (var + prev_var) / h
    tail = (state_i[0] + state_i[1]) % cap
    ring_t[tail], ring_s[tail, 0], ring_s[tail, 1] = t_ns, step, noise
    state_i[1] += 1
    sum_steps, sum_noise = state_f[0] + step, state_f[1] + noise
    cutoff = t_ns - period_ns
    while state_i[1] > 0 and ring_t[state_i[0]] <= cutoff:
        sum_steps -= ring_s[state_i[0], 0]
        sum_noise -= ring_s[state_i[0], 1]
        state_i[0] = (state_i[0] + 1) % cap
        state_i[1] -= 1
    state_f[0], state_f[1] = sum_steps, sum_noise
    n = state_i[1]
    mean_steps, mean_noise = max(sum_steps, 0.0) / n, max(sum_noise, 0.0) / n
    excess = max(mean_steps - mean_noise, mean_noise)
    return np.sqrt(excess / 3.0), mean_steps > resolved_factor * mean_noise, True


@njit(cache=True, nogil=True)
def predict_window(F, Q, c, P, x_newest, T, cross):
    """The prediction one step after the newest state (:meth:`WindowFilter.predict`): the new state's mean
    ``F x + c`` and covariance ``F P Fᵀ + Q`` (symmetrised), the recent states' cross-covariances
    ``C_i Fᵀ`` in place and the old ones' factor ``T Fᵀ`` returned."""
    x = _mv_plus(c, F, x_newest)
    FP = _mm(F, P)
    Ft = np.ascontiguousarray(F.T)  # (one layout for _mm: one compilation)
    P_new = _symmetrised(_plus(_mm(FP, Ft), Q, 1.0))
    # F's nonzero entries by row (a motion model's transition is mostly zeros): skipping the zero terms of
    # each sum leaves it the same number (x + 0 = x), at a fraction of the products
    nnz = np.zeros(9, dtype=np.int64)
    cols = np.empty((9, 9), dtype=np.int64)
    for j in range(9):
        for k in range(9):
            if F[j, k] != 0.0:
                cols[j, nnz[j]] = k
                nnz[j] += 1
    row = np.empty(9)
    for l in range(cross.shape[0]):
        C = cross[l]
        for i in range(9):
            for j in range(9):
                s = 0.0
                for t in range(nnz[j]):
                    k = cols[j, t]
                    s += C[i, k] * F[j, k]
                row[j] = s
            for j in range(9):
                C[i, j] = row[j]
    return x, P_new, _mm(T, Ft)


@njit(cache=True, nogil=True)
def step_residual2(F, Q, x0, x1):
    """``dᵀ Q⁻¹ d`` over the six ω, ω̇ rows of the step from x0 to x1, ``d = x1 - F x0`` (-1 where Q's block
    is singular): the motion-model step's squared whitened residual (:meth:`WindowFilter.settle`)."""
    d = np.empty(6)
    for i in range(6):
        s = x1[i]
        for j in range(6):
            s -= F[i, j] * x0[j]
        d[i] = s
    return _quadratic_form_inverse(np.ascontiguousarray(Q[:6, :6]), d)


@njit(cache=True, nogil=True)
def measure_update(y, xp, P, x0, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance, branches, normal,
                   prior_margin, c_process, process_loss, Q, robust_step, T, u, W, mean, var, cross):
    """:meth:`WindowFilter.measure <gfimu.smoother.stream.window_filter.WindowFilter.measure>` on the readings
    alone, in one call: the update's minimum (:func:`search`), then with ``robust_step`` the robust loss of
    the motion-model step (threshold ``c_process``): where the step's whitened residual ``(x - x̂)ᵀ P⁻¹ (x - x̂)
    / 9`` gives an IRLS weight w < 1, the prediction's covariance widened by ``(1/w - 1) Q`` and the minimum
    solved again from where it is; then :func:`update_window` with the last linearisation (its ``Hᵀ S⁻¹ [H, ν]``). Returns
    ``(T, u, W, P_after, P_before, ok)``: ``P_before`` the newest state's covariance the update started from
    (widened or not), ``ok`` False on a singular innovation covariance or non-finite values (nothing moved)."""
    if branches or (robust_step and c_process > 0.0):  # P's factors: the branches' distances and costs, the step's residual
        LU, piv, lu_ok = _factored(P)
    else:  # (nothing reads them)
        LU, piv, lu_ok = P, np.zeros(P.shape[0], dtype=np.int64), False
    x, H, AG, J, ok = search(y, xp, P, x0, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance, branches,
                            normal, prior_margin, LU, piv, lu_ok)
    if not ok:
        return T, u, W, P, P, False
    if robust_step and c_process > 0.0:
        e2 = _factored_form_inverse(LU, piv, lu_ok, x - xp)
        e2 = max(e2, 0.0) / 9.0  # (P singular: 0)
        w = _weight(np.sqrt(e2), c_process, process_loss)
        if w < 1.0:
            P = _symmetrised(_plus(P, Q, 1.0 / w - 1.0))
            last = cross.shape[0] - 1  # the newest state: its covariance is the widened one
            for i in range(9):
                var[last, i] = P[i, i]
                for j in range(9):
                    cross[last, i, j] = P[i, j]
            x, H, AG, J, ok = search(y, xp, P, x, R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance,
                                    _FALSE, normal, prior_margin, LU, piv, _FALSE)
            if not ok:
                return T, u, W, P, P, False
    T2, u2, W2, P_after, ok = update_window(AG, P, T, u, W, mean, var, cross)
    return T2, u2, W2, P_after, P, ok


@njit(cache=True, nogil=True)
def flush_window(T, u, W, mean, var, cross):
    """The lazy states brought up to date (:meth:`WindowFilter._flush`): for each state's cross-covariance C,
    ``m += C u``, ``v -= diag(C W Cᵀ)``, ``C ← C T``, in place."""
    CW = np.empty((9, 9))
    row = np.empty(9)
    for l in range(mean.shape[0]):
        C = cross[l]
        for i in range(9):
            s = 0.0
            for k in range(9):
                s += C[i, k] * u[k]
            mean[l, i] += s
            for j in range(9):
                s = 0.0
                for k in range(9):
                    s += C[i, k] * W[k, j]
                CW[i, j] = s
            s = 0.0
            for j in range(9):
                s += CW[i, j] * C[i, j]
            var[l, i] -= s
            for j in range(9):
                s = 0.0
                for k in range(9):
                    s += C[i, k] * T[k, j]
                row[j] = s
            for j in range(9):
                C[i, j] = row[j]


@njit(cache=True, nogil=True)
def compose_epochs(Ts, us, Ws, first):
    """The updates of epochs ``first, first + 1, …`` of ``(Ts, us, Ws)`` (each an epoch's factors ``(T, u, W)``,
    :meth:`WindowFilter._boundary <gfimu.smoother.stream.window_filter.WindowFilter._boundary>`) as one: applying
    ``(T₁, u₁, W₁)`` then ``(T₂, u₂, W₂)`` to a state (``m += C u``, ``v -= diag(C W Cᵀ)``, ``C ← C T``) is
    applying ``(T₁ T₂, u₁ + T₁ u₂, W₁ + T₁ W₂ T₁ᵀ)``."""
    T = Ts[first].copy()
    u = us[first].copy()
    W = Ws[first].copy()
    for e in range(first + 1, Ts.shape[0]):
        TW = _mm(T, Ws[e])
        for i in range(9):
            s = 0.0
            for j in range(9):
                s += T[i, j] * us[e, j]
            u[i] += s
            for j in range(9):
                s = 0.0
                for k in range(9):
                    s += TW[i, k] * T[j, k]
                W[i, j] += s
        T = _mm(T, Ts[e])
    return T, u, W


@njit(cache=True, nogil=True)
def advance_update(F, Q, c, P, T, u, W, mean, var, cross, lo, split, hi, lazy_steps, y, R0, S_q, S_dw, S_f, slope,
                   c_robust, loss, iterations, tolerance, branches, normal, prior_margin, c_process, process_loss):
    """One sample in one call (:meth:`WindowFilter.advance <gfimu.smoother.stream.window_filter.WindowFilter.advance>`
    on the readings alone, from the prediction): :func:`predict_window` from the newest state (slot ``hi - 1``
    of the window's arrays, whose states are the slots ``[lo, hi)``: the recent ones ``[split, hi)``, the older
    ones brought up to date through ``T, u, W``), the new state written into slot ``hi``, :func:`measure_update`
    on it with the robust loss of the step (``c_process`` > 0), its covariance after the update written into
    the window, and the older states brought up to date (:func:`flush_window`) once ``lazy_steps`` recent ones
    have gathered. Returns ``(split, ok)``; the window's arrays are updated in place, and so are ``T``, ``u``,
    ``W`` (the factors after the update) and ``P`` (the newest state's covariance after it): four arrays
    written rather than returned, which would make four new Python objects per sample. Where ``ok`` is False
    (a singular innovation covariance, non-finite values) the prediction is made, the update not (``P`` is the
    covariance it started from)."""
    newest = hi - 1
    x_newest = mean[newest].copy()
    if newest < split:  # a lazy state: its mean given the updates since the last flush
        for i in range(9):
            s = 0.0
            for j in range(9):
                s += cross[newest, i, j] * u[j]
            x_newest[i] += s
    x, P_new, T_predicted = predict_window(F, Q, c, P, x_newest, T, cross[split:hi])
    for i in range(9):
        mean[hi, i] = x[i]
        var[hi, i] = P_new[i, i]
        for j in range(9):
            cross[hi, i, j] = P_new[i, j]
    robust_step = c_process > 0.0
    T2, u2, W2, P_after, P_before, ok = measure_update(
        y, x, P_new, x.copy(), R0, S_q, S_dw, S_f, slope, c_robust, loss, iterations, tolerance, branches, normal,
        prior_margin, c_process, process_loss, Q if robust_step else P_new, robust_step, T_predicted, u, W,
        mean[split:hi + 1], var[split:hi + 1], cross[split:hi + 1])
    if not ok:
        _written(T, u, W, P, T2, u2, W2, P_after)
        return split, False
    for i in range(9):  # the newest state's covariance after the update (symmetrised)
        var[hi, i] = P_after[i, i]
        for j in range(9):
            cross[hi, i, j] = P_after[i, j]
    if hi + 1 - split >= lazy_steps:
        if split > lo:
            flush_window(T2, u2, W2, mean[lo:split], var[lo:split], cross[lo:split])
        T2 = np.eye(9)
        u2 = np.zeros(9)
        W2 = np.zeros((9, 9))
        split = hi + 1
    _written(T, u, W, P, T2, u2, W2, P_after)
    return split, True


@njit(cache=True, nogil=True, inline="always")
def _written(T, u, W, P, T2, u2, W2, P2):
    """``T2, u2, W2, P2`` copied into ``T, u, W, P`` (:func:`advance_update`'s results, in place)."""
    for i in range(9):
        u[i] = u2[i]
        for j in range(9):
            T[i, j] = T2[i, j]
            W[i, j] = W2[i, j]
            P[i, j] = P2[i, j]


@njit(cache=True, nogil=True)
def window_step_residual2(F, Q, mean, cross, u, split, s0):
    """:func:`step_residual2` of the step from the window's state in slot ``s0`` to the next, their means taken
    from the window's arrays (a slot before ``split`` given the updates since the last flush, ``m + C u``)."""
    x = np.empty((2, 9))
    for a in range(2):
        s = s0 + a
        for i in range(9):
            v = mean[s, i]
            if s < split:
                t = 0.0
                for j in range(9):
                    t += cross[s, i, j] * u[j]
                v += t
            x[a, i] = v
    return step_residual2(F, Q, x[0], x[1])


# --- the epochs of the window's older states (gfimu.smoother.stream.window_filter.Epochs) ------------------------
# ``ep`` (4,) int64: the epochs kept, the number of the epoch in row 0, the first run's slot in ``stale`` and the
# runs' count; ``stale`` (R, 3) int64: a ring of the runs of waiting states [k_first, k_stop, epoch]

EP_N, EP_FIRST, EP_HEAD, EP_COUNT = 0, 1, 2, 3


@njit(cache=True, nogil=True, inline="always")
def _run_pop(stale, ep):
    """The first run, taken off the ring."""
    h = ep[EP_HEAD]
    a, b, e = stale[h, 0], stale[h, 1], stale[h, 2]
    ep[EP_HEAD] = (h + 1) % stale.shape[0]
    ep[EP_COUNT] -= 1
    return a, b, e


@njit(cache=True, nogil=True, inline="always")
def _run_push(stale, ep, front, a, b, e):
    """A run put first (``front``) or last on the ring (the caller has made room)."""
    R = stale.shape[0]
    if front:
        h = (ep[EP_HEAD] + R - 1) % R
        ep[EP_HEAD] = h
    else:
        h = (ep[EP_HEAD] + ep[EP_COUNT]) % R
    stale[h, 0], stale[h, 1], stale[h, 2] = a, b, e
    ep[EP_COUNT] += 1


@njit(cache=True, nogil=True)
def epochs_close(Ts, us, Ws, ep, stale, T, u, W, k_lo, k_split):
    """:meth:`Epochs.close <gfimu.smoother.stream.window_filter.Epochs.close>`: an epoch ends with factors ``(T, u, W)``,
    kept in row ``ep[EP_N]`` of ``(Ts, us, Ws)`` (the rows no waiting run needs dropped first when they are all
    taken), and the older states ``[k_lo, k_split)`` not waiting yet wait for it. Returns 0 when done, 1 when
    the rows are full (the caller grows them and calls again), 2 when the ring of runs is (nothing done)."""
    R = stale.shape[0]
    count = ep[EP_COUNT]
    if count + 2 > R:
        return 2
    n, first = ep[EP_N], ep[EP_FIRST]
    if n == Ts.shape[0]:
        need = first + n
        for j in range(count):
            e = stale[(ep[EP_HEAD] + j) % R, 2]
            if e < need:
                need = e
        need -= first
        if need > 0:
            for i in range(n - need):
                for a in range(9):
                    us[i, a] = us[i + need, a]
                    for b in range(9):
                        Ts[i, a, b] = Ts[i + need, a, b]
                        Ws[i, a, b] = Ws[i + need, a, b]
            first += need
            n -= need
            ep[EP_FIRST], ep[EP_N] = first, n
        if n == Ts.shape[0]:
            return 1
    epoch = first + n
    for a in range(9):
        us[n, a] = u[a]
        for b in range(9):
            Ts[n, a, b] = T[a, b]
            Ws[n, a, b] = W[a, b]
    ep[EP_N] = n + 1
    if count == 0:
        _run_push(stale, ep, False, k_lo, k_split, epoch)
        return 0
    head_first = stale[ep[EP_HEAD], 0]
    tail_stop = stale[(ep[EP_HEAD] + count - 1) % R, 1]
    if k_lo < head_first:
        _run_push(stale, ep, True, k_lo, head_first, epoch)
    if tail_stop < k_split:
        _run_push(stale, ep, False, tail_stop, k_split, epoch)
    return 0


@njit(cache=True, nogil=True)
def epochs_bring_up(Ts, us, Ws, ep, stale, k_stop, k_lo, least, base, mean, var, cross):
    """:meth:`WindowFilter._bring_up <gfimu.smoother.stream.window_filter.WindowFilter._bring_up>`: the runs of
    waiting states before ``k_stop`` (at least ``least`` states of a run; the rest of it goes on waiting, and
    states before ``k_lo`` have left), each brought up to date through its epochs since, composed
    (:func:`compose_epochs`) and applied (:func:`flush_window`) to the window's arrays (slot = k - ``base``)."""
    n, first = ep[EP_N], ep[EP_FIRST]
    while ep[EP_COUNT] > 0 and stale[ep[EP_HEAD], 0] < k_stop:
        k0, k1, epoch = _run_pop(stale, ep)
        if k0 < k_lo:
            k0 = k_lo
        if k1 <= k0:
            continue
        cut = max(k_stop, k0 + least)
        if cut < k1:
            _run_push(stale, ep, True, cut, k1, epoch)
            k1 = cut
        T, u, W = compose_epochs(Ts[:n], us[:n], Ws[:n], epoch - first)
        a, b = k0 - base, k1 - base
        flush_window(T, u, W, mean[a:b], var[a:b], cross[a:b])


# --- the streaming sign chain (gfimu.smoother.stream.model_choice.StreamSignChain) --------------------------------
# ``st`` (5,) int64: the ring's first slot and count, the newest state's time [ns], whether there is one, the moves

CH_HEAD, CH_COUNT, CH_T, CH_HAS, CH_FLIPS = 0, 1, 2, 3, 4


@njit(cache=True, nogil=True)
def chain_push(k, t_ns, w, dw, c2, oldest_k, margin, normal, prev_w, prev_dw, cost, backs, ks, st, out):
    """:meth:`StreamSignChain.push <gfimu.smoother.stream.model_choice.StreamSignChain.push>` of state ``k`` at
    ``t_ns`` with (ω, ω̇) = (``w``, ``dw``), Cauchy scale² ``c2``, the window's oldest state ``oldest_k``, on the
    chain's arrays (``prev_w``, ``prev_dw`` (4, 3), ``cost`` (4,), ``backs`` (window, 4), ``ks`` (window,),
    ``st``), in place. Returns True when the states from ``out[0]`` are to move onto branch ``out[1]`` (the
    chain then starts again from them), False otherwise; the chain's first state (none before it) is taken
    in by the caller."""
    window = ks.shape[0]
    head, count = st[CH_HEAD], st[CH_COUNT]
    if count == window:  # the oldest step beyond the window is dropped
        head = (head + 1) % window
        count -= 1
    slot = (head + count) % window
    count += 1
    ks[slot] = k
    best = chain_step(prev_w, prev_dw, w, dw, normal, (t_ns - st[CH_T]) * 1e-9, c2, cost, backs[slot])
    st[CH_T] = t_ns
    while count > 0 and ks[head] <= oldest_k:
        head = (head + 1) % window
        count -= 1
    st[CH_HEAD], st[CH_COUNT] = head, count
    if best == 0 or not cost[best] + margin * c2 < cost[0]:
        return False
    # the best path's last run on branch `best` (within the window) moves onto it
    first = k
    state = best
    for j in range(count - 1, -1, -1):
        slot = (head + j) % window
        state = backs[slot, state]
        if state != best:
            break
        first = ks[slot] - 1
    if first < oldest_k:
        first = oldest_k
    nb = cost.shape[0]
    c = cost.copy()
    pw = prev_w.copy()
    pdw = prev_dw.copy()
    for b in range(nb):
        a = b ^ best
        cost[b] = c[a]
        for j in range(3):
            prev_w[b, j] = pw[a, j]
            prev_dw[b, j] = pdw[a, j]
    st[CH_HEAD] = 0
    st[CH_COUNT] = 0
    st[CH_FLIPS] += 1
    out[0], out[1] = first, best
    return True


@njit(cache=True, nogil=True)
def lazy_mean(mean_s, cross_s, u):
    """A lazy state's mean given the updates since the last flush, ``m + C u`` (:meth:`WindowFilter.mean
    <gfimu.smoother.stream.window_filter.WindowFilter.mean>`; each sum in the order :func:`window_step_residual2` and
    the block's reads take it)."""
    out = np.empty(9)
    for i in range(9):
        s = 0.0
        for j in range(9):
            s += cross_s[i, j] * u[j]
        out[i] = mean_s[i] + s
    return out


@njit(cache=True, nogil=True)
def scaled_process_noise(M, scale):
    """``Q = M diag(scale) Mᵀ``, symmetrised ``(Q + Qᵀ) / 2``: a step's process noise with the rows of ``M``'s
    columns ``k`` scaled by ``scale[k]`` (:meth:`ArrayModel.step <gfimu.smoother.stream.array_model.ArrayModel.step>`:
    the motion model's rows by the local motion factor squared)."""
    n = M.shape[0]
    Q = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += M[i, k] * scale[k] * M[j, k]
            Q[i, j] = s
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.5 * (Q[i, j] + Q[j, i])
    return out


@njit(cache=True, nogil=True)
def reset_factors(T, u, W):
    """The open epoch's factors ``(T, u, W)`` back to no update (``I``, 0, 0), in place."""
    for a in range(9):
        u[a] = 0.0
        for b in range(9):
            T[a, b] = 1.0 if a == b else 0.0
            W[a, b] = 0.0


@njit(cache=True, nogil=True)
def flush_lazy(lo, split, base, lazy_steps, mean, var, cross, T, u, W, Ts, us, Ws, ep, stale):
    """:meth:`WindowFilter._flush <gfimu.smoother.stream.window_filter.WindowFilter._flush>` on the window's arrays
    (slots ``[lo, …)``, slot = k - ``base``): every state waiting for epochs brought up to date
    (:func:`epochs_bring_up`), no epoch kept, the lazy states ``[lo, split)`` given the open epoch's factors
    (:func:`flush_window`) and those reset (:func:`reset_factors`)."""
    epochs_bring_up(Ts, us, Ws, ep, stale, 1 << 62, base + lo, lazy_steps, base, mean, var, cross)
    ep[EP_COUNT] = 0  # (Epochs.clear)
    ep[EP_FIRST] += ep[EP_N]
    ep[EP_N] = 0
    if split > lo:
        flush_window(T, u, W, mean[lo:split], var[lo:split], cross[lo:split])
    reset_factors(T, u, W)


@njit(cache=True, nogil=True)
def move_to_start(lo, hi, mean, var, cross, F, Q, has_step, t_ns):
    """The window's slots ``[lo, hi)`` moved to the start of its arrays (:meth:`WindowFilter._make_room
    <gfimu.smoother.stream.window_filter.WindowFilter._make_room>`: one value per slot in each,
    :attr:`WindowStore.ARRAYS <gfimu.smoother.stream.window_filter.WindowStore.ARRAYS>`)."""
    for s in range(hi - lo):
        for a in range(9):
            mean[s, a] = mean[lo + s, a]
            var[s, a] = var[lo + s, a]
            for b in range(9):
                cross[s, a, b] = cross[lo + s, a, b]
                F[s, a, b] = F[lo + s, a, b]
                Q[s, a, b] = Q[lo + s, a, b]
        has_step[s] = has_step[lo + s]
        t_ns[s] = t_ns[lo + s]
