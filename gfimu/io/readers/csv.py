"""Delimited text tables (phone apps, EuRoC, TUM-style whitespace files, a logger's own CSV): ``gfimu convert csv``.

What the columns mean is said by a *column map*, a TOML document of format
``gfimu-csv-map/1`` (``docs/convert.md``), or
by a built-in preset (:data:`PRESETS`: ``euroc``, ``phyphox``,
``sensorlogger``). The map names the time column and its unit, how the file
is split (delimiter, comment prefix, header row, decimal mark) and, for each
accelerometer axis and the optional gyroscope, the column (by name or
0-based index), its unit and sign. The array's geometry comes either from the
map itself (the keys of ``array.toml``'s ``[[accelerometers]]``) or from an
``array.toml`` given with ``--array``; neither, for one accelerometer, puts it
at the body origin, unrotated.

Units come from the map or from the header (``a [m s^-2]``, ``Time (s)``) and
are converted by :mod:`gfimu.io.units`; a column with no unit in either, or
with two different ones, is refused. Sensors in different files (one file
per sensor, as phone apps and EuRoC write) are brought onto the timestamps of
the first accelerometer's file (or, with ``resample_hz``, onto a uniform
grid) by linear interpolation, over the time span all files share, never
across a gap of a file: a step longer than ``max_gap_periods`` of the file's
nominal period (its median step, :mod:`gfimu.io.time_grid`); the times
of the time base inside a gap are left out and the report says where.

INPUT may be a file, a folder or a zip archive (phyphox and Sensor Logger
export zips); a preset picks its files from what the folder holds (phyphox's
one file per sensor or its ``Raw Data.csv``; Sensor Logger's Android or iOS
export; a EuRoC dataset folder at any level) and reports what it read.
"""

from __future__ import annotations

import argparse
import csv as _csv
import dataclasses
import math
import re
import tomllib
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import Conversion, Reader
from ..time_grid import (GAP_FACTOR, MAX_GAP_PERIODS, find_gaps, interpolate, nominal_rate_hz,
                         uniform_grid)
from ...array import Gyroscope, SensorArray
from ...log import Log
from ...motion import Motion
from ..array_toml import TomlContext as _TomlContext, parse_array_toml, read_array_toml
from ..errors import LogFormatError, LogPlausibilityWarning, read_utf8_text, toml_nested_too_deep
from ...errors import InputError
from ..plausibility import check_specific_force_scale
from ..units import (TIME_UNITS_NS, TimestampError, header_name_and_unit, same_nanosecond, time_unit_ns, timestamps_ns,
                     unit_factor, unit_help)

MAP_FORMAT = "gfimu-csv-map/1"
AXES = ("x", "y", "z")
DELIMITERS = {",": ",", ";": ";", "\t": "\t", "tab": "\t", "|": "|", " ": None, "whitespace": None}

PRESETS: dict[str, str] = {
    "euroc": f'''format = "{MAP_FORMAT}"
name = "euroc-imu0"
# mav0/imu0/data.csv of the EuRoC MAV datasets (and TUM-VI): units in the header
[time]
column = "timestamp"
[[accelerometers]]
name = "imu0"
x = "a_RS_S_x"
y = "a_RS_S_y"
z = "a_RS_S_z"
[gyroscope]
x = "w_RS_S_x"
y = "w_RS_S_y"
z = "w_RS_S_z"
''',
    "phyphox": f'''format = "{MAP_FORMAT}"
name = "phyphox"
# phyphox "Acceleration with g" (or "Linear Acceleration") export, one CSV file; a gyroscope
# in the same file is read when present; any of phyphox's CSV exports (comma, tab or semicolon,
# decimal point or comma)
[csv]
decimal = "auto"
[time]
column = "Time"
[[accelerometers]]
name = "phone"
x = ["Acceleration x", "Linear Acceleration x"]
y = ["Acceleration y", "Linear Acceleration y"]
z = ["Acceleration z", "Linear Acceleration z"]
[gyroscope]
optional = true
x = "Gyroscope x"
y = "Gyroscope y"
z = "Gyroscope z"
''',
    "sensorlogger": f'''format = "{MAP_FORMAT}"
name = "sensorlogger"
# Sensor Logger's CSV export, the folder of its files: time in epoch nanoseconds
[time]
column = "time"
unit = "ns"
[[accelerometers]]
name = "phone"
file = "TotalAcceleration.csv"
unit = "m/s^2"
x = "x"
y = "y"
z = "z"
[gyroscope]
optional = true
file = "Gyroscope.csv"
unit = "rad/s"
x = "x"
y = "y"
z = "z"
''',
}
"""Built-in column maps, used with ``--map NAME``."""

_PHYPHOX_SENSORS = f'''format = "{MAP_FORMAT}"
name = "phyphox"
# phyphox's export of a sensor experiment as one CSV file per sensor (a folder, or the zip phyphox writes)
[csv]
decimal = "auto"
[time]
column = "Time"
[[accelerometers]]
name = "phone"
file = {{file}}
x = "X"
y = "Y"
z = "Z"
[gyroscope]
optional = true
file = "Gyroscope.csv"
x = "X"
y = "Y"
z = "Z"
'''

_SENSORLOGGER_ACCELEROMETER = f'''format = "{MAP_FORMAT}"
name = "sensorlogger"
# Sensor Logger's export without TotalAcceleration.csv: Accelerometer.csv, the acceleration without gravity
[time]
column = "time"
unit = "ns"
[[accelerometers]]
name = "phone"
file = "Accelerometer.csv"
unit = "m/s^2"
x = {{ column = "x", sign = {{sign}} }}
y = {{ column = "y", sign = {{sign}} }}
z = {{ column = "z", sign = {{sign}} }}
[gyroscope]
optional = true
file = "Gyroscope.csv"
unit = "rad/s"
x = "x"
y = "y"
z = "z"
'''


def _gravity_map(name: str, source: "_Source", accel_map: str) -> tuple[str, str] | None:
    """(a one-accelerometer map reading the export's own gravity vector, in the same axes, signs and units as
    ``accel_map`` reads the linear acceleration; the file's name), or None when the export holds none:
    Sensor Logger's Gravity.csv, a phyphox gravity sensor's Gravity.csv."""
    if not source.is_folder or name not in ("sensorlogger", "phyphox"):
        return None
    file = "Gravity.csv"
    if not source.exists(source.folder / file):
        return None
    for linear in ('"Accelerometer.csv"', '"Linear Accelerometer.csv"'):
        if f"file = {linear}" in accel_map:
            return accel_map.replace(f"file = {linear}", f'file = "{file}"', 1), file
    return None


def _metadata(source: "_Source", path: Path) -> dict[str, str]:
    """The first row of Sensor Logger's Metadata.csv as {column: value} (empty when unreadable)."""
    try:
        text = source.text(path)
        if text is None:
            text = read_utf8_text(path)
        rows = list(_csv.reader(text.splitlines()))
    except (LogFormatError, OSError):
        return {}
    if len(rows) < 2:
        return {}
    return {k.strip().lower(): v.strip() for k, v in zip(rows[0], rows[1])}


def _preset_for(name: str, source: "_Source") -> tuple[str, Path, list[str], bool]:
    """(the preset's map text for what ``source`` holds, the input to read, report lines, whether the
    accelerometer file read holds the acceleration without gravity)."""
    folder = source.folder
    if not source.is_folder:
        return PRESETS[name], source.input, [], False
    if name == "euroc":
        for sub in ("mav0/imu0/data.csv", "imu0/data.csv", "data.csv"):
            if source.exists(folder / sub):
                return PRESETS[name], folder / sub, [f"EuRoC: {folder / sub}"], False
        raise LogFormatError("holds no mav0/imu0/data.csv, imu0/data.csv or data.csv (give a EuRoC dataset folder, "
                             "its mav0 or mav0/imu0 folder, or the data.csv)", source.input)
    if name == "phyphox":
        if source.exists(folder / "Raw Data.csv"):
            return PRESETS[name].replace("[csv]\n", '[csv]\nfile = "Raw Data.csv"\n', 1), source.input, [], False
        present = [f for f in ("Accelerometer.csv", "Linear Accelerometer.csv") if source.exists(folder / f)]
        if not present:
            raise LogFormatError("holds neither Accelerometer.csv, Linear Accelerometer.csv nor Raw Data.csv (a "
                                 "phyphox export)", source.input)
        meaning = ("the specific force (gravity included)" if present[0] == "Accelerometer.csv" else
                   "the linear acceleration (gravity removed by the phone), not the specific force: the same at "
                   "every sensor of a rigid body, so ω is unaffected")
        return (_PHYPHOX_SENSORS.replace("{file}", f'"{present[0]}"'), source.input,
                [f"phyphox: {present[0]}, {meaning}"], present[0] != "Accelerometer.csv")
    if name == "sensorlogger":
        if source.exists(folder / "TotalAcceleration.csv") or not source.exists(folder / "Accelerometer.csv"):
            return PRESETS[name], source.input, ["Sensor Logger: TotalAcceleration.csv, the specific force "
                                                 "(gravity included)"], False
        meta_path = next((folder / m for m in ("Metadata.csv", "metadata.csv") if source.exists(folder / m)), None)
        meta = _metadata(source, meta_path) if meta_path is not None else {}
        platform = meta.get("platform", "").lower()
        if platform not in ("ios", "android"):
            raise LogFormatError("holds Accelerometer.csv but no TotalAcceleration.csv, and no Metadata.csv naming "
                                 "the platform (iOS and Android give Accelerometer.csv opposite signs): cannot be "
                                 "read unambiguously", source.input)
        standardised = meta.get("standardisation", "").lower() == "true"
        flip = platform == "ios" and not standardised
        how = ("its signs turned (iOS reports the opposite of Android's convention, +9.81 m/s² up at rest)" if flip
               else "in Android's sign convention" + (" (Standardise Units & Frames on)" if platform == "ios" else ""))
        return (_SENSORLOGGER_ACCELEROMETER.replace("{sign}", "-1" if flip else "1"), source.input,
                [f"Sensor Logger ({meta_path.name}: platform {meta.get('platform')}, app "
                 f"{meta.get('appversion', '?')}): Accelerometer.csv, the acceleration without gravity in m/s², "
                 f"{how}; not the specific force (no TotalAcceleration.csv): the same at every sensor of a rigid "
                 "body, so ω is unaffected"], True)
    return PRESETS[name], source.input, [], False


def resample_linear(t_src_ns: np.ndarray, values: np.ndarray, t_dst_ns: np.ndarray) -> np.ndarray:
    """``values`` (N, k) sampled at ``t_src_ns`` linearly interpolated at ``t_dst_ns`` (inside the source span)."""
    t0 = t_dst_ns[0]
    src = (np.asarray(t_src_ns, dtype=np.int64) - t0).astype(float)
    dst = (np.asarray(t_dst_ns, dtype=np.int64) - t0).astype(float)
    values = np.asarray(values, dtype=float).reshape(len(src), -1)
    return np.column_stack([np.interp(dst, src, values[:, j]) for j in range(values.shape[1])])


# --- the map ------------------------------------------------------------------------------

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
    text: str
    ctx: _TomlContext
    layout: Layout
    file: str | None
    accelerometers: tuple[Sensor, ...]
    gyroscope: Sensor | None
    gyro_rotation: np.ndarray | None
    has_geometry: bool
    placed: tuple[bool, ...]


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _column(ctx: _TomlContext, value, table: str, index: int, key: str, default_unit: str | None) -> Column:
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
    elif _is_int(value):
        if value < 0:
            raise ctx.error(f"a column index counts from 0, got {value}", table, index, key)
    else:
        raise ctx.error(f"expected a column name, a list of names or a 0-based index, got {value!r}",
                        table, index, key)
    return Column(value, unit, float(sign), table, index, key)


def _sensor(ctx: _TomlContext, doc: dict, table: str, index: int, name: str, default_time: Column | None,
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
    too_deep = toml_nested_too_deep(text)
    if too_deep:
        raise LogFormatError(too_deep, path)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise LogFormatError(f"not valid TOML: {exc}", path) from None
    ctx = _TomlContext(Path(path), text)
    if doc.get("format") != MAP_FORMAT:
        raise ctx.error(f"expected format = \"{MAP_FORMAT}\" (a column map), got {doc.get('format')!r}", key="format")
    csv = doc.get("csv", {})
    if not isinstance(csv, dict):
        raise ctx.error("expected a table [csv]", key="csv")
    unknown = sorted(set(csv) - {"delimiter", "comment", "header_row", "skip_rows", "decimal", "file"})
    if unknown:
        raise ctx.error(f"unknown key {unknown[0]!r} (known: delimiter, comment, header_row, skip_rows, decimal, "
                        "file)", "csv", 0, unknown[0])
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
        if not _is_int(v) or v < 0:
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
        unknown = sorted(set(t) - {"column", "unit"})
        if unknown:
            raise ctx.error(f"unknown key {unknown[0]!r} (known: column, unit)", "time", 0, unknown[0])
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
    return ColumnMap(path, text, ctx, layout, None if file is None else file.strip(), tuple(accs), gyro,
                     gyro_rotation, any(placed), placed)


def load_map(spec: str) -> ColumnMap:
    """The column map of a file or of a preset name."""
    p = Path(spec)
    if not p.exists() and spec in PRESETS:
        return parse_map(PRESETS[spec], f"preset {spec}")
    text = read_utf8_text(spec, missing=f"column map not found (a TOML file, or a preset: {', '.join(sorted(PRESETS))})",
                          folder="is a folder; --map takes a TOML file or a preset name")
    return parse_map(text, spec)


# --- tables -------------------------------------------------------------------------------

@dataclass
class Table:
    """A delimited file split into fields: header names and units, data rows and their line numbers."""

    path: Path
    names: list[str]
    headers: list[str]
    units: list[str | None]
    rows: list[list[str]]
    lines: list[int]

    @property
    def n_fields(self) -> int:
        return len(self.rows[0])

    def field(self, j: int) -> list[str]:
        return [r[j] for r in self.rows]

    def shown(self, j: int) -> str:
        return repr(self.headers[j]) if self.headers else f"field {j}"


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return [f.strip().strip('"').strip() for f in line.split(delimiter)]


def _split_quoted(lines: list[str], delimiter: str) -> list[list[str]]:
    """Lines split by a CSV tokenizer: a quoted field may hold the delimiter (``"9,81"`` in a comma file)."""
    return [[f.strip() for f in r] for r in _csv.reader(lines, delimiter=delimiter, quotechar='"',
                                                       skipinitialspace=True)]


_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+([eE][+-]?\d+)?$")
"""A number written with a decimal comma (``decimal = "auto"``)."""


def _refuse_long_lines(path: Path) -> None:
    """A :class:`LogFormatError` naming the file and line when a line of ``path`` is longer than
    :data:`~gfimu.io.tables.MAX_LINE_BYTES`, found reading a block at a time (a 50 MB line of NUL bytes is
    refused after its first block, never held whole)."""
    from ..tables import MAX_LINE_BYTES, line_too_long

    try:
        fh = open(path, "rb")
    except (FileNotFoundError, IsADirectoryError):
        return  # read_utf8_text names these
    with fh:
        line, current = 1, 0  # the line being read, its bytes so far
        for block in iter(lambda: fh.read(1 << 20), b""):
            block = block.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
            parts = block.split(b"\n")
            if current + len(parts[0]) > MAX_LINE_BYTES:
                raise LogFormatError(line_too_long(current + len(parts[0]), ended=len(parts) > 1), path, line)
            for k, part in enumerate(parts[1:-1], start=1):
                if len(part) > MAX_LINE_BYTES:
                    raise LogFormatError(line_too_long(len(part), ended=True), path, line + k)
            if len(parts) > 1:
                line += len(parts) - 1
                current = len(parts[-1])
                if current > MAX_LINE_BYTES:
                    raise LogFormatError(line_too_long(current), path, line)
            else:
                current += len(parts[0])


def read_table(path: Path, layout: Layout, text: str | None = None) -> Table:
    """Split a text file (or ``text``, read from ``path``) by ``layout``; errors name the file and line. A
    line longer than :data:`~gfimu.io.tables.MAX_LINE_BYTES` is refused before the file is read whole."""
    from ..tables import MAX_LINE_BYTES, line_too_long

    if text is None:
        _refuse_long_lines(path)
        text = read_utf8_text(path, folder="is a folder, expected a CSV file", line_of_bad_byte=True)
    lines = text.splitlines()
    if lines and max(map(len, lines)) > MAX_LINE_BYTES // 4:  # characters: up to 4 bytes each
        for k, ln in enumerate(lines):
            if len(ln.encode("utf-8")) > MAX_LINE_BYTES:
                raise LogFormatError(line_too_long(len(ln.encode("utf-8")), ended=True), path, k + 1)
    header = None
    if layout.header_row:
        if len(lines) < layout.header_row:
            raise LogFormatError(f"has {len(lines)} line(s); the map puts the header on line {layout.header_row}",
                                 path)
        header = lines[layout.header_row - 1].strip()
        for prefix in (layout.comment, "#"):
            if prefix and header.startswith(prefix):
                header = header[len(prefix):].strip()
    first = layout.header_row + layout.skip_rows
    data = [(k + 1, ln) for k, ln in enumerate(lines[first:], start=first)
            if ln.strip() and not (layout.comment and ln.lstrip().startswith(layout.comment))]
    if not data:
        raise LogFormatError("has no data rows", path, first + 1)
    delimiter = layout.delimiter
    if delimiter == "auto":
        probe = header if header is not None else data[0][1]
        delimiter = next((d for d in (",", "\t", ";") if d in probe), None)
    names: list[str] = []
    headers: list[str] = []
    units: list[str | None] = []
    def split(block: list[str], quoted: bool) -> list[list[str]]:
        """A CSV tokenizer where a field is quoted; the fast split otherwise."""
        return _split_quoted(block, delimiter) if quoted else [_split(ln, delimiter) for ln in block]

    quoted = delimiter is not None and any('"' in ln for _, ln in data)
    if header is not None:
        headers = split([header], delimiter is not None and '"' in header)[0]
        for h in headers:
            n, u = header_name_and_unit(h)
            names.append(n)
            units.append(u)
    rows = split([ln for _, ln in data], quoted)
    n_fields = len(headers) if headers else len(rows[0])
    for (line, _), r in zip(data, rows):
        if len(r) != n_fields:
            what = "the header has" if headers else "the first row has"
            raise LogFormatError(f"row has {len(r)} fields, {what} {n_fields}", path, line)
    if layout.decimal == "," and delimiter == "," and not quoted:
        raise LogFormatError("the map gives a decimal comma and a comma delimiter, but no field is quoted: a "
                             "number like 9,81 can then not be told from two fields", path)
    if layout.decimal == "," or (layout.decimal == "auto" and (delimiter != "," or quoted)
                                 and any(_DECIMAL_COMMA.match(f) for f in rows[0])):
        rows = [[f.replace(",", ".") for f in r] for r in rows]
    return Table(path, names, headers, units if headers else [None] * n_fields, rows, [ln for ln, _ in data])


# --- reading ------------------------------------------------------------------------------

PLAUSIBLE_RATE_HZ = (1.0, 100e3)
"""Sample rates [Hz] an accelerometer array records at; times stepping outside suggest a wrong time unit."""


def _rate_warning(t: np.ndarray, unit: str, table: Table, j: int) -> str | None:
    """A warning when the median time step gives an implausible sample rate under the time unit read."""
    if t.size < 2:
        return None
    step_ns = float(np.median(np.diff(t)))
    lo, hi = PLAUSIBLE_RATE_HZ
    if step_ns <= 0 or lo <= 1e9 / step_ns <= hi:
        return None
    try:
        scale = time_unit_ns(unit)
    except KeyError:
        return None
    raw = step_ns / scale
    likely = sorted((abs(np.log10(1e9 / (raw * ns)) - 2.5), u) for u, ns in TIME_UNITS_NS.items()
                    if ns != scale and lo <= 1e9 / (raw * ns) <= hi)
    hint = f"; in [{likely[0][1]}] that is {1e9 / (raw * TIME_UNITS_NS[likely[0][1]]):.4g} Hz" if likely else ""
    return (f"{table.path}: the times of {table.shown(j)} step by a median {raw:.6g} {unit}, a sample rate of "
            f"{1e9 / step_ns:.4g} Hz, implausible for an accelerometer array: is the time unit [{unit}] right{hint}?")


class _PresetContext:
    """Errors of a built-in preset name the recording, never a line of the preset's text."""

    def __init__(self, name: str, input_path: Path):
        self.name = name
        self.input = input_path

    def error(self, message: str, table: str = "", index: int = 0, key: str | None = None) -> LogFormatError:
        return LogFormatError(f"{message} (read with the preset {self.name})", self.input)


ZIP_MEMBER_BYTES = 1 << 30
"""Largest zip member read, inflated [bytes]."""
ZIP_BOMB_BYTES = 64 << 20
"""A member inflating beyond this many bytes ..."""
ZIP_BOMB_RATIO = 100
"""... to more than this many times its compressed size is refused as a zip bomb (sensor tables compress 3 to
20 times)."""


def _zip_member(archive: Path, member: str, shown: Path) -> bytes:
    """The bytes of ``member`` of ``archive``, inflated a block at a time and refused (a :class:`LogFormatError`
    naming ``shown``) as soon as they pass :data:`ZIP_MEMBER_BYTES`, or :data:`ZIP_BOMB_BYTES` at more than
    :data:`ZIP_BOMB_RATIO` times the member's compressed size: a small archive never takes the memory of what it
    claims to hold."""
    try:
        with zipfile.ZipFile(archive) as z:
            info = z.getinfo(member)
            packed = max(int(info.compress_size), 1)
            limit = min(ZIP_MEMBER_BYTES, max(ZIP_BOMB_BYTES, ZIP_BOMB_RATIO * packed))
            if info.file_size > limit:
                raise LogFormatError(_zip_too_big(info.file_size, packed, limit), shown)
            blocks, size = [], 0
            with z.open(info) as fh:
                while True:
                    block = fh.read(1 << 20)
                    if not block:
                        break
                    size += len(block)
                    if size > limit:
                        raise LogFormatError(_zip_too_big(size, packed, limit, more=True), shown)
                    blocks.append(block)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError, NotImplementedError) as exc:
        if isinstance(exc, LogFormatError):
            raise
        raise LogFormatError(f"cannot read this member of the zip archive {archive}: {exc}", shown) from None
    return b"".join(blocks)


def _zip_too_big(size: int, packed: int, limit: int, more: bool = False) -> str:
    return (f"inflates to {'more than ' if more else ''}{size / 2**20:.1f} MiB from {packed / 2**10:.1f} KiB in the zip "
            f"archive, beyond the {limit / 2**20:.0f} MiB read from a member of that size (a zip bomb?); unpack it "
            "and give the folder if it is a real recording")


class _Source:
    """The files of a recording: a file, a folder, or a zip archive (its members read in memory)."""

    def __init__(self, input_path: Path):
        self.input = input_path
        self.members: dict[str, str] | None = None  # zip: name inside the archive's top folder -> member
        if input_path.is_file() and zipfile.is_zipfile(input_path):
            try:
                with zipfile.ZipFile(input_path) as z:
                    names = [n for n in z.namelist() if not n.endswith("/")]
            except (zipfile.BadZipFile, OSError) as exc:
                raise LogFormatError(f"cannot read this zip archive: {exc}", input_path) from None
            twice = sorted({n for n in names if names.count(n) > 1})
            if twice:  # which of the two is read would depend on the zip library
                raise LogFormatError(f"the zip archive holds {twice[0]!r} {names.count(twice[0])} times; which one is "
                                     "the recording is not known (keep one)", input_path)
            tops = {n.split("/", 1)[0] for n in names if "/" in n}
            strip = (next(iter(tops)) + "/") if len(tops) == 1 and all("/" in n for n in names) else ""
            self.members = {n[len(strip):]: n for n in names}
        self.is_folder = input_path.is_dir() or self.members is not None
        self.folder = input_path if self.is_folder else input_path.parent

    def exists(self, path: Path) -> bool:
        if self.members is not None and self.input in path.parents:
            return path.relative_to(self.input).as_posix() in self.members
        return path.is_file()

    def text(self, path: Path) -> str | None:
        """The text of a zip member (None for a file on disk, which :func:`read_table` reads itself)."""
        if self.members is None or self.input not in path.parents:
            return None
        raw = _zip_member(self.input, self.members[path.relative_to(self.input).as_posix()], path)
        try:
            return raw.decode("utf-8").lstrip("\ufeff")
        except UnicodeDecodeError as exc:
            raise LogFormatError(f"not UTF-8 text (byte {exc.start})", path,
                                 raw[: exc.start].count(b"\n") + 1) from None


class _Reader:
    def __init__(self, cmap: ColumnMap, input_path: Path, source: _Source | None = None):
        self.map = cmap
        self.input = input_path
        self.source = source if source is not None else _Source(input_path)
        self.folder = self.source.folder
        self.tables: dict[Path, Table] = {}
        self.rate_warnings: list[str] = []  # issued once the recording has been read
        self.accel_units: dict[Path, list[tuple[str, str]]] = {}  # file -> (column, unit read) of accelerometers

    def error(self, message: str, column: Column) -> LogFormatError:
        return self.map.ctx.error(message, column.table, column.index, column.key)

    def file_of(self, sensor: Sensor) -> Path:
        name = sensor.file or self.map.file
        if name is None:
            if self.source.is_folder:
                what = "a zip archive" if self.source.members is not None else "a folder"
                raise self.map.ctx.error(f"{self.input} is {what} and the map names no file for this sensor "
                                         "(give file = NAME here or [csv] file)", sensor.table, sensor.index)
            return self.input
        if isinstance(name, tuple):  # alternatives: the first present
            return next((self.folder / n for n in name if self.source.exists(self.folder / n)), self.folder / name[0])
        return self.folder / name

    def existing_file_of(self, sensor: Sensor) -> Path:
        """:meth:`file_of`, refused naming the map's ``file`` key when that file is missing."""
        path = self.file_of(sensor)
        if path != self.input and not self.source.exists(path):
            shown = (" or ".join(str(self.folder / n) for n in sensor.file) if isinstance(sensor.file, tuple)
                     else str(path))
            if sensor.file is not None:
                raise self.map.ctx.error(f"{shown}: file not found", sensor.table, sensor.index, "file")
            raise self.map.ctx.error(f"{shown}: file not found", "csv", 0, "file")
        return path

    def table(self, path: Path) -> Table:
        if path not in self.tables:
            self.tables[path] = read_table(path, self.map.layout, self.source.text(path))
        return self.tables[path]

    def find(self, table: Table, column: Column, required: bool = True) -> int | None:
        if _is_int(column.column):
            if column.column < table.n_fields:
                return column.column
            if not required:
                return None
            raise self.error(f"column index {column.column} is past the last field of {table.path} "
                             f"({table.n_fields} fields, counted from 0)", column)
        wanted = column.column if isinstance(column.column, tuple) else (column.column,)
        for w in wanted:
            for pool in (table.names, table.headers):
                hits = [j for j, n in enumerate(pool) if n == w]
                if len(hits) == 1:
                    return hits[0]
            hits = [j for j, n in enumerate(table.names) if n.casefold() == w.casefold().lstrip("#").strip()]
            if len(hits) == 1:
                return hits[0]
            if len(hits) > 1:
                raise self.error(f"column {w!r} appears {len(hits)} times in {table.path}", column)
        if not required:
            return None
        if not table.headers:
            raise self.error(f"{table.path} has no header (header_row = 0): give the column as a 0-based index",
                             column)
        shown = " or ".join(repr(w) for w in wanted)
        raise self.error(f"column {shown} is not in {table.path} (its columns: "
                         f"{', '.join(repr(h) for h in table.headers)})", column)

    def unit(self, table: Table, j: int, column: Column, kind: str) -> tuple[float, str]:
        """(factor to the canonical unit, or to ns for time; the unit's text)."""
        header_unit = table.units[j]

        def factor(u: str) -> float:
            try:
                return time_unit_ns(u) if kind == "time" else unit_factor(u, kind)
            except KeyError:
                expected = "[ns], [us], [ms] or [s]" if kind == "time" else unit_help(kind)
                raise self.error(f"unit [{u}] of {table.shown(j)} in {table.path} is not understood here; "
                                 f"expected {expected}", column) from None

        if header_unit is not None and column.unit is not None:
            try:
                time_unit_ns(header_unit) if kind == "time" else unit_factor(header_unit, kind)
            except KeyError:  # bracketed text that is no unit ("ax (raw)"): the map says the unit
                header_unit = None
        if header_unit is None and column.unit is None:
            what = ("the time column" if kind == "time" else f"column {table.shown(j)}")
            expected = "ns, us, ms or s" if kind == "time" else unit_help(kind)
            raise self.error(f"{what} of {table.path} has no unit in its header nor in the map; its unit is "
                             f"ambiguous: give unit = \"...\" ({expected})", column)
        if header_unit is not None and column.unit is not None and factor(header_unit) != factor(column.unit):
            raise self.error(f"conflicting units for {table.shown(j)} of {table.path}: [{header_unit}] in the "
                             f"header, [{column.unit}] in the map", column)
        u = column.unit if column.unit is not None else header_unit
        return factor(u), u

    def timestamps(self, table: Table, column: Column) -> tuple[np.ndarray, str]:
        j = self.find(table, column)
        scale, unit = self.unit(table, j, column, "time")
        tokens = table.field(j)
        try:
            t = timestamps_ns(tokens, int(scale))
        except TimestampError as exc:
            hint = (" (a decimal comma: give [csv] decimal = \",\" or \"auto\" in the map)"
                    if _DECIMAL_COMMA.match(tokens[exc.index].strip()) else "")
            raise LogFormatError(f"{table.shown(j)}: {exc}{hint}", table.path, table.lines[exc.index]) from None
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            k = int(bad[0]) + 1
            if t[k] == t[k - 1] and same_nanosecond(tokens[k - 1], tokens[k]):
                raise LogFormatError(f"time {tokens[k]} ({table.shown(j)}) and the previous row's {tokens[k - 1]} "
                                     f"(line {table.lines[k - 1]}) are the same nanosecond in [{unit}]; "
                                     "is the time unit right?", table.path, table.lines[k])
            raise LogFormatError(f"time {tokens[k]} ({table.shown(j)}) is not after the previous row's "
                                 f"{tokens[k - 1]} (line {table.lines[k - 1]}); time must be strictly increasing",
                                 table.path, table.lines[k])
        warning = _rate_warning(t, unit, table, j)
        if warning is not None:
            self.rate_warnings.append(warning)
        return t, unit

    def _one_use(self, table: Table, j: int, column: Column, axis: str) -> None:
        """Refuse a column of ``table`` mapped to a second axis (two readings of one number are no two readings)."""
        used = self.__dict__.setdefault("_used", {})
        other = used.setdefault((table.path, j), axis)
        if other != axis:
            raise self.error(f"column {table.shown(j)} of {table.path} is mapped to {other} already; each axis needs a "
                             "column of its own", column)

    def values(self, table: Table, sensor: Sensor, kind: str, axes: tuple[str, ...]) -> tuple[np.ndarray, list[str]]:
        out = np.empty((len(table.rows), len(axes)))
        shown = []
        for c, a in enumerate(axes):
            column = sensor.axes[a]
            j = self.find(table, column)
            self._one_use(table, j, column, f"{sensor.name}.{a}")
            factor, unit = self.unit(table, j, column, kind)
            tokens = table.field(j)
            try:
                v = np.array(tokens).astype(float)
            except ValueError:
                for k, tok in enumerate(tokens):
                    try:
                        float(tok)
                    except ValueError:
                        what = "is empty" if not tok else f"value {tok!r} is not a number"
                        if _DECIMAL_COMMA.match(tok):
                            what += " (a decimal comma: give [csv] decimal = \",\" or \"auto\" in the map)"
                        raise LogFormatError(f"{table.shown(j)} (field {j + 1}) {what}", table.path,
                                             table.lines[k]) from None
                raise
            out[:, c] = v * (factor * column.sign)
            if kind == "acceleration":
                self.accel_units.setdefault(table.path, []).append((table.shown(j), unit))
            shown.append(f"{a} = {'-' if column.sign < 0 else ''}{table.shown(j)} [{unit}]")
        return out, shown

    def gyro_present(self, sensor: Sensor) -> bool:
        path = self.file_of(sensor)
        if not self.source.exists(path):
            return False
        table = self.table(path)
        return all(self.find(table, c, required=False) is not None for c in sensor.axes.values())


def _array_and_order(cmap: ColumnMap, array_path: str | None, with_gyro: bool) -> tuple[SensorArray, list[int],
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
        array = parse_array_toml(cmap.text, cmap.path, expected_format=MAP_FORMAT, positions_required=False)
        accs = []
        doc = tomllib.loads(cmap.text)["accelerometers"]
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


MAX_SHOWN_GAPS = 5
"""Gaps listed one by one in the report; the others are counted."""


def _align(groups: dict, blocks: list, base_key: tuple, tables: dict, max_gap_periods: float,
           resample_hz: float | None, report: list[str]) -> tuple[np.ndarray, list[np.ndarray]]:
    """The log's timestamps and each block's values on them, never interpolated across a gap of any file.

    The time base is the first accelerometer's rows (or, with ``resample_hz``, a uniform grid), over the
    span all files share; its times strictly inside a gap of a file whose columns are interpolated (a step
    over ``max_gap_periods`` of that file's nominal period) are left out, and the report says where.
    """
    def name(key: tuple) -> str:
        same_file = sum(1 for k in groups if k[0] == key[0]) > 1
        return str(key[0]) + (f" (time column {key[1]!r})" if same_file else "")

    lo = max(int(g[0][0]) for g in groups.values())
    hi = min(int(g[0][-1]) for g in groups.values())
    t_base = groups[base_key][0]
    if resample_hz is None:
        in_span = (t_base >= lo) & (t_base <= hi)
        grid = t_base[in_span]
        interpolated = [k for k in groups if k != base_key]
    else:
        period = max(1, int(round(1e9 / resample_hz)))
        grid = uniform_grid(lo, hi, period) if hi >= lo else np.zeros(0, dtype=np.int64)
        interpolated = list(groups)
    if len(groups) > 1 and grid.size < 2:
        raise LogFormatError(f"the files {', '.join(str(k[0]) for k in groups)} share no common time span "
                             "(are their times in the same clock and unit?)", base_key[0])
    if resample_hz is not None:
        report.append(f"resampled: {', '.join(name(k) for k in groups)} linearly interpolated onto a uniform grid "
                      f"at {resample_hz:g} Hz (every {period} ns) over the span all files share "
                      f"({(hi - lo) * 1e-9:.3f} s)")
    elif len(groups) > 1:
        report.append(f"aligned: {', '.join(name(k) for k in interpolated)} linearly interpolated onto the "
                      f"timestamps of {base_key[0]}; {int(np.count_nonzero(~in_span))} row(s) of {base_key[0]} "
                      "outside the span all files share left out")
    t0 = int(grid[0]) if grid.size else 0
    keep = np.ones(grid.size, dtype=bool)
    found = []  # (start, end, file, lines, period, rows left out)
    gaps = {k: find_gaps(groups[k][0], max_gap_periods) for k in groups}
    for k in interpolated:
        g = gaps[k]
        t = groups[k][0]
        for a, b in zip(g.start_ns.tolist(), g.end_ns.tolist()):
            inside = (grid > a) & (grid < b)
            n = int(np.count_nonzero(inside & keep))
            if inside.any():
                keep &= ~inside
                i = int(np.searchsorted(t, a))
                lines = (tables[k].lines[i], tables[k].lines[i + 1])
                found.append((a, b, name(k), lines, g.period_ns, n))
    found.sort()
    for a, b, where, (la, lb), p, n in found[:MAX_SHOWN_GAPS]:
        report.append(f"gap: {where} has no row from {(a - t0) * 1e-9:.3f} s to {(b - t0) * 1e-9:.3f} s of the log "
                      f"(lines {la} to {lb}, a step of {(b - a) * 1e-9:.3f} s, over {max_gap_periods:g} of its "
                      f"{p * 1e-6:.4g} ms periods): {n} row(s) of the time base in it left out, not interpolated")
    if len(found) > MAX_SHOWN_GAPS:
        rest = found[MAX_SHOWN_GAPS:]
        report.append(f"gap: {len(rest)} more, {sum(f[5] for f in rest)} row(s) of the time base left out in them")
    if found:
        report.append(f"gaps: {len(found)} step(s) over {max_gap_periods:g} periods in the interpolated files, "
                      f"{sum(f[5] for f in found)} row(s) of the time base left out; the log has a time gap at each")
    elif resample_hz is not None or len(groups) > 1:
        report.append(f"gaps: no step over {max_gap_periods:g} periods in the interpolated files")
    t_out = grid[keep]
    if resample_hz is None and len(gaps[base_key]):
        g = gaps[base_key]
        # only those whose two rows are both in the written log (the others lie in rows left out)
        step = np.searchsorted(t_out, g.start_ns)
        inside = step < t_out.size - 1
        inside[inside] &= (t_out[step[inside]] == g.start_ns[inside]) & (t_out[step[inside] + 1] == g.end_ns[inside])
        kept = int(np.count_nonzero(inside))
        report.append(f"gaps of the time base {base_key[0]}: {kept} step(s) over {max_gap_periods:g} of its "
                      f"{g.period_ns * 1e-6:.4g} ms periods, kept as time gaps of the log"
                      + (f" ({len(g) - kept} more in rows left out)" if kept < len(g) else ""))
    if resample_hz is None and t_out.size > 2:
        dt = np.diff(t_out)
        breaks = int(np.count_nonzero(dt > GAP_FACTOR * float(np.median(dt))))
        if breaks > len(found) + len(gaps[base_key]):
            rate = nominal_rate_hz(t_out)
            report.append(f"timing: {breaks} step(s) of the log's timestamps exceed {GAP_FACTOR:g} of their median "
                          f"{float(np.median(dt)) * 1e-6:.4g} ms (jitter of {base_key[0]}'s times); readers of the "
                          f"log treat each as a break, where estimators restart: --resample-hz {rate:.4g} puts the "
                          "log on a uniform grid")
    columns = []
    for key, values in blocks:
        if key == base_key and resample_hz is None:
            columns.append(values[in_span][keep])
        else:
            columns.append(interpolate(groups[key][0], values, t_out))
    return t_out, columns


def read_csv_recording(input_path, map_spec: str, array_path: str | None = None,
                       gyro_as_reference: bool = False, max_gap_periods: float = MAX_GAP_PERIODS,
                       resample_hz: float | None = None) -> Conversion:
    """Read the file(s) of ``input_path`` with a column map (a TOML file or a preset name)."""
    input_path = Path(input_path)
    report: list[str] = []
    without_gravity = False  # the accelerometers read acceleration without gravity (a preset says so)
    if not Path(map_spec).exists() and map_spec in PRESETS:
        source = _Source(input_path)
        text, read_path, report, without_gravity = _preset_for(map_spec, source)
        cmap = parse_map(text, f"preset {map_spec}")
        cmap = dataclasses.replace(cmap, ctx=_PresetContext(map_spec, input_path))
        if read_path != input_path:
            source = _Source(read_path)
        reader = _Reader(cmap, read_path, source)
    else:
        cmap = load_map(map_spec)
        reader = _Reader(cmap, input_path)
    gravity = _gravity_map(map_spec, reader.source, text) if without_gravity else None
    gravity_sensor = None if gravity is None else parse_map(gravity[0], f"preset {map_spec}").accelerometers[0]
    gyro = cmap.gyroscope
    if gyro is not None and gyro.optional and not reader.gyro_present(gyro):
        report.append(f"gyroscope: not in {reader.file_of(gyro)}; none read")
        gyro = None
    array, order, unplaced, geometry_report = _array_and_order(cmap, array_path, gyro is not None)
    # sensors in file order: the array's accelerometers, then the gyroscope
    sensors = [(cmap.accelerometers[i], acc.axes, "acceleration") for acc, i in zip(array.accelerometers, order)]
    if gyro is not None:
        sensors.append((gyro, AXES, "angular_rate"))
    if gravity_sensor is not None:
        sensors.append((gravity_sensor, AXES, "acceleration"))
    groups: dict[tuple, tuple[np.ndarray, str]] = {}
    tables: dict[tuple, Table] = {}
    linear = without_gravity
    blocks = []
    for sensor, axes, kind in sensors:
        path = reader.existing_file_of(sensor)
        table = reader.table(path)
        key = (path, sensor.time.column, sensor.time.unit)
        if key not in groups:
            t, unit = reader.timestamps(table, sensor.time)
            groups[key] = (t, unit)
            tables[key] = table
            report.append(f"{path}: {t.size} rows, time from {table.shown(reader.find(table, sensor.time))} "
                          f"in [{unit}]")
        values, shown = reader.values(table, sensor, kind, axes)
        blocks.append((key, values))
        report.append(f"  {'gravity' if sensor is gravity_sensor else sensor.name}: {', '.join(shown)}")
        if kind == "acceleration" and sensor is not gravity_sensor:
            linear |= any("Linear" in sh for sh in shown)
    base_key = blocks[0][0]
    t_out, columns = _align(groups, blocks, base_key, tables, max_gap_periods, resample_hz, report)
    n_acc = len(array.accelerometers)
    accel = np.hstack(columns[:n_acc])
    omega = None
    if gyro is not None:
        omega = columns[n_acc]
        if cmap.gyro_rotation is not None:
            omega = omega @ cmap.gyro_rotation.T
    if gravity_sensor is not None:  # the export's own gravity added back: the readings are the specific force
        accel = accel + columns[-1]
        linear = False
        report.append(f"specific force: the linear acceleration plus the phone's own gravity vector ({gravity[1]}), "
                      "so attitude and gravity-free acceleration can be estimated")
    array = dataclasses.replace(array, readings="linear_acceleration" if linear else array.readings)
    if array.readings == "linear_acceleration":
        linear = True
        report.append("readings: linear acceleration (gravity removed by the phone), recorded as readings = "
                      "\"linear_acceleration\" in array.toml: ω and the acceleration a are estimated, attitude "
                      "(--orientation, --tum) is refused" + ("" if gravity_sensor is not None or not without_gravity else
                                   " (the export holds no Gravity.csv to add back)"))
    if t_out.size < 2:
        raise LogFormatError(f"holds {t_out.size} sample(s); a log needs at least two", base_key[0])
    reference = None
    if gyro_as_reference:
        if omega is None and cmap.gyroscope is not None:  # optional, and not in the recording
            where = reader.file_of(cmap.gyroscope)
            names = ", ".join(" or ".join(map(str, c.column)) if isinstance(c.column, tuple) else str(c.column)
                              for c in cmap.gyroscope.axes.values())
            found = (f"its columns ({names}) are not in {where}" if reader.source.exists(where)
                     else f"{where} is not there")
            raise LogFormatError(f"--gyro-as-reference: no gyroscope to take as the reference: {found}", input_path)
        if omega is None:
            raise LogFormatError("--gyro-as-reference: the map names no gyroscope columns", cmap.path)
        reference = Motion(t_out, omega_b_radps=omega.copy())
    log = Log(array, t_out, accel, gyro_b_radps=omega, reference=reference, source=str(input_path))
    for warning in reader.rate_warnings:
        warnings.warn(warning, LogPlausibilityWarning, stacklevel=2)
    read_as = []
    for path, cols in reader.accel_units.items():
        names = [c for c, _ in cols]
        units = sorted({u for _, u in cols})
        read_as.append(f"{path} (columns {', '.join(names[:3])}{', ...' if len(names) > 3 else ''} read as "
                       f"{', '.join(f'[{u}]' for u in units)})")
    read_units = {u for cols in reader.accel_units.values() for _, u in cols}
    for warning in check_specific_force_scale(log, "; ".join(read_as), gravity_included=not linear,
                                              read_unit=read_units.pop() if len(read_units) == 1 else "m s^-2"):
        warnings.warn(warning, LogPlausibilityWarning, stacklevel=2)
    return Conversion(log, tuple(report + geometry_report), unplaced)


# --- reader of `gfimu convert csv` ------------------------------------------------------------

def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--map", required=True, metavar="MAP",
                        help="column map: a TOML file (format gfimu-csv-map/1: time column and unit, delimiter, "
                             "header row, each axis's column, unit [m/s^2, g, mg, rad/s, deg/s ...] and sign) or a "
                             f"preset: {', '.join(sorted(PRESETS))} (required; no default)")
    parser.add_argument("--array", default=None, metavar="ARRAY.toml",
                        help="array.toml giving the accelerometers' positions [m] and rotations, matched to the "
                             "map's accelerometers by name (default: none: the map's own position_m and "
                             "rotation_body_sensor, or --extrinsics)")
    parser.add_argument("--gyro-as-reference", action="store_true",
                        help="also write the gyroscope [rad/s] as reference.csv, the angular-velocity reference of "
                             "gfimu evaluate (default: off)")
    parser.add_argument("--max-gap-periods", type=float, default=MAX_GAP_PERIODS,
                        help="a step of a file's times up to this many of its nominal periods (its median step) "
                             "[periods] is interpolated over; in a longer one no row is interpolated, the log has a "
                             f"time gap there and the report says where (default {MAX_GAP_PERIODS:g})")
    parser.add_argument("--resample-hz", type=float, default=None, metavar="RATE",
                        help="put the log on a uniform grid at RATE [Hz]: every file linearly interpolated, never "
                             "across a gap (default: none: the first accelerometer's own timestamps)")


def read(path, map: str, array: str | None = None, gyro_as_reference: bool = False,  # noqa: A002
         max_gap_periods: float = MAX_GAP_PERIODS, resample_hz: float | None = None) -> Conversion:
    """Columns of one or more delimited text files, by a column map."""
    if not (math.isfinite(max_gap_periods) and max_gap_periods >= GAP_FACTOR):
        raise InputError(f"--max-gap-periods: expected a number >= {GAP_FACTOR:g}, got {max_gap_periods!r}")
    if resample_hz is not None and not (math.isfinite(resample_hz) and 0 < resample_hz <= PLAUSIBLE_RATE_HZ[1]):
        raise InputError(f"--resample-hz: expected a rate in Hz above 0 and at most {PLAUSIBLE_RATE_HZ[1]:g}, "
                         f"got {resample_hz!r}")
    return read_csv_recording(path, map, array, gyro_as_reference, max_gap_periods, resample_hz)


READER = Reader(
    name="csv",
    summary="delimited text files (CSV, semicolon, tab or whitespace; phyphox, Sensor Logger, EuRoC, TUM and "
            "others) read by a column map (--map FILE.toml or a preset)",
    read=read,
    add_arguments=_add_arguments,
    input_help="the CSV file, or the folder or zip archive holding the files the map names",
)

__all__ = ["MAP_FORMAT", "PRESETS", "READER", "load_map", "parse_map", "read_csv_recording", "read_table",
           "resample_linear"]
