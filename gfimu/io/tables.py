"""CSV tables of a log: ``imu.csv`` (readings) and motion tables (truth, reference, estimates).

Layout (see ``docs/log-format.md``): the first column is ``#timestamp [ns]``,
every other column carries its unit in brackets. Every problem raises
:class:`~gfimu.io.errors.LogFormatError` naming file, line and column:
missing, duplicated or unknown-unit columns, timestamps that are not strictly
increasing, empty files, ragged rows, text where a number belongs. Extra
columns are ignored.

Finite values. ``imu.csv`` readings may be ``nan``, ``inf`` or huge numbers
(a sensor's glitch): they are read as written and masked later, with a
warning; text that is not a number is an error. Truth and reference must be
finite, except in reference rows marked ``valid`` = 0; estimates may hold
non-finite values (``allow_nan=True``).

Validity mask. ``reference.csv`` may carry a column ``valid []`` holding 1
where the reference is valid and 0 where it is not (for example a saturated
reference gyro).

Writing goes through :func:`gfimu.io.atomic.atomic_write`. Floats are
written with Python's shortest round-trip representation, so reading a
written file gives back exactly the same numbers; timestamps are integer
nanoseconds.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..array import SensorArray
from ..log import GYRO_COLUMNS, TILT_COLUMNS, Log
from ..motion import QUANTITIES, Motion
from ..parallel import forked_map
from .atomic import atomic_write
from .errors import LogFormatError
from .units import (KIND_OF_UNIT, TIME_UNITS_NS, UNITS, TimestampError, canonical_unit, same_nanosecond, timestamps_ns,
                    unit_factor, unit_help)
from ..errors import InputError

TIMESTAMP_HEADER = "#timestamp [ns]"
VALID_COLUMN = "valid"

_ROWS_PER_BLOCK = 4096
"""Rows formatted at a time when writing CSV: the unit of work of the writer's workers, and short enough
that each block's text stays small."""


def _format_block(timestamps: list[int], values: list[list[float]], fmt, flags: list[int] | None = None) -> str:
    """CSV text of one block of rows: timestamp, values, then optional integer flags."""
    if flags is None:
        return "".join(f"{t},{','.join(map(fmt, row))}\n" for t, row in zip(timestamps, values))
    return "".join(f"{t},{','.join(map(fmt, row))}{',' if row else ''}{flag}\n"
                   for t, row, flag in zip(timestamps, values, flags))


class _BlockText:
    """CSV text of the block of rows starting at a given row (a job for :func:`gfimu.parallel.forked_map`)."""

    def __init__(self, timestamps_ns: np.ndarray, values: np.ndarray, fmt, flags: np.ndarray | None):
        self.timestamps_ns, self.values, self.fmt, self.flags = timestamps_ns, values, fmt, flags

    def __call__(self, start: int) -> str:
        stop = start + _ROWS_PER_BLOCK
        return _format_block(self.timestamps_ns[start:stop].tolist(), self.values[start:stop].tolist(), self.fmt,
                             None if self.flags is None else self.flags[start:stop].tolist())


def _csv_chunks(header: list[str], timestamps_ns: np.ndarray, values: np.ndarray, fmt,
                flags: np.ndarray | None = None, workers: int = 0) -> Iterator[str]:
    """The header line, then the rows in blocks of :data:`_ROWS_PER_BLOCK`, formatted by up to ``workers``
    forked processes (0: one per CPU; :mod:`gfimu.parallel`), written in order: the same text either way."""
    yield ",".join(header) + "\n"
    yield from forked_map(_BlockText(timestamps_ns, values, fmt, flags), range(0, timestamps_ns.size, _ROWS_PER_BLOCK),
                          workers, min_tasks=PARALLEL_MIN_BLOCKS)


def _float_formatter(digits: int | None):
    if digits is None:
        return float.__repr__
    if not 1 <= int(digits) <= 17:
        raise InputError(f"digits must be between 1 and 17, got {digits}")
    spec = f"%.{int(digits)}g"
    return spec.__mod__


PARALLEL_MIN_BLOCKS = 8
"""Blocks (of :data:`_ROWS_PER_BLOCK` rows written, of :data:`_BLOCK_BYTES` read) from which a table is
formatted or parsed in worker processes (:mod:`gfimu.parallel`); shorter tables in this process,
where starting the workers and copying their results back would cost more than they save (the
10,000-sample cube log's reading, writing and model check each took longer with workers)."""


# --- CSV reading ---------------------------------------------------------------

_HEADER_RE = re.compile(r"^(.*?)\s*\[([^\[\]]*)\]\s*$")


def parse_header(header: str, path, line: int = 1) -> tuple[list[tuple[str, str | None]], str]:
    """The (name, unit or None) of each column of a table's header line, and its timestamp unit (a key of
    :data:`~gfimu.io.units.TIME_UNITS_NS`); :class:`LogFormatError` naming ``path`` and ``line`` when the
    first column is not a timestamp with a time unit. The rules of every imu.csv and motion table, also
    of the rows ``gfimu live`` reads."""
    columns: list[tuple[str, str | None]] = []
    for field in header.split(","):
        field = field.strip().strip('"').strip()
        m = _HEADER_RE.match(field)
        columns.append((m.group(1).strip(), m.group(2).strip()) if m else (field.strip(), None))
    first_name, first_unit = columns[0]
    if first_name.lstrip("#").strip().lower() != "timestamp":
        hint = " (columns must be separated by commas)" if (";" in header or "\t" in header) else ""
        raise LogFormatError(f"the first column must be {TIMESTAMP_HEADER!r}, found {header.split(',')[0]!r}"
                             f"{hint}", path, line)
    unit = canonical_unit(first_unit) if first_unit is not None else None
    if unit not in TIME_UNITS_NS:
        raise LogFormatError(
            f"timestamp unit [{first_unit}] not understood; expected [ns] (or, converted: [us], [ms], [s])"
            if first_unit is not None else f"timestamp column has no unit; expected {TIMESTAMP_HEADER!r}",
            path, line)
    if len(columns) < 2:
        raise LogFormatError("has only a timestamp column", path, line)
    return columns, unit


def find_column(names: list[str], name: str, path, line: int = 1) -> int | None:
    """Index of column ``name`` among ``names``; :class:`LogFormatError` when it appears more than once."""
    idx = [i for i, n in enumerate(names) if n == name]
    if len(idx) > 1:
        raise LogFormatError(f"column {name!r} appears {len(idx)} times (fields {', '.join(str(i + 1) for i in idx)})",
                             path, line)
    return idx[0] if idx else None


def column_factor(columns: list[tuple[str, str | None]], index: int, kind: str, path, line: int = 1) -> float:
    """The factor to SI of column ``index`` holding a quantity of ``kind``; :class:`LogFormatError` when its
    unit is missing or not one of that kind."""
    name, unit = columns[index]
    if unit is None:
        raise LogFormatError(f"column {name!r} has no unit; expected '{name} {unit_help(kind)}'", path, line)
    try:
        return unit_factor(unit, kind)
    except KeyError:
        raise LogFormatError(f"column {name!r} has unit [{unit}], which is not understood here; expected "
                             f"{unit_help(kind)}", path, line) from None


_BLOCK_BYTES = 1 << 20
"""Bytes of text read, decoded and parsed at a time: the file is never held whole in memory."""

MAX_LINE_BYTES = 1 << 16
"""The longest line of a CSV table (64 KiB, header included; a row of a thousand columns is a tenth of
it): a longer one is refused at once, naming its line, rather than read on (a file of NUL bytes, a
binary recording given as CSV)."""


def line_too_long(length: int, ended: bool = False) -> str:
    """The message for a line of ``length`` bytes, over :data:`MAX_LINE_BYTES` (``ended``: the line end was
    seen; otherwise reading stopped there)."""
    what = f"{length} bytes" if ended else f"{length} bytes and no line end yet"
    return f"line is longer than {MAX_LINE_BYTES} bytes ({what}); not a row of a CSV table (a binary file?)"


def _timestamp_tokens(lines: list[str]) -> list[str]:
    """The first field of each row."""
    return [ln[: ln.find(",")] for ln in lines]


class _Csv:
    """A CSV header, checked, and its body read in blocks of whole lines; values are converted column by
    column on demand, block by block, into preallocated arrays (peak memory: the result plus one block)."""

    def __init__(self, path: Path):
        self.path = path
        try:
            with open(path, "rb") as fh:
                head = fh.read(65536)
                if re.match(rb"\s*\S", head) is None and not any(
                        re.search(rb"\S", block) for block in iter(lambda: fh.read(1 << 20), b"")):
                    raise LogFormatError("file is empty (expected a header line and one row per sample)", path)
        except FileNotFoundError:
            raise LogFormatError("file not found", path) from None
        except IsADirectoryError:
            raise LogFormatError("is a folder, expected a CSV file", path) from None
        header = None
        n_fields = 0
        last_nonempty = -1
        first_bad = None  # (row, what) of the first line with the wrong number of fields
        n_bad_nonempty = 0
        pending_first, pending_n = None, 0  # empty lines ("") after the last non-empty one so far
        n_empty_middle = 0  # empty lines followed by data: errors
        first_empty = None
        self._spans: list = []
        for line0, lines in self._blocks(self._spans):
            if header is None:
                header = lines[0].lstrip("\ufeff")
                self._parse_header(header)
                n_fields = len(self.columns)
                lines = lines[1:]
                line0 += 1
            if not lines:
                continue
            row0 = line0 - 1
            counts = np.fromiter((ln.count(",") for ln in lines), dtype=np.int64, count=len(lines))
            empty = np.fromiter((not ln for ln in lines), dtype=bool, count=len(lines))
            nonempty = np.flatnonzero(~empty)
            if nonempty.size:
                last = int(nonempty[-1])
                inner = np.flatnonzero(empty[:last])
                if pending_n and first_empty is None:
                    first_empty = pending_first
                if inner.size and first_empty is None:
                    first_empty = row0 + int(inner[0])
                n_empty_middle += pending_n + inner.size
                last_nonempty = row0 + last
                pending_n = len(lines) - 1 - last
                pending_first = last_nonempty + 1
            else:
                if not pending_n:
                    pending_first = row0
                pending_n += len(lines)
            bad = np.flatnonzero((counts != n_fields - 1) & ~empty)
            if bad.size:
                n_bad_nonempty += bad.size
                k = int(bad[0])
                if first_bad is None:
                    what = "is empty" if not lines[k].strip() else f"has {counts[k] + 1} fields"
                    first_bad = (row0 + k, what)
        if header is None:
            raise LogFormatError("file is empty (expected a header line and one row per sample)", path)
        self.n_rows = last_nonempty + 1
        if self.n_rows == 0:
            raise LogFormatError("has a header but no data rows", path, 2)
        candidates = [b for b in (first_bad, (first_empty, "is empty") if first_empty is not None else None) if b]
        if candidates:
            k, what = min(candidates)
            raise LogFormatError(f"row {what}, the header has {n_fields} (ragged rows: {n_bad_nonempty + n_empty_middle})",
                                 path, k + 2)
        self.names = [n for n, _ in self.columns]

    def _parse_header(self, header: str) -> None:
        self.columns, self.time_unit = parse_header(header, self.path)

    def _blocks(self, spans: list | None = None) -> Iterator[tuple[int, list[str]]]:
        """(index of the first line, lines) over the whole file, header included, in blocks of whole lines
        (``\\r\\n`` and lone ``\\r`` read as line ends); ``spans`` receives each block's (byte offset, byte
        length, index of its first line, whether it is the last) to read it again (:meth:`_span_lines`)."""
        line0 = 0
        offset = 0  # byte offset of the start of ``carry``
        carry = b""
        with open(self.path, "rb") as fh:
            while True:
                data = fh.read(_BLOCK_BYTES)
                buf = carry + data if carry else data
                last = not data
                if last and not buf:
                    return
                # the last line end, LF or a lone CR (a CR as the block's last byte may be the first half of a
                # CRLF: the block is cut before it)
                cut = len(buf) if last else max(buf.rfind(b"\n"), buf.rfind(b"\r", 0, len(buf) - 1)) + 1
                if cut == 0 or len(buf) - cut > MAX_LINE_BYTES:  # no line end yet: read on
                    if len(buf) - cut > MAX_LINE_BYTES:
                        line = line0 + buf[:cut].count(b"\n") + 1
                        raise LogFormatError(line_too_long(len(buf) - cut), self.path, line)
                    carry = buf
                    continue
                block, carry = buf[:cut], buf[cut:]
                del buf
                lines = self._lines(block, last, line0, offset)
                if spans is not None:
                    spans.append((offset, cut, line0, last))
                offset += cut
                del block
                if lines:
                    yield line0, lines
                line0 += len(lines)
                if last:
                    return

    def _lines(self, block: bytes, last: bool, line0: int, offset: int) -> list[str]:
        """The lines of one block of :meth:`_blocks` (its first line has index ``line0``, its first byte is at ``offset``)."""
        try:
            text = block.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = line0 + block[: exc.start].count(b"\n") + 1
            raise LogFormatError(f"not UTF-8 text (byte {offset + exc.start})", self.path, line) from None
        if "\r" in text:
            text = text.replace("\r\n", "\n").replace("\r", "\n")
        lines = text.split("\n")
        if not last:
            lines.pop()  # the block ends with a line end
        if lines and max(map(len, lines)) > MAX_LINE_BYTES // 4:  # characters: up to 4 bytes each
            for k, ln in enumerate(lines):
                size = len(ln.encode("utf-8"))
                if size > MAX_LINE_BYTES:
                    raise LogFormatError(line_too_long(size, ended=True), self.path, line0 + k + 1)
        return lines

    def _span_lines(self, span: tuple) -> tuple[int, list[str]]:
        """(index of the first row, data rows) of one block that :meth:`_blocks` recorded."""
        offset, length, line0, last = span
        with open(self.path, "rb") as fh:
            fh.seek(offset)
            lines = self._lines(fh.read(length), last, line0, offset)
        row0 = line0 - 1
        if row0 < 0:
            lines, row0 = lines[1:], 0
        return row0, lines[: max(0, self.n_rows - row0)]

    def _row_blocks(self) -> Iterator[tuple[int, list[str]]]:
        """(index of the first row, rows) of the data rows (trailing empty lines left out)."""
        for line0, lines in self._blocks():
            row0 = line0 - 1
            if row0 < 0:
                lines, row0 = lines[1:], 0
            lines = lines[: max(0, self.n_rows - row0)]
            if lines:
                yield row0, lines
            if row0 + len(lines) >= self.n_rows:
                return

    def _row(self, row: int) -> str:
        for row0, lines in self._row_blocks():
            if row < row0 + len(lines):
                return lines[row - row0]
        raise IndexError(row)

    def line_of_row(self, row: int) -> int:
        return row + 2

    def find(self, name: str) -> int | None:
        """Index of column ``name``; error when it appears more than once."""
        return find_column(self.names, name, self.path)

    def factor(self, index: int, kind: str) -> float:
        return column_factor(self.columns, index, kind, self.path)

    def timestamps_ns(self) -> np.ndarray:
        scale = TIME_UNITS_NS[self.time_unit]
        t = np.empty(self.n_rows, dtype=np.int64)
        prev = None  # (value, token) of the last row of the previous block
        for row0, lines in self._row_blocks():
            tokens = _timestamp_tokens(lines)
            try:
                part = timestamps_ns(tokens, scale)
            except TimestampError as exc:
                raise LogFormatError(str(exc), self.path, self.line_of_row(row0 + exc.index)) from None
            t[row0:row0 + len(tokens)] = part
            bad = np.flatnonzero(np.diff(part) <= 0) + 1
            if prev is not None and part[0] <= prev[0]:
                bad = np.r_[0, bad]
            if bad.size:
                k = int(bad[0])
                before = tokens[k - 1] if k > 0 else prev[1]
                where = f"{before.strip()} on line {row0 + k + 1}"
                if part[k] == (part[k - 1] if k > 0 else prev[0]) and same_nanosecond(before, tokens[k]):
                    raise LogFormatError(
                        f"timestamp {tokens[k].strip()} and the previous one ({where}) are the same nanosecond in "
                        f"[{self.time_unit}]; is the time unit right?", self.path, self.line_of_row(row0 + k))
                raise LogFormatError(
                    f"timestamp {tokens[k].strip()} is not after the previous one ({where}); timestamps must be "
                    "strictly increasing", self.path, self.line_of_row(row0 + k))
            prev = (part[-1], tokens[-1])
        return t

    def values(self, indices: list[int], allow_nan: bool = False, rows: np.ndarray | None = None) -> np.ndarray:
        """Float values of the given columns (N, len(indices)), not yet unit-converted.

        Unless ``allow_nan``, every value (or every value in the ``rows`` mask) must be finite.
        """
        if not indices:
            return np.zeros((self.n_rows, 0))
        out = np.empty((self.n_rows, len(indices)))
        for row0, lines in self._row_blocks():
            try:
                part = np.loadtxt(lines, delimiter=",", usecols=indices, dtype=float, ndmin=2, comments=None)
            except ValueError:
                self._raise_first_bad_value(indices, row0, lines)
                raise
            out[row0:row0 + len(lines)] = part
        if not allow_nan:
            self._check_finite(out, indices, rows)
        return out

    def timestamps_and_values(self, indices: list[int], allow_nan: bool = False,
                              workers: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`timestamps_ns` and :meth:`values` in one pass over the file (:meth:`parsed`). The same
        numbers and the same errors: where the pass finds a problem, those two read the file again and
        name it."""
        parsed = self.parsed(indices, workers)
        if parsed is None:
            return self.timestamps_ns(), self.values(indices, allow_nan)
        if not allow_nan:
            self._check_finite(parsed[1], indices, None)
        return parsed

    def parsed(self, indices: list[int], workers: int = 0) -> tuple[np.ndarray, np.ndarray] | None:
        """(timestamps, values of ``indices``, finite or not) in one pass over the file, its blocks parsed
        by up to ``workers`` forked processes (0: one per CPU, from :data:`PARALLEL_MIN_BLOCKS` blocks on;
        :mod:`gfimu.parallel`); None where a timestamp or a value is not a number or the timestamps do not
        increase (:meth:`timestamps_ns` and :meth:`values` name the first such line)."""
        t = np.empty(self.n_rows, dtype=np.int64)
        out = np.empty((self.n_rows, len(indices)))
        parse = _BlockParser(self, indices)
        for row0, part_t, part_v in forked_map(parse, self._spans, workers, min_tasks=PARALLEL_MIN_BLOCKS):
            if part_t is None:
                return None
            t[row0:row0 + part_t.size] = part_t
            out[row0:row0 + part_t.size] = part_v
        if t.size > 1 and not np.all(t[1:] > t[:-1]):
            return None
        return t, out

    def _check_finite(self, out: np.ndarray, indices: list[int], rows: np.ndarray | None) -> None:
        bad = ~np.isfinite(out)
        if rows is not None:
            bad &= rows[:, None]
        if bad.any():
            rows_bad, cols = np.nonzero(bad)
            r, c = int(rows_bad[0]), int(cols[0])
            token = self._row(r).split(",")[indices[c]].strip()
            shown = repr(token) + ("" if token == repr(float(out[r, c])) else f" = {float(out[r, c])!r}")
            where = "" if rows is None else " where valid is 1"
            raise LogFormatError(
                f"column {self.names[indices[c]]!r} is {shown}; values must be finite{where} "
                f"({rows_bad.size} non-finite value(s) in the file)", self.path, self.line_of_row(r))

    def _raise_first_bad_value(self, indices: list[int], row0: int, lines: list[str]) -> None:
        for k, ln in enumerate(lines):
            fields = ln.split(",")
            for i in indices:
                tok = fields[i].strip()
                try:
                    if "_" in tok:  # Python's float() takes 1_0.5 as 10.5; no CSV reader does
                        raise ValueError(tok)
                    float(tok)
                except ValueError:
                    what = "is empty" if not tok else f"value {tok[:40]!r} is not a number"
                    raise LogFormatError(f"column {self.names[i]!r} (field {i + 1}) {what}", self.path,
                                         self.line_of_row(row0 + k)) from None
        raise LogFormatError(f"a value in columns {', '.join(repr(self.names[i]) for i in indices[:3])}... is not a "
                             f"number", self.path, self.line_of_row(row0))


class _BlockParser:
    """Timestamps and values of one block of a :class:`_Csv` (a job for :func:`gfimu.parallel.forked_map`):
    (index of the first row, timestamps, values), or (index, None, None) where the block has a problem."""

    def __init__(self, csv: _Csv, indices: list[int]):
        self.csv, self.indices = csv, indices
        self.scale = TIME_UNITS_NS[csv.time_unit]

    def __call__(self, span: tuple):
        row0, lines = self.csv._span_lines(span)
        if not lines:
            return row0, np.zeros(0, dtype=np.int64), np.zeros((0, len(self.indices)))
        try:
            t = timestamps_ns(_timestamp_tokens(lines), self.scale)
            if not self.indices:
                return row0, t, np.zeros((len(lines), 0))
            values = np.loadtxt(lines, delimiter=",", usecols=self.indices, dtype=float, ndmin=2, comments=None)
        except (TimestampError, ValueError):
            return row0, None, None
        return row0, t, values


def imu_columns(array: SensorArray) -> list[tuple[str, str]]:
    """(name, kind) of the imu.csv columns an array needs, in file order."""
    cols = [(c, "acceleration") for c in array.accel_columns]
    if array.gyroscope is not None:
        cols += [(c, "angular_rate") for c in GYRO_COLUMNS]
    if array.inclinometer is not None:
        cols += [(c, "angle") for c in TILT_COLUMNS]
    return cols


def _missing_imu_columns(csv: _Csv, array: SensorArray, array_path: str) -> None:
    present = set(csv.names)
    for acc in array.accelerometers:
        missing = [c for c in acc.column_names if c not in present]
        if len(missing) == len(acc.column_names):
            expected = ", ".join(f"'{c} [m s^-2]'" for c in acc.column_names)
            raise LogFormatError(f"accelerometer {acc.name!r} of {array_path} has no columns here; expected {expected}",
                                 csv.path, 1)
        if missing:
            raise LogFormatError(f"column '{missing[0]} [m s^-2]' is missing (accelerometer {acc.name!r} lists axes "
                                 f"{', '.join(acc.axes)} in {array_path})", csv.path, 1)
    for sensor, cols, unit in (("gyroscope", GYRO_COLUMNS, "rad s^-1"), ("inclinometer", TILT_COLUMNS, "rad")):
        if getattr(array, sensor) is None:
            continue
        missing = [c for c in cols if c not in present]
        if missing:
            raise LogFormatError(f"{array_path} has a [{sensor}] but column '{missing[0]} [{unit}]' is missing",
                                 csv.path, 1)


def read_imu_csv(path: str | os.PathLike, array: SensorArray, array_path: str = "array.toml"):
    """Read ``imu.csv`` for ``array``: (timestamps_ns, accel_mps2, gyro_b_radps | None, tilt_rad | None).

    Readings may be NaN, infinite or huge (a sensor's glitch): they are read
    as written and masked later; text that is not a number is an error.
    """
    return read_imu_table(path, array, array_path)[:4]


def read_imu_table(path: str | os.PathLike, array: SensorArray, array_path: str = "array.toml"):
    """As :func:`read_imu_csv`, plus the header's timestamp unit and the unit of the first accelerometer column."""
    csv = _Csv(Path(path))
    wanted = imu_columns(array)
    indices = [csv.find(name) for name, _ in wanted]
    _missing_imu_columns(csv, array, array_path)
    factors = np.array([csv.factor(i, kind) for i, (_, kind) in zip(indices, wanted)])
    t, values = csv.timestamps_and_values(indices, allow_nan=True)
    values = values * factors if np.any(factors != 1.0) else values
    n_acc = array.n_axes
    accel = values[:, :n_acc]
    k = n_acc
    gyro = tilt = None
    if array.gyroscope is not None:
        gyro, k = values[:, k:k + 3], k + 3
    if array.inclinometer is not None:
        tilt = values[:, k:k + 2]
    accel_unit = csv.columns[indices[0]][1] if indices else "m s^-2"
    return t, accel, gyro, tilt, csv.time_unit, accel_unit


def write_imu_csv(log: Log, path: str | os.PathLike) -> None:
    """Write the readings of ``log`` as ``imu.csv`` (atomic, exact floats)."""
    array = log.array
    header = [TIMESTAMP_HEADER] + [f"{c} [{UNITS[k][0]}]" for c, k in imu_columns(array)]
    parts = [log.accel_mps2]
    if array.gyroscope is not None:
        if log.gyro_b_radps is None:
            raise InputError(f"{log.source}: the array has a gyroscope but the log has no gyro readings")
        parts.append(log.gyro_b_radps)
    if array.inclinometer is not None:
        if log.tilt_rad is None:
            raise InputError(f"{log.source}: the array has an inclinometer but the log has no tilt readings")
        parts.append(log.tilt_rad)
    values = np.hstack(parts)
    atomic_write(path, _csv_chunks(header, log.timestamps_ns, values, float.__repr__))



def motion_columns(motion: Motion) -> list[tuple[str, str, np.ndarray]]:
    """(column name, unit, values) of every column a Motion writes, in file order."""
    cols = []
    for field, (prefix, unit, comps) in QUANTITIES.items():
        v = getattr(motion, field)
        if v is not None:
            cols += [(f"{prefix}_{c}", unit, v[:, j]) for j, c in enumerate(comps)]
    for field, (prefix, unit, comps) in QUANTITIES.items():
        s = motion.sigma.get(field)
        if s is not None:
            s = np.asarray(s, dtype=float)
            cols += [(f"sigma_{prefix}_{c}", unit, s[:, j]) for j, c in enumerate(comps)]
    return cols


def motion_csv_chunks(motion: Motion, digits: int | None = None, valid: np.ndarray | None = None,
                      path: str | os.PathLike = "<estimate>") -> Iterator[str]:
    """Text chunks of a motion CSV (see :func:`write_motion_csv`); checks run before the first chunk."""
    cols = motion_columns(motion)
    header = [TIMESTAMP_HEADER] + [f"{name} [{unit}]" for name, unit, _ in cols]
    n = len(motion)
    values = np.column_stack([v for _, _, v in cols]) if cols else np.zeros((n, 0))
    fmt = _float_formatter(digits)
    flags = None
    if valid is not None:
        valid = np.asarray(valid)
        if valid.shape != (n,):
            raise ValueError(f"valid has shape {valid.shape}, expected ({n},)")
        header.append(f"{VALID_COLUMN} []")
        flags = valid.astype(bool).astype(np.int8)
    if not cols and valid is None:
        raise InputError(f"{path}: the motion has no quantities to write")
    return _csv_chunks(header, motion.timestamps_ns, values, fmt, flags)


def write_motion_csv(motion: Motion, path: str | os.PathLike, digits: int | None = None,
                     valid: np.ndarray | None = None) -> None:
    """Write a Motion (truth, reference or estimate) as CSV, atomically.

    Quantities that are ``None`` are left out; ``sigma`` entries become
    ``sigma_`` columns. ``digits=None`` writes floats exactly (shortest
    round-trip form); an integer writes that many significant digits
    (``%.9g`` is ample for estimates). ``valid`` (N,) bool adds the ``valid []``
    column of reference files. Non-finite estimate values are written as
    ``nan``/``inf`` and can be read back with ``allow_nan=True``.
    """
    atomic_write(path, motion_csv_chunks(motion, digits, valid, path))


def read_motion_table(path: str | os.PathLike, allow_nan: bool = False) -> tuple[Motion, np.ndarray | None]:
    """Read truth/reference/estimate CSV: (Motion, valid mask or None).

    A quantity must have all its components (``w_x, w_y, w_z``) or none.
    ``allow_nan`` accepts non-finite values (estimates that failed on some
    samples); truth and reference must be finite, except in reference rows
    marked ``valid`` = 0.
    """
    path = Path(path)
    csv = _Csv(path)
    kinds = {}
    groups: list[tuple[str, bool, list[int]]] = []
    for field, (prefix, unit, comps) in QUANTITIES.items():
        for is_sigma in (False, True):
            names = [f"{'sigma_' if is_sigma else ''}{prefix}_{c}" for c in comps]
            idx = [csv.find(n) for n in names]
            present = [i is not None for i in idx]
            if any(present) and not all(present):
                missing = [n for n, p in zip(names, present) if not p]
                raise LogFormatError(f"column '{missing[0]} [{unit}]' is missing (a quantity needs all of "
                                     f"{', '.join(names)})", path, 1)
            if all(present):
                groups.append((field, is_sigma, idx))
                for i in idx:
                    kinds[i] = KIND_OF_UNIT[unit]
    valid_index = csv.find(VALID_COLUMN)
    if not groups and valid_index is None:
        known = ", ".join(f"{p}_{c[0]}" for p, _, c in QUANTITIES.values())
        raise LogFormatError(f"no motion columns (expected some of {known} ... with units)", path, 1)
    indices = [i for _, _, idx in groups for i in idx]
    factors = np.array([csv.factor(i, kinds[i]) for i in indices])
    parsed = csv.parsed(indices + ([valid_index] if valid_index is not None else []))
    t = csv.timestamps_ns() if parsed is None else parsed[0]
    valid = None
    if valid_index is not None:
        unit = csv.columns[valid_index][1]
        if unit is not None and canonical_unit(unit) != "":
            raise LogFormatError(f"column 'valid' has unit [{unit}]; expected 'valid []' with 1 (valid) or 0 "
                                 "(invalid)", path, 1)
        raw = parsed[1][:, -1] if parsed is not None else None
        if raw is None or not np.all(np.isfinite(raw)):
            raw = csv.values([valid_index])[:, 0]  # (names a value that is not finite)
        bad = np.flatnonzero((raw != 0) & (raw != 1))
        if bad.size:
            r = int(bad[0])
            raise LogFormatError(f"column 'valid' is {float(raw[r])!r}; expected 1 (valid) or 0 (invalid)", path,
                                 csv.line_of_row(r))
        valid = raw == 1
    if not indices:
        values = np.zeros((len(t), 0))
    elif parsed is None:
        values = csv.values(indices, allow_nan=allow_nan, rows=valid) * factors
    else:
        if not allow_nan:
            csv._check_finite(parsed[1][:, :len(indices)], indices, valid)
        values = parsed[1][:, :len(indices)] * factors
    kw: dict = {}
    sigma: dict = {}
    k = 0
    for field, is_sigma, idx in groups:
        block = values[:, k:k + len(idx)]
        k += len(idx)
        (sigma if is_sigma else kw)[field] = block
    q = kw.get("quaternion_wb")
    if q is not None:
        off = np.abs(np.linalg.norm(q, axis=1) - 1.0) > 1e-6
        if valid is not None:
            off &= valid
        bad = np.flatnonzero(off)
        if bad.size:
            r = int(bad[0])
            raise LogFormatError(f"quaternion q_w..q_z has norm {np.linalg.norm(q[r]):.9g}; expected a unit "
                                 f"quaternion ({bad.size} row(s) off by more than 1e-6)", path, csv.line_of_row(r))
    return Motion(t, sigma=sigma, **kw), valid


def read_motion_csv(path: str | os.PathLike, allow_nan: bool = False) -> Motion:
    """Read a truth, reference or estimate CSV into a :class:`Motion`."""
    return read_motion_table(path, allow_nan=allow_nan)[0]
