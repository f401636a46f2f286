"""Compiled Levenberg–Marquardt iterations of the per-sample ML fit (:mod:`gfimu.estimators.ml`).

:meth:`MLEstimator._iterate <gfimu.estimators.ml.MLEstimator._iterate>` runs the iterations of every
sample at once on arrays: each of its few dozen numpy operations per iteration costs a call for a
handful of flops per sample, and the samples that need many iterations keep the whole set of calls
going. Here the same iterations run sample by sample as loops that numba compiles: the same
arithmetic term for term (the 3 × 3 systems by the same Jacobi-scaled adjugate, the same acceptance,
damping and stopping rules), so the two agree to rounding; the numpy expressions stay in
:mod:`gfimu.estimators.ml` as the oracle (``MLEstimator.compiled = False``) that
``tests/test_ml_kernels.py`` compares this kernel with.

Imported only where the iterations run (numba's import is not paid by a command that does not fit
per-sample ML); compiled on first use and cached on disk (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _cost(zb, R, w0, w1, w2, gyro, gyro_var, has_gyro):
    """``|z - R q(ω)|² + z₆²`` (+ the gyro term) of one sample: :func:`gfimu.estimators.ml._cost`."""
    q0, q1, q2 = w0 * w0 + w1 * w1, w0 * w0 + w2 * w2, w1 * w1 + w2 * w2
    q3, q4, q5 = w0 * w1, w0 * w2, w1 * w2
    s = 0.0
    for i in range(6):
        r = zb[i] - (R[i, 0] * q0 + R[i, 1] * q1 + R[i, 2] * q2 + R[i, 3] * q3 + R[i, 4] * q4 + R[i, 5] * q5)
        s += r * r
    s += zb[6] * zb[6]
    if has_gyro:
        d0, d1, d2 = gyro[0] - w0, gyro[1] - w1, gyro[2] - w2
        s += (d0 * d0 + d1 * d1 + d2 * d2) / gyro_var
    return s


@njit(cache=True, nogil=True)
def _solve3(m, r0, r1, r2):
    """:func:`gfimu.estimators.ml._solve_symmetric_3x3` of one system (m: the six entries a, b, c, d, e, f
    of ``[[a, b, c], [b, d, e], [c, e, f]]``), its LU fallback by Gaussian elimination with partial pivoting."""
    s0 = 1.0 / np.sqrt(max(m[0], 1e-300))
    s1 = 1.0 / np.sqrt(max(m[3], 1e-300))
    s2 = 1.0 / np.sqrt(max(m[5], 1e-300))
    a, d, f = m[0] * s0 * s0, m[3] * s1 * s1, m[5] * s2 * s2
    b, c, e = m[1] * (s0 * s1), m[2] * (s0 * s2), m[4] * (s1 * s2)
    t0, t1, t2 = r0 * s0, r1 * s1, r2 * s2
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    if det > 1e-12:
        inv = 1.0 / det
        return ((c00 * t0 + c01 * t1 + c02 * t2) * inv * s0, (c01 * t0 + c11 * t1 + c12 * t2) * inv * s1,
                (c02 * t0 + c12 * t1 + c22 * t2) * inv * s2)
    A = np.empty((3, 4))
    A[0, 0], A[0, 1], A[0, 2], A[0, 3] = m[0], m[1], m[2], r0
    A[1, 0], A[1, 1], A[1, 2], A[1, 3] = m[1], m[3], m[4], r1
    A[2, 0], A[2, 1], A[2, 2], A[2, 3] = m[2], m[4], m[5], r2
    for col in range(3):
        p, best = col, abs(A[col, col])
        for row in range(col + 1, 3):
            if abs(A[row, col]) > best:
                p, best = row, abs(A[row, col])
        if not best > 0.0:
            return np.nan, np.nan, np.nan  # singular: a step that cannot lower the cost
        if p != col:
            for j in range(4):
                A[col, j], A[p, j] = A[p, j], A[col, j]
        for row in range(col + 1, 3):
            g = A[row, col] / A[col, col]
            for j in range(col, 4):
                A[row, j] -= g * A[col, j]
    x2 = A[2, 3] / A[2, 2]
    x1 = (A[1, 3] - A[1, 2] * x2) / A[1, 1]
    x0 = (A[0, 3] - A[0, 1] * x1 - A[0, 2] * x2) / A[0, 0]
    return x0, x1, x2


@njit(cache=True, nogil=True)
def iterate(zb, c, w_start, R, qm, gram, curvature, gyro, gyro_var, has_gyro, max_iterations, tol2):
    """:meth:`MLEstimator._iterate <gfimu.estimators.ml.MLEstimator._iterate>` sample by sample: ``zb`` (N, 7)
    the reduced readings, ``c`` (N, 6) ``Aᵀ b``, ``w_start`` (N, 3), ``R`` (6, 6) of the projected model,
    ``qm`` (6, 6) ``_MONOMIAL_TO_Q @ M``, ``gram`` (6, 6) and ``curvature`` (6, 6) as the numpy iteration
    holds them (six entries per symmetric 3 × 3 matrix), ``gyro`` (N, 3) read where ``has_gyro``. Returns
    ω (N, 3)."""
    n = w_start.shape[0]
    out = w_start.copy()
    mono = np.empty(6)
    g6 = np.empty(6)
    jtj = np.empty(6)
    hess = np.empty(6)
    for s in range(n):
        w0, w1, w2 = out[s, 0], out[s, 1], out[s, 2]
        lam = 1e-3
        cost = _cost(zb[s], R, w0, w1, w2, gyro[s], gyro_var, has_gyro)
        for _ in range(max_iterations):
            mono[0], mono[1], mono[2] = w0 * w0, w1 * w1, w2 * w2
            mono[3], mono[4], mono[5] = w0 * w1, w0 * w2, w1 * w2
            for j in range(6):
                v = 0.0
                for k in range(6):
                    v += mono[k] * qm[k, j]
                g6[j] = c[s, j] - v
            gr0 = 2 * w0 * (g6[0] + g6[1]) + w1 * g6[3] + w2 * g6[4]
            gr1 = 2 * w1 * (g6[0] + g6[2]) + w0 * g6[3] + w2 * g6[5]
            gr2 = 2 * w2 * (g6[1] + g6[2]) + w0 * g6[4] + w1 * g6[5]
            for j in range(6):
                v = 0.0
                h = 0.0
                for k in range(6):
                    v += mono[k] * gram[k, j]
                    h += g6[k] * curvature[k, j]
                jtj[j] = v
                hess[j] = v - h
            tr = max(jtj[0] + jtj[3] + jtj[5], 1e-300)
            h00, h01, h11 = hess[0], hess[1], hess[3]
            det = hess[0] * (hess[3] * hess[5] - hess[4] * hess[4]) + hess[1] * (hess[2] * hess[4] - hess[1] * hess[5]) \
                + hess[2] * (hess[1] * hess[4] - hess[2] * hess[3])
            if h00 > 1e-12 * tr and h00 * h11 - h01 * h01 > 1e-12 * tr * tr and det > 1e-12 * tr * tr * tr:
                for j in range(6):
                    jtj[j] = hess[j]
            if has_gyro:
                gr0 += (gyro[s, 0] - w0) / gyro_var
                gr1 += (gyro[s, 1] - w1) / gyro_var
                gr2 += (gyro[s, 2] - w2) / gyro_var
                jtj[0] += 1.0 / gyro_var
                jtj[3] += 1.0 / gyro_var
                jtj[5] += 1.0 / gyro_var
            top = max(jtj[0], max(jtj[3], jtj[5]))
            floor = 1e-12 * top + 1e-300
            jtj[0] = jtj[0] + lam * max(jtj[0], floor)
            jtj[3] = jtj[3] + lam * max(jtj[3], floor)
            jtj[5] = jtj[5] + lam * max(jtj[5], floor)
            st0, st1, st2 = _solve3(jtj, gr0, gr1, gr2)
            t0, t1, t2 = w0 + st0, w1 + st1, w2 + st2
            tcost = _cost(zb[s], R, t0, t1, t2, gyro[s], gyro_var, has_gyro)
            ok = tcost <= cost
            gain = cost - tcost
            size = 1.0 + np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            if ok:
                w0, w1, w2 = t0, t1, t2
                cost = tcost
                lam = max(lam / 10, 1e-12)
            else:
                lam = lam * 10
            small = st0 * st0 + st1 * st1 + st2 * st2 <= tol2 * size * size
            flat = gain <= 1e-15 * (tcost + 1e-300)
            if (ok and (small or flat)) or lam > 1e12:
                break
        out[s, 0], out[s, 1], out[s, 2] = w0, w1, w2
    return out
