"""Compiled per-state pieces of the fixed-lag smoother's running σ scale (:class:`gfimu.smoother.solve.sigma_scale.
RunningSigmaScale`).

The batch smoother scales σ over a whole log at once, and the numpy expressions of
:mod:`gfimu.smoother.solve.sigma_scale` cost little there; the fixed-lag smoother scales each state as it
leaves the window, and the same expressions on one row cost a numpy call per term (about 0.13 ms for
:func:`gfimu.smoother.solve.sigma_scale.kinematic_shares` alone, against 0.05 ms for a whole push at 20 kHz).
:func:`kinematic_shares_row` is that function for one row, term for term: the numpy expression stays the
oracle that ``tests/test_sigma_kernels.py`` compares it with (the same numbers to rounding: the quadrature's
sums are taken in another order).

Imported only where the fixed-lag smoother scales σ (numba's import is not paid by commands that do not);
compiled on first use and cached on disk (numba's ``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def kinematic_shares_row(single, trapezoid_var, step_var, h, weight, cm, cp, sn, share, a, b):
    """:func:`gfimu.smoother.solve.sigma_scale.kinematic_shares` of one state into ``share``, ``a``, ``b`` (3,):
    ``single`` (≥ 6,) the variances one sample's readings give ω and ω̇, ``trapezoid_var`` and ``step_var`` (3,)
    the step's, ``h`` its length [s]; ``weight``, ``cm``, ``cp``, ``sn`` the quadrature
    (:func:`gfimu.smoother.solve.sigma_scale._quadrature`)."""
    hh = 0.5 * h
    for j in range(3):
        sw, sd = single[j], single[3 + j]
        aw = 1.0 / sw if np.isfinite(sw) and sw > 0.0 else 0.0
        ad = 1.0 / sd if np.isfinite(sd) and sd > 0.0 else 0.0
        t, s = trapezoid_var[j], step_var[j]
        p_w = d_w = a_j = b_j = 0.0
        for p in range(weight.shape[0]):
            H00 = aw - 2.0 * cm[p] / t
            H11 = ad + 0.5 * h * h * cp[p] / t - 2.0 * cm[p] / s
            g = h * sn[p] / t
            inv_det = 1.0 / (H00 * H11 - g * g)
            c0r = (H11 * cm[p] + g * hh * sn[p]) * inv_det  # H⁻¹ uᴴ, ω row
            c0i = (-H11 * sn[p] + g * hh * cp[p]) * inv_det
            c1r = (g * sn[p] - H00 * hh * cp[p]) * inv_det  # ... ω̇ row
            c1i = (g * cm[p] + H00 * hh * sn[p]) * inv_det
            c0 = c0r * c0r + c0i * c0i
            c1 = c1r * c1r + c1i * c1i
            w = weight[p]
            p_w += w * H11 * inv_det
            d_w += w * c0 / t
            hat = (cm[p] * c0r - sn[p] * c0i - hh * (cp[p] * c1r - sn[p] * c1i)) / t
            a_j += w * (1.0 - hat) ** 2
            b_j += w * (aw * c0 + ad * c1) / t
        ratio = d_w / p_w
        if np.isfinite(ratio) and np.isfinite(a_j) and np.isfinite(b_j):
            share[j], a[j], b[j] = min(max(ratio, 0.0), 1.0), a_j, b_j
        else:
            share[j], a[j], b[j] = 0.0, 1.0, 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def parity_row(y, x, std, S_f, S_dw, S_q, c_robust, cauchy, rank_tolerance, p, single, slope):
    """:func:`gfimu.smoother.solve.sigma_scale.parity` of one sample: the parity residual into ``p`` (m,), each
    state's single-sample variance into ``single`` (9,) and the robust sandwich's sums into ``slope`` (3,) (its
    ``slopes``); returns the rank of the whitened Jacobian. ``y`` (m,)
    the readings, ``x`` (≥ 9,) the state, ``std`` (m,) the noise; ``S_f``, ``S_dw``, ``S_q`` the structure
    matrix's parts; ``c_robust`` > 0 the robust threshold (``cauchy`` True for Cauchy, else Huber), 0 none."""
    m = y.shape[0]
    d = np.ones(m)
    wa = np.ones(m)
    w0, w1, w2 = x[0], x[1], x[2]
    q0, q1, q2 = w0 * w0 + w1 * w1, w0 * w0 + w2 * w2, w1 * w1 + w2 * w2
    q3, q4, q5 = w0 * w1, w0 * w2, w1 * w2
    z = np.empty(m)
    J = np.empty((m, 9))
    for i in range(m):
        pf = S_f[i, 0] * x[6] + S_f[i, 1] * x[7] + S_f[i, 2] * x[8]
        pd = S_dw[i, 0] * x[3] + S_dw[i, 1] * x[4] + S_dw[i, 2] * x[5]
        pq = (S_q[i, 0] * q0 + S_q[i, 1] * q1 + S_q[i, 2] * q2 + S_q[i, 3] * q3 + S_q[i, 4] * q4
              + S_q[i, 5] * q5)
        inv = 1.0 / std[i]
        zi = (y[i] - pf - pd - pq) * inv
        if c_robust > 0.0:
            e = abs(zi)
            if cauchy:
                irls = 1.0 / (1.0 + (e / c_robust) ** 2)
                weight = np.sqrt(irls)
                d[i] = 2.0 * irls - 1.0
                wa[i] = irls
            else:
                irls = 1.0 if e <= c_robust else c_robust / max(e, 1e-300)
                weight = np.sqrt(irls)
                d[i] = 1.0 if e <= c_robust else 0.0
                wa[i] = irls
            zi *= weight
            inv *= weight
        z[i] = zi
        # ∂(S_q q)/∂ω: q's Jacobian [[2x,2y,0],[2x,0,2z],[0,2y,2z],[y,x,0],[z,0,x],[0,z,y]]
        J[i, 0] = (S_q[i, 0] * (2.0 * w0) + S_q[i, 1] * (2.0 * w0) + S_q[i, 3] * w1 + S_q[i, 4] * w2) * inv
        J[i, 1] = (S_q[i, 0] * (2.0 * w1) + S_q[i, 2] * (2.0 * w1) + S_q[i, 3] * w0 + S_q[i, 5] * w2) * inv
        J[i, 2] = (S_q[i, 1] * (2.0 * w2) + S_q[i, 2] * (2.0 * w2) + S_q[i, 4] * w0 + S_q[i, 5] * w1) * inv
        for j in range(3):
            J[i, 3 + j] = S_dw[i, j] * inv
            J[i, 6 + j] = S_f[i, j] * inv
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    r = s.shape[0]
    rank = 0
    for k in range(r):
        if s[k] > rank_tolerance * s[0]:
            rank += 1
    for i in range(m):
        p[i] = z[i]
    for k in range(rank):  # (the kept singular values are the leading ones: s is in decreasing order)
        c = 0.0
        for i in range(m):
            c += U[i, k] * z[i]
        for i in range(m):
            p[i] -= U[i, k] * c
    for j in range(9):
        v = 0.0
        unseen = False
        for k in range(r):
            v2 = Vt[k, j] * Vt[k, j]
            if k < rank:
                v += v2 / (s[k] * s[k])
            elif v2 > 1e-12:
                unseen = True
        single[j] = np.inf if unseen else v
    s0 = s1 = s2 = 0.0
    for i in range(m):
        h = 0.0
        for k in range(rank):
            h += U[i, k] * U[i, k]
        s0 += wa[i] * p[i] * p[i]
        s1 += wa[i] * (1.0 - h)
        s2 += h * d[i]
    slope[0], slope[1], slope[2] = s0, s1, s2
    return rank
