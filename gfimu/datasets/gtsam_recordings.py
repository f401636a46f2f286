"""Real IMU recordings shipped with the GTSAM 4.3 wheel (``<gtsam>/Data``).

* EuRoC MAV ``V1_01_easy`` (ETH ASL, Vicon room), first 30 s, 200 Hz:
  ``eqvio_processed_30s.csv``, the rows with ``row_type == imu``; columns
  ``t_rel`` (s), ``gx gy gz`` (rad/s), ``ax ay az`` (m/s², specific force).
* KITTI (car, ~470 s, 100 Hz): ``KittiEquivBiasedImu.txt``, whitespace
  separated with a header ``Time dt accelX accelY accelZ omegaX omegaY omegaZ``.
  Its first row stands alone about 1.9 s before the rest.

Both give the specific force (a still sensor reads +9.8 m/s² upward) and the
angular velocity in the IMU frame. :mod:`gfimu.simulate` uses them as real
motion profiles for synthetic array readings. Reading files is this module's
only job; no processing beyond parsing.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataError, InputError

EUROC_FILE = "eqvio_processed_30s.csv"
KITTI_FILE = "KittiEquivBiasedImu.txt"


@dataclass(frozen=True)
class RecordedImu:
    """One IMU recording: times (s, from its first sample), ω and specific force in the IMU frame."""

    name: str
    times_s: np.ndarray
    omega_radps: np.ndarray
    specific_force_mps2: np.ndarray
    source: str

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.times_s)))

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1] - self.times_s[0])

    def longest_segment(self, gap_factor: float = 5.0) -> "RecordedImu":
        """The longest run of samples without a step longer than ``gap_factor`` × the median step."""
        dt = np.diff(self.times_s)
        cuts = np.nonzero(dt > gap_factor * np.median(dt))[0] + 1
        bounds = np.concatenate([[0], cuts, [self.times_s.size]])
        k = int(np.argmax(np.diff(bounds)))
        sl = slice(int(bounds[k]), int(bounds[k + 1]))
        t = self.times_s[sl]
        return RecordedImu(self.name, t - t[0], self.omega_radps[sl], self.specific_force_mps2[sl], self.source)


def data_dir() -> Path:
    """The ``Data`` folder of the installed gtsam package."""
    try:
        import gtsam
    except ImportError as exc:  # pragma: no cover - gtsam is a dependency
        raise FileNotFoundError("the real-motion recordings come with the gtsam package (pip install gtsam==4.3.*), "
                                "which is not importable") from exc
    return Path(os.path.dirname(gtsam.__file__)) / "Data"


def _locate(path, default_name: str) -> Path:
    p = Path(path) if path is not None else data_dir() / default_name
    if not p.is_file():
        raise FileNotFoundError(
            f"recording {p} not found; it ships with the gtsam 4.3 wheel's Data folder "
            f"(pip install gtsam==4.3.*) or pass the file's path explicitly"
        )
    return p


def load_euroc(path: str | os.PathLike | None = None) -> RecordedImu:
    """EuRoC V1_01_easy IMU rows of ``eqvio_processed_30s.csv`` (200 Hz, 30 s)."""
    p = _locate(path, EUROC_FILE)
    with open(p, newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        need = ["row_type", "t_rel", "gx", "gy", "gz", "ax", "ay", "az"]
        if header is None or any(n not in header for n in need):
            raise InputError(f"{p}: header must contain {need}, got {header}")
        col = [header.index(n) for n in need[1:]]
        rows = []
        for line_no, row in enumerate(reader, start=2):
            if not row or row[0] != "imu":
                continue
            try:
                rows.append([float(row[c]) for c in col])
            except (ValueError, IndexError) as exc:
                raise InputError(f"{p}, line {line_no}: malformed imu row ({exc})") from None
    if len(rows) < 2:
        raise DataError(f"{p}: fewer than two imu rows")
    data = np.array(rows)
    t = data[:, 0]
    if np.any(np.diff(t) <= 0):
        raise InputError(f"{p}: imu times not strictly increasing at row {int(np.argmax(np.diff(t) <= 0)) + 1}")
    return RecordedImu("euroc-V1_01_easy", t - t[0], data[:, 1:4], data[:, 4:7], str(p))


def load_kitti(path: str | os.PathLike | None = None) -> RecordedImu:
    """KITTI IMU of ``KittiEquivBiasedImu.txt`` (100 Hz), all rows."""
    p = _locate(path, KITTI_FILE)
    with open(p) as fh:
        header = fh.readline().split()
    need = ["Time", "accelX", "accelY", "accelZ", "omegaX", "omegaY", "omegaZ"]
    if any(n not in header for n in need):
        raise InputError(f"{p}: header must contain {need}, got {header}")
    try:
        data = np.loadtxt(p, skiprows=1, ndmin=2)
    except ValueError as exc:
        raise InputError(f"{p}: malformed row ({exc})") from None
    if data.shape[1] != len(header):
        raise InputError(f"{p}: {data.shape[1]} columns per row, header has {len(header)}")
    idx = {n: header.index(n) for n in need}
    t = data[:, idx["Time"]]
    if np.any(np.diff(t) <= 0):
        raise InputError(f"{p}: times not strictly increasing at row {int(np.argmax(np.diff(t) <= 0)) + 2}")
    f = data[:, [idx["accelX"], idx["accelY"], idx["accelZ"]]]
    w = data[:, [idx["omegaX"], idx["omegaY"], idx["omegaZ"]]]
    return RecordedImu("kitti", t - t[0], w, f, str(p))


RECORDINGS = {"euroc": load_euroc, "kitti": load_kitti}
