"""Reading one delimited text file into rows of numbers (:func:`read_table`): splitting by the map's
delimiter, comment prefix, header row and decimal mark, the units a header states, and the check of
the sample rate the times imply (:func:`rate_warning`).
"""

from __future__ import annotations

import csv as _csv
from dataclasses import dataclass
from pathlib import Path
import re

import numpy as np

from ...errors import LogFormatError, read_utf8_text
from ...units import TIME_UNITS_NS, header_name_and_unit, time_unit_ns
from .column_map import Layout


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


DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+([eE][+-]?\d+)?$")
"""A number written with a decimal comma (``decimal = "auto"``)."""


def _refuse_long_lines(path: Path) -> None:
    """A :class:`LogFormatError` naming the file and line when a line of ``path`` is longer than
    :data:`~gfimu.io.tables.MAX_LINE_BYTES`, found reading a block at a time (a 50 MB line of NUL bytes is
    refused after its first block, never held whole)."""
    from ...tables import MAX_LINE_BYTES, line_too_long

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
    from ...tables import MAX_LINE_BYTES, line_too_long

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
                                 and any(DECIMAL_COMMA.match(f) for f in rows[0])):
        rows = [[f.replace(",", ".") for f in r] for r in rows]
    return Table(path, names, headers, units if headers else [None] * n_fields, rows, [ln for ln, _ in data])


PLAUSIBLE_RATE_HZ = (1.0, 100e3)
"""Sample rates [Hz] an accelerometer array records at; times stepping outside suggest a wrong time unit."""


def rate_warning(t: np.ndarray, unit: str, table: Table, j: int) -> str | None:
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
