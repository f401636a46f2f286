"""Screening of accelerometer readings for gross errors (pure maths, no I/O).

One corrupt cell — a non-finite value, a transmission error of 1e30, a 1000 m/s²
spike on one sensor — must not spoil the estimate around it. :func:`screen` finds
such readings channel by channel and replaces them by the median of their
neighbours in time, so every estimator (per-sample or smoother) reads a plausible
value there and the rest of the log is untouched:

- readings that are not finite;
- readings outside the sensor's range when the array states one;
- isolated spikes (a Hampel identifier with a local scale): the reading's
  distance from the median of the 5 samples centred on it exceeds
  :data:`SPIKE_SCALES` times the local noise scale, read from the second
  differences within ±:data:`SCALE_HALF_WIDTH` samples (leaving out those the
  sample itself touches), and no other accelerometer jumps at the same sample.
  Real motion, however fast, moves neighbouring samples together and is felt by
  every sensor; a spike stands alone.
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


@dataclass(frozen=True)
class Screening:
    """Readings found to be gross errors and replaced (:func:`screen`)."""

    replaced: np.ndarray
    """(N, n_axes) bool: the readings replaced."""
    non_finite: int
    out_of_range: int
    spikes: int

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
                                                         (self.spikes, "isolated spikes")) if n)
        return (f"{self.count} accelerometer reading(s) replaced by the median of their neighbours "
                f"({kinds}): {where}{more}")


def _rolling_median(x: np.ndarray, half: int) -> np.ndarray:
    """Median over ±``half`` samples per column, ignoring NaN (edges: the samples that exist)."""
    n = x.shape[0]
    pad = np.full((half, x.shape[1]), np.nan)
    padded = np.concatenate([pad, x, pad])
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1, axis=0)  # (n, cols, w)
    out = np.empty_like(x)
    step = 65536  # bounded memory on long logs
    for s in range(0, n, step):
        block = windows[s:s + step]
        with np.errstate(all="ignore"):
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                out[s:s + step] = np.nanmedian(block, axis=2)
    return out


def screen(accel_mps2: np.ndarray, range_mps2: np.ndarray | None = None,
           sensor_of_axis: np.ndarray | None = None) -> tuple[np.ndarray, Screening]:
    """(readings with gross errors replaced, :class:`Screening`) of ``accel_mps2`` (N, n_axes);
    ``range_mps2`` (n_axes,) the largest magnitude each axis can read (NaN or None: not stated);
    ``sensor_of_axis`` (n_axes,) the accelerometer each axis belongs to: a spike seen by two or more
    accelerometers at the same sample is a real event of the body (a knock), not a gross error."""
    y = np.array(accel_mps2, dtype=float)
    n = y.shape[0]
    bad_value = ~np.isfinite(y)
    out_range = np.zeros_like(bad_value)
    if range_mps2 is not None:
        limit = np.asarray(range_mps2, dtype=float)
        stated = np.isfinite(limit) & (limit > 0)
        with np.errstate(invalid="ignore"):
            out_range = ~bad_value & stated[None, :] & (np.abs(y) > 1.001 * np.where(stated, limit, np.inf)[None, :])
    work = np.where(bad_value | out_range, np.nan, y)
    spikes = np.zeros_like(bad_value)
    if n >= 2 * SCALE_HALF_WIDTH + 1:
        med = _rolling_median(work, MEDIAN_HALF_WIDTH)
        dev = np.abs(work - med)
        # local noise scale from the second differences around the sample, leaving out the three a
        # spike at k touches (k-1, k, k+1): mean |y[j+1] - 2 y[j] + y[j-1]| = σ √6 √(2/π) for white noise
        d2 = np.zeros_like(work)
        d2[1:-1] = np.abs(work[2:] - 2.0 * work[1:-1] + work[:-2])
        ok = np.isfinite(d2)
        d2 = np.where(ok, d2, 0.0)
        wide = np.ones(2 * SCALE_HALF_WIDTH + 1)
        near = np.ones(3)

        def window_sum(x, kernel):
            return np.apply_along_axis(lambda c: np.convolve(c, kernel, mode="same"), 0, x)

        total = window_sum(d2, wide) - window_sum(d2, near)
        number = window_sum(ok.astype(float), wide) - window_sum(ok.astype(float), near)
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
    replaced = bad_value | out_range | spikes
    if np.any(replaced):
        fill = _rolling_median(np.where(replaced, np.nan, y), MEDIAN_HALF_WIDTH)
        still_bad = replaced & ~np.isfinite(fill)
        if np.any(still_bad):  # a run of bad readings longer than the median window: nearest good value
            for c in np.nonzero(still_bad.any(axis=0))[0]:
                good = np.nonzero(~replaced[:, c])[0]
                if good.size:
                    idx = np.nonzero(still_bad[:, c])[0]
                    nearest = good[np.clip(np.searchsorted(good, idx), 0, good.size - 1)]
                    fill[idx, c] = y[nearest, c]
        y = np.where(replaced, fill, y)
    return y, Screening(replaced, int(bad_value.sum()), int(out_range.sum()), int(spikes.sum()))


def screen_log(log):
    """(log with gross errors replaced, :class:`Screening`); the log itself when none is found."""
    sensor_of_axis = np.concatenate([np.full(len(a.axes), i) for i, a in enumerate(log.array.accelerometers)])
    rng = getattr(log.array, "range_per_axis_mps2", None)
    accel, result = screen(log.accel_mps2, rng() if callable(rng) else rng, sensor_of_axis)
    if result.count == 0:
        return log, result
    return log.replace(accel_mps2=accel), result
