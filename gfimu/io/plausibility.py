"""Plausibility of a log that reads: values that are valid but probably not what the writer meant.

Each check returns plain sentences that name the file, what was found and
the likely mistake; :func:`gfimu.io.read_log` issues them as
:class:`~gfimu.io.errors.LogPlausibilityWarning`. Nothing here changes the
log. The checks:

- the sample rate from the timestamps against ``rate_hz`` in ``array.toml``
  (when given);
- the timestamp unit: steps that imply more than 100 kHz or less than 0.1 Hz
  under the header's unit, with the units that would give a plausible rate;
- the array size: an accelerometer more than 1 m from the body origin, or
  all of them within 1 mm of each other (``position_m`` is in metres);
- gravity: the specific force of a still array, in m/s², far from
  9.81 (readings in g or mg under a ``[m s^-2]`` header); a log without
  a still stretch by the median over the whole log of the array's
  common-mode specific force, whose size stays near 9.81 m/s² on any
  hand-held or vehicle motion (:func:`check_specific_force_scale`);
- readings that are NaN or infinite (masked later; counted here).
"""

from __future__ import annotations

import numpy as np

from ..array import SensorArray
from ..log import Log
from .units import STANDARD_GRAVITY_MPS2, TIME_UNITS_NS

MAX_RATE_HZ = 100e3
MIN_RATE_HZ = 0.1
RATE_TOLERANCE = 0.05  # relative difference between rate_hz and the timestamps' rate
MAX_POSITION_M = 1.0
MIN_EXTENT_M = 1e-3
STILL_WINDOW_S = 0.25
STILL_SENSOR_SPREAD = 0.1  # sensors agree within 10 % of |f| (uncalibrated biases) ...
STILL_TIME_SPREAD = 0.03  # ... and |f| varies by less than 3 % (std) over the window
_BLOCK_ROWS = 65536


def _median_step_ns(t_ns: np.ndarray) -> float | None:
    if t_ns.size < 2:
        return None
    return float(np.median(np.diff(t_ns)))


def check_rate(t_ns: np.ndarray, declared_rate_hz: float | None, time_unit: str, imu_name: str,
               array_name: str) -> list[str]:
    """The timestamps' rate against the declared one, and the timestamp unit."""
    out: list[str] = []
    step = _median_step_ns(t_ns)
    if step is None or step <= 0:
        return out
    rate = 1e9 / step
    scale = TIME_UNITS_NS.get(time_unit, 1)
    raw_step = step / scale
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
        likely = []
        for unit, ns in TIME_UNITS_NS.items():
            r = 1e9 / (raw_step * ns)
            if unit != time_unit and MIN_RATE_HZ <= r <= MAX_RATE_HZ:
                likely.append((abs(np.log10(r) - 2.5), unit, r))  # closest to a few hundred Hz first
        hint = ""
        if likely:
            _, unit, r = min(likely)
            hint = (f"; likely the timestamps are in [{unit}] ({r:.4g} Hz): write the header as "
                    f"'#timestamp [{unit}]'")
        out.append(f"{imu_name}: the timestamps under '#timestamp [{time_unit}]' step by a median {raw_step:.6g} "
                   f"{time_unit}, a sample rate of {rate:.4g} Hz, implausible for an IMU (expected between "
                   f"{MIN_RATE_HZ:g} Hz and {MAX_RATE_HZ / 1e3:g} kHz){hint}")
    if declared_rate_hz is not None and abs(rate / declared_rate_hz - 1.0) > RATE_TOLERANCE:
        out.append(f"{array_name}: rate_hz = {declared_rate_hz:g}, but the timestamps of {imu_name} step by a "
                   f"median {step / 1e6:.6g} ms ({rate:.4g} Hz); either rate_hz is wrong or the timestamps are "
                   f"not in [{time_unit}]")
    return out


def check_geometry(array: SensorArray, array_name: str) -> list[str]:
    """Positions that look like millimetres (or metres divided once too often)."""
    out: list[str] = []
    pos = np.array([a.position_m for a in array.accelerometers], dtype=float)
    dist = np.linalg.norm(pos, axis=1)
    far = int(np.argmax(dist))
    if dist[far] > MAX_POSITION_M:
        out.append(f"{array_name}: accelerometer {array.accelerometers[far].name!r} sits {dist[far]:.4g} m from "
                   "the body origin; position_m is in metres: likely the positions were written in mm or cm")
    if len(pos) > 1:
        extent = float(np.max(np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=2)))
        if extent == 0.0:
            out.append(f"{array_name}: all {len(pos)} accelerometers have the same position_m; the rotation "
                       "cannot be sensed from their differences: check position_m (metres, body frame)")
        elif extent < MIN_EXTENT_M:
            out.append(f"{array_name}: the accelerometers lie within {extent * 1e3:.3g} mm of each other; "
                       "position_m is in metres: likely the positions were divided by 1000 once too often")
    return out


def still_specific_force(log: Log) -> float | None:
    """Median |f| [m/s², as read] over still stretches of the array (every triad reads the same f in B, steadily);
    None when the log has none."""
    return _still_specific_force(log)


def _still_specific_force(log: Log) -> float | None:
    """Median |f| [m/s²] over still stretches (every triad reads the same f in B, steadily); None if none."""
    with np.errstate(all="ignore"):  # NaN or huge readings are simply not still
        return _still_specific_force_of(log)


def _still_specific_force_of(log: Log) -> float | None:
    arr = log.array
    triads, col = [], 0
    for a in arr.accelerometers:
        if tuple(a.axes) == ("x", "y", "z"):
            triads.append((col, a.rotation_body_sensor))
        col += len(a.axes)
    if len(triads) < 2 or len(log) < 5:
        return None
    n = len(log)
    norm = np.empty(n)
    spread = np.empty(n)
    for start in range(0, n, _BLOCK_ROWS):  # in blocks: (rows, sensors, 3) stays small on long logs
        rows = slice(start, min(start + _BLOCK_ROWS, n))
        f_b = np.stack([log.accel_mps2[rows, c:c + 3] @ np.asarray(rot).T for c, rot in triads], axis=1)
        mean = np.mean(f_b, axis=1)
        norm[rows] = np.linalg.norm(mean, axis=1)
        spread[rows] = np.max(np.linalg.norm(f_b - mean[:, None, :], axis=2), axis=1)
    finite = np.isfinite(norm) & np.isfinite(spread)
    agree = finite & (spread <= STILL_SENSOR_SPREAD * norm) & (norm > 0)
    step = _median_step_ns(log.timestamps_ns)
    w = max(5, int(round(STILL_WINDOW_S * 1e9 / step))) if step and step > 0 else 5
    if len(log) < w:
        return None
    m = len(log) // w
    nw = norm[: m * w].reshape(m, w)
    still = agree[: m * w].reshape(m, w).all(axis=1) & (np.std(nw, axis=1) <= STILL_TIME_SPREAD * np.mean(nw, axis=1))
    return float(np.median(np.median(nw[still], axis=1))) if still.any() else None


def _origin_force_rows(array) -> np.ndarray | None:
    """The rows ``P`` (3, n_axes) that give the specific force at the body origin from one sample's readings,
    rotation removed (``f = P y``, the first three rows of the inverse of the structure matrix, Ho & Lin 2009
    eq. 7), for an array whose 12 unknowns are resolved (rank 12, condition below 1e6); None otherwise."""
    if array.n_axes < 12:
        return None
    S = array.structure_matrix()
    sv = np.linalg.svd(S, compute_uv=False)
    if sv[-1] <= 1e-6 * sv[0]:
        return None
    return np.linalg.pinv(S)[0:3]


def median_specific_force(log: Log) -> float | None:
    """Median over the log of |f| [m/s², as read] with the rotation taken out where the array resolves it:
    the specific force at the origin from the per-sample inversion (an array with 12 resolved unknowns: a
    fast spin of sensors off its axis reads centripetal force, which is no unit error), else the array's
    common mode, the mean over the three-axis accelerometers of their readings turned into B (one triad:
    its |f|); None without a triad."""
    arr = log.array
    P = _origin_force_rows(arr)
    if P is not None and len(log) >= 2:
        norms = []
        with np.errstate(all="ignore"):
            for start in range(0, len(log), _BLOCK_ROWS):
                rows = slice(start, min(start + _BLOCK_ROWS, len(log)))
                norms.append(np.linalg.norm(log.accel_mps2[rows] @ P.T, axis=1))
        norm = np.concatenate(norms)
        norm = norm[np.isfinite(norm)]
        return float(np.median(norm)) if norm.size else None
    triads, col = [], 0
    for a in arr.accelerometers:
        if tuple(a.axes) == ("x", "y", "z"):
            triads.append((col, np.asarray(a.rotation_body_sensor, dtype=float)))
        col += len(a.axes)
    if not triads or len(log) < 2:
        return None
    norms = []
    with np.errstate(all="ignore"):
        for start in range(0, len(log), _BLOCK_ROWS):
            rows = slice(start, min(start + _BLOCK_ROWS, len(log)))
            mean = sum(log.accel_mps2[rows, c:c + 3] @ rot.T for c, rot in triads) / len(triads)
            norms.append(np.linalg.norm(mean, axis=1))
    norm = np.concatenate(norms)
    norm = norm[np.isfinite(norm)]
    return float(np.median(norm)) if norm.size else None


SCALE_BANDS = ((8.0, 12.0, "m/s² under a [g] unit", "m/s^2"), (0.07, 0.14, "g under an [m/s²] unit", "g"),
               (70.0, 140.0, "mg under an [m/s²] unit", "mg"))
"""(low, high, what, the unit to give) of median |f| / 9.80665 over a moving log: a unit misread."""


MOVING_HIGH = 6.0
"""Median |f| / g over a moving log above which the readings' scale is taken as wrong (whatever the factor):
the body's common-mode specific force would have to exceed 6 g for most of the log."""
MOVING_LOW = 0.05
"""Median |f| / g over a moving log below which the readings' scale is suspect: 1/20 of gravity for most of
the log is either a unit off by a factor or an array in free fall the whole time."""

KNOWN_ACCEL_UNITS = (("m/s²", 1.0), ("g", STANDARD_GRAVITY_MPS2), ("mg", STANDARD_GRAVITY_MPS2 * 1e-3),
                     ("cm/s² (gal)", 1e-2), ("mm/s²", 1e-3), ("ft/s²", 0.3048), ("µg", STANDARD_GRAVITY_MPS2 * 1e-6))
"""Units an accelerometer's values are commonly written in, with their size in m/s²."""


def suggested_factor(ratio: float, read_unit: str = "m s^-2") -> str:
    """Words for readings whose |f| is ``ratio`` × gravity where gravity was expected: the factor that brings
    them to gravity, and the unit their values are likely in (from :data:`KNOWN_ACCEL_UNITS`, relative to
    ``read_unit``, the unit they were read under) when one fits within 15 %."""
    from .units import UNITS, canonical_unit

    factor = 1.0 / ratio
    text = f"scaled by {factor:.4g} they would read gravity"
    read = UNITS["acceleration"][1].get(canonical_unit(read_unit or "m s^-2"))
    if read is not None:
        size = read * factor  # m/s² per unit of the values, if the body saw gravity
        near = [(abs(np.log(size / unit_size)), name) for name, unit_size in KNOWN_ACCEL_UNITS
                if abs(size / unit_size - 1.0) <= 0.15]
        if near and canonical_unit(min(near)[1].split()[0]) != canonical_unit(read_unit or "m s^-2"):
            return f"{text}: likely the values are in {min(near)[1]}, not [{read_unit}]"
    return text


def _spin_caveat(array, ratio: float) -> str:
    """For |f| above gravity read by an array that cannot take its rotation out (fewer than 12 resolved
    unknowns): the other cause, a fast spin of sensors off its axis, named; "" otherwise."""
    if ratio < 1.0 or _origin_force_rows(array) is not None:
        return ""
    return (" (or the sensors spin fast off the rotation axis: centripetal force, which this array cannot tell "
            "apart from a unit error)")


def check_specific_force_scale(log: Log, where: str, gravity_included: bool = True,
                               read_unit: str = "m s^-2") -> list[str]:
    """The median |f| of the array's common mode over the whole log, far from 9.81 m/s² by a factor of
    9.81 or 1000: a unit misread, found without a still stretch. ``where`` names the file, columns and the
    unit read. A log of acceleration without gravity (``gravity_included`` False) is not checked, and the
    g-read-as-m/s² band only when gravity is known to be included."""
    if not gravity_included:
        return []
    m = median_specific_force(log)
    if m is None or m <= 0:
        return []
    ratio = m / STANDARD_GRAVITY_MPS2
    for lo, hi, what, unit in SCALE_BANDS:
        if lo <= ratio <= hi:
            return [f"{where}: over the whole log the accelerometers read a median |f| = {m:.4g} m/s², "
                    f"{ratio:.3g} × gravity, where a moving body's specific force stays near "
                    f"{STANDARD_GRAVITY_MPS2:g}: likely the values are in {what}; give the unit [{unit}] (in the "
                    "header or the map)"]
    if ratio >= MOVING_HIGH or ratio <= MOVING_LOW:
        return [f"{where}: over the whole log the accelerometers read a median |f| = {m:.4g} m/s², {ratio:.3g} × "
                f"gravity, where a moving body's specific force stays near {STANDARD_GRAVITY_MPS2:g}: "
                f"{suggested_factor(ratio, read_unit)}" + (_spin_caveat(log.array, ratio) if ratio >= MOVING_HIGH else
                                                           " (or the array was in free fall the whole time)")
                + "; check the unit of the values (in the header or the map)"]
    return []


def check_gravity(log: Log, imu_name: str, accel_units: str = "m s^-2") -> list[str]:
    """|f| of a still array far from 9.81 m/s² (likely g or mg); without a still stretch, the median |f| of
    the whole log by a factor of about 9.81 or 1000 above gravity (a unit misread that acceleration
    without gravity cannot explain)."""
    g0 = _still_specific_force(log)
    if g0 is None:
        m = median_specific_force(log)
        ratio = None if m is None else m / STANDARD_GRAVITY_MPS2
        if ratio is not None and (8.0 <= ratio <= 12.0 or 70.0 <= ratio <= 140.0):
            cause = ("m/s² taken for g (scaled by 9.81)" if ratio <= 12.0 else
                     "mg taken for m/s² (1000 times too large)")
            return [f"{imu_name}: no still stretch, but over the whole log the accelerometers read a median |f| = "
                    f"{m:.4g} m/s² (under [{accel_units}]), {ratio:.3g} × gravity, where a moving body's specific "
                    f"force stays near {STANDARD_GRAVITY_MPS2:g}: likely {cause} when the log was written"
                    + _spin_caveat(log.array, ratio) + "; check the unit of the recording it came from"]
        if ratio is not None and 0 < ratio and (ratio >= MOVING_HIGH or ratio <= MOVING_LOW):
            return [f"{imu_name}: no still stretch, but over the whole log the accelerometers read a median |f| = "
                    f"{m:.4g} m/s² (under [{accel_units}]), {ratio:.3g} × gravity, where a moving body's specific "
                    f"force stays near {STANDARD_GRAVITY_MPS2:g}: {suggested_factor(ratio, accel_units)}"
                    + (_spin_caveat(log.array, ratio) if ratio >= MOVING_HIGH else
                       " (or the array was in free fall the whole time)")
                    + "; check the unit of the recording it came from"]
        return []
    ratio = g0 / STANDARD_GRAVITY_MPS2
    if g0 < 0.3:  # the sensors agree and hold steady on a tiny |f|: a scale off by a factor (free fall's noise
        # would not agree between sensors)
        return [f"{imu_name}: over a still stretch the accelerometers agree on |f| = {g0:.4g} m/s² (read under "
                f"[{accel_units}]), {ratio:.3g} × gravity: {suggested_factor(ratio, accel_units)} (or the array "
                "was in free fall); check the unit and scale of the accelerometer readings"]
    if 0.5 <= ratio <= 2.0:
        return []
    where = (f"{imu_name}: at rest the accelerometers read |f| = {g0:.4g} m/s² (read under [{accel_units}]), "
             f"not {STANDARD_GRAVITY_MPS2:g}")
    if 0.07 <= ratio <= 0.14:
        return [f"{where}: likely the readings are in g; write the column units as [g] to convert them"]
    if 70 <= ratio <= 140:
        return [f"{where}: likely the readings are in mg; write the column units as [mg] to convert them"]
    if 8 <= ratio <= 12:
        return [f"{where}: likely readings in m/s² under a [g] header; write the column units as [m s^-2]"]
    return [f"{where}: {suggested_factor(ratio, accel_units)}; check the unit and scale of the accelerometer readings"]


def check_finite(log: Log, imu_name: str) -> list[str]:
    """NaN or infinite readings (let through to be masked by the estimators)."""
    out = []
    bad = ~np.isfinite(log.accel_mps2)
    if bad.any():
        rows, cols = np.nonzero(bad)
        out.append(f"{imu_name}:{int(rows[0]) + 2}: {int(bad.sum())} accelerometer reading(s) are NaN or infinite "
                   f"(first in column {log.array.accel_columns[int(cols[0])]!r}); they are masked out of the estimates")
    for name, values, columns in (("gyroscope", log.gyro_b_radps, ("w_x", "w_y", "w_z")),
                                  ("inclinometer", log.tilt_rad, ("tilt_x", "tilt_y"))):
        if values is None:
            continue
        bad = ~np.isfinite(values)
        if bad.any():
            rows, cols = np.nonzero(bad)
            out.append(f"{imu_name}:{int(rows[0]) + 2}: {int(bad.sum())} {name} reading(s) are NaN or infinite "
                       f"(first in column {columns[int(cols[0])]!r})")
    return out
