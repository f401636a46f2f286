"""Compiled rows of the batch smoother's normal equations (:mod:`gfimu.smoother.solve.banded`).

:meth:`AccelerometerGroup.accumulate <gfimu.smoother.model.groups.AccelerometerGroup.accumulate>` without
per-sensor calibration adds, for every sample k and axis a with whitening w (``1 / σ``), the whitened
residual ``e = w (h_a(x_k) - y_ka)`` of the accelerometer equation (Ho & Lin 2009, eq. 6;
:func:`gfimu.factors.accelerometer.rigid_body_readings`) and its Jacobian
``J = w [∂h_a/∂ω, c_a]`` (``∂h_a/∂ω = (rᵀω) s + (sᵀω) r - 2 (sᵀr) ω``,
:func:`gfimu.factors.accelerometer.omega_jacobian`; ``c_a`` the structure-matrix row over ``[ω̇, f]``) into
the sample's block ``JᵀJ`` and gradient ``Jᵀe``. In numpy that is a dozen whole-array operations through
(N, axes, 3) temporaries; :func:`accumulate` makes one pass over the samples instead, each sample's
9 × 9 block summed over its axes in registers and written once. The numpy expressions stay in the group
as the oracle (``AccelerometerGroup.compiled = False``) that ``tests/test_model_kernels.py`` compares
this kernel with; the two agree to rounding (the same products, summed in another order).

:func:`squared_norm` is the whitened residuals' sum of squares alone (the cost the Levenberg-Marquardt
step is accepted on, :meth:`AccelerometerGroup.squared_norm`), :func:`whitened_residual` the residuals
themselves (the robust re-weighting's, :meth:`AccelerometerGroup.whitened_residual`): all three read the
rigid-body equation from one function (:func:`_reading`), so the cost, the residuals and the normal
equations are the same numbers at the same states.

:func:`white_jerk` is the white-jerk motion model's rows (:meth:`MotionModelGroup.accumulate
<gfimu.smoother.model.groups.MotionModelGroup.accumulate>`): the trapezoid and ω̇ random-walk rows of every
step added into the two samples' blocks and the block between them, without numpy's fancy-indexed
updates of the whole window, each entry by the same operations in the same order.

Imported only where the batch smoother solves (numba's import is not paid by commands that do not);
compiled on first use and cached on disk (numba's ``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def accumulate(X, y, S, P, rows, white, diag, grad, sq):
    """Add every sample's accelerometer ``JᵀJ`` into ``diag`` (N, m, m) (the ``[ω, ω̇, f]`` block, the first
    nine columns) and ``Jᵀe`` into ``grad`` (N, m), and each sample's ``Σ_a e²`` into ``sq`` (N,).

    ``X`` (N, ≥ 9) the states ``[ω, ω̇, f, ...]``; ``y`` (N, axes) the readings; ``S``, ``P`` (axes, 3) the
    axes' directions and positions; ``rows`` (axes, 12) their structure-matrix rows; ``white`` the
    whitening ``1 / σ``: (N, axes) per sample, or (1, axes) for every sample (then the constant block
    ``Σ_a w_a² c_a c_aᵀ`` is summed once)."""
    n, axes = y.shape
    per_sample = white.shape[0] != 1 or n == 1
    sr, c, cc, lin = _axis_constants(S, P, rows, white, per_sample)
    lin21 = np.zeros(21)  # Σ_a w_a² c_a c_aᵀ of one sample (per-sample whitening)
    for k in range(n):
        w0, w1, w2_ = X[k, 0], X[k, 1], X[k, 2]
        ww = w0 * w0 + w1 * w1 + w2_ * w2_
        kw = k if per_sample else 0
        # the sample's sums over its axes: Jᵀe (g), the ω block (h, lower triangle), the [ω̇, f] × ω
        # block (x); the [ω̇, f] block in ``lin`` (per-sample whitening only)
        g0 = g1 = g2 = g3 = g4 = g5 = g6 = g7 = g8 = 0.0
        h00 = h10 = h11 = h20 = h21 = h22 = 0.0
        x00 = x01 = x02 = x10 = x11 = x12 = x20 = x21 = x22 = 0.0
        x30 = x31 = x32 = x40 = x41 = x42 = x50 = x51 = x52 = 0.0
        if per_sample:
            for p in range(21):
                lin21[p] = 0.0
        s2 = 0.0
        for a in range(axes):
            pred, ws, wr = _reading(X, k, a, S, P, rows, sr, ww)
            wt = white[kw, a]
            e = (pred - y[k, a]) * wt
            s2 += e * e
            two_sr = 2.0 * sr[a]
            jw0 = (wr * S[a, 0] + ws * P[a, 0] - two_sr * w0) * wt
            jw1 = (wr * S[a, 1] + ws * P[a, 1] - two_sr * w1) * wt
            jw2 = (wr * S[a, 2] + ws * P[a, 2] - two_sr * w2_) * wt
            g0 += jw0 * e
            g1 += jw1 * e
            g2 += jw2 * e
            h00 += jw0 * jw0
            h10 += jw1 * jw0; h11 += jw1 * jw1
            h20 += jw2 * jw0; h21 += jw2 * jw1; h22 += jw2 * jw2
            jl = wt * c[a, 0]
            g3 += jl * e
            x00 += jl * jw0; x01 += jl * jw1; x02 += jl * jw2
            jl = wt * c[a, 1]
            g4 += jl * e
            x10 += jl * jw0; x11 += jl * jw1; x12 += jl * jw2
            jl = wt * c[a, 2]
            g5 += jl * e
            x20 += jl * jw0; x21 += jl * jw1; x22 += jl * jw2
            jl = wt * c[a, 3]
            g6 += jl * e
            x30 += jl * jw0; x31 += jl * jw1; x32 += jl * jw2
            jl = wt * c[a, 4]
            g7 += jl * e
            x40 += jl * jw0; x41 += jl * jw1; x42 += jl * jw2
            jl = wt * c[a, 5]
            g8 += jl * e
            x50 += jl * jw0; x51 += jl * jw1; x52 += jl * jw2
            if per_sample:
                w2 = wt * wt
                for p in range(21):
                    lin21[p] += w2 * cc[a, p]
        sq[k] = s2
        _add_sample(diag[k], grad[k], (g0, g1, g2, g3, g4, g5, g6, g7, g8), (h00, h10, h11, h20, h21, h22),
                    ((x00, x01, x02), (x10, x11, x12), (x20, x21, x22), (x30, x31, x32), (x40, x41, x42),
                     (x50, x51, x52)), lin21, lin, per_sample)


@njit(cache=True, nogil=True, inline="always")
def _reading(X, k, a, S, P, rows, sr, ww):
    """Axis a's predicted reading at sample k, ``c_aᵀ [ω̇, f] + (sᵀω)(rᵀω) - (sᵀr)|ω|²`` (``sr`` = sᵀr,
    ``ww`` = |ω|²), with the products ``sᵀω`` and ``rᵀω`` its ω Jacobian reads."""
    w0, w1, w2 = X[k, 0], X[k, 1], X[k, 2]
    ws = S[a, 0] * w0 + S[a, 1] * w1 + S[a, 2] * w2
    wr = P[a, 0] * w0 + P[a, 1] * w1 + P[a, 2] * w2
    pred = ((X[k, 6] * rows[a, 0] + X[k, 7] * rows[a, 1] + X[k, 8] * rows[a, 2])
            + (X[k, 3] * rows[a, 3] + X[k, 4] * rows[a, 4] + X[k, 5] * rows[a, 5]) + ws * wr - sr[a] * ww)
    return pred, ws, wr


@njit(cache=True, nogil=True, inline="always")
def _directions_dot_positions(S, P):
    """``sᵀr`` of each axis (axes,): what :func:`_reading` takes as ``sr``."""
    axes = S.shape[0]
    sr = np.empty(axes)
    for a in range(axes):
        sr[a] = S[a, 0] * P[a, 0] + S[a, 1] * P[a, 1] + S[a, 2] * P[a, 2]
    return sr


@njit(cache=True, nogil=True, inline="always")
def _axis_constants(S, P, rows, white, per_sample):
    """What :func:`accumulate` reads of each axis and keeps for every sample: ``sᵀr`` (axes,), the
    structure-matrix row over [ω̇, f] ``c`` (axes, 6), ``c cᵀ``'s lower triangle row by row (axes, 21), and
    (one whitening for every sample: not ``per_sample``) ``Σ_a w_a² c_a c_aᵀ``'s lower triangle (6, 6)."""
    axes = S.shape[0]
    sr = _directions_dot_positions(S, P)
    c = np.empty((axes, 6))
    for a in range(axes):
        for i in range(3):
            c[a, i] = rows[a, 3 + i]
            c[a, 3 + i] = rows[a, i]
    cc = np.empty((axes, 21))
    for a in range(axes):
        p = 0
        for i in range(6):
            for j in range(i + 1):
                cc[a, p] = c[a, i] * c[a, j]
                p += 1
    lin = np.zeros((6, 6))
    if not per_sample:
        for a in range(axes):
            w2 = white[0, a] * white[0, a]
            for i in range(6):
                for j in range(i + 1):
                    lin[i, j] += w2 * c[a, i] * c[a, j]
    return sr, c, cc, lin


@njit(cache=True, nogil=True, inline="always")
def _add_sample(D, G, g, h, x, lin21, lin, per_sample):
    """One sample's sums added into its blocks: ``g`` (9) into ``G``; the ω block's lower triangle ``h`` (6,
    row by row), the [ω̇, f] × ω block ``x`` (6 × 3) and the [ω̇, f] block (its lower triangle: ``lin21``, 21
    values row by row, with ``per_sample``, else ``lin``, 6 × 6) into ``D`` and its mirror."""
    for i in range(9):
        G[i] += g[i]
    p = 0
    for i in range(3):
        for j in range(i + 1):
            D[i, j] += h[p]
            if j < i:
                D[j, i] += h[p]
            p += 1
    for i in range(6):
        for j in range(3):
            D[3 + i, j] += x[i][j]
            D[j, 3 + i] += x[i][j]
    p = 0
    for i in range(6):
        for j in range(i + 1):
            v = lin21[p] if per_sample else lin[i, j]
            D[3 + i, 3 + j] += v
            if j < i:
                D[3 + j, 3 + i] += v
            p += 1


@njit(cache=True, nogil=True)
def squared_norm(X, S, P, rows, y, white, sq):
    """Each sample's ``Σ_a e²`` into ``sq`` (N,): the whitened residuals ``e = w (h(x) - y)`` with ``h`` the
    rigid-body reading :func:`accumulate` linearises (:func:`_reading`), by the same operations, so that the
    cost a Levenberg-Marquardt step is accepted on is the one its normal equations were built at (the
    arguments as :func:`accumulate`'s)."""
    n, axes = y.shape
    per_sample = white.shape[0] != 1 or n == 1
    sr = _directions_dot_positions(S, P)
    for k in range(n):
        w0, w1, w2 = X[k, 0], X[k, 1], X[k, 2]
        ww = w0 * w0 + w1 * w1 + w2 * w2
        kw = k if per_sample else 0
        s2 = 0.0
        for a in range(axes):
            e = (_reading(X, k, a, S, P, rows, sr, ww)[0] - y[k, a]) * white[kw, a]
            s2 += e * e
        sq[k] = s2


@njit(cache=True, nogil=True)
def whitened_residual(X, S, P, rows, y, white, out):
    """The whitened residuals ``w (h(x) - y)`` (N, axes) into ``out``, ``h`` as :func:`accumulate` has it
    (:meth:`AccelerometerGroup._all_axes <gfimu.smoother.model.groups.AccelerometerGroup._all_axes>`'s
    first value; the arguments as :func:`accumulate`'s)."""
    n, axes = y.shape
    per_sample = white.shape[0] != 1 or n == 1
    sr = _directions_dot_positions(S, P)
    for k in range(n):
        w0, w1, w2 = X[k, 0], X[k, 1], X[k, 2]
        ww = w0 * w0 + w1 * w1 + w2 * w2
        kw = k if per_sample else 0
        for a in range(axes):
            out[k, a] = (_reading(X, k, a, S, P, rows, sr, ww)[0] - y[k, a]) * white[kw, a]


@njit(cache=True, nogil=True)
def white_jerk(X, h, wb, diag, lower, grad, e1, e2):
    """:meth:`MotionModelGroup.accumulate <gfimu.smoother.model.groups.MotionModelGroup.accumulate>` (white
    jerk) sample by sample: the whitened rows of every step k (``X`` (N, ≥ 6) the states ``[ω, ω̇, ...]``,
    ``h`` (N-1,) the steps [s], ``wb`` (N-1, 6) the rows' whitening) into ``e1`` (trapezoid) and ``e2`` (ω̇
    random walk), each (N-1, 3), and their ``JᵀJ`` and ``Jᵀe`` added into ``diag``, ``lower`` and ``grad``.
    Each entry gets the same terms by the same operations in the same order as the numpy expressions (the
    step that starts at the sample, then the one that ends there), so the two agree to the last bit
    wherever the compiler, like numpy, does not fuse a product and a sum."""
    n = X.shape[0]
    for k in range(n - 1):
        hh = 0.5 * h[k]
        for a in range(3):
            e1[k, a] = (X[k + 1, a] - X[k, a] - hh * (X[k, 3 + a] + X[k + 1, 3 + a])) * wb[k, a]
            e2[k, a] = (X[k + 1, 3 + a] - X[k, 3 + a]) * wb[k, 3 + a]
    for k in range(n):
        if k < n - 1:  # the step from sample k: its first sample's blocks, and the block tying k+1 to k
            hh = 0.5 * h[k]
            for a in range(3):
                d = 3 + a
                t, u = wb[k, a], wb[k, d]
                t2, u2 = t * t, u * u
                t2h = hh * t2
                t2hh = hh * t2h
                diag[k, a, a] += t2
                diag[k, a, d] += t2h
                diag[k, d, a] += t2h
                diag[k, d, d] += t2hh + u2
                lower[k, a, a] -= t2
                lower[k, a, d] -= t2h
                lower[k, d, a] += t2h
                lower[k, d, d] += t2hh - u2
                grad[k, a] -= t * e1[k, a]
                grad[k, d] -= hh * t * e1[k, a] + u * e2[k, a]
        if k > 0:  # the step into sample k: its second sample's blocks
            j = k - 1
            hh = 0.5 * h[j]
            for a in range(3):
                d = 3 + a
                t, u = wb[j, a], wb[j, d]
                t2, u2 = t * t, u * u
                t2h = hh * t2
                t2hh = hh * t2h
                diag[k, a, a] += t2
                diag[k, a, d] -= t2h
                diag[k, d, a] -= t2h
                diag[k, d, d] += t2hh + u2
                grad[k, a] += t * e1[j, a]
                grad[k, d] += u * e2[j, a] - hh * t * e1[j, a]


def warm() -> None:
    """The kernels loaded (from numba's cache, or compiled where it holds none): each called once on two
    samples of one axis, with the argument types of every call (C-contiguous float arrays)."""
    X, y, S, P, rows, white = np.zeros((2, 9)), np.zeros((2, 1)), np.ones((1, 3)), np.ones((1, 3)), np.ones((1, 12)), np.ones((2, 1))
    sq = np.zeros(2)
    accumulate(X, y, S, P, rows, white, np.zeros((2, 9, 9)), np.zeros((2, 9)), sq)
    squared_norm(X, S, P, rows, y, white, sq)
    whitened_residual(X, S, P, rows, y, white, np.zeros((2, 1)))
    e = np.zeros((1, 3))
    white_jerk(X, np.ones(1), np.ones((1, 6)), np.zeros((2, 9, 9)), np.zeros((1, 9, 9)), np.zeros((2, 9)), e, e.copy())
