"""The columns of the map read from their tables in SI units (:class:`ColumnReader`): each sensor's file,
its columns found by name or index, their units (map or header, never two) converted by
:mod:`gfimu.io.units`, the signs applied, the times in nanoseconds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import LogFormatError
from ...units import (STANDARD_GRAVITY_MPS2, TimestampError, canonical_unit, same_nanosecond, time_unit_ns,
                      timestamps_ns, unit_factor, unit_help)
from .column_map import Column, ColumnMap, Sensor, is_int
from .files import Source
from .table import DECIMAL_COMMA, Table, rate_warning, read_table


class ColumnReader:
    """The columns of ``cmap`` read from the files of ``input_path`` (each table read once)."""

    def __init__(self, cmap: ColumnMap, input_path: Path, source: Source | None = None):
        self.map = cmap
        self.input = input_path
        self.source = source if source is not None else Source(input_path)
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
        if is_int(column.column):
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
                if kind == "time":
                    return time_unit_ns(u)
                if kind == "acceleration" and canonical_unit(u) in ("g", "mg"):  # counted in the map's g
                    return unit_factor(u, kind) * (self.map.g_mps2 / STANDARD_GRAVITY_MPS2)
                return unit_factor(u, kind)
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
                    if DECIMAL_COMMA.match(tokens[exc.index].strip()) else "")
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
        warning = rate_warning(t, unit, table, j)
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
                        if DECIMAL_COMMA.match(tok):
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
