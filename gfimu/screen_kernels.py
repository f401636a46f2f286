"""The spike rule of the readings' screening compiled, for a stream's decisions (:class:`gfimu.readings.StreamScreen`).

A stream decides its readings a block at a time (one sample at 62.5 Hz, ten at 500 Hz), each decision on a
buffer of a few dozen rows: there the numpy expressions of :func:`gfimu.readings._spikes` cost their calls
(about forty, 0.2-0.3 ms a decision) far more than their arithmetic. Around a spike every block is decided so (a spike
every 2.4 s at 62.5 Hz: nine decisions in ten), and a buffer whose only faults can be spikes is decided whole by
:func:`spike_decision`: the value checks, the spikes and their replacements in one call, the numpy expressions of
:func:`gfimu.readings._screen` its oracle (``StreamScreen.compiled = False``). :func:`spike_mask` is that rule for a
buffer's middle (no end of the log in it), term for term and in the same order of operations, so it gives the same
mask to the bit: the rolling median is a selection (the middle value, or the mean of the two middle finite ones where
a window holds a missing reading), the centred sums are differences of running sums taken in row
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
    return spike_mask_rows(work, median_half, scale_half, floor, spike_scales, white_factor, 0, work.shape[0])


@njit(cache=True, nogil=True, error_model="numpy")
def spike_mask_rows(work, median_half, scale_half, floor, spike_scales, white_factor, r0, r1):
    """:func:`spike_mask` of the rows ``[r0, r1)`` alone (the others False): the same numbers there, the local
    scales' running sums still taken from the first row."""
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
    for i in range(max(r0, 0), min(r1, n)):
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


@njit(cache=True, nogil=True, error_model="numpy")
def _select(a, k):
    """The ``k``-th smallest value of ``a`` (no NaN), ``a`` reordered in place so that the values before
    position ``k`` are at most it (Hoare's selection)."""
    lo, hi = 0, a.shape[0] - 1
    while lo < hi:
        pivot = a[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while a[j] > pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return a[k]


@njit(cache=True, nogil=True, error_model="numpy")
def spike_decision(buf, low_limit, high_limit, min_repeats, start, reach, known, sensor_of_axis, median_half,
                   scale_half, spike_scales, white_factor, out_of_any, log_start, first, stop):
    """A stream's decision (:meth:`gfimu.readings.StreamScreen._decide`) on a buffer ``buf`` (N, n_axes) that
    holds only finite readings within range and no run of repeats long enough to be stuck, in one call:
    ``(ok, y, spikes)``, ``ok`` False (nothing computed, ``buf`` and ``known`` returned) where the buffer
    holds any other fault, or the spike rule would read from the log's first rows (``start`` 0 and
    ``log_start``, the buffer's first row the log's): the numpy expressions then decide.

    The checks are :func:`gfimu.readings._value_faults`' (not finite, beyond ``out_of_any``, beyond
    ``high_limit`` = (1 + tolerance) × the stated range, at or beyond ``low_limit`` = (1 - tolerance) × it: a
    clip; infinite where no range is stated, :func:`gfimu.readings.range_limits`) and a column repeating one
    value over ``min_repeats`` + 1 readings in a row (as long as :func:`gfimu.readings.stuck_runs`' shortest
    run). Then, as :func:`gfimu.readings._screen` decides: the spikes of the rows from ``start`` (0: every
    row's; :func:`spike_mask`, the floor from the whole buffer's median |reading|,
    :func:`gfimu.readings._nanmedian_flat`), a row whose spikes two sensors (``sensor_of_axis``) share
    cleared, those of the rows before ``start + reach`` as ``known``; each spike replaced by the median of its
    good neighbours within ``median_half`` rows, else by the next good reading of its column (the last where
    none follows; :func:`gfimu.readings._replaced`). Only the rows decided, ``[first, stop)``, are given out:
    their readings (``y``, the other rows as they came) and their spikes are those of the numpy expressions."""
    n, m = buf.shape
    if (start == 0 and log_start) or n < 2 * scale_half + 1:
        return False, buf, known  # (not ok: nothing made, the arrays given returned)
    for i in range(n):
        for j in range(m):
            v = buf[i, j]
            if not np.isfinite(v):
                return False, buf, known
            a = abs(v)
            if a > out_of_any or a > high_limit[j] or a >= low_limit[j]:
                return False, buf, known
    for j in range(m):  # a run of one value over min_repeats + 1 readings may be stuck: the numpy rule judges it
        run = 0
        for i in range(1, n):
            run = run + 1 if buf[i, j] == buf[i - 1, j] else 0
            if run >= min_repeats:
                return False, buf, known
    flat = np.abs(buf).reshape(-1)
    k = flat.shape[0]
    hi = k // 2  # the two middle values (one where k is odd): the order statistics numpy's partition finds
    hi_value = _select(flat, hi)  # (flat now holds the values below it before it)
    lo_value = hi_value
    if (k - 1) // 2 < hi:
        lo_value = flat[0]
        for i in range(1, hi):
            if flat[i] > lo_value:
                lo_value = flat[i]
    typical = (lo_value + hi_value) / 2
    floor = 1e-6 * max(typical if np.isfinite(typical) else 1.0, 1.0)
    # the rows decided (``[first, stop)``) and the median windows around them: their spikes alone tell the
    # readings given out, unless a window holds no good reading (then every row's, below)
    work = np.ascontiguousarray(buf[start:])
    ok, y, spikes = _spikes_replaced(buf, work, start, reach, known, sensor_of_axis, median_half, scale_half, floor,
                                     spike_scales, white_factor, first - median_half, stop + median_half, first, stop)
    if ok:
        return True, y, spikes
    return _spikes_replaced(buf, work, start, reach, known, sensor_of_axis, median_half, scale_half, floor,
                            spike_scales, white_factor, 0, n, 0, n)


@njit(cache=True, nogil=True, error_model="numpy")
def _spikes_replaced(buf, work, start, reach, known, sensor_of_axis, median_half, scale_half, floor, spike_scales,
                     white_factor, lo, hi, first, stop):
    """:func:`spike_decision`'s spikes of the buffer's rows ``[lo, hi)`` and the readings of rows ``[first, stop)``
    with theirs replaced: ``(ok, y, spikes)``, ``ok`` False where a replaced reading's window holds no good
    reading and the rows outside ``[lo, hi)`` were not looked at (its replacement is then the next good
    reading of its column, anywhere in the buffer)."""
    n, m = buf.shape
    y = buf.copy()
    spikes = known.copy()
    part = spike_mask_rows(work, median_half, scale_half, floor, spike_scales, white_factor, max(lo, 0) - start,
                           min(hi, n) - start)
    for i in range(part.shape[0]):  # a spike seen by two sensors at one sample is an event of the body
        first_sensor = -1
        shared = False
        for j in range(m):
            if part[i, j]:
                if first_sensor < 0:
                    first_sensor = sensor_of_axis[j]
                elif sensor_of_axis[j] != first_sensor:
                    shared = True
        if shared:
            for j in range(m):
                part[i, j] = False
    for i in range(start + reach if start > 0 else 0, n):  # (from start 0: every row's, as the whole buffer's rule)
        for j in range(m):
            spikes[i, j] = part[i - start, j]
    vals = np.empty(2 * median_half + 1)
    x = buf.copy()
    for i in range(n):
        for j in range(m):
            if spikes[i, j]:
                x[i, j] = np.nan
    whole = lo <= 0 and hi >= n
    for i in range(max(first, 0), min(stop, n)):
        for j in range(m):
            if not spikes[i, j]:
                continue
            fill = _window_median(x, i, j, median_half, vals)
            if np.isnan(fill):  # no good reading within the window: the next good one of the column (else the last)
                if not whole:
                    return False, y, spikes
                nxt, last = -1, -1
                for r in range(n):
                    if not spikes[r, j]:
                        last = r
                        if r >= i and nxt < 0:
                            nxt = r
                if nxt >= 0:
                    fill = buf[nxt, j]
                elif last >= 0:
                    fill = buf[last, j]
            y[i, j] = fill
    return True, y, spikes
