"""In-memory log: a sensor array and its synchronised readings (no I/O here).

pandas bridge (``pip install 'gfimu[pandas]'``): :meth:`Log.to_dataframe` gives the readings as
``imu.csv`` holds them, one column per axis named as in its header without the unit
(``a1_x``, ``w_x``, ``tilt_x``), units in ``df.attrs["units"]``, indexed by the integer
timestamps in nanoseconds (index name ``timestamp_ns``: exact, unlike float seconds);
:meth:`Log.from_dataframe` reads such a frame back with its array.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .array import SensorArray
from .errors import InputError
from .motion import TIME_INDEX, Motion, _require_pandas, index_ns

GYRO_COLUMNS = ("w_x", "w_y", "w_z")
"""Columns of the gyroscope readings (in B) in ``imu.csv`` and in :meth:`Log.to_dataframe`."""
TILT_COLUMNS = ("tilt_x", "tilt_y")
"""Columns of the inclinometer readings."""
READING_UNITS = {"accel": "m s^-2", "gyro": "rad s^-1", "tilt": "rad"}


@dataclass(frozen=True)
class Gap:
    """A time gap between samples ``index - 1`` and ``index``."""

    index: int
    dt_s: float
    nominal_dt_s: float


@dataclass(frozen=True)
class Log:
    """Readings of one recording.

    ``accel_mps2`` has one column per accelerometer axis, in each sensor's own
    frame, ordered as ``array.accel_columns``. ``gyro_b_radps`` (N, 3) and
    ``tilt_rad`` (N, 2) are present when the array has those sensors.
    ``invalid_reference`` marks rows where the reference is not valid (for
    example a saturated gyro); evaluation leaves them out.
    """

    array: SensorArray
    timestamps_ns: np.ndarray
    accel_mps2: np.ndarray
    gyro_b_radps: np.ndarray | None = None
    tilt_rad: np.ndarray | None = None
    truth: Motion | None = None
    reference: Motion | None = None
    invalid_reference: np.ndarray | None = None
    source: str = "<memory>"

    def __post_init__(self) -> None:
        t = np.asarray(self.timestamps_ns, dtype=np.int64).reshape(-1)
        object.__setattr__(self, "timestamps_ns", t)
        acc = np.asarray(self.accel_mps2, dtype=float)
        if acc.shape != (t.size, self.array.n_axes):
            raise ValueError(f"{self.source}: accel_mps2 has shape {acc.shape}, expected {(t.size, self.array.n_axes)}")
        object.__setattr__(self, "accel_mps2", acc)
        if t.size > 1 and np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise InputError(f"{self.source}: timestamps not strictly increasing at sample {k}")
        for name, width in (("gyro_b_radps", 3), ("tilt_rad", 2)):
            v = getattr(self, name)
            if v is not None:
                v = np.asarray(v, dtype=float)
                if v.shape != (t.size, width):
                    raise ValueError(f"{self.source}: {name} has shape {v.shape}, expected {(t.size, width)}")
                object.__setattr__(self, name, v)

    def __len__(self) -> int:
        return int(self.timestamps_ns.size)

    @property
    def times_s(self) -> np.ndarray:
        return (self.timestamps_ns - self.timestamps_ns[0]) * 1e-9

    @property
    def dt_s(self) -> np.ndarray:
        """Step to each sample from the previous one, (N-1,)."""
        return np.diff(self.timestamps_ns) * 1e-9

    @property
    def nominal_dt_s(self) -> float:
        return float(np.median(self.dt_s)) if len(self) > 1 else float("nan")

    @property
    def rate_hz(self) -> float:
        return 1.0 / self.nominal_dt_s

    def gaps(self, factor: float = 1.5) -> list[Gap]:
        """Steps longer than ``factor`` times the median step."""
        if len(self) < 3:
            return []
        dt = self.dt_s
        nominal = float(np.median(dt))
        idx = np.nonzero(dt > factor * nominal)[0]
        return [Gap(int(i) + 1, float(dt[i]), nominal) for i in idx]

    def segments(self, factor: float = 1.5) -> list[slice]:
        """Contiguous runs of samples with no gap; integrators restart at each."""
        starts = [0] + [g.index for g in self.gaps(factor)]
        ends = starts[1:] + [len(self)]
        return [slice(s, e) for s, e in zip(starts, ends)]

    def select(self, index: slice) -> "Log":
        """A contiguous part of the log (slice)."""
        return replace(
            self,
            timestamps_ns=self.timestamps_ns[index],
            accel_mps2=self.accel_mps2[index],
            gyro_b_radps=None if self.gyro_b_radps is None else self.gyro_b_radps[index],
            tilt_rad=None if self.tilt_rad is None else self.tilt_rad[index],
            truth=None if self.truth is None else self.truth.select(index),
            reference=None if self.reference is None else self.reference.select(index),
            invalid_reference=None if self.invalid_reference is None else self.invalid_reference[index],
        )

    def replace(self, **changes) -> "Log":
        return replace(self, **changes)

    def reading_columns(self) -> list[tuple[str, str]]:
        """(name, unit) of every reading column, in ``imu.csv`` order: accelerometer axes, gyro, tilt."""
        cols = [(c, READING_UNITS["accel"]) for c in self.array.accel_columns]
        if self.gyro_b_radps is not None:
            cols += [(c, READING_UNITS["gyro"]) for c in GYRO_COLUMNS]
        if self.tilt_rad is not None:
            cols += [(c, READING_UNITS["tilt"]) for c in TILT_COLUMNS]
        return cols

    def to_dataframe(self):
        """The readings as a ``pandas.DataFrame``: index ``timestamp_ns`` (int64 nanoseconds), one float
        column per reading named as in ``imu.csv`` without its unit (``a1_x`` ..., ``w_x`` ..., ``tilt_x``
        ...), the units in ``df.attrs["units"]``. Truth and reference: ``log.truth.to_dataframe()``."""
        pd = _require_pandas("Log.to_dataframe")
        parts = [self.accel_mps2]
        if self.gyro_b_radps is not None:
            parts.append(self.gyro_b_radps)
        if self.tilt_rad is not None:
            parts.append(self.tilt_rad)
        cols = self.reading_columns()
        df = pd.DataFrame(np.hstack(parts), columns=[c for c, _ in cols],
                          index=pd.Index(self.timestamps_ns.copy(), name=TIME_INDEX))
        df.attrs["units"] = dict(cols)
        return df

    @classmethod
    def from_dataframe(cls, df, array: SensorArray, truth: Motion | None = None, reference: Motion | None = None,
                       source: str = "<dataframe>") -> "Log":
        """A log from readings in a ``pandas.DataFrame`` laid out as :meth:`to_dataframe` writes it: integer
        nanosecond index, the array's accelerometer columns (``<name>_<axis>`` in each sensor's frame, m/s²),
        ``w_x, w_y, w_z`` [rad/s] when the array has a gyroscope, ``tilt_x, tilt_y`` [rad] with an
        inclinometer; other columns are ignored. An :class:`~gfimu.errors.InputError` names a missing column or a bad index."""
        pd = _require_pandas("Log.from_dataframe")
        if not isinstance(df, pd.DataFrame):
            raise TypeError(f"{source}: expected a pandas.DataFrame, got {type(df).__name__}")
        t = _timestamps_from_index(df, source)
        names = list(array.accel_columns)
        if array.gyroscope is not None:
            names += list(GYRO_COLUMNS)
        if array.inclinometer is not None:
            names += list(TILT_COLUMNS)
        missing = [n for n in names if n not in df.columns]
        if missing:
            raise InputError(f"{source}: column {missing[0]!r} is missing ({len(missing)} of the {len(names)} "
                             f"reading columns of array {array.name!r}: {', '.join(names)})")
        values = df[names].to_numpy(dtype=float)
        n_acc = array.n_axes
        gyro = tilt = None
        k = n_acc
        if array.gyroscope is not None:
            gyro, k = values[:, k:k + 3], k + 3
        if array.inclinometer is not None:
            tilt = values[:, k:k + 2]
        return cls(array, t, values[:, :n_acc], gyro_b_radps=gyro, tilt_rad=tilt, truth=truth,
                   reference=reference, source=source)


def _timestamps_from_index(df, source: str) -> np.ndarray:
    """The integer nanoseconds of a frame's index (``timestamp_ns``, or a DatetimeIndex: ns since the epoch)."""
    return index_ns(df, source)
