"""Live estimation: readings in as they come, estimates out as they leave the lag window.

:class:`LiveSession` wraps the fixed-lag smoother (:mod:`gfimu.smoother.fixed_lag`)
for a stream of imu.csv rows (text) or of decoded readings, and counts what
happens: samples in and out, rows that could not be read, samples the smoother
dropped for going back in time or repeating a timestamp and its clock resets
(time going back by more than its ``clock_reset_s``: the window restarts),
samples that never came, and the processing time of each sample. It formats estimate rows exactly as ``gfimu estimate`` writes
them, so a log fed row by row gives the file ``gfimu estimate --method
fixed-lag`` writes. No I/O here: the command (:mod:`gfimu.cli.live`) owns the
sockets, files and signals.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError

ESTIMATE_HEADER = ("#timestamp [ns],w_x [rad s^-1],w_y [rad s^-1],w_z [rad s^-1],dw_x [rad s^-2],dw_y [rad s^-2],"
                   "dw_z [rad s^-2],f_x [m s^-2],f_y [m s^-2],f_z [m s^-2]")
"""The columns of the estimate rows (those of ``gfimu estimate`` for ω, ω̇ and f)."""

_HEADER_RE = re.compile(r"^\s*(.*?)\s*\[([^\[\]]*)\]\s*$")


class LiveInputError(InputError):
    """A header or row that cannot be read (the message names it)."""


@dataclass
class LiveStats:
    """Counts and processing times of a session."""

    samples_in: int = 0
    samples_out: int = 0
    bad_rows: int = 0
    late_or_repeated: int = 0
    clock_resets: int = 0
    missing: int = 0
    """Samples that never arrived: gaps in time of more than 1.5 nominal steps."""
    overrun_dropped: int = 0
    processing_s: list = field(default_factory=list)

    def percentiles_ms(self) -> tuple[float, float, float]:
        """(p50, p99, max) processing time per sample [ms] (NaN before any sample)."""
        if not self.processing_s:
            return (float("nan"),) * 3
        p = np.asarray(self.processing_s) * 1e3
        return float(np.percentile(p, 50)), float(np.percentile(p, 99)), float(p.max())

    def summary(self) -> str:
        p50, p99, mx = self.percentiles_ms()
        return (f"{self.samples_in} samples in, {self.samples_out} estimates out; {self.bad_rows} bad rows, "
                f"{self.late_or_repeated} late or repeated, {self.missing} missing (gaps), {self.overrun_dropped} dropped (input faster than the "
                f"smoother), {self.clock_resets} clock resets; processing per sample p50 {p50:.3f} ms, "
                f"p99 {p99:.3f} ms, max {mx:.3f} ms")


def imu_row_parser(array, header: str):
    """A function turning one imu.csv data row (text) into ``(timestamp_ns, accel_row, gyro_row)`` for
    ``array``, given the imu.csv header line; columns may come in any order, units are converted
    (``[g]``, ``[deg s^-1]``, ``[ms]``…) or refused."""
    from .io.tables import imu_columns
    from .io.units import TIME_UNITS_NS, unit_factor

    names = [c.strip() for c in header.strip().lstrip("\ufeff").split(",")]
    parsed = []
    for i, text in enumerate(names):
        m = _HEADER_RE.match(text.lstrip("#"))
        if not m:
            raise LiveInputError(f"header column {i + 1} {text!r} has no [unit]")
        parsed.append((m.group(1).strip(), m.group(2).strip()))
    if not parsed or parsed[0][0] != "timestamp":
        raise LiveInputError("the header must start with '#timestamp [ns]' (as imu.csv)")
    time_unit = parsed[0][1]
    if time_unit not in TIME_UNITS_NS:
        raise LiveInputError(f"time unit [{time_unit}] not understood; use one of {', '.join(TIME_UNITS_NS)}")
    time_factor = TIME_UNITS_NS[time_unit]
    where = {name: (i, unit) for i, (name, unit) in enumerate(parsed)}
    index, factor = [], []
    for name, kind in imu_columns(array):
        if name not in where:
            raise LiveInputError(f"column '{name}' of the array is missing from the header")
        i, unit = where[name]
        try:
            factor.append(unit_factor(unit, kind))
        except ValueError as exc:
            raise LiveInputError(f"column '{name}': {exc}") from None
        index.append(i)
    index_a, factor_a = np.array(index), np.array(factor)
    n_acc = array.n_axes
    gyro = array.gyroscope is not None
    width = len(parsed)

    def parse(row: str):
        cells = row.strip().split(",")
        if len(cells) != width:
            raise LiveInputError(f"{len(cells)} values, expected {width}")
        try:
            t = int(cells[0]) if time_factor == 1 else int(round(float(cells[0]) * time_factor))
            values = np.array([float(cells[i]) for i in index_a]) * factor_a
        except ValueError as exc:
            raise LiveInputError(f"not a number ({exc})") from None
        if not np.all(np.isfinite(values)):
            raise LiveInputError("a value is not finite")
        return t, values[:n_acc], (values[n_acc:n_acc + 3] if gyro else None)

    return parse


def default_header(array) -> str:
    """The imu.csv header of ``array`` (the column order of rows that come without a header, e.g. UDP)."""
    from .io.tables import imu_columns

    unit = {"acceleration": "m s^-2", "angular_rate": "rad s^-1", "angle": "rad"}
    return ",".join(["#timestamp [ns]"] + [f"{name} [{unit[kind]}]" for name, kind in imu_columns(array)])


class LiveSession:
    """The fixed-lag smoother on a stream, with the counts of :class:`LiveStats`.

    ``estimator``: a :class:`gfimu.smoother.fixed_lag.FixedLagEstimator` (its options and lag);
    ``rate_hz``: the nominal rate (array.toml's ``rate_hz``) used to tell gaps.
    """

    def __init__(self, array, estimator, rate_hz: float):
        self.array = array
        self.estimator = estimator
        self.rate_hz = float(rate_hz)
        self.stats = LiveStats()
        self._smoother = estimator.smoother(array, self.rate_hz)
        self._last_t: int | None = None
        self._use_gyro = bool(estimator.use_gyro and array.gyroscope is not None)

    def push(self, timestamp_ns: int, accel_row, gyro_row=None) -> list[str]:
        """One sample in; the estimate rows that left the lag window (text, with newlines). Late,
        repeated and clock-reset samples are handled and counted by the smoother itself
        (:meth:`gfimu.smoother.fixed_lag.FixedLagSmoother.push`)."""
        self.stats.samples_in += 1
        t0 = time.perf_counter()
        update = self._smoother.push(int(timestamp_ns), np.asarray(accel_row, dtype=float),
                                     gyro_row if self._use_gyro else None)
        counts = self._smoother.counts
        self.stats.late_or_repeated = counts["duplicates"] + counts["out_of_order"]
        self.stats.clock_resets = counts["clock_resets"]
        if update.dropped is not None:
            return self._rows(update.smoothed)
        self.stats.processing_s.append(time.perf_counter() - t0)
        if len(self.stats.processing_s) > 200_000:  # bounded memory on long streams
            self.stats.processing_s = self.stats.processing_s[-100_000:]
        if self._last_t is not None and timestamp_ns > self._last_t:
            steps = (timestamp_ns - self._last_t) * 1e-9 * self.rate_hz
            if steps > 1.5:  # samples that never came (lost datagrams, a sensor pause)
                self.stats.missing += int(round(steps)) - 1
        self._last_t = timestamp_ns
        return self._rows(update.smoothed)

    def flush(self) -> list[str]:
        """The rows still in the window (end of the stream)."""
        return self._rows(self._smoother.flush())

    def _rows(self, states) -> list[str]:
        rows = []
        for s in states:
            values = np.concatenate([s.omega_b_radps, s.omega_dot_b_radps2, s.specific_force_b_mps2])
            rows.append(f"{int(s.timestamp_ns)}," + ",".join(float.__repr__(float(v)) for v in values) + "\n")
        self.stats.samples_out += len(rows)
        return rows
