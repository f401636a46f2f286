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
least-squares fit of the 12 unknowns [f, ω̇, q(ω)], paper 000 eq. 6) when the
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

    def describe(self, columns: list[str] | tuple[str, ...], limit: int = 5) -> str:
        """One line: counts by kind and the first rows and columns."""
        rows, cols = np.nonzero(self.replaced)
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
    import warnings

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
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out[r, c] = np.nanmedian(windows[r, c], axis=1)
    return out


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


def clipped_readings(accel_mps2: np.ndarray, range_mps2) -> np.ndarray:
    """(N, n_axes) readings within :data:`CLIP_TOLERANCE` of the stated range (NaN: none stated) or beyond it."""
    y = np.asarray(accel_mps2, dtype=float)
    limit = np.broadcast_to(np.asarray(range_mps2, dtype=float), (y.shape[1],))
    stated = np.isfinite(limit) & (limit > 0)
    with np.errstate(invalid="ignore"):
        return np.isfinite(y) & stated[None, :] & (np.abs(y) >= (1 - CLIP_TOLERANCE) * np.where(stated, limit, np.inf))


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
    min_len = STUCK_MIN_SAMPLES
    if rate_hz is not None and np.isfinite(rate_hz) and rate_hz > 0:
        min_len = max(min_len, int(round(STUCK_MIN_S * rate_hz)))
    out = []
    for c in range(m):
        same = np.zeros(n, bool)
        same[1:] = (y[1:, c] == y[:-1, c]) & np.isfinite(y[1:, c])
        if exclude is not None:
            same[1:] &= ~exclude[1:, c] & ~exclude[:-1, c]
        if np.count_nonzero(same) < min_len - 1:
            continue
        others = np.delete(changed, c, axis=1)
        for a, b in runs_of(same):
            start = a - 1  # the first sample holding the repeated value
            if b - start >= min_len and np.median(np.mean(others[a:b], axis=0)) >= 0.5:
                out.append((c, start, b))
    return out


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


def screen(accel_mps2: np.ndarray, range_mps2: np.ndarray | None = None,
           sensor_of_axis: np.ndarray | None = None, rate_hz: float | None = None,
           structure_matrix: np.ndarray | None = None) -> tuple[np.ndarray, Screening]:
    """(readings with gross errors replaced, :class:`Screening`) of ``accel_mps2`` (N, n_axes);
    ``range_mps2`` (n_axes,) the largest magnitude each axis can read (NaN or None: not stated);
    ``sensor_of_axis`` (n_axes,) the accelerometer each axis belongs to: a spike seen by two or more
    accelerometers at the same sample is a real event of the body (a knock), not a gross error;
    ``rate_hz`` the sample rate (for the shortest stuck run); ``structure_matrix`` (n_axes, 12) the array's S,
    to replace clipped and stuck readings by the other axes' rigid-body prediction."""
    y = np.array(accel_mps2, dtype=float)
    n = y.shape[0]
    bad_value = ~np.isfinite(y)
    with np.errstate(invalid="ignore"):
        out_range = ~bad_value & (np.abs(y) > OUT_OF_ANY_RANGE_MPS2)
    clipped = np.zeros_like(bad_value)
    if range_mps2 is not None:
        limit = np.asarray(range_mps2, dtype=float)
        stated = np.isfinite(limit) & (limit > 0)
        with np.errstate(invalid="ignore"):
            out_range |= ~bad_value & stated[None, :] & (
                np.abs(y) > (1 + CLIP_TOLERANCE) * np.where(stated, limit, np.inf)[None, :])
        clipped = clipped_readings(y, limit) & ~out_range
    stuck = np.zeros_like(bad_value)
    runs = []
    for c, a, b in stuck_runs(y, rate_hz, exclude=bad_value | out_range | clipped):
        stuck[a:b, c] = True
        runs.append(("stuck", c, a, b - 1))
    for c in np.nonzero(clipped.any(axis=0))[0]:
        runs += [("clipped", int(c), a, b - 1) for a, b in runs_of(clipped[:, c])]
    runs.sort(key=lambda r: (r[2], r[1]))
    long_bad = clipped | stuck
    work = np.where(bad_value | out_range | long_bad, np.nan, y)
    spikes = np.zeros_like(bad_value)
    if n >= 2 * SCALE_HALF_WIDTH + 1:
        med = _rolling_median(work, MEDIAN_HALF_WIDTH)
        # the first and last rows have a median window cut short, whose median lags a ramp: there, a
        # robust line through the 2 h + 1 end rows instead (a spike at an end row still stands out of it)
        h, m = MEDIAN_HALF_WIDTH, 2 * MEDIAN_HALF_WIDTH + 1
        first, last = _edge_line(work[:m])[:h], _edge_line(work[n - m:])[m - h:]
        med[:h] = np.where(np.isfinite(first), first, med[:h])
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
        local = total / np.maximum(number, 1.0) / (np.sqrt(6.0) * np.sqrt(2.0 / np.pi))
        # constant (quantised, still) channels have no local scale: a floor at 1e-6 of the typical magnitude
        floor = 1e-6 * max(float(np.nanmedian(np.abs(work))) if np.any(np.isfinite(work)) else 1.0, 1.0)
        spikes = np.isfinite(dev) & (dev > SPIKE_SCALES * np.maximum(local, floor))
        if sensor_of_axis is not None and np.any(spikes):
            sensors = np.asarray(sensor_of_axis)
            rows = np.nonzero(spikes.any(axis=1))[0]
            for r in rows:
                if np.unique(sensors[spikes[r]]).size > 1:
                    spikes[r] = False
    spikes &= ~long_bad
    short = bad_value | out_range | spikes
    replaced = short | long_bad
    if np.any(long_bad):
        raw = y
        y = np.where(short, np.nan, y)  # the short ones are filled below, from good readings only
        done = _rigid_body_fill(y, long_bad, structure_matrix)
        _line_fill(y, long_bad & ~done)
        y = np.where(short, raw, y)
    if np.any(short):
        fill = _rolling_median(np.where(replaced, np.nan, y), MEDIAN_HALF_WIDTH)
        still_bad = replaced & ~np.isfinite(fill)
        if np.any(still_bad):  # a run of bad readings longer than the median window: nearest good value
            for c in np.nonzero(still_bad.any(axis=0))[0]:
                good = np.nonzero(~replaced[:, c])[0]
                if good.size:
                    idx = np.nonzero(still_bad[:, c])[0]
                    nearest = good[np.clip(np.searchsorted(good, idx), 0, good.size - 1)]
                    fill[idx, c] = y[nearest, c]
        y = np.where(short, fill, y)
    return y, Screening(replaced, int(bad_value.sum()), int(out_range.sum()), int(spikes.sum()), int(clipped.sum()),
                        int(stuck.sum()), tuple(runs))


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
