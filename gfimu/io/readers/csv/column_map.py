"""The column map (format ``gfimu-csv-map/1``, ``docs/convert.md``): what each column of a table means.

:func:`parse_map` reads the TOML text into a :class:`ColumnMap` (time column and unit, how the file is
split, each accelerometer's and the gyroscope's columns with their unit and sign, each refused with the
key that is wrong); :func:`array_and_order` gives the sensor array the map (or an ``array.toml``) places.
"""

from __future__ import annotations

from dataclasses import dataclass
import dataclasses

import numpy as np

from ....array import Gyroscope, SensorArray
from ...array_toml import array_from_toml, read_array_toml
from ...errors import LogFormatError
from ...toml_input import TomlContext, load_toml
from ...units import STANDARD_GRAVITY_MPS2


MAP_FORMAT = "gfimu-csv-map/1"

MAP_KEYS = ("format", "name", "g_mps2", "csv", "time", "accelerometers", "gyroscope", "rate_hz", "readings", "body",
            "inclinometer")
"""The keys a map may hold at its top: its own and those of array.toml it may carry (a misspelt key is refused,
not passed over: ``g_mps`` for ``g_mps2`` would leave every reading off by the ratio of the two g)."""

G_RANGE_MPS2 = (9.7, 9.9)
"""The values a map's ``g_mps2`` may take [m/s²]: gravity on the Earth's surface lies within 9.76-9.84, and the
conventions tools count [g] in (9.8, 9.81, 9.80665) within that."""


AXES = ("x", "y", "z")


DELIMITERS = {",": ",", ";": ";", "\t": "\t", "tab": "\t", "|": "|", " ": None, "whitespace": None}


@dataclass(frozen=True)
class Column:
    """One column of the map: a name, a list of alternative names or a 0-based index; its unit and sign."""

    column: str | int | tuple[str, ...]
    unit: str | None
    sign: float
    table: str
    index: int
    key: str


@dataclass(frozen=True)
class Sensor:
    """The columns of one accelerometer (or the gyroscope) and the file they are in."""

    name: str
    file: str | tuple[str, ...] | None  # a tuple: alternatives, the first present is read
    time: Column
    axes: dict[str, Column]
    table: str
    index: int
    optional: bool = False


@dataclass(frozen=True)
class Layout:
    """How a file is split into rows and fields."""

    delimiter: str | None  # None: runs of whitespace; "auto": guessed from the header line
    comment: str
    header_row: int  # 1-based line of the header; 0: no header
    skip_rows: int
    decimal: str


@dataclass(frozen=True)
class ColumnMap:
    path: str
    doc: dict
    ctx: TomlContext
    layout: Layout
    file: str | None
    accelerometers: tuple[Sensor, ...]
    gyroscope: Sensor | None
    gyro_rotation: np.ndarray | None
    has_geometry: bool
    placed: tuple[bool, ...]
    g_mps2: float = STANDARD_GRAVITY_MPS2
    """The gravity the file's [g] and [mg] values count in (the map's ``g_mps2``; standard gravity unless given)."""


def is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _column(ctx: TomlContext, value, table: str, index: int, key: str, default_unit: str | None) -> Column:
    unit, sign = default_unit, 1.0
    if isinstance(value, dict):
        unknown = sorted(set(value) - {"column", "unit", "sign"})
        if unknown:
            raise ctx.error(f"unknown key {unknown[0]!r}; a column is {{ column = NAME or INDEX, unit = \"...\", "
                            "sign = 1 or -1 }", table, index, key)
        if "column" not in value:
            raise ctx.error("no column (a header name, a list of alternative names, or a 0-based index)",
                            table, index, key)
        unit = value.get("unit", default_unit)
        sign = value.get("sign", 1)
        value = value["column"]
        if sign not in (1, -1) or isinstance(sign, bool):
            raise ctx.error(f"sign must be 1 or -1, got {sign!r}", table, index, key)
    if unit is not None and not isinstance(unit, str):
        raise ctx.error(f"unit must be a string such as \"m/s^2\", got {unit!r}", table, index, key)
    if isinstance(value, list):
        if not value or not all(isinstance(v, str) and v.strip() for v in value):
            raise ctx.error(f"expected a column name, a list of names or a 0-based index, got {value!r}",
                            table, index, key)
        value = tuple(v.strip() for v in value)
    elif isinstance(value, str):
        if not value.strip():
            raise ctx.error("empty column name", table, index, key)
        value = value.strip()
    elif is_int(value):
        if value < 0:
            raise ctx.error(f"a column index counts from 0, got {value}", table, index, key)
    else:
        raise ctx.error(f"expected a column name, a list of names or a 0-based index, got {value!r}",
                        table, index, key)
    return Column(value, unit, float(sign), table, index, key)


def _sensor(ctx: TomlContext, doc: dict, table: str, index: int, name: str, default_time: Column | None,
            kind: str) -> Sensor:
    file = doc.get("file")
    if isinstance(file, list) and file and all(isinstance(f, str) and f.strip() for f in file):
        file = tuple(f.strip() for f in file)
    elif file is not None and (not isinstance(file, str) or not file.strip()):
        raise ctx.error(f"expected a file name or a list of alternative names, got {file!r}", table, index, "file")
    unit = doc.get("unit")
    if unit is not None and not isinstance(unit, str):
        raise ctx.error(f"expected a unit such as \"m/s^2\", got {unit!r}", table, index, "unit")
    time = _column(ctx, doc["time"], table, index, "time", None) if "time" in doc else default_time
    if time is None:
        raise ctx.error("no time column: give [time] column = NAME (and unit) for every file, or time = ... here",
                        table, index)
    axes = {a: _column(ctx, doc[a], table, index, a, unit) for a in AXES if a in doc}
    if not axes:
        raise ctx.error(f"names no column: give x, y and/or z (the {kind} axes' columns)", table, index)
    optional = doc.get("optional", False)
    if not isinstance(optional, bool):
        raise ctx.error(f"expected true or false, got {optional!r}", table, index, "optional")
    return Sensor(name, file.strip() if isinstance(file, str) else file, time, axes, table, index, optional)


def parse_map(text: str, path: str) -> ColumnMap:
    """A column map from its TOML text; every problem names the map, the key and its line."""
    doc, ctx = load_toml(text, path)
    if doc.get("format") != MAP_FORMAT:
        raise ctx.error(f"expected format = \"{MAP_FORMAT}\" (a column map), got {doc.get('format')!r}", key="format")
    ctx.refuse_unknown(doc, MAP_KEYS, "")
    csv = doc.get("csv", {})
    if not isinstance(csv, dict):
        raise ctx.error("expected a table [csv]", key="csv")
    ctx.refuse_unknown(csv, ("delimiter", "comment", "header_row", "skip_rows", "decimal", "file"), "csv")
    delimiter = csv.get("delimiter", "auto")
    if delimiter != "auto" and (not isinstance(delimiter, str) or delimiter not in DELIMITERS):
        raise ctx.error(f"expected \"auto\", \",\", \";\", \"tab\", \"|\" or \"whitespace\", got {delimiter!r}",
                        "csv", 0, "delimiter")
    comment = csv.get("comment", "#")
    if not isinstance(comment, str):
        raise ctx.error(f"expected a string (\"\" for none), got {comment!r}", "csv", 0, "comment")
    header_row = csv.get("header_row", 1)
    skip_rows = csv.get("skip_rows", 0)
    for key, v in (("header_row", header_row), ("skip_rows", skip_rows)):
        if not is_int(v) or v < 0:
            raise ctx.error(f"expected a whole number >= 0, got {v!r}", "csv", 0, key)
    decimal = csv.get("decimal", ".")
    if decimal not in (".", ",", "auto"):
        raise ctx.error(f"expected \".\", \",\" or \"auto\", got {decimal!r}", "csv", 0, "decimal")
    file = csv.get("file")
    if file is not None and (not isinstance(file, str) or not file.strip()):
        raise ctx.error(f"expected a file name, got {file!r}", "csv", 0, "file")
    layout = Layout(delimiter if delimiter == "auto" else DELIMITERS[delimiter], comment, header_row, skip_rows,
                    decimal)
    default_time = None
    if "time" in doc:
        t = doc["time"]
        if not isinstance(t, dict):
            raise ctx.error("expected a table [time] with column = NAME or INDEX and unit", key="time")
        ctx.refuse_unknown(t, ("column", "unit"), "time")
        if "column" not in t:
            raise ctx.error("no column (the time column's name or 0-based index)", "time", 0)
        default_time = _column(ctx, t, "time", 0, "column", None)
    if "inclinometer" in doc:
        raise ctx.error("the csv reader reads accelerometers and a gyroscope; an inclinometer is not read",
                        key="inclinometer")
    accs_doc = doc.get("accelerometers")
    if not isinstance(accs_doc, list) or not accs_doc or not all(isinstance(a, dict) for a in accs_doc):
        raise ctx.error("expected one or more [[accelerometers]] tables (name, and x, y, z columns)",
                        key="accelerometers")
    accs = []
    for i, a in enumerate(accs_doc):
        name = a.get("name")
        if not isinstance(name, str) or not name.strip():
            raise ctx.error(f"expected a non-empty string, got {name!r}", "accelerometers", i, "name")
        accs.append(_sensor(ctx, a, "accelerometers", i, name, default_time, "accelerometer"))
    gyro = gyro_rotation = None
    if "gyroscope" in doc:
        g = doc["gyroscope"]
        if not isinstance(g, dict):
            raise ctx.error("expected a table [gyroscope]", key="gyroscope")
        gyro = _sensor(ctx, g, "gyroscope", 0, "gyroscope", default_time, "gyroscope")
        if set(gyro.axes) != set(AXES):
            missing = [a for a in AXES if a not in gyro.axes]
            raise ctx.error(f"names no column for {missing[0]}; a gyroscope needs x, y and z", "gyroscope", 0)
        if "rotation_body_sensor" in g:
            r = g["rotation_body_sensor"]
            try:
                rot = np.array(r, dtype=float)
            except (TypeError, ValueError):
                rot = np.zeros(0)
            if (rot.shape != (3, 3) or not np.all(np.isfinite(rot)) or np.max(np.abs(rot @ rot.T - np.eye(3))) > 1e-6
                    or np.linalg.det(rot) < 0):
                raise ctx.error(f"expected a rotation matrix (three rows of three numbers, orthonormal, "
                                f"determinant +1), got {r!r}", "gyroscope", 0, "rotation_body_sensor")
            gyro_rotation = rot
    placed = tuple("position_m" in a or "rotation_body_sensor" in a for a in accs_doc)
    g = doc.get("g_mps2", STANDARD_GRAVITY_MPS2)
    if isinstance(g, bool) or not isinstance(g, (int, float)) or not G_RANGE_MPS2[0] <= g <= G_RANGE_MPS2[1]:
        raise ctx.error(f"expected the gravity the file's [g] values count in, a number from {G_RANGE_MPS2[0]:g} to "
                        f"{G_RANGE_MPS2[1]:g} [m/s²] (9.80665, standard gravity, unless given), got {g!r}",
                        key="g_mps2")
    return ColumnMap(path, doc, ctx, layout, None if file is None else file.strip(), tuple(accs), gyro,
                     gyro_rotation, any(placed), placed, float(g))


def array_and_order(cmap: ColumnMap, array_path: str | None, with_gyro: bool) -> tuple[SensorArray, list[int],
                                                                                        tuple[str, ...], list[str]]:
    """(array, index of the map's accelerometer for each array accelerometer, unplaced names, report lines)."""
    mapped_axes = [tuple(a for a in AXES if a in s.axes) for s in cmap.accelerometers]
    report = []
    if array_path is not None:
        if cmap.has_geometry:
            k = cmap.placed.index(True)
            raise cmap.ctx.error(f"gives position_m / rotation_body_sensor, and --array {array_path} gives the "
                                 "geometry too; give it in one place", "accelerometers", k)
        array = read_array_toml(array_path)
        names = [s.name for s in cmap.accelerometers]
        if len(names) == 1 and len(array.accelerometers) == 1:
            order = [0]
            if array.accelerometers[0].name != names[0]:
                report.append(f"accelerometer {names[0]!r} of the map is {array.accelerometers[0].name!r} of "
                              f"{array_path}")
        else:
            order = []
            for acc in array.accelerometers:
                if acc.name not in names:
                    raise LogFormatError(f"accelerometer {acc.name!r} has no columns in the map {cmap.path} "
                                         f"(it names {', '.join(map(repr, names))})", array_path)
                order.append(names.index(acc.name))
            extra = [i for i in range(len(names)) if i not in order]
            if extra:
                raise cmap.ctx.error(f"accelerometer {names[extra[0]]!r} is not in --array {array_path}",
                                     "accelerometers", extra[0], "name")
        for acc, i in zip(array.accelerometers, order):
            if set(acc.axes) != set(mapped_axes[i]):
                raise cmap.ctx.error(f"names columns for axes {', '.join(mapped_axes[i])} but accelerometer "
                                     f"{acc.name!r} of {array_path} lists axes {', '.join(acc.axes)}",
                                     "accelerometers", i)
        if array.gyroscope is not None and not with_gyro:
            raise LogFormatError(f"has a [gyroscope] but the map {cmap.path} names no gyroscope columns (or they "
                                 "are not in the file)", array_path)
        report.append(f"geometry: {array_path}")
        unplaced: tuple[str, ...] = ()
    else:
        array = array_from_toml(cmap.doc, cmap.ctx, positions_required=False)[0]
        accs = []
        doc = cmap.doc["accelerometers"]
        for i, acc in enumerate(array.accelerometers):
            if "axes" in doc[i] and tuple(doc[i]["axes"]) != mapped_axes[i] and set(doc[i]["axes"]) != set(
                    mapped_axes[i]):
                raise cmap.ctx.error(f"lists axes {doc[i]['axes']!r} but names columns for "
                                     f"{', '.join(mapped_axes[i])}", "accelerometers", i, "axes")
            accs.append(dataclasses.replace(acc, axes=mapped_axes[i]))
        array = dataclasses.replace(array, accelerometers=tuple(accs))
        order = list(range(len(accs)))
        if cmap.has_geometry:
            report.append(f"geometry: {cmap.path}")
            unplaced = tuple(s.name for s, p in zip(cmap.accelerometers, cmap.placed) if not p)
        elif len(accs) == 1:
            report.append(f"geometry: one accelerometer, no place given: at the body origin, its axes the body axes")
            unplaced = ()
        else:
            unplaced = tuple(s.name for s in cmap.accelerometers)
    if with_gyro and array.gyroscope is None:
        array = dataclasses.replace(array, gyroscope=Gyroscope())
    if not with_gyro and array.gyroscope is not None:
        array = dataclasses.replace(array, gyroscope=None)
    return array, order, unplaced, report
