"""Time bases shared by the readers: the nominal period of a stream, its gaps, and linear interpolation
that never crosses a gap.

One definition for every reader (``gfimu convert csv`` and ``gfimu convert rosbag``):

- the **nominal period** of a stream is the median of its time steps (integer nanoseconds, rounded);
  its nominal rate is 1e9 / that period [Hz];
- the nominal period of several streams together is the median of their nominal periods;
- a **gap** of a stream is a step longer than ``max_gap_periods`` times its nominal period
  (default :data:`MAX_GAP_PERIODS`); shorter steps, timing jitter included, are interpolated over,
  and no time of a target grid strictly inside a gap gets a value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GAP_FACTOR = 1.5
"""A step over 1.5 nominal periods is a break of a log's samples (:meth:`gfimu.log.Log.gaps`)."""
MAX_GAP_PERIODS = 3.0
"""Default of ``--max-gap-periods``: steps up to 3 periods (2 missing samples) are interpolated over."""


def nominal_period_ns(stamps_ns: np.ndarray) -> int:
    """The median step of sorted ``stamps_ns`` [ns], rounded to an integer (0 for fewer than two stamps)."""
    dt = np.diff(np.asarray(stamps_ns, dtype=np.int64))
    return int(round(float(np.median(dt)))) if dt.size else 0


def common_period_ns(periods_ns) -> int:
    """The nominal period of several streams: the median of their nominal periods [ns], rounded."""
    return int(round(float(np.median(np.asarray(periods_ns, dtype=float)))))


def nominal_rate_hz(stamps_ns: np.ndarray) -> float:
    """1e9 / the median step [Hz] (nan for fewer than two stamps)."""
    dt = np.diff(np.asarray(stamps_ns, dtype=np.int64))
    return 1e9 / float(np.median(dt)) if dt.size else float("nan")


@dataclass(frozen=True)
class Gaps:
    """Steps of one stream longer than ``max_gap_periods`` of its nominal period."""

    period_ns: int
    start_ns: np.ndarray  # stamp before each gap
    end_ns: np.ndarray  # stamp after each gap

    def __len__(self) -> int:
        return int(self.start_ns.size)


def find_gaps(stamps_ns: np.ndarray, max_gap_periods: float = MAX_GAP_PERIODS) -> Gaps:
    """The gaps of sorted, distinct ``stamps_ns``: steps over ``max_gap_periods`` × the nominal period."""
    t = np.asarray(stamps_ns, dtype=np.int64)
    period = nominal_period_ns(t)
    idx = np.nonzero(np.diff(t) > max_gap_periods * period)[0] if t.size > 1 else np.zeros(0, dtype=np.int64)
    return Gaps(period, t[idx], t[idx + 1])


def interpolate(stamps_ns: np.ndarray, values: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
    """``values`` (n, k) at sorted ``stamps_ns`` linearly interpolated at ``t_ns`` (inside the stamps' span).

    y(t) = y_j + (t - t_j) / (t_{j+1} - t_j) (y_{j+1} - y_j), the fraction from exact integer
    offsets; a time on a stamp gets that reading itself.
    """
    t = np.asarray(stamps_ns, dtype=np.int64)
    q = np.asarray(t_ns, dtype=np.int64)
    v = np.asarray(values, dtype=float).reshape(t.size, -1)
    if t.size == 1:
        return np.repeat(v, q.size, axis=0)
    j = np.clip(np.searchsorted(t, q, side="right") - 1, 0, t.size - 2)
    frac = (q - t[j]).astype(float) / (t[j + 1] - t[j]).astype(float)
    y = v[j] + frac[:, None] * (v[j + 1] - v[j])
    y[frac == 0.0] = v[j[frac == 0.0]]
    y[frac == 1.0] = v[j[frac == 1.0] + 1]
    return y


def uniform_grid(start_ns: int, end_ns: int, period_ns: int) -> np.ndarray:
    """start, start + period, ... up to ``end_ns`` (int64)."""
    return start_ns + period_ns * np.arange((end_ns - start_ns) // period_ns + 1, dtype=np.int64)
