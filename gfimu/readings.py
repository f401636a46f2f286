"""Screening of accelerometer readings for gross errors (pure maths, no I/O).

One corrupt cell — a non-finite value, a transmission error of 1e30, a 1000 m/s²
spike on one sensor — must not spoil the estimate around it. :func:`screen` finds
such readings channel by channel and replaces them by the median of their
neighbours in time, so every estimator (per-sample or smoother) reads a plausible
value there and the rest of the log is untouched:

- readings that are not finite;
- readings outside the sensor's range when the array states one;
- isolated spikes (a Hampel identifier with a local scale): the reading's
  distance from the median of the 5 samples centred on it (at the first and
  last two rows, from a robust straight line through the 5 end samples) exceeds
  :data:`SPIKE_SCALES` times the local noise scale, read from the second
  differences within ±:data:`SCALE_HALF_WIDTH` samples (leaving out those the
  sample itself touches), and no other accelerometer jumps at the same sample.
  Real motion, however fast, moves neighbouring samples together and is felt by
  every sensor; a spike stands alone;
- readings *clipped* at the sensor's range (within :data:`CLIP_TOLERANCE` of it);
- *stuck* channels: one value repeated for at least :data:`STUCK_MIN_S` (and
  :data:`STUCK_MIN_SAMPLES`) while most other channels change (:func:`stuck_runs`).

Clipped and stuck readings come in runs longer than the median window; they are
replaced by the rigid-body prediction of the other axes at the same sample (the
least-squares fit of the 12 unknowns [f, ω̇, q(ω)], Ho & Lin 2009, eq. 6) when the
remaining axes determine it, else by a straight line between the channel's good
readings on either side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SPIKE_SCALES = 50.0
"""A reading this many local noise stds from its neighbours' median is a gross error (white noise
reaches 6 stds once in a billion readings)."""
SCALE_HALF_WIDTH = 25
"""Half width [samples] of the window of the local scale."""
MEDIAN_HALF_WIDTH = 2
"""Half width [samples] of the median a reading is compared with and replaced by."""
OUT_OF_ANY_RANGE_MPS2 = 1e7
"""A reading beyond ±1e7 m/s² (a million g; shock accelerometers read up to about 1e6 m/s²) is out of range
whatever ``range_mps2`` says or when it says nothing: no accelerometer reads it (1e308 would overflow the
screening and the estimators)."""

CLIP_TOLERANCE = 1e-3
"""A reading within this fraction of the stated range is clipped (one count of a 10-bit converter is 2e-3 of its
full scale; wider converters are finer); beyond the range by more than it, out of range."""
STUCK_MIN_S = 0.2
"""Shortest run [s] of one repeated value reported as a stuck channel (and at least :data:`STUCK_MIN_SAMPLES`)."""
STUCK_MIN_SAMPLES = 10
"""A quantised channel with white noise of one quantum std repeats its value with probability about 0.3 per step;
ten repeats in a row: 2e-5 (and a run counts only while most other channels change)."""


@dataclass(frozen=True)
class Screening:
    """Readings found to be gross errors and replaced (:func:`screen`)."""

    replaced: np.ndarray
    """(N, n_axes) bool: the readings replaced."""
    non_finite: int
    out_of_range: int
    spikes: int
    clipped: int = 0
    stuck: int = 0
    runs: tuple = ()
    """(kind, column index, first row, last row) of each run of clipped or stuck readings."""

    @property
    def count(self) -> int:
        return int(self.replaced.sum())

    def describe(self, columns: list[str] | tuple[str, ...], limit: int = 5, row_numbers=None) -> str:
        """One line: counts by kind and the first rows and columns (``row_numbers``: the row number of each row
        of :attr:`replaced`, when it holds only some rows)."""
        rows, cols = np.nonzero(self.replaced)
        if row_numbers is not None:
            rows = np.asarray(row_numbers)[rows]
        where = ", ".join(f"row {r} {columns[c]}" for r, c in zip(rows[:limit], cols[:limit]))
        more = f" and {len(rows) - limit} more" if len(rows) > limit else ""
        kinds = ", ".join(f"{n} {name}" for n, name in ((self.non_finite, "not finite"),
                                                         (self.out_of_range, "out of range"),
                                                         (self.spikes, "isolated spikes"),
                                                         (self.clipped, "clipped at the range"),
                                                         (self.stuck, "stuck")) if n)
        if not self.runs:
            return (f"{self.count} accelerometer reading(s) replaced by the median of their neighbours "
                    f"({kinds}): {where}{more}")
        spans = ", ".join(f"{columns[c]} {kind} rows {a}-{b}" for kind, c, a, b in self.runs[:limit])
        spans += f" and {len(self.runs) - limit} more run(s)" if len(self.runs) > limit else ""
        return (f"{self.count} accelerometer reading(s) replaced ({kinds}; clipped and stuck ones by the other "
                f"sensors' rigid-body prediction or a line between good neighbours, the others by the median of "
                f"their neighbours): {spans}; {where}{more}")


def _median_of_five(a, b, c, d, e):
    """Element-wise median of five arrays without NaN, by minima and maxima (six comparisons): the larger
    of the two pairs' smaller values and the smaller of their larger values leave out the two extremes
    of a, b, c, d, and the median of those two with e is the median of all five. Exactly the value
    ``np.median`` picks, several times faster than sorting each window."""
    low = np.maximum(np.minimum(a, b), np.minimum(c, d))
    high = np.minimum(np.maximum(a, b), np.maximum(c, d))
    return np.maximum(np.minimum(low, e), np.minimum(np.maximum(low, e), high))


def _rolling_median(x: np.ndarray, half: int) -> np.ndarray:
    """Median over ±``half`` samples per column, ignoring NaN (edges: the samples that exist).

    Windows without NaN take the plain median (a partition, several times faster than NaN-aware
    medians); only the windows that hold a NaN (the edges, missing readings) take ``nanmedian``:
    the same numbers either way."""
    n = x.shape[0]
    w = 2 * half + 1
    pad = np.full((half, x.shape[1]), np.nan)
    padded = np.concatenate([pad, x, pad])
    windows = np.lib.stride_tricks.sliding_window_view(padded, w, axis=0)  # (n, cols, w)
    missing = np.cumsum(np.isnan(padded), axis=0)
    missing = missing[w - 1:] - np.concatenate([np.zeros((1, x.shape[1]), missing.dtype), missing[:-w]])  # NaN per window
    out = np.empty_like(x)
    step = 65536  # bounded memory on long logs
    if w == 5:  # the middle of five values by comparisons alone (:func:`_median_of_five`): the same value
        shifted = [padded[k:k + n] for k in range(5)]
        out[:] = _median_of_five(*shifted)
    else:
        for s in range(0, n, step):
            out[s:s + step] = np.median(windows[s:s + step], axis=2)
    rows, cols = np.nonzero(missing)
    for s in range(0, rows.size, step):
        r, c = rows[s:s + step], cols[s:s + step]
        out[r, c] = _nanmedian_last(windows[r, c])
    return out


def _rolling_median_at(x: np.ndarray, half: int, where: np.ndarray) -> np.ndarray:
    """:func:`_rolling_median` of ``x`` at the entries ``where`` (N, cols) bool, each window's median taken the
    same way (the same numbers); the other entries are zero."""
    w = 2 * half + 1
    pad = np.full((half, x.shape[1]), np.nan)
    windows = np.lib.stride_tricks.sliding_window_view(np.concatenate([pad, x, pad]), w, axis=0)  # (n, cols, w)
    rows, cols = np.nonzero(where)
    v = windows[rows, cols]  # (k, w)
    missing = np.isnan(v).any(axis=1)
    values = _median_of_five(*v.T) if w == 5 else np.median(v, axis=1)
    values[missing] = _nanmedian_last(v[missing])
    out = np.zeros_like(x)
    out[rows, cols] = values
    return out


def _nanmedian_last(v: np.ndarray) -> np.ndarray:
    """``np.nanmedian(v, axis=-1)`` (the mean of the middle two finite values, NaN where there is none) by
    one sort, without its warnings and its per-call cost on small arrays."""
    s = np.sort(v, axis=-1)  # NaN last
    k = np.count_nonzero(~np.isnan(v), axis=-1)
    lo = np.take_along_axis(s, np.maximum((k - 1) // 2, 0)[..., None], axis=-1)[..., 0]
    hi = np.take_along_axis(s, np.minimum(k // 2, v.shape[-1] - 1)[..., None], axis=-1)[..., 0]
    with np.errstate(invalid="ignore"):
        return np.where(k > 0, (lo + hi) / 2, np.nan)


def _nanmedian_flat(v: np.ndarray) -> float:
    """``_nanmedian_last`` of all of ``v`` as one row: the same two middle finite values, found by a partition
    instead of a sort of every value (NaN last in both)."""
    v = v.reshape(-1)
    k = int(np.count_nonzero(~np.isnan(v)))
    if k == 0:
        return float("nan")
    lo, hi = (k - 1) // 2, k // 2
    part = np.partition(v, [lo, hi])
    return float((part[lo] + part[hi]) / 2)


def _edge_line(x: np.ndarray) -> np.ndarray:
    """A robust straight line through the rows of ``x`` (m, cols) per column, at those rows: the median of the
    pairwise slopes and the median intercept (Theil-Sen), NaN readings left out. One gross error among the rows
    moves it little; a ramp is followed exactly."""
    import warnings

    t = np.arange(x.shape[0], dtype=float)
    i, j = np.triu_indices(x.shape[0], k=1)
    def median(v):  # NaN left out (the plain median when there is none: the same value, faster)
        if np.isnan(v).any():
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # a column without two finite rows: NaN
                return np.nanmedian(v, axis=0)
        return np.median(v, axis=0)

    slope = median((x[j] - x[i]) / (j - i)[:, None])
    intercept = median(x - slope[None, :] * t[:, None])
    return intercept[None, :] + slope[None, :] * t[:, None]


def _centred_sum(x: np.ndarray, half: int) -> np.ndarray:
    """Per column, the sum of the rows within ±``half`` of each row (those that exist)."""
    n = x.shape[0]
    c = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    k = np.arange(n)
    return c[np.minimum(k + half + 1, n)] - c[np.maximum(k - half, 0)]


def runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of the runs of True in a 1-D mask."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.nonzero(d == 1)[0].tolist(), np.nonzero(d == -1)[0].tolist()))


def range_limits(range_mps2, n_axes: int) -> tuple[np.ndarray, np.ndarray]:
    """(clip, over) (n_axes,): a reading of at least ``clip`` in magnitude is clipped, one beyond ``over`` out of
    range: the stated range (NaN or None: none stated, both infinite) less and more :data:`CLIP_TOLERANCE`."""
    limit = np.broadcast_to(np.asarray(np.nan if range_mps2 is None else range_mps2, dtype=float), (n_axes,))
    stated = np.isfinite(limit) & (limit > 0)
    limit = np.where(stated, limit, np.inf)
    return (1 - CLIP_TOLERANCE) * limit, (1 + CLIP_TOLERANCE) * limit


def clipped_readings(accel_mps2: np.ndarray, range_mps2) -> np.ndarray:
    """(N, n_axes) readings within :data:`CLIP_TOLERANCE` of the stated range (NaN: none stated) or beyond it."""
    y = np.asarray(accel_mps2, dtype=float)
    clip, _ = range_limits(range_mps2, y.shape[1])
    with np.errstate(invalid="ignore"):
        return np.isfinite(y) & (np.abs(y) >= clip[None, :])


def stuck_min_samples(rate_hz: float | None) -> int:
    """The shortest stuck run [samples]: :data:`STUCK_MIN_S` at ``rate_hz``, at least :data:`STUCK_MIN_SAMPLES`."""
    if rate_hz is not None and np.isfinite(rate_hz) and rate_hz > 0:
        return max(STUCK_MIN_SAMPLES, round(STUCK_MIN_S * rate_hz))
    return STUCK_MIN_SAMPLES


def stuck_runs(accel_mps2: np.ndarray, rate_hz: float | None = None,
               exclude: np.ndarray | None = None) -> list[tuple[int, int, int]]:
    """(column, first row, stop row) of the runs in which a channel repeats one value for at least
    :data:`STUCK_MIN_S` (at ``rate_hz``; :data:`STUCK_MIN_SAMPLES` when not given) while most other channels change
    at most of those steps; readings in ``exclude`` (N, n_axes) never count as repeats."""
    y = np.asarray(accel_mps2, dtype=float)
    n, m = y.shape
    if n < 2 or m < 2:
        return []
    changed = np.zeros((n, m), bool)
    changed[1:] = y[1:] != y[:-1]
    min_len = stuck_min_samples(rate_hz)
    out = []
    repeats = np.zeros((n, m), bool)
    repeats[1:] = (y[1:] == y[:-1]) & np.isfinite(y[1:])
    if exclude is not None:
        repeats[1:] &= ~exclude[1:] & ~exclude[:-1]
    for c in np.nonzero(np.count_nonzero(repeats, axis=0) >= min_len - 1)[0].tolist():
        same = repeats[:, c]
        others = np.delete(changed, c, axis=1)
        for a, b in runs_of(same):
            start = a - 1  # the first sample holding the repeated value
            if b - start >= min_len and np.median(np.mean(others[a:b], axis=0)) >= 0.5:
                out.append((c, start, b))
    return out


PLACEHOLDER_VALUES_MPS2 = (-999.0, 999.0, -9999.0, 9999.0, -99999.0, 99999.0, -32768.0, 32767.0, 65535.0,
                          -2147483648.0, 2147483647.0)
"""Fill values loggers and spreadsheets write where a reading is missing (-999, the 16- and 32-bit integer limits):
a reading exactly equal to one (beyond any phone or IMU accelerometer's range but the 1e7 m/s² bound) is a
placeholder, not a measurement."""


@dataclass(frozen=True)
class DeadChannel:
    """A channel that carries no measurement (:func:`dead_channels`)."""

    column: str
    kind: str
    """'dead' (every reading exactly 0), 'constant' (every finite reading one value) or 'placeholder' (readings
    exactly at a fill value of :data:`PLACEHOLDER_VALUES_MPS2`)."""
    value_mps2: float
    samples: int
    first_row: int


def dead_channels(accel_mps2: np.ndarray, columns) -> list[DeadChannel]:
    """Channels of readings (N, n_axes) that measure nothing: every finite reading exactly 0 (*dead*), every
    finite reading one other value (*constant*: no real accelerometer, whose noise moves its last bit, reads one
    value over a whole log of three samples or more), or readings exactly at a fill value (*placeholder*)."""
    y = np.asarray(accel_mps2, dtype=float)
    out = []
    for c, name in enumerate(columns):
        col = y[:, c]
        finite = np.flatnonzero(np.isfinite(col))
        if finite.size >= STUCK_MIN_SAMPLES and np.all(col[finite] == col[finite[0]]):
            v = float(col[finite[0]])
            out.append(DeadChannel(name, "dead" if v == 0.0 else "constant", v, int(finite.size), int(finite[0])))
            continue
        at = np.isin(col, PLACEHOLDER_VALUES_MPS2)
        if at.any():
            rows = np.flatnonzero(at)
            out.append(DeadChannel(name, "placeholder", float(col[rows[0]]), int(rows.size), int(rows[0])))
    return out


def describe_dead_channels(found: list[DeadChannel], n_columns: int) -> list[str]:
    """One line per kind of :func:`dead_channels` finding, naming the columns (the first few)."""
    lines = []
    for kind, what in (("dead", "read exactly 0 in every row (a dead sensor, or no data written)"),
                       ("constant", "read one value in every row (a stuck sensor, or a value filled in)"),
                       ("placeholder", "hold a fill value (a missing reading written as a number)")):
        hits = [d for d in found if d.kind == kind]
        if not hits:
            continue
        names = ", ".join(d.column + (f" = {d.value_mps2:g}" if kind != "dead" else "") +
                          (f" ({d.samples} rows from row {d.first_row})" if kind == "placeholder" else "")
                          for d in hits[:6]) + (f" and {len(hits) - 6} more" if len(hits) > 6 else "")
        every = "all " if len(hits) == n_columns else ""
        lines.append(f"{every}{len(hits)} of {n_columns} accelerometer channel(s) {what}: {names}")
    return lines


def _rigid_body_fill(y: np.ndarray, bad: np.ndarray, structure_matrix: np.ndarray | None) -> np.ndarray:
    """(N, n_axes) bool: the readings of ``bad`` that were replaced in ``y`` (in place) by the rigid-body
    prediction of the good axes of their sample, where those determine the 12 unknowns."""
    done = np.zeros_like(bad)
    if structure_matrix is None:
        return done
    S = np.asarray(structure_matrix, dtype=float)
    rows = np.nonzero(bad.any(axis=1))[0]
    if rows.size == 0:
        return done
    patterns, inverse = np.unique(bad[rows], axis=0, return_inverse=True)
    for k, pattern in enumerate(patterns):
        good = ~pattern
        sg = S[good]
        if sg.shape[0] < S.shape[1]:
            continue
        sv = np.linalg.svd(sg, compute_uv=False)
        if sv[-1] <= 1e-9 * sv[0]:
            continue
        r = rows[inverse.reshape(-1) == k]
        r = r[np.all(np.isfinite(y[np.ix_(r, np.nonzero(good)[0])]), axis=1)]
        if r.size == 0:
            continue
        x, *_ = np.linalg.lstsq(sg, y[np.ix_(r, np.nonzero(good)[0])].T, rcond=None)
        y[np.ix_(r, np.nonzero(pattern)[0])] = (S[pattern] @ x).T
        done[np.ix_(r, np.nonzero(pattern)[0])] = True
    return done


def _line_fill(y: np.ndarray, bad: np.ndarray) -> None:
    """Readings of ``bad`` replaced in ``y`` (in place) by a straight line between the channel's good readings."""
    for c in np.nonzero(bad.any(axis=0))[0]:
        good = np.nonzero(~bad[:, c] & np.isfinite(y[:, c]))[0]
        idx = np.nonzero(bad[:, c])[0]
        if good.size:
            y[idx, c] = np.interp(idx, good, y[good, c])


KINDS = ("non_finite", "out_of_range", "spikes", "clipped", "stuck")
"""The kinds of gross error, in the order :class:`Screening` counts them."""


def screen(accel_mps2: np.ndarray, range_mps2: np.ndarray | None = None,
           sensor_of_axis: np.ndarray | None = None, rate_hz: float | None = None,
           structure_matrix: np.ndarray | None = None) -> tuple[np.ndarray, Screening]:
    """(readings with gross errors replaced, :class:`Screening`) of ``accel_mps2`` (N, n_axes);
    ``range_mps2`` (n_axes,) the largest magnitude each axis can read (NaN or None: not stated);
    ``sensor_of_axis`` (n_axes,) the accelerometer each axis belongs to: a spike seen by two or more
    accelerometers at the same sample is a real event of the body (a knock), not a gross error;
    ``rate_hz`` the sample rate (for the shortest stuck run); ``structure_matrix`` (n_axes, 12) the array's S,
    to replace clipped and stuck readings by the other axes' rigid-body prediction."""
    y, kinds, runs = _screen(accel_mps2, range_mps2, sensor_of_axis, rate_hz, structure_matrix)
    replaced = np.logical_or.reduce([kinds[k] for k in KINDS])
    return y, Screening(replaced, *(int(kinds[k].sum()) for k in KINDS), runs=tuple(runs))


SPIKE_REACH = SCALE_HALF_WIDTH + MEDIAN_HALF_WIDTH + 2
"""Rows on either side of a reading that its spike decision reads (the median window, the local scale's second
differences, and a margin): a buffer's rows this far from its cut are decided as in the whole log."""


def _screen(accel_mps2, range_mps2, sensor_of_axis, rate_hz, structure_matrix, ends=(True, True), decide_from=None,
            known_spikes=None):
    """(readings with gross errors replaced, {kind: (N, n_axes) bool} for each of :data:`KINDS`, runs of
    clipped and stuck readings): :func:`screen`'s work. ``ends``: whether the first and the last rows are
    the log's own (a stream's buffer cut from its middle is not: the rows near its cut are not decided).
    ``decide_from`` (a stream's buffer, :class:`StreamScreen`): the rows before it are decided already, their
    spikes given in ``known_spikes`` (N, n_axes) bool; the spike rule then runs on the rows from
    2 :data:`SPIKE_REACH` before it only (the stuck and clipped runs still on the whole buffer)."""
    y = np.array(accel_mps2, dtype=float)
    bad_value, out_range, clipped = _value_faults(y, range_mps2)
    stuck, runs = _long_runs(y, rate_hz, bad_value, out_range, clipped)
    long_bad = clipped | stuck
    work = np.where(bad_value | out_range | long_bad, np.nan, y)
    start = 0 if decide_from is None else max(0, decide_from - 2 * SPIKE_REACH)
    stream = decide_from is not None
    if y.shape[0] < 2 * SCALE_HALF_WIDTH + 1:
        spikes = np.zeros_like(bad_value)
    elif start == 0:
        spikes = _spikes(work, sensor_of_axis, ends, compiled=stream)
    else:  # the rows near the part's cut read from the decisions already taken on them
        part = _spikes(work[start:], sensor_of_axis, (False, ends[1]), typical=_nanmedian_flat(np.abs(work)),
                       compiled=True)
        spikes = np.array(known_spikes, dtype=bool)
        spikes[start + SPIKE_REACH:] = part[SPIKE_REACH:]
    spikes &= ~long_bad
    short = bad_value | out_range | spikes
    y = _replaced(y, short, long_bad, structure_matrix)
    kinds = dict(zip(KINDS, (bad_value, out_range, spikes, clipped, stuck)))
    return y, kinds, runs


def _value_faults(y: np.ndarray, range_mps2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(not finite, out of range, clipped), each (N, n_axes) bool, of the readings ``y`` against
    :data:`OUT_OF_ANY_RANGE_MPS2` and the stated ``range_mps2`` (None: not stated)."""
    bad_value = ~np.isfinite(y)
    with np.errstate(invalid="ignore"):
        out_range = ~bad_value & (np.abs(y) > OUT_OF_ANY_RANGE_MPS2)
    clipped = np.zeros_like(bad_value)
    if range_mps2 is not None:
        _, over = range_limits(range_mps2, y.shape[1])
        with np.errstate(invalid="ignore"):
            out_range |= ~bad_value & (np.abs(y) > over[None, :])
        clipped = clipped_readings(y, range_mps2) & ~out_range
    return bad_value, out_range, clipped


def _long_runs(y: np.ndarray, rate_hz, bad_value: np.ndarray, out_range: np.ndarray,
               clipped: np.ndarray) -> tuple[np.ndarray, list]:
    """(stuck readings (N, n_axes) bool, runs): the stuck runs of ``y`` among the readings not already at fault,
    and (kind, column, first row, last row) of every stuck and clipped run, by first row then column."""
    stuck = np.zeros_like(bad_value)
    runs = []
    for c, a, b in stuck_runs(y, rate_hz, exclude=bad_value | out_range | clipped):
        stuck[a:b, c] = True
        runs.append(("stuck", c, a, b - 1))
    for c in np.nonzero(clipped.any(axis=0))[0]:
        runs += [("clipped", int(c), a, b - 1) for a, b in runs_of(clipped[:, c])]
    runs.sort(key=lambda r: (r[2], r[1]))
    return stuck, runs


_WHITE_SECOND_DIFFERENCE = float(np.sqrt(6.0) * np.sqrt(2.0 / np.pi))
"""Mean |y[j+1] - 2 y[j] + y[j-1]| of white noise of unit std: √6 √(2/π)."""


def _spikes(work: np.ndarray, sensor_of_axis, ends, typical: float | None = None, compiled: bool = False) -> np.ndarray:
    """(N, n_axes) bool: the isolated spikes of ``work`` (the readings, NaN where already at fault; at least
    2 :data:`SCALE_HALF_WIDTH` + 1 rows), a Hampel identifier with a local scale; a spike seen by two or more
    accelerometers (``sensor_of_axis``) at one sample is an event of the body, not one. ``typical``: the median
    |reading| the scale's floor is taken from (default: that of ``work``). ``compiled``: a buffer's middle (no end
    of the log in it) through :func:`gfimu.screen_kernels.spike_mask`, the same mask (a stream's decisions)."""
    typical = _nanmedian_flat(np.abs(work)) if typical is None else typical
    floor = 1e-6 * max(float(typical) if np.isfinite(typical) else 1.0, 1.0)
    if compiled and not (ends[0] or ends[1]):
        from .screen_kernels import spike_mask

        spikes = spike_mask(np.ascontiguousarray(work, dtype=float), MEDIAN_HALF_WIDTH, SCALE_HALF_WIDTH, floor,
                            SPIKE_SCALES, _WHITE_SECOND_DIFFERENCE)
    else:
        spikes = _spike_mask(work, ends, floor)
    if sensor_of_axis is not None and np.any(spikes):
        sensors = np.asarray(sensor_of_axis)
        rows = np.nonzero(spikes.any(axis=1))[0]
        for r in rows:
            if np.unique(sensors[spikes[r]]).size > 1:
                spikes[r] = False
    return spikes


def _spike_mask(work: np.ndarray, ends, floor: float) -> np.ndarray:
    """:func:`_spikes` before its check across sensors, as numpy expressions (the oracle of
    :func:`gfimu.screen_kernels.spike_mask`)."""
    n = work.shape[0]
    med = _rolling_median(work, MEDIAN_HALF_WIDTH)
    # the first and last rows have a median window cut short, whose median lags a ramp: there, a
    # robust line through the 2 h + 1 end rows instead (a spike at an end row still stands out of it)
    h, m = MEDIAN_HALF_WIDTH, 2 * MEDIAN_HALF_WIDTH + 1
    if ends[0]:
        first = _edge_line(work[:m])[:h]
        med[:h] = np.where(np.isfinite(first), first, med[:h])
    if ends[1]:
        last = _edge_line(work[n - m:])[m - h:]
        med[n - h:] = np.where(np.isfinite(last), last, med[n - h:])
    dev = np.abs(work - med)
    # local noise scale from the second differences around the sample, leaving out the three a
    # spike at k touches (k-1, k, k+1): mean |y[j+1] - 2 y[j] + y[j-1]| = σ √6 √(2/π) for white noise
    d2 = np.zeros_like(work)
    d2[1:-1] = np.abs(work[2:] - 2.0 * work[1:-1] + work[:-2])
    ok = np.isfinite(d2)
    d2 = np.where(ok, d2, 0.0)
    total = _centred_sum(d2, SCALE_HALF_WIDTH) - _centred_sum(d2, 1)
    number = _centred_sum(ok.astype(float), SCALE_HALF_WIDTH) - _centred_sum(ok.astype(float), 1)
    local = total / np.maximum(number, 1.0) / _WHITE_SECOND_DIFFERENCE
    # constant (quantised, still) channels have no local scale: the floor, at 1e-6 of the typical magnitude
    return np.isfinite(dev) & (dev > SPIKE_SCALES * np.maximum(local, floor))


def _replaced(y: np.ndarray, short: np.ndarray, long_bad: np.ndarray, structure_matrix) -> np.ndarray:
    """``y`` with its faulty readings replaced: the runs (``long_bad``, clipped or stuck) by the rigid-body
    prediction or a line between good readings, the others (``short``) by the median of their good neighbours
    (the nearest good reading where a run of them is longer than the median window)."""
    replaced = short | long_bad
    if np.any(long_bad):
        raw = y
        y = np.where(short, np.nan, y)  # the short ones are filled below, from good readings only
        done = _rigid_body_fill(y, long_bad, structure_matrix)
        _line_fill(y, long_bad & ~done)
        y = np.where(short, raw, y)
    if np.any(short):
        fill = _rolling_median_at(np.where(replaced, np.nan, y), MEDIAN_HALF_WIDTH, replaced)  # (read only there)
        still_bad = replaced & ~np.isfinite(fill)
        if np.any(still_bad):  # a run of bad readings longer than the median window: nearest good value
            for c in np.nonzero(still_bad.any(axis=0))[0]:
                good = np.nonzero(~replaced[:, c])[0]
                if good.size:
                    idx = np.nonzero(still_bad[:, c])[0]
                    nearest = good[np.clip(np.searchsorted(good, idx), 0, good.size - 1)]
                    fill[idx, c] = y[nearest, c]
        y = np.where(short, fill, y)
    return y


def refuse_unreplaceable(log, accel: np.ndarray | None = None) -> None:
    """A :class:`~gfimu.errors.DataError` naming ``imu.csv`` and the column when readings of ``accel`` (the
    log's own by default) are not finite (a column of NaN: after the screening, none near them to
    replace them by)."""
    accel = log.accel_mps2 if accel is None else accel
    left = ~np.isfinite(accel)
    if not left.any():
        return
    from .errors import DataError

    column = int(np.argmax(left.any(axis=0)))
    name = log.array.accel_columns[column]
    where = f"{log.source}/imu.csv" if log.source else "the readings"
    raise DataError(f"{where}: column {name!r}: {int(left[:, column].sum())} of {len(log)} readings are not "
                    f"finite, the first at row {int(np.argmax(left[:, column]))}, with no finite reading near "
                    "them to replace them")


GYRO_OUT_OF_RANGE_RADPS = 1e4
"""A gyroscope reading beyond ±1e4 rad/s (about 95,000 rpm) is read by no gyroscope: the screening reads it as
NaN, with a warning (1e308 made the gyro-aided estimate infinite)."""


def _screen_gyro(log):
    """``log`` with gyroscope readings beyond :data:`GYRO_OUT_OF_RANGE_RADPS` read as NaN (a warning names the
    first's line and column)."""
    if log.gyro_b_radps is None:
        return log
    with np.errstate(invalid="ignore"):
        huge = np.abs(log.gyro_b_radps) > GYRO_OUT_OF_RANGE_RADPS
    if not huge.any():
        return log
    import warnings

    row, col = (int(v) for v in np.argwhere(huge)[0])
    where = f"{log.source}/imu.csv:{row + 2}" if log.source else f"sample {row}"
    warnings.warn(f"{where}: {int(huge.sum())} gyroscope reading(s) beyond ±{GYRO_OUT_OF_RANGE_RADPS:g} rad/s (first in "
                  f"column {('w_x', 'w_y', 'w_z')[col]!r}, {log.gyro_b_radps[row, col]:g}): no gyroscope reads that; "
                  "read as NaN", stacklevel=3)
    return log.replace(gyro_b_radps=np.where(huge, np.nan, log.gyro_b_radps))


def screen_log(log):
    """(log with gross errors replaced, :class:`Screening`); the log itself when none is found. Gyroscope
    readings beyond :data:`GYRO_OUT_OF_RANGE_RADPS` are read as NaN (with a warning)."""
    log = _screen_gyro(log)
    accel, result = screen(log.accel_mps2, log.array.range_per_axis_mps2, log.array.axis_owner,
                           log.rate_hz if len(log) > 1 else None, log.array.structure_matrix())
    refuse_unreplaceable(log, accel)
    if result.count == 0:
        return log, result
    return log.replace(accel_mps2=accel), result


STREAM_BLOCK_S = 0.02
"""The stream screening decides its readings in blocks of this length [s] (at least one sample): one
:func:`screen` of its buffer per block."""


def stream_delay_samples(rate_hz: float | None) -> int:
    """Samples a stream's reading waits for before it is screened (:class:`StreamScreen`): the look-ahead of
    :func:`screen`'s spike rule. A spike's local scale reaches :data:`SCALE_HALF_WIDTH` + 1 samples ahead and its
    replacement, the median of :data:`MEDIAN_HALF_WIDTH` neighbours, waits for theirs. A stuck run is not waited
    for: it counts from the reading at which it has lasted :func:`stuck_min_samples` within the buffer (its
    first ``stuck_min_samples - 1 - delay`` readings, where that is positive, pass as they are)."""
    return SCALE_HALF_WIDTH + 1 + MEDIAN_HALF_WIDTH


def stream_block_samples(rate_hz: float | None) -> int:
    """Samples the stream screening decides at once: :data:`STREAM_BLOCK_S` at ``rate_hz``, at least one."""
    return max(1, round(STREAM_BLOCK_S * rate_hz)) if rate_hz and np.isfinite(rate_hz) else 1


def stream_wait_s(rate_hz: float) -> float:
    """The longest a reading waits in the stream screening [s]: its delay and one block."""
    return (stream_delay_samples(rate_hz) + stream_block_samples(rate_hz)) / rate_hz


@dataclass(frozen=True)
class ScreenRule:
    """What :class:`StreamScreen` decides with: the array's accelerometer ``columns``, ``range_mps2`` per axis,
    ``sensor_of_axis`` and ``structure_matrix``; the ``rate_hz``; the samples a reading waits for before it is
    decided (``delay``, :func:`stream_delay_samples`), the samples decided at once (``block``,
    :func:`stream_block_samples`) and the rows kept behind the first undecided one (``history``: the spike
    rule's reach, and a stuck run's shortest length)."""

    columns: tuple
    range_mps2: object
    sensor_of_axis: object
    structure_matrix: np.ndarray
    rate_hz: float | None
    delay: int
    block: int
    history: int

    @classmethod
    def of(cls, array, rate_hz: float | None) -> ScreenRule:
        delay = stream_delay_samples(rate_hz)
        return cls(tuple(array.accel_columns), array.range_per_axis_mps2, array.axis_owner, array.structure_matrix(),
                   rate_hz, delay, stream_block_samples(rate_hz),
                   max(delay, stuck_min_samples(rate_hz)) + MEDIAN_HALF_WIDTH)


class StreamScreen:
    """:func:`screen_log`'s rule on readings as they come: each reading is decided (and replaced when it is a
    gross error) once :func:`stream_delay_samples` later ones have arrived, from a buffer of that many before
    and after it, so its decision is the one :func:`screen` takes on the whole log wherever the evidence
    lies within that reach (a reading between two spikes, a stuck channel, a clipped run: all of them).
    What differs lies beyond it: a clipped or missing run longer than the buffer is bridged from the good
    readings the buffer holds, and a stuck run longer than it is judged on the part the buffer holds.

    ``push(timestamp_ns, accel_row, gyro_row)`` returns the rows decided by it, oldest first, as
    ``(timestamp_ns, accel_row, gyro_row)`` (each ``accel_row`` an array of its own); :meth:`flush` decides
    the rest, the last arrived being the stream's end (as a log's last row is). Gyroscope readings beyond :data:`GYRO_OUT_OF_RANGE_RADPS` are
    NaN at once. :meth:`screening` is what was replaced, as :class:`Screening`.

    The same rows in the same order give the same rows out, whatever their timing: ``gfimu live`` and
    ``gfimu estimate --method fixed-lag`` (:func:`screen_stream`) screen a recording alike.
    """

    compiled = True
    """A decision on a buffer whose only faults can be spikes made in one compiled call
    (:func:`gfimu.screen_kernels.spike_decision`: the same readings and spikes to the bit); False: the numpy
    expressions of :func:`_screen` for every decision (the tests' oracle). Around a spike every block is decided
    on its buffer: at 62.5 Hz, a sample at a time."""

    def __init__(self, array, rate_hz: float | None, clean=None):
        self.clean = clean
        """None, or ``clean(first, stop)``: True where the rows ``[first, stop)`` (counted from the first pushed)
        are known to hold nothing the rule would replace, so that a block whose buffer lies there is passed
        without running the rule (:func:`screen_stream`: from the whole-log screening)."""
        self.rule = ScreenRule.of(array, rate_hz)
        rule = self.rule
        # the value checks of _value_faults, for the compiled decision (a reading at or beyond ``_low`` is
        # clipped, one beyond ``_high`` out of range; none where no range is stated)
        self._low, self._high = (np.ascontiguousarray(v) for v in range_limits(rule.range_mps2, len(rule.columns)))
        self._sensors = np.ascontiguousarray(np.asarray(rule.sensor_of_axis, dtype=np.int64))
        self._min_repeats = stuck_min_samples(rule.rate_hz) - 1  # (a run of one value this long may be stuck)
        self._decision = None  # the compiled decision, imported at its first use
        self._times: list[int] = []
        # the buffer's readings, rows [0, len(self._times)) of an array that grows as needed (one copy of the
        # rows kept per block, not a stack of rows per decision)
        self._accel = np.empty((2 * (rule.delay + rule.block) + rule.history + 8, len(rule.columns)))
        self._gyro: list = []
        self._first = 0  # stream index of the buffer's first row
        self._next = 0  # stream index of the first undecided row
        self._counts = dict.fromkeys(KINDS, 0)
        self._replaced: dict[int, np.ndarray] = {}
        self._spike_rows: dict[int, np.ndarray] = {}  # the spikes decided on rows still in the buffer (stream index)
        self._open: dict[tuple[str, int], int] = {}
        self._runs: list[tuple[str, int, int, int]] = []
        self.gyro_out_of_range = 0
        """Gyroscope readings read as NaN (beyond :data:`GYRO_OUT_OF_RANGE_RADPS`)."""

    @property
    def count(self) -> int:
        """Readings replaced so far."""
        return sum(self._counts.values())

    def push(self, timestamp_ns: int, accel_row, gyro_row=None) -> list[tuple]:
        n = len(self._times)
        self._room(n + 1, n)
        self._accel[n] = np.asarray(accel_row, dtype=float).reshape(-1)
        self._times.append(int(timestamp_ns))
        if gyro_row is not None:
            gyro_row = np.array(gyro_row, dtype=float).reshape(-1)
            with np.errstate(invalid="ignore"):
                huge = np.abs(gyro_row) > GYRO_OUT_OF_RANGE_RADPS
            if huge.any():
                self.gyro_out_of_range += int(huge.sum())
                gyro_row = np.where(huge, np.nan, gyro_row)
        self._gyro.append(gyro_row)
        newest = self._first + len(self._times)
        rule = self.rule
        ready = newest - rule.delay
        if ready - self._next >= rule.block and len(self._times) >= 2 * SCALE_HALF_WIDTH + 1:
            return self._decide(ready)
        return []

    def extend(self, timestamps_ns, accel, gyro=None) -> list[tuple]:
        """:meth:`push` of the rows of ``accel`` (and of ``gyro``, or None) in turn, made a block at a time: the
        rows are added up to the next row at which a push would decide, and decided there, so the decisions,
        rows and counts are those of pushing them one by one (without a Python call per row)."""
        accel = np.asarray(accel, dtype=float)
        if gyro is not None:
            gyro = np.array(gyro, dtype=float)
            with np.errstate(invalid="ignore"):
                huge = np.abs(gyro) > GYRO_OUT_OF_RANGE_RADPS
            if huge.any():
                self.gyro_out_of_range += int(huge.sum())
                gyro[huge] = np.nan
        rule = self.rule
        out: list[tuple] = []
        i, total = 0, len(timestamps_ns)
        while i < total:
            n = len(self._times)
            newest = self._first + n
            if self.clean is not None and not self._open and n >= 2 * SCALE_HALF_WIDTH + 1:
                k = self._clean_reach(newest, total - i)
                if k > rule.block:
                    out.extend(self._pass_clean(timestamps_ns[i:i + k], accel[i:i + k],
                                                None if gyro is None else gyro[i:i + k]))
                    i += k
                    continue
            # a push decides once ``block`` rows wait past the delay and the buffer holds a scale window
            j = max(1, self._next + rule.block + rule.delay - newest, 2 * SCALE_HALF_WIDTH + 1 - n)
            j = min(j, total - i)
            self._room(n + j, n)
            self._accel[n:n + j] = accel[i:i + j]
            self._times.extend(int(t) for t in timestamps_ns[i:i + j])
            self._gyro.extend([None] * j if gyro is None else list(gyro[i:i + j]))
            i += j
            ready = newest + j - rule.delay
            if ready - self._next >= rule.block and n + j >= 2 * SCALE_HALF_WIDTH + 1:
                out.extend(self._decide(ready))
        return out

    def _room(self, size: int, kept: int) -> None:
        """The buffer's array made to hold ``size`` rows (at least doubled when it grows), its first ``kept``
        rows kept."""
        if size > self._accel.shape[0]:
            grown = np.empty((max(2 * self._accel.shape[0], size), self._accel.shape[1]))
            grown[:kept] = self._accel[:kept]
            self._accel = grown

    def _clean_reach(self, newest: int, most: int) -> int:
        """The most rows (up to ``most``) that can be added after row ``newest`` with the buffer, from its first
        row to the last added, known clean (:attr:`clean`: then every decision among them passes its rows)."""
        if not self.clean(self._first, newest + 1):
            return 0
        lo, hi = 0, most  # clean(first, newest + lo) holds; find the largest such lo
        while lo < hi:
            mid = (lo + hi + 1) // 2
            if self.clean(self._first, newest + mid):
                lo = mid
            else:
                hi = mid - 1
        return lo

    def _pass_clean(self, times_ns, accel, gyro) -> list[tuple]:
        """The rows given added where :meth:`_clean_reach` says every decision they bring passes its rows as they
        are: the decisions a push per row would make (one every ``block`` rows), made at once; the buffer left as
        those pushes would leave it."""
        rule = self.rule
        k = len(times_ns)
        n = len(self._times)
        newest = self._first + n
        steps = (newest + k - rule.delay - self._next) // rule.block
        upto = self._next + max(steps, 0) * rule.block
        out = []
        for g in range(self._next, upto):
            j = g - self._first
            if j < n:
                out.append((self._times[j], self._accel[j].copy(), self._gyro[j]))
            else:
                j -= n
                out.append((int(times_ns[j]), accel[j].copy(), None if gyro is None else gyro[j]))
        # the buffer: from the first row the history keeps behind ``upto`` to the newest row added
        first = max(self._first, upto - rule.history)
        keep_old = max(0, newest - first)
        new_from = max(0, first - newest)
        size = keep_old + k - new_from
        self._accel[:keep_old] = self._accel[n - keep_old:n]
        self._room(size, keep_old)
        self._accel[keep_old:size] = accel[new_from:]
        self._times = self._times[n - keep_old:] + [int(t) for t in times_ns[new_from:]]
        self._gyro = self._gyro[n - keep_old:] + ([None] * (k - new_from) if gyro is None else list(gyro[new_from:]))
        self._first = first
        self._next = max(self._next, upto)
        return out

    def flush(self) -> list[tuple]:
        """The rows still held, decided with the newest as the end of the stream."""
        out = self._decide(self._first + len(self._times))
        self._runs = self._runs_so_far()
        self._open.clear()
        return out

    def screening(self, n: int | None = None) -> Screening:
        """What was replaced among the first ``n`` rows (default: all decided), as :class:`Screening`."""
        n = self._next if n is None else n
        replaced = np.zeros((n, len(self.rule.columns)), bool)
        for row, mask in self._replaced.items():
            if row < n:
                replaced[row] = mask
        return Screening(replaced, *(self._counts[k] for k in KINDS), runs=tuple(self._runs_so_far()))

    def describe(self, limit: int = 5) -> str:
        """:meth:`Screening.describe` of what was replaced so far (rows counted from the first pushed)."""
        rows = sorted(self._replaced)
        mask = np.array([self._replaced[r] for r in rows]).reshape(len(rows), len(self.rule.columns))
        return Screening(mask, *(self._counts[k] for k in KINDS), runs=tuple(self._runs_so_far())).describe(
            self.rule.columns, limit, row_numbers=rows)

    def _runs_so_far(self) -> list[tuple[str, int, int, int]]:
        """The runs of clipped and stuck readings decided so far, those still open ending at the last decided
        row, in the order of :attr:`Screening.runs` (first row, then column)."""
        runs = self._runs + [(kind, col, start, self._next - 1) for (kind, col), start in self._open.items()]
        return sorted(runs, key=lambda r: (r[2], r[1]))

    def _decide(self, upto: int) -> list[tuple]:
        """Rows ``[self._next, upto)`` decided from the buffer, returned, and the buffer cut to the history."""
        if upto <= self._next:
            return []
        end = upto == self._first + len(self._times)  # flush: the newest row is the stream's last
        n = len(self._times)
        a, b = self._next - self._first, upto - self._first
        clean = self.clean is not None and self.clean(self._first, self._first + n)
        if clean and not self._open:
            # nothing to replace and no run to close: the rows pass as they came
            out = [(self._times[k], self._accel[k].copy(), self._gyro[k]) for k in range(a, b)]
            self._next = upto
            self._cut(upto)
            return out
        if clean:
            y = self._accel[:n].copy()
            kinds = {}  # (a kind not there: none of its faults)
        else:
            rule = self.rule
            known = np.zeros((n, len(rule.columns)), bool)
            for row, mask in self._spike_rows.items():
                if row >= self._first:
                    known[row - self._first] = mask
            fast = False
            if self.compiled and not end:
                if self._decision is None:
                    from .screen_kernels import spike_decision

                    self._decision = spike_decision
                fast, y, spikes = self._decision(
                    self._accel[:n], self._low, self._high, self._min_repeats,
                    max(0, a - 2 * SPIKE_REACH), SPIKE_REACH, known, self._sensors, MEDIAN_HALF_WIDTH,
                    SCALE_HALF_WIDTH, SPIKE_SCALES, _WHITE_SECOND_DIFFERENCE, OUT_OF_ANY_RANGE_MPS2, self._first == 0,
                    a, b)
                if fast:
                    kinds = {"spikes": spikes}
            if not fast:
                y, kinds, _ = _screen(self._accel[:n], rule.range_mps2, rule.sensor_of_axis, rule.rate_hz,
                                      rule.structure_matrix, ends=(self._first == 0, end), decide_from=a,
                                      known_spikes=known)
            for k in np.nonzero(kinds["spikes"][a:b].any(axis=1))[0]:
                self._spike_rows[self._next + int(k)] = kinds["spikes"][a + k]
        # each reading handed out an array of its own: one kept downstream holds its row, not the buffer
        out = [(self._times[k], y[k].copy(), self._gyro[k]) for k in range(a, b)]
        replaced = np.zeros((b - a, y.shape[1]), bool)
        for kind in KINDS:
            if kind not in kinds:
                if kind in ("clipped", "stuck") and any(k == kind for k, _ in self._open):  # its open runs end
                    self._track_runs(kind, np.zeros((b - a, y.shape[1]), bool))
                continue
            mask = kinds[kind][a:b]
            self._counts[kind] += int(mask.sum())
            replaced |= mask
            if kind in ("clipped", "stuck"):
                self._track_runs(kind, mask)
        for k in np.nonzero(replaced.any(axis=1))[0]:
            self._replaced[self._next + int(k)] = replaced[k]
        self._next = upto
        self._cut(upto)
        return out

    def _cut(self, upto: int) -> None:
        """The buffer cut to the history kept behind row ``upto``."""
        cut = max(0, upto - self.rule.history - self._first)
        if cut:
            kept = len(self._times) - cut
            self._accel[:kept] = self._accel[cut:cut + kept]
            del self._times[:cut], self._gyro[:cut]
            self._first += cut
            for row in [r for r in self._spike_rows if r < self._first]:
                del self._spike_rows[row]

    def _track_runs(self, kind: str, mask: np.ndarray) -> None:
        """Runs of ``kind`` per column across blocks: those that end within ``mask`` (rows from ``self._next``)
        are kept, those reaching its end stay open."""
        busy = set(np.nonzero(mask.any(axis=0))[0].tolist()) | {c for k, c in self._open if k == kind}
        for col in sorted(busy):
            key = (kind, col)
            column = mask[:, col]
            if key in self._open and not column[0]:
                self._runs.append((kind, col, self._open.pop(key), self._next - 1))
            for a, b in runs_of(column):
                start = self._open.pop(key, self._next + a) if a == 0 else self._next + a
                if b == column.size:
                    self._open[key] = start
                else:
                    self._runs.append((kind, col, start, self._next + b - 1))


def screen_stream(log):
    """(log screened by :class:`StreamScreen` row by row, :class:`Screening`): what ``gfimu live`` makes of the
    log's rows; the log itself when nothing is replaced. As :func:`screen_log`, a column with no finite
    reading near its missing ones is refused."""
    rate_hz = log.rate_hz if len(log) > 1 else None
    # The rule on the whole log first: a block whose buffer, and the rule's reach around it, holds nothing the
    # whole-log rule replaces is passed as it is (the rule decides a reading from the readings within its reach,
    # which are those of the whole log there); the others are decided from their buffer as a stream decides them.
    _, whole = _screen(log.accel_mps2, log.array.range_per_axis_mps2, log.array.axis_owner, rate_hz,
                       log.array.structure_matrix())[:2]
    flagged = np.concatenate([[0], np.cumsum(np.logical_or.reduce([whole[k] for k in KINDS]).any(axis=1))])
    reach = stream_delay_samples(rate_hz) + stuck_min_samples(rate_hz) + MEDIAN_HALF_WIDTH

    def clean(first: int, stop: int) -> bool:
        return bool(flagged[min(stop + reach, len(log))] == flagged[max(first - reach, 0)])

    screen_ = StreamScreen(log.array, rate_hz, clean=clean)
    rows = screen_.extend(log.timestamps_ns, log.accel_mps2, log.gyro_b_radps)
    rows.extend(screen_.flush())
    result = screen_.screening(len(log))
    if screen_.gyro_out_of_range:
        log = _screen_gyro(log)
    if result.count == 0:
        return log, result
    accel = np.vstack([r[1] for r in rows])
    refuse_unreplaceable(log, accel)
    return log.replace(accel_mps2=accel), result
