"""Static multi-position calibration of an accelerometer array against gravity.

Ho & Lin 2009 §V calibrates the misalignment of each triad by rotating the
array through known orientations and fitting by least squares. Here the
orientations need not be known: the array is held still in several
orientations, and every accelerometer's bias and full 3x3 gain (scale,
cross-axis and misalignment) are fitted jointly with the unknown direction of
gravity in each still period.

Model, per accelerometer ``i`` (axes in its own frame, ``n_i`` of them) and
still period ``k``::

    y_ik = K_i · f_k + b_i,    |f_k| = g

with ``f_k`` the specific force in the body frame B (at rest it is the same at
every lever arm) and ``K_i`` (n_i x 3) whose rows are the effective sensing
vectors in B (nominally the sensor's axis directions ``D_i``).

Gauge: rotating every ``f_k`` by R and every ``K_i`` by Rᵀ leaves the
readings unchanged, so the frame is fixed by requiring that the fitted
sensing axes of all accelerometers together be as close as possible to their
nominal directions: ``Q = argmin_R Σ_i ||K_i R − D_i||²`` (orthogonal
Procrustes) is applied after fitting. The board frame is thus the average
frame of the sensors' nominal axes.

Fit: alternating least squares — gains and biases per accelerometer by
linear least squares given the ``f_k``; each ``f_k`` by the
sphere-constrained least squares (trust-region secular equation) given the
gains — started from the nominal gains, until the residual stops falling.

Application: calibrated readings in each sensor's own frame are
``y' = (K_i D_iᵀ)⁻¹ (y − b_i)``, which equals ``D_i K_i⁻¹ (y − b_i)`` for a
triad (exact). For a one- or two-axis sensor it neglects the sensitivity to
the directions it does not measure.

Still-period detector (:func:`find_still_periods`): a sample is still when,
over a centred window of ``window_s`` (default 1.0 s), the standard deviation
of every accelerometer axis is below ``accel_std_mps2`` (default 0.15 m/s²,
a few times the sensors' noise) and, if the log has a gyroscope, every gyro
axis' std is below ``gyro_std_radps`` (0.05 rad/s) and the mean rate below
``gyro_mean_radps`` (0.15 rad/s); and the array-mean specific force is within
``gravity_tolerance_mps2`` (0.5 m/s²) of g. Runs of still samples at least
``min_duration_s`` (2 s) long are the still periods; ``trim_s`` (0.25 s) is
cut from both ends.

Inter-sensor spread (:func:`inter_sensor_spread`): for each still period the
common specific force is the least-squares fit to all axes' mean readings
(for triads in a common frame, the array mean); the spread is the RMS, over
still periods and accelerometers, of the norm of the deviation of each
accelerometer's mean reading from it (``spread_*``); ``spread_per_axis_*``
takes the RMS over single axes instead (norm value / √3 for triads).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .array import AXIS_INDEX, SensorArray
from .errors import DataError, InputError
from .io.array_toml import format_toml
from .io.atomic import atomic_write_text

GRAVITY_MPS2 = 9.80665
FORMAT = "gfimu-calibration/1"


class CalibrationError(DataError):
    """The data cannot support the calibration (names the cause)."""


class CalibrationFileError(CalibrationError, InputError):
    """A calibration file (or calibration given) is malformed (names the file and key)."""


@dataclass(frozen=True)
class SensorCalibration:
    """Gain (n_axes x 3, rows = sensing vectors in B) and bias (n_axes,) in m/s²."""

    name: str
    axes: tuple[str, ...]
    gain: np.ndarray
    bias_mps2: np.ndarray

    def __post_init__(self) -> None:
        gain = np.asarray(self.gain, dtype=float)
        bias = np.asarray(self.bias_mps2, dtype=float).reshape(-1)
        n = len(self.axes)
        if gain.shape != (n, 3) or bias.shape != (n,) or not (np.all(np.isfinite(gain)) and np.all(np.isfinite(bias))):
            raise CalibrationFileError(f"calibration of {self.name!r}: gain must be {n}x3 and bias {n} finite numbers")
        object.__setattr__(self, "gain", gain)
        object.__setattr__(self, "bias_mps2", bias)
        object.__setattr__(self, "axes", tuple(self.axes))


@dataclass(frozen=True)
class Calibration:
    """Per-accelerometer gains and biases, an optional gyro bias, and fit statistics."""

    sensors: tuple[SensorCalibration, ...]
    gyro_bias_b_radps: np.ndarray | None = None
    gravity_mps2: float = GRAVITY_MPS2
    info: dict = field(default_factory=dict)

    def sensor(self, name: str) -> SensorCalibration:
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(f"calibration has no accelerometer {name!r}; it has {[s.name for s in self.sensors]}")


# --- still periods ------------------------------------------------------------

@dataclass(frozen=True)
class StillDetector:
    """Thresholds of the still-period detector (see the module docstring)."""

    window_s: float = 1.0
    accel_std_mps2: float = 0.15
    gyro_std_radps: float = 0.05
    gyro_mean_radps: float = 0.15
    gravity_tolerance_mps2: float = 0.5
    min_duration_s: float = 2.0
    trim_s: float = 0.25


def _rolling_std(x: np.ndarray, w: int) -> np.ndarray:
    """Centred rolling std over ``w`` samples along axis 0 (edges: NaN)."""
    n = x.shape[0]
    out = np.full(x.shape, np.nan)
    if n < w:
        return out
    xc = x - x.mean(axis=0)
    c1 = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(xc, axis=0)])
    c2 = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(xc * xc, axis=0)])
    s1 = c1[w:] - c1[:-w]
    s2 = c2[w:] - c2[:-w]
    var = np.maximum(s2 / w - (s1 / w) ** 2, 0.0)
    h = w // 2
    out[h : h + n - w + 1] = np.sqrt(var)
    return out


def _rolling_mean(x: np.ndarray, w: int) -> np.ndarray:
    n = x.shape[0]
    out = np.full(x.shape, np.nan)
    if n < w:
        return out
    c1 = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])
    h = w // 2
    out[h : h + n - w + 1] = (c1[w:] - c1[:-w]) / w
    return out


def body_frame_readings(array: SensorArray, accel_mps2: np.ndarray) -> np.ndarray:
    """Least-squares common specific force in B from all axes, (N, 3)."""
    d = array.axis_directions_b
    return np.linalg.lstsq(d, np.asarray(accel_mps2, dtype=float).T, rcond=None)[0].T


def find_still_periods(log, detector: StillDetector | None = None) -> list[slice]:
    """Still periods of a log (slices), by the detector described in the module docstring."""
    det = detector or StillDetector()
    n = len(log)
    if n < 3:
        return []
    rate = log.rate_hz
    w = max(3, int(round(det.window_s * rate)))
    still = np.all(_rolling_std(log.accel_mps2, w) < det.accel_std_mps2, axis=1)
    if log.gyro_b_radps is not None:
        still &= np.all(_rolling_std(log.gyro_b_radps, w) < det.gyro_std_radps, axis=1)
        still &= np.linalg.norm(_rolling_mean(log.gyro_b_radps, w), axis=1) < det.gyro_mean_radps
    f = body_frame_readings(log.array, log.accel_mps2)
    still &= np.abs(np.linalg.norm(f, axis=1) - GRAVITY_MPS2) < det.gravity_tolerance_mps2
    # no still period across a time gap
    for g in log.gaps():
        still[g.index] = False
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
    trim = int(round(det.trim_s * rate))
    min_len = int(round(det.min_duration_s * rate))
    return [slice(int(s) + trim, int(e) - trim) for s, e in zip(starts, ends) if e - s - 2 * trim >= min_len]


def still_means(log, periods: list[slice]) -> np.ndarray:
    """(n_periods, n_axes) mean accelerometer readings per still period."""
    if not periods:
        raise CalibrationError(f"{log.source}: no still period found")
    return np.array([log.accel_mps2[p].mean(axis=0) for p in periods])


# --- fit -------------------------------------------------------------------------

def _sphere_lstsq(a: np.ndarray, c: np.ndarray, radius: float) -> np.ndarray:
    """argmin_f ||A f − c||² subject to |f| = radius, for one 3-vector.

    Solves the secular equation of the trust-region subproblem on the
    eigen-decomposition of AᵀA (Lagrange multiplier found by bisection).
    """
    h = a.T @ a
    g = a.T @ c
    lam_e, v = np.linalg.eigh(h)
    gv = v.T @ g

    def norm_at(mu: float) -> float:
        return float(np.linalg.norm(gv / (lam_e + mu)))

    lo = -lam_e[0] + 1e-12 * max(1.0, abs(lam_e[-1]))
    if norm_at(lo) < radius:  # hard case: pick the boundary point along the smallest eigenvector
        base = gv / np.where(np.abs(lam_e + lo) > 1e-15, lam_e + lo, np.inf)
        base[0] = math.sqrt(max(radius**2 - float(base[1:] @ base[1:]), 0.0))
        return v @ base
    hi = lo + 1.0
    while norm_at(hi) > radius:
        hi = lo + 2 * (hi - lo)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if norm_at(mid) > radius:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-13 * max(1.0, abs(hi)):
            break
    return v @ (gv / (lam_e + 0.5 * (lo + hi)))


def fit_static(
    array: SensorArray,
    means_mps2: np.ndarray,
    gravity_mps2: float = GRAVITY_MPS2,
    max_iterations: int = 500,
    tolerance: float = 1e-12,
) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray, dict]:
    """Fit gains and biases to still-period mean readings (model in the module docstring).

    ``means_mps2`` is (n_periods, n_axes) in ``array.accel_columns`` order.
    Returns ``(gains, biases, f_b_mps2 (n_periods, 3), info)``.
    """
    y = np.asarray(means_mps2, dtype=float)
    n_axes = array.n_axes
    if y.ndim != 2 or y.shape[1] != n_axes:
        raise CalibrationError(f"still means have shape {y.shape}, expected (n_periods, {n_axes})")
    m = y.shape[0]
    owner = array.axis_owner
    nominal = [a.directions_b for a in array.accelerometers]
    # orientation diversity: each accelerometer has 4 unknowns per axis (3 gain + bias)
    if m < 4:
        raise CalibrationError(f"{m} still period(s); a gain-and-bias fit needs at least 4 orientations (ideally 6 or more)")
    f = body_frame_readings(array, y)
    f *= gravity_mps2 / np.linalg.norm(f, axis=1, keepdims=True)
    design = np.column_stack([f, np.ones(m)])
    sv = np.linalg.svd(design / np.array([gravity_mps2] * 3 + [1.0]), compute_uv=False)
    if sv[-1] < 1e-3 * sv[0]:
        raise CalibrationError(
            f"the {m} still periods do not span enough orientations (design singular values {np.round(sv, 4).tolist()}); "
            "hold the array still in at least 4 orientations that are not all in one plane"
        )
    gains = [d.copy() for d in nominal]
    biases = [np.zeros(len(d)) for d in nominal]
    prev = np.inf
    it = 0
    for it in range(1, max_iterations + 1):
        design = np.column_stack([f, np.ones(m)])
        for i in range(len(nominal)):
            cols = np.nonzero(owner == i)[0]
            sol = np.linalg.lstsq(design, y[:, cols], rcond=None)[0]  # (4, n_i)
            gains[i] = sol[:3].T
            biases[i] = sol[3]
        big_k = np.vstack(gains)
        big_b = np.concatenate(biases)
        for k in range(m):
            f[k] = _sphere_lstsq(big_k, y[k] - big_b, gravity_mps2)
        res = y - f @ big_k.T - big_b
        cost = float(np.sum(res**2))
        if np.isfinite(prev) and prev - cost <= tolerance * prev:
            break
        prev = cost
    # gauge: orthogonal Procrustes aligning all fitted axes to the nominal ones
    big_k = np.vstack(gains)
    big_d = np.vstack(nominal)
    u, _, vt = np.linalg.svd(big_k.T @ big_d)
    s = np.eye(3)
    s[2, 2] = np.sign(np.linalg.det(u @ vt))
    q = u @ s @ vt
    gains = [g @ q for g in gains]
    f = f @ q
    res = y - f @ np.vstack(gains).T - np.concatenate(biases)
    dof = max(y.size - 4 * n_axes - 2 * m + 3, 1)
    info = {
        "iterations": it,
        "residual_rms_mps2": float(np.sqrt(np.mean(res**2))),
        "residual_sigma_mps2": float(np.sqrt(np.sum(res**2) / dof)),
    }
    return gains, biases, f, info


def inter_sensor_spread(array: SensorArray, means_mps2: np.ndarray, per_axis: bool = False) -> float:
    """RMS over still periods and accelerometers of |sensor mean − common fit| (m/s²).

    With ``per_axis`` the RMS is taken over single axes instead of vector
    norms (for triads: the norm value divided by √3).
    """
    y = np.asarray(means_mps2, dtype=float)
    f = body_frame_readings(array, y)
    dev = y - f @ array.axis_directions_b.T
    count = dev.size if per_axis else y.shape[0] * len(array.accelerometers)
    return float(np.sqrt(np.sum(dev**2) / count))


def correct_readings(array: SensorArray, cal: Calibration, accel_mps2: np.ndarray) -> np.ndarray:
    """Calibrated readings, same layout as ``accel_mps2`` (each sensor's own frame)."""
    y = np.array(accel_mps2, dtype=float, copy=True)
    col = 0
    for acc in array.accelerometers:
        n = len(acc.axes)
        try:
            sc = cal.sensor(acc.name)
        except KeyError as exc:
            raise CalibrationFileError(exc.args[0]) from None
        if tuple(sc.axes) != tuple(acc.axes):
            raise CalibrationFileError(f"calibration of {acc.name!r} is for axes {list(sc.axes)}, the log has {list(acc.axes)}")
        t = sc.gain @ acc.directions_b.T  # (n, n): effective gain in the sensor's nominal axes
        if np.linalg.cond(t) > 1e6:
            raise CalibrationError(f"calibration gain of {acc.name!r} is singular")
        y[..., col : col + n] = np.linalg.solve(t, (y[..., col : col + n] - sc.bias_mps2).T).T
        col += n
    return y


def apply_calibration(log, cal: Calibration):
    """A new :class:`~gfimu.log.Log` with calibrated accelerometers (and gyro bias removed)."""
    changes = {"accel_mps2": correct_readings(log.array, cal, log.accel_mps2)}
    if cal.gyro_bias_b_radps is not None:
        if log.gyro_b_radps is not None:
            changes["gyro_b_radps"] = log.gyro_b_radps - cal.gyro_bias_b_radps
        if log.reference is not None and log.reference.omega_b_radps is not None:
            changes["reference"] = log.reference.replace(omega_b_radps=log.reference.omega_b_radps - cal.gyro_bias_b_radps)
    return log.replace(**changes)


def apply_calibration_file(log, path: str | Path):
    """:func:`apply_calibration` of the calibration read from ``path``; an error naming ``path`` when it
    does not fit the log's array (an accelerometer it lacks, other axes, a singular gain)."""
    cal = read_calibration(path)
    try:
        return apply_calibration(log, cal)
    except CalibrationFileError as exc:
        raise CalibrationFileError(f"{path}: {exc}") from None


def fit(log, detector: StillDetector | None = None, periods: list[slice] | None = None, gravity_mps2: float = GRAVITY_MPS2) -> Calibration:
    """Static calibration of a log's accelerometers (and mean gyro bias) from its still periods."""
    periods = find_still_periods(log, detector) if periods is None else periods
    if not periods:
        raise CalibrationError(f"{log.source}: no still period found (see gfimu.calibration.StillDetector)")
    means = still_means(log, periods)
    gains, biases, f, info = fit_static(log.array, means, gravity_mps2)
    sensors = tuple(SensorCalibration(a.name, a.axes, g, b) for a, g, b in zip(log.array.accelerometers, gains, biases))
    gyro_bias = None
    gyro = log.gyro_b_radps
    if gyro is None and log.reference is not None:
        gyro = log.reference.omega_b_radps
    if gyro is not None:
        gyro_bias = np.mean([gyro[p].mean(axis=0) for p in periods], axis=0)
    cal = Calibration(sensors, gyro_bias, gravity_mps2)
    corrected = correct_readings(log.array, cal, means)
    info.update(
        source=str(log.source),
        still_periods=len(periods),
        still_samples=int(sum(p.stop - p.start for p in periods)),
        spread_before_mps2=inter_sensor_spread(log.array, means),
        spread_after_mps2=inter_sensor_spread(log.array, corrected),
        spread_per_axis_before_mps2=inter_sensor_spread(log.array, means, per_axis=True),
        spread_per_axis_after_mps2=inter_sensor_spread(log.array, corrected, per_axis=True),
    )
    return replace(cal, info=info)


# --- TOML I/O ----------------------------------------------------------------------

def calibration_to_dict(cal: Calibration) -> dict:
    """The ``calibration.toml`` document of a calibration."""
    doc: dict = {"format": FORMAT, "gravity_mps2": float(cal.gravity_mps2)}
    if cal.info:
        doc["fit"] = dict(cal.info)
    if cal.gyro_bias_b_radps is not None:
        doc["gyroscope"] = {"bias_b_radps": np.asarray(cal.gyro_bias_b_radps, dtype=float)}
    doc["accelerometers"] = [{"name": s.name, "axes": list(s.axes), "bias_mps2": np.asarray(s.bias_mps2, dtype=float),
                              "gain": np.asarray(s.gain, dtype=float)} for s in cal.sensors]
    return doc


_TOML_COMMENT = "model per accelerometer: reading = gain · f_B + bias_mps2 (rows of gain: sensing vectors in B)"


def calibration_to_toml(cal: Calibration) -> str:
    """Text of ``calibration.toml``."""

    return format_toml(calibration_to_dict(cal), comment=_TOML_COMMENT, finite=False)


def write_calibration(cal: Calibration, path: str | Path) -> None:
    """Write ``calibration.toml`` atomically (temporary file, fsync, rename)."""

    atomic_write_text(path, calibration_to_toml(cal))


def read_calibration(path: str | Path) -> Calibration:
    """Read a ``calibration.toml`` written by :func:`write_calibration` (or by hand); a bad value is refused
    naming the file, its line and the key."""
    from .io.errors import LogFormatError
    from .io.toml_input import load_toml

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise CalibrationFileError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    try:
        doc, ctx = load_toml(text, path)
    except LogFormatError as exc:
        raise CalibrationFileError(str(exc)) from None

    def fail(message: str, table: str = "", index: int = 0, key: str | None = None) -> CalibrationFileError:
        return CalibrationFileError(str(ctx.error(message, table, index, key)))

    def numbers(value, shape: tuple[int, ...] | None, what: str, table: str, index: int, key: str) -> np.ndarray:
        """``value`` as finite floats of ``shape`` (None: any shape, checked by the caller)."""
        try:
            out = np.array(value, dtype=float)
        except (TypeError, ValueError):
            out = None
        if out is None or (shape is not None and out.shape != shape) or not np.all(np.isfinite(out)):
            raise fail(f"expected {what}, got {value!r}", table, index, key)
        return out

    if doc.get("format") != FORMAT:
        raise CalibrationFileError(f"{path}: format must be {FORMAT!r}, got {doc.get('format')!r}")
    accs = doc.get("accelerometers")
    if not isinstance(accs, list) or not accs:
        raise CalibrationFileError(f"{path}: no [[accelerometers]] table")
    sensors = []
    for k, a in enumerate(accs):
        if not isinstance(a, dict):
            raise fail(f"expected an [[accelerometers]] table, got {a!r}", "accelerometers", k)
        for key in ("name", "bias_mps2", "gain"):
            if key not in a:
                raise fail(f"missing key {key!r}", "accelerometers", k)
        if not isinstance(a["name"], str) or not a["name"]:
            raise fail(f"expected the accelerometer's name (text), got {a['name']!r}", "accelerometers", k, "name")
        axes = a.get("axes", ["x", "y", "z"])
        if not isinstance(axes, list) or any(not isinstance(x, str) or x not in AXIS_INDEX for x in axes):
            raise fail(f"axes must be a list among \"x\", \"y\", \"z\"; got {axes!r}", "accelerometers", k, "axes")
        axes = tuple(axes)
        gain = numbers(a["gain"], None, f"{len(axes)} rows of 3 numbers", "accelerometers", k, "gain")
        bias = numbers(a["bias_mps2"], None, f"{len(axes)} numbers [m/s²]", "accelerometers", k, "bias_mps2")
        try:
            sensors.append(SensorCalibration(str(a["name"]), axes, gain, bias))
        except (CalibrationError, ValueError) as exc:
            raise fail(str(exc), "accelerometers", k) from None
    for table in ("gyroscope", "fit"):
        if not isinstance(doc.get(table, {}), dict):
            raise fail(f"expected a table [{table}], got {doc[table]!r}", "", 0, table)
    gyro = doc.get("gyroscope", {}).get("bias_b_radps")
    if gyro is not None:
        gyro = numbers(gyro, (3,), "3 numbers [rad/s]", "gyroscope", 0, "bias_b_radps")
    gravity = numbers(doc.get("gravity_mps2", GRAVITY_MPS2), (), "a number > 0 [m/s²]", "", 0, "gravity_mps2")
    if not gravity > 0:
        raise fail(f"expected a number > 0 [m/s²], got {float(gravity)!r}", "", 0, "gravity_mps2")
    return Calibration(tuple(sensors), gyro, float(gravity), dict(doc.get("fit", {})))
