"""In-memory log: a sensor array and its synchronised readings (no I/O here)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .array import SensorArray
from .motion import Motion


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
            raise ValueError(f"{self.source}: timestamps not strictly increasing at sample {k}")
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
