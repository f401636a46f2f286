"""The recent samples a stream's model is chosen on: a ring of arrays, each sample with its per-sample ML row
once a choice has computed it.

:class:`History` keeps the newest ``capacity`` samples (timestamps, readings, gyro readings where there are)
as they come, and the ML row ``[ω, ω̇, f]`` of every sample a choice has estimated, so that each sample is
estimated once however many choices read it (:meth:`FixedLagSmoother._ml_motion
<gfimu.smoother.stream.fixed_lag.FixedLagSmoother._ml_motion>`). A choice reads a :class:`Stretch`: the
samples in order, copied (the stream goes on filling the ring meanwhile), the rows it computes written back
with :meth:`History.keep_rows`. Samples are numbered from the first ever appended (``total`` so far): a
choice's rows go back to the samples it read, wherever the ring has moved since.

A choice made in a process of its own (:mod:`.choice_worker`) keeps a history there: each request carries
the samples appended since the last (:meth:`History.since`), which that history takes in with
:meth:`History.extend`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ROW = 9
"""Values of an ML row: ω, ω̇, f."""


@dataclass
class Stretch:
    """Samples in time order: ``times_ns`` (n,), ``accel`` (n, axes), ``gyro`` (n, 3) or None (None when any
    sample has none), their ML ``rows`` (n, 9) where ``has_row`` (n,), and the number of the first sample
    (``first``, :class:`History`)."""

    times_ns: np.ndarray
    accel: np.ndarray
    gyro: np.ndarray | None
    rows: np.ndarray
    has_row: np.ndarray
    first: int = 0

    @classmethod
    def of_samples(cls, samples) -> Stretch:
        """A stretch of ``samples``, (t_ns, accel, gyro or None, ...) tuples, none with a row."""
        n = len(samples)
        times_ns = np.array([s[0] for s in samples], dtype=np.int64)
        accel = np.vstack([s[1] for s in samples])
        gyro = None if any(s[2] is None for s in samples) else np.vstack([s[2] for s in samples])
        return cls(times_ns, accel, gyro, np.zeros((n, ROW)), np.zeros(n, dtype=bool))

    def __len__(self) -> int:
        return len(self.times_ns)


class History:
    """The newest ``capacity`` samples of a stream with ``n_axes`` accelerometer axes (module docstring)."""

    def __init__(self, capacity: int, n_axes: int) -> None:
        self.capacity = int(capacity)
        self.times_ns = np.zeros(self.capacity, dtype=np.int64)
        self.accel = np.zeros((self.capacity, int(n_axes)))
        self.gyro = np.zeros((self.capacity, 3))
        self.has_gyro = np.zeros(self.capacity, dtype=bool)
        self.rows = np.zeros((self.capacity, ROW))
        self.has_row = np.zeros(self.capacity, dtype=bool)
        self.total = 0
        """Samples appended so far (the next one's number)."""
        self.sent = 0
        """The number of the first sample not yet sent to a choice's process (:meth:`since`)."""

    def __len__(self) -> int:
        return min(self.total, self.capacity)

    def append(self, t_ns: int, accel: np.ndarray, gyro: np.ndarray | None) -> None:
        i = self.total % self.capacity
        self.times_ns[i] = t_ns
        self.accel[i] = accel
        if gyro is None:
            self.has_gyro[i] = False
        else:
            self.gyro[i] = gyro
            self.has_gyro[i] = True
        self.has_row[i] = False
        self.total += 1

    def _order(self, first: int) -> np.ndarray:
        """The ring's slots of samples ``first …`` (at most the ones it holds), oldest first."""
        first = max(first, self.total - self.capacity)
        return np.arange(first, self.total) % self.capacity

    def newest_accel(self, n: int) -> np.ndarray:
        """The readings of the newest ``n`` samples held (fewer when it holds fewer), oldest first (a copy)."""
        return self.accel[self._order(self.total - int(n))]

    def stretch(self) -> Stretch:
        """Every sample held, oldest first, copied."""
        slots = self._order(0)
        gyro = self.gyro[slots] if bool(np.all(self.has_gyro[slots])) else None
        return Stretch(self.times_ns[slots], self.accel[slots], gyro, self.rows[slots], self.has_row[slots],
                       self.total - len(slots))

    def keep_rows(self, stretch: Stretch) -> None:
        """The rows of ``stretch`` (read from this history, maybe since moved on) kept for its samples still held."""
        numbers = stretch.first + np.arange(len(stretch))
        held = stretch.has_row & (numbers >= self.total - self.capacity) & (numbers < self.total)
        slots = numbers[held] % self.capacity
        self.rows[slots] = stretch.rows[held]
        self.has_row[slots] = True

    def since(self) -> tuple:
        """The samples appended since the last call (at most those held), to send to a choice's process:
        (number of the first, timestamps, readings, gyro readings, which have gyro readings)."""
        slots = self._order(self.sent)
        first = self.total - len(slots)
        self.sent = self.total
        return first, self.times_ns[slots], self.accel[slots], self.gyro[slots], self.has_gyro[slots]

    def ahead(self, times_ns, accel, gyro, has_gyro) -> tuple:
        """Samples that will be appended next (``times_ns`` (n,), ``accel`` (n, axes), ``gyro`` (n, 3), ``has_gyro``
        (n,)) in the form :meth:`since` will give them once they are: the newest ``capacity`` at most, numbered
        on from the samples appended so far."""
        n = len(times_ns)
        keep = min(n, self.capacity)
        cut = slice(n - keep, n)
        return (self.total + n - keep, np.array(times_ns[cut], dtype=np.int64), np.array(accel[cut], dtype=float),
                np.array(gyro[cut], dtype=float), np.array(has_gyro[cut], dtype=bool))

    def copy(self) -> History:
        """A history of its own with the same samples and rows."""
        other = History.__new__(History)
        other.__dict__.update({k: v.copy() if isinstance(v, np.ndarray) else v for k, v in self.__dict__.items()})
        return other

    def extend(self, first: int, times_ns, accel, gyro, has_gyro) -> None:
        """Samples ``first …`` of another history (:meth:`since`) appended, those held already skipped. Samples
        before ``first`` this history has not seen are not held by the other either (it sends the last
        ``capacity`` at most): the numbering jumps over them."""
        skip = max(0, self.total - first)
        n = len(times_ns) - skip
        if n <= 0:
            return
        self.total = max(self.total, first)
        if n > self.capacity:  # (only the newest are held)
            skip, self.total, n = skip + n - self.capacity, self.total + n - self.capacity, self.capacity
        slots = (self.total + np.arange(n)) % self.capacity
        self.times_ns[slots] = times_ns[skip:]
        self.accel[slots] = accel[skip:]
        self.gyro[slots] = gyro[skip:]
        self.has_gyro[slots] = has_gyro[skip:]
        self.has_row[slots] = False
        self.total += n


def same_samples(a: tuple, b: tuple) -> bool:
    """Whether two sets of samples in the form of :meth:`History.since` are the same, number for number and
    bit for bit (a gyro reading compared only where there is one)."""
    if a[0] != b[0] or len(a[1]) != len(b[1]):
        return False
    if not np.array_equal(a[4], b[4]):
        return False
    bits = [(np.ascontiguousarray(x).tobytes(), np.ascontiguousarray(y).tobytes())
            for x, y in ((a[1], b[1]), (a[2], b[2]), (a[3][a[4]], b[3][b[4]]))]
    return all(x == y for x, y in bits)
