"""Whole logs: a folder with ``array.toml`` and ``imu.csv``, optionally ``truth.csv`` and ``reference.csv``.

The format is specified in ``docs/log-format.md``. :func:`read_log` reads
and checks a folder; gaps in time are reported with a
:class:`~gfimu.io.errors.LogGapWarning` (estimators restart at each gap, see
:meth:`gfimu.log.Log.segments`). :func:`write_log` writes the folder
whole or not at all.
"""

from __future__ import annotations

import errno
import os
import warnings
from pathlib import Path

import numpy as np

from ..log import Log
from ..motion import Motion
from . import plausibility
from .array_toml import load_array_toml, write_array_toml
from .atomic import atomic_folder
from .errors import LogFormatError, LogGapWarning, LogPlausibilityWarning
from .tables import read_imu_table, read_motion_csv, read_motion_table, write_imu_csv, write_motion_csv

LOG_FILES = ("array.toml", "imu.csv", "truth.csv", "reference.csv")
"""The files of a log folder, in the order they are written."""


def _log_folder(path: str | os.PathLike) -> Path:
    p = Path(path)
    try:
        os.stat(p)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise LogFormatError("a loop of symbolic links (too many levels of links); not a log folder", p) from None
    if p.is_file() and p.name in ("imu.csv", "array.toml"):
        p = p.parent
    if not p.exists():
        raise LogFormatError("log folder not found", p)
    if not p.is_dir():
        raise LogFormatError("not a log folder (expected a folder holding array.toml and imu.csv)", p)
    for name in ("array.toml", "imu.csv"):
        if not (p / name).is_file():
            raise LogFormatError(f"log folder has no {name} (a log holds array.toml and imu.csv)", p)
    return p


def _check_same_timestamps(motion: Motion, t_imu: np.ndarray, path: Path, imu_path: Path) -> None:
    if len(motion) != t_imu.size:
        raise LogFormatError(f"has {len(motion)} rows but {imu_path.name} has {t_imu.size}; it needs one row per "
                             f"{imu_path.name} row, with the same timestamps", path)
    diff = np.flatnonzero(motion.timestamps_ns != t_imu)
    if diff.size:
        r = int(diff[0])
        raise LogFormatError(f"timestamp {motion.timestamps_ns[r]} differs from {imu_path.name} line {r + 2} "
                             f"({t_imu[r]}); it needs the same timestamps as {imu_path.name}", path, r + 2)


def read_log(path: str | os.PathLike, check: bool = True, truth: bool = True) -> Log:
    """Read a log folder (array.toml, imu.csv, and truth.csv / reference.csv when present; with
    ``truth=False`` neither truth.csv nor reference.csv is read, for work that never looks at them,
    such as estimating).

    Gaps in time are reported with a :class:`LogGapWarning`; with ``check``,
    implausible values (a sample rate that disagrees with ``rate_hz``,
    timestamps in another unit than their header says, positions in mm,
    readings in g or mg, NaN readings) with a
    :class:`~gfimu.io.errors.LogPlausibilityWarning` each (see
    :mod:`gfimu.io.plausibility`).
    """
    folder = _log_folder(path)
    array_path = folder / "array.toml"
    imu_path = folder / "imu.csv"
    array, declared_rate_hz = load_array_toml(array_path)
    t, accel, gyro, tilt, time_unit, accel_unit = read_imu_table(imu_path, array, array_path.name)
    read_truth = truth
    truth = reference = invalid = None
    if read_truth and (folder / "truth.csv").is_file():
        truth = read_motion_csv(folder / "truth.csv")
        _check_same_timestamps(truth, t, folder / "truth.csv", imu_path)
    if read_truth and (folder / "reference.csv").is_file():
        reference, valid = read_motion_table(folder / "reference.csv")
        _check_same_timestamps(reference, t, folder / "reference.csv", imu_path)
        if valid is not None:
            invalid = ~valid
        if not reference.available():
            reference = None
    log = Log(array, t, accel, gyro, tilt, truth, reference, invalid, source=str(folder))
    gaps = log.gaps()
    if gaps:
        worst = max(gaps, key=lambda g: g.dt_s)
        warnings.warn(
            f"{imu_path}: {len(gaps)} gap(s) in time (steps over 1.5 x the median {worst.nominal_dt_s:.6g} s); the "
            f"largest, {worst.dt_s:.6g} s, is before line {worst.index + 2}; estimators restart at each gap",
            LogGapWarning, stacklevel=2)
    if check:
        found = (plausibility.check_rate(t, declared_rate_hz, time_unit, str(imu_path), str(array_path))
                 + plausibility.check_geometry(array, str(array_path))
                 + plausibility.check_finite(log, str(imu_path))
                 + (plausibility.check_gravity(log, str(imu_path), accel_unit or "m s^-2")
                    if array.readings == "specific_force" else []))
        for message in found:
            warnings.warn(message, LogPlausibilityWarning, stacklevel=2)
    return log


def write_log(log: Log, path: str | os.PathLike, rate_hz: float | None = None, what: str = "") -> None:
    """Write a log folder: array.toml (with ``rate_hz`` when given), imu.csv, and truth.csv /
    reference.csv when present.

    The folder is written whole or not at all (:func:`gfimu.io.atomic.atomic_folder`):
    the new log goes into a temporary folder next to it, which then replaces
    the old folder in one rename. An interruption (SIGINT, SIGTERM) or a
    failure (a full disk) leaves the old folder exactly as it was. The log
    files of an earlier log (:data:`LOG_FILES`) are not carried over, so the
    folder holds exactly this log; its other files are kept. ``path`` must
    not be a symbolic link, nor exist as anything but a folder; nothing in
    the old folder is followed or written through. The folder (and the
    folders above it) is created when needed. ``what`` (an option name)
    starts the message of a refusal.
    """
    folder = Path(path)
    truth = log.truth
    reference = valid = None
    if truth is not None:
        _check_same_timestamps(truth, log.timestamps_ns, folder / "truth.csv", folder / "imu.csv")
    if log.reference is not None or log.invalid_reference is not None:
        reference = log.reference if log.reference is not None else Motion(log.timestamps_ns)
        _check_same_timestamps(reference, log.timestamps_ns, folder / "reference.csv", folder / "imu.csv")
        valid = None if log.invalid_reference is None else ~np.asarray(log.invalid_reference, dtype=bool)
    with atomic_folder(folder, replaced=LOG_FILES, what=what) as new:
        write_array_toml(log.array, new / "array.toml", rate_hz)
        write_imu_csv(log, new / "imu.csv")
        if truth is not None:
            write_motion_csv(truth, new / "truth.csv")
        if reference is not None:
            write_motion_csv(reference, new / "reference.csv", valid=valid)
