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

The reader is split by job: :mod:`.column_map` (the map), :mod:`.presets` (the built-in maps and
their files), :mod:`.files` (file, folder or zip), :mod:`.table` (rows of one file),
:mod:`.columns` (the map's columns in SI units), :mod:`.align` (one time base); this module
reads a recording with them and registers ``gfimu convert csv``.

"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
import warnings

import numpy as np

from ....errors import InputError
from ....log import Log
from ....motion import Motion
from ...errors import LogFormatError, LogPlausibilityWarning
from ...plausibility import check_specific_force_scale
from ...time_grid import GAP_FACTOR, MAX_GAP_PERIODS
from .. import Conversion, Reader
from .align import align, resample_linear
from .column_map import AXES, MAP_FORMAT, array_and_order, parse_map
from .columns import ColumnReader
from .files import Source
from .presets import PRESETS, PresetContext, gravity_map, load_map, preset_for
from .table import PLAUSIBLE_RATE_HZ, Table, read_table


def read_csv_recording(input_path, map_spec: str, array_path: str | None = None,
                       gyro_as_reference: bool = False, max_gap_periods: float = MAX_GAP_PERIODS,
                       resample_hz: float | None = None) -> Conversion:
    """Read the file(s) of ``input_path`` with a column map (a TOML file or a preset name)."""
    input_path = Path(input_path)
    cmap, reader, report, without_gravity, text = _map_and_reader(input_path, map_spec)
    gravity = gravity_map(map_spec, reader.source, text) if without_gravity else None
    gravity_sensor = None if gravity is None else parse_map(gravity[0], f"preset {map_spec}").accelerometers[0]
    gyro = cmap.gyroscope
    if gyro is not None and gyro.optional and not reader.gyro_present(gyro):
        report.append(f"gyroscope: not in {reader.file_of(gyro)}; none read")
        gyro = None
    array, order, unplaced, geometry_report = array_and_order(cmap, array_path, gyro is not None)
    # sensors in file order: the array's accelerometers, then the gyroscope
    sensors = [(cmap.accelerometers[i], acc.axes, "acceleration") for acc, i in zip(array.accelerometers, order)]
    if gyro is not None:
        sensors.append((gyro, AXES, "angular_rate"))
    if gravity_sensor is not None:
        sensors.append((gravity_sensor, AXES, "acceleration"))
    groups, tables, blocks, linear = _read_sensors(reader, sensors, gravity_sensor, report)
    linear |= without_gravity
    base_key = blocks[0][0]
    t_out, columns = align(groups, blocks, base_key, tables, max_gap_periods, resample_hz, report)
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
        reference = Motion(t_out, omega_b_radps=_gyro_reference(cmap, reader, omega, input_path).copy())
    log = Log(array, t_out, accel, gyro_b_radps=omega, reference=reference, source=str(input_path))
    _warn_plausibility(reader, log, linear)
    return Conversion(log, tuple(report + geometry_report), unplaced)


def _map_and_reader(input_path: Path, map_spec: str):
    """(column map, :class:`ColumnReader`, report lines, whether the accelerometers read acceleration without
    gravity (a preset says so), the preset's map text or None) of ``map_spec``: a TOML file or a preset, which
    picks its files from what ``input_path`` holds."""
    if not Path(map_spec).exists() and map_spec in PRESETS:
        source = Source(input_path)
        text, read_path, report, without_gravity = preset_for(map_spec, source)
        cmap = parse_map(text, f"preset {map_spec}")
        cmap = dataclasses.replace(cmap, ctx=PresetContext(map_spec, input_path))
        if read_path != input_path:
            source = Source(read_path)
        return cmap, ColumnReader(cmap, read_path, source), report, without_gravity, text
    cmap = load_map(map_spec)
    return cmap, ColumnReader(cmap, input_path), [], False, None


def _read_sensors(reader: ColumnReader, sensors: list, gravity_sensor, report: list[str]):
    """(timestamps and time unit by (file, time column, unit), the table of each, (that key, values) per sensor
    in order, whether a column's header says the acceleration is linear) of ``sensors`` ((sensor, axes, kind)
    each); each file's rows and each sensor's columns said in ``report``."""
    groups: dict[tuple, tuple[np.ndarray, str]] = {}
    tables: dict[tuple, Table] = {}
    linear = False
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
    return groups, tables, blocks, linear


def _gyro_reference(cmap, reader: ColumnReader, omega: np.ndarray | None, input_path: Path) -> np.ndarray:
    """The gyroscope's readings ``omega`` for ``--gyro-as-reference``; a :class:`LogFormatError` saying why
    when there are none (the map names no gyroscope, or its columns or file are not in the recording)."""
    if omega is None and cmap.gyroscope is not None:  # optional, and not in the recording
        where = reader.file_of(cmap.gyroscope)
        names = ", ".join(" or ".join(map(str, c.column)) if isinstance(c.column, tuple) else str(c.column)
                          for c in cmap.gyroscope.axes.values())
        found = (f"its columns ({names}) are not in {where}" if reader.source.exists(where)
                 else f"{where} is not there")
        raise LogFormatError(f"--gyro-as-reference: no gyroscope to take as the reference: {found}", input_path)
    if omega is None:
        raise LogFormatError("--gyro-as-reference: the map names no gyroscope columns", cmap.path)
    return omega


def _warn_plausibility(reader: ColumnReader, log: Log, linear: bool) -> None:
    """The reader's rate warnings and :func:`check_specific_force_scale`'s, naming the files and the units the
    accelerometer columns were read in (each attributed to the caller of :func:`read_csv_recording`)."""
    for warning in reader.rate_warnings:
        warnings.warn(warning, LogPlausibilityWarning, stacklevel=3)
    read_as = []
    for path, cols in reader.accel_units.items():
        names = [c for c, _ in cols]
        units = sorted({u for _, u in cols})
        read_as.append(f"{path} (columns {', '.join(names[:3])}{', ...' if len(names) > 3 else ''} read as "
                       f"{', '.join(f'[{u}]' for u in units)})")
    read_units = {u for cols in reader.accel_units.values() for _, u in cols}
    for warning in check_specific_force_scale(log, "; ".join(read_as), gravity_included=not linear,
                                              read_unit=read_units.pop() if len(read_units) == 1 else "m s^-2"):
        warnings.warn(warning, LogPlausibilityWarning, stacklevel=3)


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
