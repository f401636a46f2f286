"""One log through one method: the library function behind ``gfimu estimate`` and ``gfimu batch``.

:func:`estimate_log` reads a log folder, screens its readings for gross errors
(:mod:`gfimu.readings`), applies a calibration, runs the method and returns an
:class:`EstimateRun` (the :class:`~gfimu.estimate.Estimate`, motion and report, and the log
it was made from); nothing is written here. :func:`score` gives the ω RMSE against the log's truth or
reference where it has one.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .estimate import Estimate, Report
from .motion import Motion


class MethodNotApplicable(InputError):
    """The method cannot run on this log's array (the message says why)."""


@dataclass(frozen=True)
class EstimateRun:
    """Outcome of :func:`estimate_log`: the log's :class:`~gfimu.estimate.Estimate` and the log it was
    made from."""

    log_dir: str
    estimate: Estimate
    """The motion and its :class:`~gfimu.estimate.Report` (the method's choices, the model check, the
    warnings, and the time of every step: reading, screening, calibrating, the method's own, the
    orientation)."""
    log: Any = field(repr=False, default=None)
    """The log as estimated (screened, calibrated)."""
    screening: Any = None
    """:class:`gfimu.readings.Screening` of the readings."""

    @property
    def motion(self) -> Motion:
        return self.estimate.motion

    @property
    def report(self) -> Report:
        return self.estimate.report

    @property
    def method(self) -> str:
        return self.estimate.report.method

    @property
    def samples(self) -> int:
        return len(self.estimate.motion)


def _readings_bytes(log_dir) -> int | None:
    """The size of ``log_dir``'s readings file (None where there is none to measure)."""
    try:
        return (Path(log_dir) / "imu.csv").stat().st_size
    except OSError:
        return None


def estimate_log(log_dir: str | Path, method: Any = "smoother", options: dict | None = None,
                 calibration: str | Path | None = None, progress: bool = False,
                 orientation: str = "none", truth: bool = True) -> EstimateRun:
    """Read ``log_dir``, screen and calibrate its readings, run ``method`` with ``options``; warnings
    (plausibility, replaced readings) go through :mod:`warnings`. ``method``: a method name (made
    with ``options`` by :func:`gfimu.methods.make_estimator`) or an estimator already made (then
    ``options`` stays None). ``truth=False``: the log's truth.csv and reference.csv are not read
    (nothing here needs them; :func:`score` does)."""
    from . import io as gio
    from .readings import screen_log
    from .io.array_toml import check_noise_weights

    if isinstance(method, str):
        from .methods import make_estimator

        est = make_estimator(method, **dict(options or {}))
    elif options:
        raise InputError("estimate_log: options go with a method name, not with an estimator already made")
    else:
        est = method
    if hasattr(est, "preload"):  # (the smoothers' compiled kernels, while the log is read)
        est.preload(_readings_bytes(log_dir))
    timings = {}
    t0 = time.perf_counter()
    log = gio.read_log(log_dir, truth=truth)
    _warn_dead(log)
    t1 = time.perf_counter()
    _check_stream_rate(log, est)
    check_noise_weights(log.array, f"{log_dir}/array.toml")  # before estimating, naming the sensor
    # the fixed-lag smoother screens as gfimu live does, row by row (gfimu.readings.StreamScreen)
    log, screening = getattr(est, "screen", screen_log)(log)
    _warn_replaced(log, screening)
    timings.update(read=t1 - t0, screen=time.perf_counter() - t1)
    if calibration:
        from .calibration import apply_calibration_file

        t0 = time.perf_counter()
        log = apply_calibration_file(log, calibration)
        timings["calibrate"] = time.perf_counter() - t0
    reason = est.applicable(log.array)
    if reason:
        raise MethodNotApplicable(f"method {est.method!r} cannot run on {log_dir}: {reason}")
    linear = log.array.readings == "linear_acceleration"
    if linear:
        _refuse_attitude(log_dir, est, orientation)
    estimate = est.estimate(log, progress=progress)
    timings.update(estimate.report.timings)
    motion = estimate.motion
    if linear and motion.specific_force_b_mps2 is not None:
        # the readings had gravity removed: what the method took for the specific force is the acceleration a
        sigma = dict(motion.sigma)
        if "specific_force_b_mps2" in sigma:
            sigma["accel_b_mps2"] = sigma.pop("specific_force_b_mps2")
        motion = motion.replace(accel_b_mps2=motion.specific_force_b_mps2, specific_force_b_mps2=None, sigma=sigma)
    if orientation != "none":
        from .estimators.gravity import add_orientation

        t0 = time.perf_counter()
        motion = add_orientation(log, motion, source=orientation)
        timings["orientation"] = time.perf_counter() - t0
    report = replace(estimate.report, timings=timings)
    return EstimateRun(str(log_dir), Estimate(motion, report), log, screening)


LINEAR_ACCELERATION_REFUSAL = (
    "its array.toml says readings = \"linear_acceleration\": the phone removed gravity from the readings, so "
    "there is no gravity left to find the attitude from and no specific force to remove it from; ω and the "
    "gravity-free acceleration a are estimated without it. For attitude, convert the export with its gravity "
    "(Sensor Logger's Gravity.csv beside Accelerometer.csv, or TotalAcceleration.csv; phyphox's Accelerometer.csv "
    "\"with g\")")


def _refuse_attitude(log_dir, est, orientation: str) -> None:
    """Attitude asked of a log whose readings are the linear acceleration: refused, saying why."""
    asked = [f"--orientation {orientation}"] if orientation != "none" else []
    asked += [f"-O {name}=True" for name in ("estimate_attitude", "use_inclinometer") if getattr(est, name, False) is True]
    if asked:
        raise InputError(f"{log_dir}: {' and '.join(asked)} refused: {LINEAR_ACCELERATION_REFUSAL}")


def screened(log):
    """``log`` with gross errors in its accelerometer readings (not finite, out of range, isolated
    spikes) replaced by the median of their neighbours (:func:`gfimu.readings.screen_log`), the
    replacements reported as a warning with counts and rows."""
    from .readings import screen_log

    clean, screening = screen_log(log)
    _warn_replaced(log, screening)
    return clean


def _warn_dead(log) -> None:
    """A warning line per kind of channel that measures nothing (dead, constant, placeholder values)."""
    from .readings import dead_channels, describe_dead_channels

    columns = log.array.accel_columns
    for line in describe_dead_channels(dead_channels(log.accel_mps2, columns), len(columns)):
        warnings.warn(f"{log.source}: {line}; the estimate from them is not a measurement", stacklevel=3)


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


def _check_stream_rate(log, est) -> None:
    """A streaming smoother sizes its windows in samples from the rate: a rate beyond any IMU's (timestamps 1 ns
    apart, read under the wrong unit) would ask for hundreds of millions of states. Refused, naming the file."""
    from .errors import DataError
    from .io.plausibility import MAX_RATE_HZ

    if getattr(est, "method", "") != "fixed-lag" or len(log) < 2:
        return
    rate = log.rate_hz
    if rate > MAX_RATE_HZ:
        raise DataError(f"{log.source}/imu.csv: the timestamps step by a median {1e9 / rate:.4g} ns, a rate of "
                        f"{rate:.4g} Hz, beyond any IMU's ({MAX_RATE_HZ:g} Hz at most); the fixed-lag smoother sizes "
                        "its window from the rate: check the unit of the timestamps")
