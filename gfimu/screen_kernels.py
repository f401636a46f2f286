"""The spike rule of the readings' screening compiled, for a stream's decisions (:class:`gfimu.readings.StreamScreen`).

A stream decides its readings a block at a time (one sample at 62.5 Hz, ten at 500 Hz), each decision on a
buffer of a few dozen rows: there the numpy expressions of :func:`gfimu.readings._spikes` cost their calls
(about forty, 0.2-0.3 ms a decision) far more than their arithmetic. :func:`spike_mask` is that rule for a
buffer's middle (no end of the log in it), term for term and in the same order of operations, so it gives the
same mask to the bit: the rolling median is a selection (the middle value, or the mean of the two middle finite
ones where a window holds a missing reading), the centred sums are differences of running sums taken in row
order, as ``numpy.cumsum`` takes them. The numpy expression stays the oracle ``tests/test_screen_kernels.py``
compares it with; a whole log (:func:`gfimu.readings.screen_log`) is screened by the numpy expressions, on
arrays long enough for them.

Compiled on first use and cached on disk (numba's ``cache=True``); imported only where a stream is screened.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def _window_median(work, r, c, half, vals):
    """The median of column ``c`` over rows ``r - half … r + half`` of ``work`` (rows beyond it and missing
    readings left out): the middle finite value, or the mean of the two middle ones; NaN where none is finite
    (:func:`gfimu.readings._rolling_median`)."""
    n = work.shape[0]
    k = 0
    for i in range(r - half, r + half + 1):
        if 0 <= i < n:
            v = work[i, c]
            if not np.isnan(v):
                j = k  # insertion into the sorted finite values
                while j > 0 and vals[j - 1] > v:
                    vals[j] = vals[j - 1]
                    j -= 1
                vals[j] = v
                k += 1
    if k == 0:
        return np.nan
    if k == 2 * half + 1:  # a full window: its middle value (numpy's median of an odd count selects it)
        return vals[half]
    return (vals[max((k - 1) // 2, 0)] + vals[min(k // 2, 2 * half)]) / 2


@njit(cache=True, nogil=True, error_model="numpy")
def _centred_sums(x, half, out):
    """Per column, the sum of the rows within ±``half`` of each row (those that exist), into ``out``: the
    difference of two running sums, as :func:`gfimu.readings._centred_sum` takes it."""
    n, m = x.shape
    c = np.zeros((n + 1, m))
    for i in range(n):
        for j in range(m):
            c[i + 1, j] = c[i, j] + x[i, j]
    for i in range(n):
        hi = min(i + half + 1, n)
        lo = max(i - half, 0)
        for j in range(m):
            out[i, j] = c[hi, j] - c[lo, j]


@njit(cache=True, nogil=True, error_model="numpy")
def spike_mask(work, median_half, scale_half, floor, spike_scales, white_factor):
    """(N, n_axes) bool: the readings of ``work`` (NaN where already at fault) more than ``spike_scales``
    local scales from the rolling median of ±``median_half`` rows (:func:`gfimu.readings._spikes` without its
    ends and before its check across sensors). The local scale is the mean |second difference| over ±``scale_half``
    rows, the three a spike touches left out, over ``white_factor`` (√6 √(2/π)), at least ``floor``."""
    n, m = work.shape
    vals = np.empty(2 * median_half + 1)
    d2 = np.zeros((n, m))
    ok = np.zeros((n, m))
    for i in range(1, n - 1):
        for j in range(m):
            v = abs(work[i + 1, j] - 2.0 * work[i, j] + work[i - 1, j])
            if np.isfinite(v):
                d2[i, j] = v
                ok[i, j] = 1.0
    if n > 0:  # (the first and last rows: |0| is finite, as numpy's zeros there are)
        for j in range(m):
            ok[0, j] = 1.0
            ok[n - 1, j] = 1.0
    wide = np.empty((n, m))
    near = np.empty((n, m))
    _centred_sums(d2, scale_half, wide)
    _centred_sums(d2, 1, near)
    wide_n = np.empty((n, m))
    near_n = np.empty((n, m))
    _centred_sums(ok, scale_half, wide_n)
    _centred_sums(ok, 1, near_n)
    out = np.zeros((n, m), dtype=np.bool_)
    for i in range(n):
        for j in range(m):
            w = work[i, j]
            if np.isnan(w):
                continue
            dev = abs(w - _window_median(work, i, j, median_half, vals))
            if not np.isfinite(dev):
                continue
            local = (wide[i, j] - near[i, j]) / max(wide_n[i, j] - near_n[i, j], 1.0) / white_factor
            if np.isnan(local):  # (numpy's maximum keeps a NaN, and no reading stands beyond it)
                continue
            out[i, j] = dev > spike_scales * (local if local > floor else floor)
    return out
