"""Simulated logs: exact rigid-body motion, synthetic array readings, truth.

>>> from gfimu.simulate import simulate, SensorErrors
>>> log = simulate("random3d", duration_s=2.0, noise=SensorErrors.none())
>>> log.truth.available()  # doctest: +NORMALIZE_WHITESPACE
['omega_b_radps', 'omega_dot_b_radps2', 'accel_b_mps2', 'specific_force_b_mps2', 'quaternion_wb']

Each accelerometer axis reads the exact specific force at its position,
``f + ω̇ × r + ω × (ω × r)`` (Ho & Lin 2009, eq. 1), along its own axis, plus the
errors of :class:`SensorErrors`. The ``euroc`` and ``kitti`` scenarios replay
real recorded motions (shipped with GTSAM) through any array: real motion,
synthetic readings.
"""

from __future__ import annotations

import sys
from types import ModuleType

import numpy as np

from ..array import SensorArray
from ..errors import InputError
from ..log import Log
from ..motion import Motion
from ..progress import progress as _progress
from .scenarios import SCENARIOS, Scenario
from .sensor_errors import SensorErrors
from .trajectory import BodyKinematics, tilt_angles_rad
from ..datasets.gtsam_recordings import RECORDINGS

__all__ = ["simulate", "SCENARIOS", "Scenario", "SensorErrors", "BodyKinematics", "motion_from_truth",
           "sample_timestamps_ns"]

_CHUNK = 20_000


def sample_timestamps_ns(rate_hz: float, duration_s: float) -> np.ndarray:
    """``round(duration × rate)`` timestamps in ns from 0, at ``round(k · 1e9 / rate)``."""
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"rate_hz must be a positive number, got {rate_hz!r}")
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise InputError(f"duration_s must be a positive number, got {duration_s!r}")
    n = int(round(duration_s * rate_hz))
    if n < 2:
        raise InputError(f"a duration of {duration_s:g} s at {rate_hz:g} Hz gives {n} sample(s); need at least 2")
    t = np.round(np.arange(n) * (1e9 / rate_hz)).astype(np.int64)
    if np.any(np.diff(t) <= 0):
        raise InputError(f"a rate of {rate_hz:g} Hz is too high for nanosecond timestamps")
    return t


def motion_from_truth(timestamps_ns, kinematics: BodyKinematics) -> Motion:
    """The truth :class:`Motion` (ω, ω̇, a, f, q) of sampled body kinematics."""
    return Motion(
        timestamps_ns,
        omega_b_radps=kinematics.omega_b_radps,
        omega_dot_b_radps2=kinematics.omega_dot_b_radps2,
        accel_b_mps2=kinematics.accel_b_mps2,
        specific_force_b_mps2=kinematics.specific_force_b_mps2,
        quaternion_wb=kinematics.quaternion_wb,
    )


def _check_scenario_option(scenario: str, name: str, value, default) -> None:
    """An :class:`~gfimu.errors.InputError` naming the option unless ``value`` has the kind of its default:
    a finite number (an integer where the default is one), or as many finite numbers as a tuple default."""
    def number(v) -> bool:
        return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and bool(np.isfinite(v))

    if isinstance(default, (int, np.integer)) and not isinstance(default, bool):
        if not (number(value) and float(value).is_integer()):
            raise InputError(f"scenario {scenario!r} option {name}: expected an integer, got {value!r}")
    elif isinstance(default, (float, np.floating)):
        if not number(value):
            raise InputError(f"scenario {scenario!r} option {name}: expected a finite number, got {value!r}")
    elif isinstance(default, tuple):
        if not (isinstance(value, (tuple, list)) and len(value) == len(default) and all(number(v) for v in value)):
            raise InputError(f"scenario {scenario!r} option {name}: expected {len(default)} finite numbers, got {value!r}")


def simulate(
    scenario: str,
    array: SensorArray | None = None,
    rate_hz: float | None = None,
    duration_s: float | None = None,
    noise: SensorErrors | None = None,
    seed: int = 0,
    progress: bool = False,
    **scenario_options,
) -> Log:
    """Simulate ``scenario`` seen by ``array``; returns a :class:`Log` with ``truth``.

    ``array`` defaults to the scenario's (the 5 cm cube of four triads, or
    McGinnis, Perkins & King 2012's single triad on the block for the free-flight scenarios, which
    also give the log's array the block's :class:`~gfimu.array.Body`).
    ``rate_hz`` and ``duration_s`` default to the scenario's (500 Hz and 10 s
    for random3d and reversal; see :data:`SCENARIOS`). ``noise=None`` applies
    the default :class:`SensorErrors` (white noise from the array's
    ``noise_std_mps2``), ``SensorErrors.none()`` gives exact readings; an
    explicit positive noise level in ``noise`` is also written into the log's
    array (so array.toml states the noise actually applied). The
    motion and the sensor errors use independent streams derived from
    ``seed``, so changing the noise leaves the motion unchanged.
    ``scenario_options`` are the keyword options of the scenario's function
    (``Scenario.options()``). A gyroscope reads the true ω, an inclinometer
    the true tilt of the attitude (an ideal attitude sensor, undisturbed by
    acceleration), each plus its noise. ``progress`` shows a bar for long logs.
    """
    if scenario not in SCENARIOS:
        raise InputError(f"unknown scenario {scenario!r}; choose from {', '.join(SCENARIOS)}")
    spec = SCENARIOS[scenario]
    allowed = spec.options()
    unknown = sorted(set(scenario_options) - set(allowed))
    if unknown:
        raise InputError(f"scenario {scenario!r} has no option(s) {unknown}; its options are {sorted(allowed)}")
    for name, value in scenario_options.items():
        _check_scenario_option(scenario, name, value, allowed[name])
    if array is None:
        array = spec.default_array()
    if not isinstance(array, SensorArray):
        raise TypeError(f"array must be a SensorArray, got {type(array).__name__}")
    if noise is None:
        noise = SensorErrors()
    rate_hz = spec.rate_hz if rate_hz is None else float(rate_hz)
    if duration_s is None:
        duration_s = spec.duration_s if spec.duration_s is not None else _recording_duration(scenario)
    timestamps_ns = sample_timestamps_ns(rate_hz, float(duration_s))
    times_s = timestamps_ns * 1e-9

    motion_seq, noise_seq = np.random.SeedSequence(int(seed)).spawn(2)
    kin, array = spec.build(times_s, np.random.default_rng(motion_seq), array, **scenario_options)
    truth = motion_from_truth(timestamps_ns, kin)

    array = _array_with_noise_levels(array, noise)

    rng = np.random.default_rng(noise_seq)
    show = progress and len(timestamps_ns) > _CHUNK
    readings = noise.accel_readings(array, truth.specific_force_b_mps2, truth.omega_dot_b_radps2,
                                    truth.omega_b_radps, rng, chunk=_CHUNK,
                                    progress=lambda it, total: _progress(it, total=total, desc=f"simulate {scenario}",
                                                                         enable=show))
    gyro = noise.gyro_readings(array, truth.omega_b_radps, rng) if array.gyroscope is not None else None
    tilt = (noise.tilt_readings(array, tilt_angles_rad(truth.quaternion_wb), rng)
            if array.inclinometer is not None else None)
    return Log(array, timestamps_ns, readings, gyro_b_radps=gyro, tilt_rad=tilt, truth=truth,
               source=f"simulate:{scenario}")


def _array_with_noise_levels(array: SensorArray, noise: SensorErrors) -> SensorArray:
    """The array as written to the log: explicit positive noise levels replace array.toml's."""
    from dataclasses import replace

    if noise.accel_noise_std_mps2:
        array = array.with_accelerometers(replace(a, noise_std_mps2=float(noise.accel_noise_std_mps2))
                                          for a in array.accelerometers)
    if noise.gyro_noise_std_radps and array.gyroscope is not None:
        array = replace(array, gyroscope=replace(array.gyroscope, noise_std_radps=float(noise.gyro_noise_std_radps)))
    if noise.inclinometer_noise_std_rad and array.inclinometer is not None:
        array = replace(array, inclinometer=replace(array.inclinometer,
                                                    noise_std_rad=float(noise.inclinometer_noise_std_rad)))
    return array


def _recording_duration(scenario: str) -> float:

    return RECORDINGS[scenario]().longest_segment().duration_s


class _CallablePackage(ModuleType):
    """This package, callable as its function :func:`simulate`: importing ``gfimu.simulate`` binds the
    package to the name ``gfimu.simulate``, which ``from gfimu import simulate`` then finds."""

    def __call__(self, *args, **kwargs) -> Log:
        return simulate(*args, **kwargs)


sys.modules[__name__].__class__ = _CallablePackage
