"""One log through one method: the library function behind ``gfimu estimate`` and ``gfimu batch``.

:func:`estimate_log` reads a log folder, screens its readings for gross errors
(:mod:`gfimu.readings`), applies a calibration, runs the method and returns an
:class:`EstimateRun` (the estimate and what happened on the way); nothing is
written here. :func:`score` gives the ω RMSE against the log's truth or
reference where it has one.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .motion import Motion
from .errors import InputError


class MethodNotApplicable(InputError):
    """The method cannot run on this log's array (the message says why)."""


@dataclass(frozen=True)
class EstimateRun:
    """Outcome of :func:`estimate_log`."""

    log_dir: str
    method: str
    motion: Motion
    samples: int
    seconds: float
    """Wall time of the estimation itself [s]."""
    log: Any = field(repr=False, default=None)
    """The log as estimated (screened, calibrated)."""
    screening: Any = None
    """:class:`gfimu.readings.Screening` of the readings."""
    model_check: Any = None
    """The smoother's :class:`gfimu.smoother.auto.ModelCheck` (None for other methods)."""


def estimate_log(log_dir: str | Path, method: str = "smoother", options: dict | None = None,
                 calibration: str | Path | None = None, progress: bool = False,
                 orientation: str = "none", truth: bool = True) -> EstimateRun:
    """Read ``log_dir``, screen and calibrate its readings, run ``method`` with ``options``; warnings
    (plausibility, replaced readings) go through :mod:`warnings`. ``truth=False``: the log's truth.csv
    and reference.csv are not read (nothing here needs them; :func:`score` does)."""
    from . import io as gio
    from .methods import make_estimator
    from .readings import screen_log

    est = make_estimator(method, **dict(options or {}))
    log = gio.read_log(log_dir, truth=truth)
    log, screening = screen_log(log)
    _warn_replaced(log, screening)
    if calibration:
        from .calibration import apply_calibration_file

        log = apply_calibration_file(log, calibration)
    reason = est.applicable(log.array)
    if reason:
        raise MethodNotApplicable(f"method {method!r} cannot run on {log_dir}: {reason}")
    t0 = time.perf_counter()
    motion = est.estimate(log, progress=progress)
    seconds = time.perf_counter() - t0
    if orientation != "none":
        from .estimators.gravity import add_orientation

        motion = add_orientation(log, motion, source=orientation)
    return EstimateRun(str(log_dir), method, motion, len(motion), seconds, log, screening,
                       getattr(est, "last_model_check", None))


def screened(log):
    """``log`` with gross errors in its accelerometer readings (not finite, out of range, isolated
    spikes) replaced by the median of their neighbours (:func:`gfimu.readings.screen_log`), the
    replacements reported as a warning with counts and rows."""
    from .readings import screen_log

    clean, screening = screen_log(log)
    _warn_replaced(log, screening)
    return clean


def _warn_replaced(log, screening) -> None:
    if screening.count:
        warnings.warn(f"{log.source}: {screening.describe(log.array.accel_columns)}", stacklevel=3)


def score(run: EstimateRun) -> float | None:
    """ω RMSE of the error norm [rad/s] against the log's truth, else its reference (valid rows),
    or None when the log has neither."""
    log = run.log
    truth = log.truth if log.truth is not None else log.reference
    if truth is None or truth.omega_b_radps is None or run.motion.omega_b_radps is None:
        return None
    keep = np.ones(len(log), bool)
    if log.truth is None and log.invalid_reference is not None:
        keep &= ~log.invalid_reference
    err = run.motion.omega_b_radps[keep] - truth.omega_b_radps[keep]
    err = err[np.all(np.isfinite(err), axis=1)]
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) if len(err) else None
