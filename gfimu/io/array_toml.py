"""``array.toml``: the sensor array of a log (format ``gfimu-array/1``), and the TOML writer.

Reading goes through :func:`gfimu.io.toml_input.load_toml`; every problem raises
:class:`~gfimu.io.errors.LogFormatError` naming the key and its line. Unknown
keys are ignored. ``topic`` (the message topic an accelerometer was recorded
on) is read and written back, and used only by the recording readers.

Writing uses :func:`format_toml`, the only TOML writer of gfimu (also used
for ``calibration.toml``): :mod:`tomli_w` with short arrays of numbers or
strings kept on one line. Floats are written in their shortest round-trip
form, so reading a written file gives back exactly the same numbers.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from collections.abc import Mapping

import numpy as np
import tomli_w

from ..array import READINGS, Accelerometer, ArrayModelError, Body, Gyroscope, Inclinometer, SensorArray
from .atomic import atomic_write_text
from ..errors import InputError
from .errors import LogFormatError, LogFormatWarning, read_utf8_text
from .toml_input import TomlContext, load_toml

ARRAY_FORMAT = "gfimu-array/1"
ROTATION_TOLERANCE = 1e-6  # accepted as written
ROTATION_REPAIR_TOLERANCE = 1e-3  # projected onto the nearest rotation, with a warning


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


MAX_POSITION_M = 100.0
"""The farthest an accelerometer may sit from the body origin [m], as for a Kalibr IMU
(:data:`gfimu.io.kalibr.MAX_TRANSLATION_M`): larger is no rigid array (and 1e300 overflows the structure
matrix)."""


def _finite(v) -> bool:
    """``v`` a finite number, also a float can hold (an integer of 400 digits is none)."""
    try:
        return math.isfinite(v)
    except OverflowError:
        return False


def _shown(value) -> str:
    """``repr`` of a value cut to 80 characters (a 400-digit number is named, not printed whole)."""
    text = repr(value)
    return text if len(text) <= 80 else text[:60] + f"... ({len(text)} characters)"


def _vector(ctx: TomlContext, value, n: int, table: str, index: int, key: str) -> np.ndarray:
    if not isinstance(value, list) or len(value) != n or not all(_is_number(v) for v in value):
        raise ctx.error(f"expected a list of {n} numbers, got {_shown(value)}", table, index, key)
    if not all(_finite(v) for v in value):
        raise ctx.error(f"values must be finite, got {_shown(value)}", table, index, key)
    out = np.array(value, dtype=float)
    if not np.all(np.isfinite(out)):
        raise ctx.error(f"values must be finite, got {value!r}", table, index, key)
    return out


def _optional_std(ctx: TomlContext, table_value: dict, table: str, index: int, key: str,
                  stacklevel: int = 2) -> float | None:
    """The optional noise std ``key`` of a table (None when absent): a finite number >= 0; beyond
    :data:`MAX_NOISE_STD` a warning at ``stacklevel`` (the frame that reads the array)."""
    if key not in table_value:
        return None
    v = table_value[key]
    if not _is_number(v) or not _finite(v) or v < 0:
        raise ctx.error(f"expected a finite number >= 0, got {_shown(v)}", table, index, key)
    if v > MAX_NOISE_STD:  # said, not refused: the file is still what it says (and round-trips)
        from .errors import LogPlausibilityWarning

        words = (f"{v!r} is no sensor noise (beyond {MAX_NOISE_STD:g}: the readings would count for nothing); the "
                 "unit is m/s², rad/s or rad")
        warnings.warn(str(ctx.error(words, table, index, key)), LogPlausibilityWarning, stacklevel=stacklevel)
    return float(v)


MAX_NOISE_STD = 1e3
"""The largest noise standard deviation a sensor of array.toml states without a warning (m/s², rad/s or rad):
beyond it the readings carry no information (1e300 is a unit or a typing mistake)."""



def check_noise_weights(array, where: str) -> None:
    """A stated accelerometer noise beyond :data:`MAX_NOISE_STD` (warned of when read) gives the readings
    no weight and overflows the estimators' weights: a :class:`~gfimu.errors.DataError` naming the file
    (``where``) and the sensor, raised before anything is estimated (``estimate`` and ``live`` alike)."""
    from ..errors import DataError

    for a in array.accelerometers:
        if a.noise_std_mps2 is not None and a.noise_std_mps2 > MAX_NOISE_STD:
            raise DataError(f"{where}: accelerometer {a.name!r}: noise_std_mps2 = {a.noise_std_mps2:g} "
                            f"leaves its readings no weight (at most {MAX_NOISE_STD:g} m/s²); give the noise in m/s²")


MIN_RANGE_MPS2 = 1.0
"""The smallest full scale an accelerometer may state [m/s²]: one that cannot read a tenth of gravity is a unit
mistake (the smallest ranges sold are ±2 g, 19.6 m/s²)."""


def _rotation(ctx: TomlContext, value, index: int, name: str, stacklevel: int = 4) -> np.ndarray:
    """The ``rotation_body_sensor`` of ``accelerometers[index]``: a rotation as written, or the nearest one
    (with a warning at ``stacklevel``) when orthonormal only to :data:`ROTATION_REPAIR_TOLERANCE`."""
    key = "rotation_body_sensor"
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(r, list) and len(r) == 3 and all(_is_number(v) for v in r) for r in value)):
        raise ctx.error(f"expected a 3x3 matrix written as three rows of three numbers, got {value!r}",
                        "accelerometers", index, key)
    rot = np.array(value, dtype=float)
    if not np.all(np.isfinite(rot)):
        raise ctx.error("values must be finite", "accelerometers", index, key)
    if np.max(np.abs(rot)) > 1.5:  # a rotation's entries lie in [-1, 1]
        raise ctx.error(f"{rot.tolist()} is not a rotation matrix (an entry of size {np.max(np.abs(rot)):.3g}; a "
                        "rotation's entries lie between -1 and 1)", "accelerometers", index, key)
    det = np.linalg.det(rot)
    if det < 0:
        raise ctx.error(f"{rot.tolist()} has determinant {det:.6g}: a reflection, not a rotation",
                        "accelerometers", index, key)
    deviation = float(np.max(np.abs(rot @ rot.T - np.eye(3))))
    if deviation <= ROTATION_TOLERANCE:
        return rot
    if deviation <= ROTATION_REPAIR_TOLERANCE:
        u, _, vt = np.linalg.svd(rot)
        fixed = u @ vt
        err = ctx.error(f"orthonormal only to {deviation:.2g}; using the nearest rotation matrix (write more digits "
                        "to silence this)", "accelerometers", index, key)
        warnings.warn(str(err), LogFormatWarning, stacklevel=stacklevel)
        return fixed
    raise ctx.error(f"{rot.tolist()} is not a rotation matrix (R Rᵀ differs from the identity by {deviation:.3g}; "
                    f"expected orthonormal rows, determinant +1)", "accelerometers", index, key)


def parse_array_toml(text: str, path: str | os.PathLike = "array.toml") -> SensorArray:
    """A :class:`SensorArray` from the text of an ``array.toml``; errors name the key and line."""
    return _array_toml(text, path)[0]


def _array_toml(text: str, path: str | os.PathLike) -> tuple[SensorArray, float | None]:
    doc, ctx = load_toml(text, path)
    fmt = doc.get("format")
    if fmt is None:
        raise ctx.error(f"key is missing; the first line should be format = \"{ARRAY_FORMAT}\"", key="format")
    if fmt != ARRAY_FORMAT:
        raise ctx.error(f"unknown format {fmt!r}; this version of gfimu reads {ARRAY_FORMAT!r}", key="format")
    return array_from_toml(doc, ctx)


def array_from_toml(doc: dict, ctx: TomlContext, *, positions_required: bool = True) -> tuple[SensorArray, float | None]:
    """(array, declared rate_hz or None) from the document of an ``array.toml`` (its format checked), loaded by
    :func:`~gfimu.io.toml_input.load_toml`.

    Another document holding the same ``[[accelerometers]]`` keys (a CSV column map) is read the same way;
    without ``positions_required`` an accelerometer without ``position_m`` sits at the origin (its place is
    given elsewhere)."""
    name = doc.get("name", "array")
    if not isinstance(name, str):
        raise ctx.error(f"expected a string, got {name!r}", key="name")
    rate_hz = doc.get("rate_hz")
    if rate_hz is not None and (not _is_number(rate_hz) or not math.isfinite(rate_hz) or rate_hz <= 0):
        raise ctx.error(f"expected the nominal sample rate in Hz, a number > 0, got {rate_hz!r}", key="rate_hz")
    readings = doc.get("readings", "specific_force")
    if readings not in READINGS:
        raise ctx.error(f"expected what the accelerometers report, {' or '.join(map(repr, READINGS))}, got "
                        f"{readings!r}", key="readings")
    accs_doc = doc.get("accelerometers")
    if accs_doc is None:
        raise ctx.error("no [[accelerometers]] table; an array needs at least one accelerometer", key="accelerometers")
    if not isinstance(accs_doc, list) or not accs_doc or not all(isinstance(a, dict) for a in accs_doc):
        raise ctx.error("expected one or more [[accelerometers]] tables", key="accelerometers")
    accs = []
    seen: dict[str, int] = {}
    for i, a in enumerate(accs_doc):
        accs.append(_accelerometer(ctx, a, i, seen, positions_required))
    gyro, inclinometer = _other_sensors(ctx, doc)
    return (SensorArray(tuple(accs), name, gyro, inclinometer, _body(ctx, doc), readings),
            (None if rate_hz is None else float(rate_hz)))


def _accelerometer_name(ctx: TomlContext, a: dict, i: int, seen: dict[str, int]) -> str:
    """The ``name`` of ``accelerometers[i]``: a non-empty CSV column prefix, not reserved, not in ``seen``
    (name -> index, updated)."""
    t = "accelerometers"
    acc_name = a.get("name")
    if not isinstance(acc_name, str) or not acc_name.strip():
        raise ctx.error(f"expected a non-empty string (the CSV column prefix), got {acc_name!r}", t, i, "name")
    if acc_name != acc_name.strip() or re.search(r"[,\[\]\"\n\r]", acc_name):
        raise ctx.error(f"{acc_name!r} cannot be a CSV column prefix (no commas, brackets, quotes, line breaks "
                        "or surrounding spaces)", t, i, "name")
    if acc_name in ("w", "tilt", "sigma"):
        raise ctx.error(f"{acc_name!r} is reserved (its columns would clash with the gyroscope, inclinometer or "
                        "uncertainty columns)", t, i, "name")
    if acc_name in seen:
        raise ctx.error(f"{acc_name!r} is also the name of accelerometers[{seen[acc_name]}]; names must be unique",
                        t, i, "name")
    seen[acc_name] = i
    return acc_name


def _accelerometer(ctx: TomlContext, a: dict, i: int, seen: dict[str, int], positions_required: bool) -> Accelerometer:
    """The :class:`Accelerometer` of the table ``accelerometers[i]``, every key checked (errors name it)."""
    t = "accelerometers"
    acc_name = _accelerometer_name(ctx, a, i, seen)
    if "position_m" not in a and not positions_required:
        position = np.zeros(3)
    elif "position_m" not in a:
        raise ctx.error(f"accelerometer {acc_name!r} has no position_m (3 numbers, in metres, in the body frame)",
                        t, i)
    else:
        position = _vector(ctx, a["position_m"], 3, t, i, "position_m")
        far = float(np.max(np.abs(position)))
        if far > MAX_POSITION_M / np.sqrt(3.0) and far * np.linalg.norm(position / far) > MAX_POSITION_M:
            raise ctx.error(f"{position.tolist()} puts the accelerometer {far * np.linalg.norm(position / far):.3g} m "
                            f"from the body origin; an accelerometer of one rigid body lies within "
                            f"{MAX_POSITION_M:g} m (position_m is in metres)", t, i, "position_m")
    rot = (_rotation(ctx, a["rotation_body_sensor"], i, acc_name, stacklevel=5) if "rotation_body_sensor" in a
           else np.eye(3))
    axes = a.get("axes", ["x", "y", "z"])
    if (not isinstance(axes, list) or not axes or not all(isinstance(x, str) for x in axes)
            or len(set(axes)) != len(axes) or any(x not in ("x", "y", "z") for x in axes)):
        raise ctx.error(f"expected a list of distinct axes among \"x\", \"y\", \"z\", got {axes!r}", t, i, "axes")
    noise = _optional_std(ctx, a, t, i, "noise_std_mps2", stacklevel=3)
    topic = a.get("topic")
    if topic is not None and (not isinstance(topic, str) or not topic.strip() or topic != topic.strip()):
        raise ctx.error(f"expected the message topic as a non-empty string without surrounding spaces, "
                        f"got {topic!r}", t, i, "topic")
    full_scale = None
    if "range_mps2" in a:
        full_scale = a["range_mps2"]
        if not _is_number(full_scale) or not _finite(full_scale) or full_scale <= 0:
            raise ctx.error(f"expected the full scale in m/s², a finite number > 0, got {_shown(full_scale)}", t,
                            i, "range_mps2")
        if full_scale < MIN_RANGE_MPS2:
            raise ctx.error(f"{full_scale!r} m/s² is no accelerometer's full scale (at least {MIN_RANGE_MPS2:g}: "
                            "±2 g is 19.6); is the unit m/s²?", t, i, "range_mps2")
        full_scale = float(full_scale)
    try:
        return Accelerometer(acc_name, position, rot, tuple(axes), noise, topic=topic, range_mps2=full_scale)
    except ArrayModelError as exc:
        raise ctx.error(str(exc), t, i) from None


def _other_sensors(ctx: TomlContext, doc: dict) -> tuple[Gyroscope | None, Inclinometer | None]:
    """(gyroscope, inclinometer) of the ``[gyroscope]`` and ``[inclinometer]`` tables, None where absent."""
    gyro = inclinometer = None
    for table, cls, key in (("gyroscope", Gyroscope, "noise_std_radps"), ("inclinometer", Inclinometer, "noise_std_rad")):
        if table in doc:
            if not isinstance(doc[table], dict):
                raise ctx.error(f"expected a table [{table}]", key=table)
            obj = cls(_optional_std(ctx, doc[table], table, 0, key, stacklevel=3))
            if table == "gyroscope":
                gyro = obj
            else:
                inclinometer = obj
    return gyro, inclinometer


def _body(ctx: TomlContext, doc: dict) -> Body | None:
    """The rigid body of the ``[body]`` table (its principal inertia), or None."""
    if "body" not in doc:
        return None
    b = doc["body"]
    if not isinstance(b, dict) or "principal_inertia_kgm2" not in b:
        raise ctx.error("[body] needs principal_inertia_kgm2 = [I1, I2, I3]", "body", 0)
    inertia = _vector(ctx, b["principal_inertia_kgm2"], 3, "body", 0, "principal_inertia_kgm2")
    try:
        return Body(tuple(inertia))
    except ArrayModelError as exc:
        raise ctx.error(str(exc), "body", 0, "principal_inertia_kgm2") from None


def read_array_toml(path: str | os.PathLike) -> SensorArray:
    """Read ``array.toml`` (format ``gfimu-array/1``) into a :class:`SensorArray`."""
    return load_array_toml(path)[0]


def load_array_toml(path: str | os.PathLike) -> tuple[SensorArray, float | None]:
    """Read ``array.toml``: (array, its optional ``rate_hz``, the nominal sample rate in Hz)."""
    text = read_utf8_text(path)
    if not text.strip():
        raise LogFormatError(f"file is empty; expected format = \"{ARRAY_FORMAT}\" and [[accelerometers]] tables", path)
    return _array_toml(text, path)


# --- writing -------------------------------------------------------------------------

def _plain(value, where: str, finite: bool = True):
    """``value`` with numpy scalars and arrays as Python numbers and lists (non-finite refused if ``finite``)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v, f"{where}.{k}" if where else str(k), finite) for k, v in value.items()
                if v is not None}
    if isinstance(value, (str, bool)):
        return value
    if isinstance(value, (np.bool_,)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        x = float(value)
        if finite and not math.isfinite(x):
            raise ValueError(f"{where}: cannot write the non-finite number {x!r} to TOML")
        return x
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v, f"{where}[{i}]", finite) for i, v in enumerate(value)]
    raise TypeError(f"{where}: cannot write a {type(value).__name__} to TOML")


_SCALAR = r'(?:[-+0-9][-+0-9.eE_]*|true|false|"[^"\\\n\[\]]*")'
_FLAT_ARRAY = re.compile(r"\[\n(?:[ ]+" + _SCALAR + r",\n)+[ ]*\]")
_NESTED_ARRAY = re.compile(r"\[\n(?:[ ]+\[[^\[\]\n]*\],\n)+[ ]*\]")


def _one_line(match: re.Match) -> str:
    items = [ln.strip().rstrip(",") for ln in match.group(0).split("\n")[1:-1]]
    return "[" + ", ".join(items) + "]"


def format_toml(doc: Mapping, comment: str = "", finite: bool = True) -> str:
    """TOML text of a mapping; arrays of numbers or short strings stay on one line.

    numpy scalars and arrays are accepted; keys whose value is ``None`` are
    left out; ``comment`` lines are written first, each after ``#``. With
    ``finite`` (the default) a NaN or infinite number is refused with a
    ValueError naming its key, otherwise it is written as ``nan``/``inf``.
    """
    text = tomli_w.dumps(_plain(doc, "", finite))
    text = _FLAT_ARRAY.sub(_one_line, text)
    text = _NESTED_ARRAY.sub(_one_line, text)
    head = "".join(f"# {line}\n" for line in comment.splitlines())
    return head + text


def write_toml(doc: Mapping, path: str | os.PathLike, comment: str = "", finite: bool = True) -> None:
    """Write a mapping as TOML (see :func:`format_toml`), atomically."""
    atomic_write_text(path, format_toml(doc, comment, finite))


def array_to_dict(array: SensorArray, rate_hz: float | None = None) -> dict:
    """The ``array.toml`` document of an array (with ``rate_hz``, the nominal sample rate, when given)."""
    doc: dict = {"format": ARRAY_FORMAT, "name": array.name}
    if rate_hz is not None:
        doc["rate_hz"] = float(rate_hz)
    doc["readings"] = array.readings
    accs = []
    for a in array.accelerometers:
        entry: dict = {"name": a.name, "position_m": np.asarray(a.position_m, dtype=float)}
        if not np.array_equal(a.rotation_body_sensor, np.eye(3)):
            entry["rotation_body_sensor"] = np.asarray(a.rotation_body_sensor, dtype=float)
        entry["axes"] = list(a.axes)
        if a.noise_std_mps2 is not None:
            entry["noise_std_mps2"] = float(a.noise_std_mps2)
        if a.topic is not None:
            entry["topic"] = a.topic
        if a.range_mps2 is not None:
            entry["range_mps2"] = float(a.range_mps2)
        accs.append(entry)
    doc["accelerometers"] = accs
    if array.gyroscope is not None:
        doc["gyroscope"] = ({} if array.gyroscope.noise_std_radps is None
                            else {"noise_std_radps": float(array.gyroscope.noise_std_radps)})
    if array.inclinometer is not None:
        doc["inclinometer"] = ({} if array.inclinometer.noise_std_rad is None
                               else {"noise_std_rad": float(array.inclinometer.noise_std_rad)})
    if array.body is not None:
        doc["body"] = {"principal_inertia_kgm2": np.asarray(array.body.principal_inertia_kgm2, dtype=float)}
    return doc


def format_array_toml(array: SensorArray, rate_hz: float | None = None) -> str:
    """Deterministic ``array.toml`` text of an array (floats round-trip exactly)."""
    try:
        return format_toml(array_to_dict(array, rate_hz))
    except ValueError as exc:
        raise InputError(f"array.toml: {exc}") from None


def write_array_toml(array: SensorArray, path: str | os.PathLike, rate_hz: float | None = None) -> None:
    """Write ``array.toml`` atomically (with ``rate_hz`` when given)."""
    atomic_write_text(path, format_array_toml(array, rate_hz))
