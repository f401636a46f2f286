"""Reading and writing gfimu logs, log format version 1.

The format is specified in ``conventions/log-format.md``: a log is a folder
with ``array.toml`` (the sensor array) and ``imu.csv`` (one row per sample),
optionally ``truth.csv`` (simulations) and ``reference.csv`` (a reference
instrument). Estimates are written in the same CSV layout as truth.

Validation. Every problem raises :class:`LogFormatError` (a ``ValueError``)
whose message starts with ``file:line`` (or names the TOML key) and says what
was expected: missing, duplicated or unknown-unit columns, timestamps that are
not strictly increasing, NaN or infinite values, empty files, ragged rows,
sensors of ``array.toml`` absent from ``imu.csv``, an unknown ``format``,
malformed rotation matrices, vectors of the wrong length. Extra columns and
keys are ignored. Gaps in time are not errors: :func:`read_log` reports them
with a :class:`LogGapWarning` (estimators restart at each gap, see
:meth:`gfimu.log.Log.segments`).

Units. A header unit that differs from the specified one is converted when
the conversion is unambiguous and refused otherwise (never misread):

- acceleration ``[m s^-2]``; also ``[g]`` and ``[mg]`` with g = 9.80665 m/s²;
- angular rate ``[rad s^-1]``; also ``[deg s^-1]`` (``[dps]``), ``[rpm]``;
- angular acceleration ``[rad s^-2]``; also ``[deg s^-2]``;
- angle ``[rad]``; also ``[deg]``, ``[mrad]``;
- timestamps ``[ns]``; also ``[us]``, ``[ms]``, ``[s]``, converted exactly
  from the decimal text and rounded to the nearest nanosecond.

Equivalent spellings are accepted (``m/s^2``, ``m/s²``, ``rad/s``,
``deg/s``, ``°``, ``µs`` ...).

Validity mask. ``reference.csv`` may carry a column ``valid []`` holding 1
where the reference is valid and 0 where it is not (for example a saturated
reference gyro). :func:`read_log` turns it into ``Log.invalid_reference``
(True where ``valid`` is 0) and :func:`write_log` writes it back; evaluation
leaves those rows out. Values in rows with ``valid`` = 0 may be ``nan``.

Writing is atomic: each file is written to a temporary file in the same
folder, flushed to disk, then renamed over the target, so a failure never
leaves a half-written or lost file. Floats are written with Python's
shortest round-trip representation, so reading a written file gives back
exactly the same numbers; timestamps are integer nanoseconds.
"""

from __future__ import annotations

import math
import os
import re
import tempfile
import tomllib
import warnings
from collections.abc import Iterable, Iterator
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from .array import Accelerometer, ArrayModelError, Body, Gyroscope, Inclinometer, SensorArray
from .log import Log
from .motion import QUANTITIES, Motion

ARRAY_FORMAT = "gfimu-array/1"
STANDARD_GRAVITY_MPS2 = 9.80665
TIMESTAMP_HEADER = "#timestamp [ns]"
GYRO_COLUMNS = ("w_x", "w_y", "w_z")
TILT_COLUMNS = ("tilt_x", "tilt_y")
VALID_COLUMN = "valid"
ROTATION_TOLERANCE = 1e-6  # accepted as written
ROTATION_REPAIR_TOLERANCE = 1e-3  # projected onto the nearest rotation, with a warning

_ROWS_PER_BLOCK = 16384  # rows formatted at a time when writing CSV


class LogFormatError(ValueError):
    """A log file does not follow the log format; the message names file and line or key."""

    def __init__(self, message: str, path: str | os.PathLike | None = None, line: int | None = None,
                 key: str | None = None):
        where = "" if path is None else str(path)
        if path is not None and line is not None:
            where += f":{line}"
        super().__init__(f"{where}: {message}" if where else message)
        self.path = None if path is None else str(path)
        self.line = line
        self.key = key


class LogGapWarning(UserWarning):
    """The timestamps of a log have gaps (estimators restart at each gap)."""


class LogFormatWarning(UserWarning):
    """A value was repaired while reading (for example a nearly orthonormal rotation)."""


# --- units -------------------------------------------------------------------

_DEG = math.pi / 180.0
# kind -> (canonical unit, {accepted canonical spelling: factor to the canonical unit})
UNITS: dict[str, tuple[str, dict[str, float]]] = {
    "acceleration": ("m s^-2", {"m s^-2": 1.0, "g": STANDARD_GRAVITY_MPS2, "mg": STANDARD_GRAVITY_MPS2 * 1e-3}),
    "angular_rate": ("rad s^-1", {"rad s^-1": 1.0, "deg s^-1": _DEG, "mrad s^-1": 1e-3, "rpm": 2.0 * math.pi / 60.0}),
    "angular_acceleration": ("rad s^-2", {"rad s^-2": 1.0, "deg s^-2": _DEG}),
    "angle": ("rad", {"rad": 1.0, "deg": _DEG, "mrad": 1e-3}),
    "dimensionless": ("", {"": 1.0}),
}
# timestamp unit -> nanoseconds per unit
TIME_UNITS_NS = {"ns": 1, "us": 1_000, "ms": 1_000_000, "s": 1_000_000_000}
_KIND_OF_UNIT = {"m s^-2": "acceleration", "rad s^-1": "angular_rate", "rad s^-2": "angular_acceleration",
                 "rad": "angle", "": "dimensionless"}
_WORDS = {"degree": "deg", "degrees": "deg", "°": "deg", "radian": "rad", "radians": "rad", "sec": "s",
          "second": "s", "seconds": "s", "dps": "deg s^-1", "1": "", "-": "", "µs": "us", "μs": "us",
          "nanoseconds": "ns", "microseconds": "us", "milliseconds": "ms", "rev/min": "rpm"}


def canonical_unit(text: str) -> str:
    """Spelling-independent form of a unit: ``m/s²``, ``m s-2``, ``m*s^-2`` -> ``m s^-2``."""
    u = text.strip()
    for a, b in (("⁻¹", "^-1"), ("⁻²", "^-2"), ("²", "^2"), ("¹", "^1"), ("·", " "), ("*", " "), (".", " "),
                 ("°/", "deg/"), ("° ", "deg ")):
        u = u.replace(a, b)
    u = re.sub(r"\s+", " ", u).strip()
    u = _WORDS.get(u.lower(), u)
    m = re.fullmatch(r"([A-Za-z°µμ]+) ?/ ?s(?: ?\^? ?(\d))?(?: ?/ ?s)?", u)
    if m:
        power = int(m.group(2) or 1) + (1 if u.rstrip().endswith("/s") and u.count("/") == 2 else 0)
        return f"{_WORDS.get(m.group(1).lower(), m.group(1))} s^-{power}"
    m = re.fullmatch(r"([A-Za-z°µμ]+) ?s ?\^? ?-(\d)", u)
    if m:
        return f"{_WORDS.get(m.group(1).lower(), m.group(1))} s^-{m.group(2)}"
    return u


def unit_factor(unit: str, kind: str) -> float:
    """Factor converting a value in ``unit`` to the canonical unit of ``kind``; KeyError if not accepted."""
    return UNITS[kind][1][canonical_unit(unit)]


def _unit_help(kind: str) -> str:
    canonical, accepted = UNITS[kind]
    others = [f"[{u}]" for u in accepted if u != canonical]
    return f"[{canonical}]" + (f" (or, converted: {', '.join(others)})" if others else "")


# --- atomic writing ------------------------------------------------------------

def _atomic_write(path: str | os.PathLike, chunks: Iterable[str]) -> None:
    """Write text chunks to ``path`` atomically: temp file in the same folder, fsync, rename.

    If producing a chunk raises, the temporary file is removed and an existing
    ``path`` is left untouched.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
            for chunk in chunks:
                fh.write(chunk)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    try:  # make the rename itself durable
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (never a half-written file)."""
    _atomic_write(path, [text])


def _format_block(timestamps: list[int], values: list[list[float]], fmt, flags: list[int] | None = None) -> str:
    """CSV text of one block of rows: timestamp, values, then optional integer flags."""
    if flags is None:
        return "".join(f"{t},{','.join(map(fmt, row))}\n" for t, row in zip(timestamps, values))
    return "".join(f"{t},{','.join(map(fmt, row))}{',' if row else ''}{flag}\n"
                   for t, row, flag in zip(timestamps, values, flags))


def _csv_chunks(header: list[str], timestamps_ns: np.ndarray, values: np.ndarray, fmt,
                flags: np.ndarray | None = None) -> Iterator[str]:
    yield ",".join(header) + "\n"
    for start in range(0, timestamps_ns.size, _ROWS_PER_BLOCK):
        stop = start + _ROWS_PER_BLOCK
        yield _format_block(timestamps_ns[start:stop].tolist(), values[start:stop].tolist(), fmt,
                            None if flags is None else flags[start:stop].tolist())


def _float_formatter(digits: int | None):
    if digits is None:
        return float.__repr__
    if not 1 <= int(digits) <= 17:
        raise ValueError(f"digits must be between 1 and 17, got {digits}")
    spec = f"%.{int(digits)}g"
    return spec.__mod__


# --- CSV reading ---------------------------------------------------------------

_HEADER_RE = re.compile(r"^(.*?)\s*\[([^\[\]]*)\]\s*$")


class _Csv:
    """A parsed CSV header and its raw body; values are converted column by column on demand."""

    def __init__(self, path: Path):
        self.path = path
        try:
            raw = path.read_bytes()
        except FileNotFoundError:
            raise LogFormatError("file not found", path) from None
        except IsADirectoryError:
            raise LogFormatError("is a folder, expected a CSV file", path) from None
        if re.match(rb"\s*\S", raw[:65536]) is None and not raw.strip():
            raise LogFormatError("file is empty (expected a header line and one row per sample)", path)
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = raw[: exc.start].count(b"\n") + 1
            raise LogFormatError(f"not UTF-8 text (byte {exc.start})", path, line) from None
        if "\r" in text:
            text = text.replace("\r\n", "\n").replace("\r", "\n")
        lines = text.split("\n")
        del text
        header = lines[0].lstrip("\ufeff")
        end = len(lines)
        while end > 1 and not lines[end - 1]:
            end -= 1
        self.columns: list[tuple[str, str | None]] = []
        for field in header.split(","):
            field = field.strip().strip('"').strip()
            m = _HEADER_RE.match(field)
            self.columns.append((m.group(1).strip(), m.group(2).strip()) if m else (field.strip(), None))
        first_name, first_unit = self.columns[0]
        if first_name.lstrip("#").strip().lower() != "timestamp":
            hint = " (columns must be separated by commas)" if (";" in header or "\t" in header) else ""
            raise LogFormatError(f"the first column must be {TIMESTAMP_HEADER!r}, found {header.split(',')[0]!r}"
                                 f"{hint}", path, 1)
        unit = canonical_unit(first_unit) if first_unit is not None else None
        if unit not in TIME_UNITS_NS:
            raise LogFormatError(
                f"timestamp unit [{first_unit}] not understood; expected [ns] (or, converted: [us], [ms], [s])"
                if first_unit is not None else f"timestamp column has no unit; expected {TIMESTAMP_HEADER!r}",
                path, 1)
        self.time_unit = unit
        if len(self.columns) < 2:
            raise LogFormatError("has only a timestamp column", path, 1)
        if end == 1:
            raise LogFormatError("has a header but no data rows", path, 2)
        self.lines = lines[1:end]
        del lines
        n_fields = len(self.columns)
        counts = np.fromiter((ln.count(",") for ln in self.lines), dtype=np.int64, count=len(self.lines))
        bad = np.flatnonzero(counts != n_fields - 1)
        if bad.size:
            k = int(bad[0])
            what = "is empty" if not self.lines[k].strip() else f"has {counts[k] + 1} fields"
            raise LogFormatError(f"row {what}, the header has {n_fields} (ragged rows: {bad.size})", path, k + 2)
        self.names = [n for n, _ in self.columns]

    def line_of_row(self, row: int) -> int:
        return row + 2

    def find(self, name: str) -> int | None:
        """Index of column ``name``; error when it appears more than once."""
        idx = [i for i, n in enumerate(self.names) if n == name]
        if len(idx) > 1:
            raise LogFormatError(f"column {name!r} appears {len(idx)} times (fields {', '.join(str(i + 1) for i in idx)})",
                                 self.path, 1)
        return idx[0] if idx else None

    def factor(self, index: int, kind: str) -> float:
        name, unit = self.columns[index]
        if unit is None:
            raise LogFormatError(f"column {name!r} has no unit; expected '{name} {_unit_help(kind)}'", self.path, 1)
        try:
            return unit_factor(unit, kind)
        except KeyError:
            raise LogFormatError(f"column {name!r} has unit [{unit}], which is not understood here; expected "
                                 f"{_unit_help(kind)}", self.path, 1) from None

    def timestamps_ns(self) -> np.ndarray:
        tokens = [ln[: ln.find(",")] for ln in self.lines]
        scale = TIME_UNITS_NS[self.time_unit]
        t = None
        if scale == 1:
            try:
                t = np.array(tokens).astype(np.int64)
            except (ValueError, OverflowError):
                t = None
        if t is None:
            t = np.empty(len(tokens), dtype=np.int64)
            for k, tok in enumerate(tokens):
                t[k] = self._parse_time(tok, scale, k)
        d = np.diff(t)
        bad = np.flatnonzero(d <= 0)
        if bad.size:
            k = int(bad[0]) + 1
            raise LogFormatError(
                f"timestamp {tokens[k].strip()} is not after the previous one ({tokens[k - 1].strip()} on line "
                f"{k + 1}); timestamps must be strictly increasing", self.path, self.line_of_row(k))
        return t

    def _parse_time(self, token: str, scale: int, row: int) -> int:
        tok = token.strip()
        try:
            value = Decimal(tok) * scale
        except InvalidOperation:
            value = None
        if value is None or not value.is_finite():
            raise LogFormatError(f"timestamp {tok!r} is not a number", self.path, self.line_of_row(row))
        ns = int(value.to_integral_value())
        if scale == 1 and ns != value:
            raise LogFormatError(f"timestamp {tok!r} is not an integer number of nanoseconds", self.path,
                                 self.line_of_row(row))
        if not -(2**63) <= ns < 2**63:
            raise LogFormatError(f"timestamp {tok!r} is out of range for 64-bit nanoseconds", self.path,
                                 self.line_of_row(row))
        return ns

    def values(self, indices: list[int], allow_nan: bool = False, rows: np.ndarray | None = None) -> np.ndarray:
        """Float values of the given columns (N, len(indices)), not yet unit-converted.

        Unless ``allow_nan``, every value (or every value in the ``rows`` mask) must be finite.
        """
        if not indices:
            return np.zeros((len(self.lines), 0))
        try:
            out = np.loadtxt(self.lines, delimiter=",", usecols=indices, dtype=float, ndmin=2, comments=None)
        except ValueError:
            self._raise_first_bad_value(indices)
            raise
        if not allow_nan:
            bad = ~np.isfinite(out)
            if rows is not None:
                bad &= rows[:, None]
            if bad.any():
                rows_bad, cols = np.nonzero(bad)
                r, c = int(rows_bad[0]), int(cols[0])
                token = self.lines[r].split(",")[indices[c]].strip()
                shown = repr(token) + ("" if token == repr(float(out[r, c])) else f" = {float(out[r, c])!r}")
                where = "" if rows is None else " where valid is 1"
                raise LogFormatError(
                    f"column {self.names[indices[c]]!r} is {shown}; values must be finite{where} "
                    f"({rows_bad.size} non-finite value(s) in the file)", self.path, self.line_of_row(r))
        return out

    def _raise_first_bad_value(self, indices: list[int]) -> None:
        for k, ln in enumerate(self.lines):
            fields = ln.split(",")
            for i in indices:
                tok = fields[i].strip()
                try:
                    float(tok)
                except ValueError:
                    what = "is empty" if not tok else f"value {tok!r} is not a number"
                    raise LogFormatError(f"column {self.names[i]!r} (field {i + 1}) {what}", self.path,
                                         self.line_of_row(k)) from None


# --- array.toml ----------------------------------------------------------------

def _key_lines(text: str) -> dict[tuple, int]:
    """Line numbers of keys: (table, index, key) -> line, for error messages.

    ``table`` is ``""`` for top-level keys; ``index`` counts ``[[accelerometers]]``
    entries (0 for plain tables). Table header lines are stored under key ``None``.
    """
    out: dict[tuple, int] = {}
    table, index = "", 0
    counts: dict[str, int] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        m = re.match(r"^\[\[\s*([A-Za-z0-9_\-]+)\s*\]\]", s)
        if m:
            table = m.group(1)
            index = counts.get(table, 0)
            counts[table] = index + 1
            out.setdefault((table, index, None), lineno)
            continue
        m = re.match(r"^\[\s*([A-Za-z0-9_\-]+)\s*\]", s)
        if m:
            table, index = m.group(1), 0
            out.setdefault((table, index, None), lineno)
            continue
        m = re.match(r"^([A-Za-z0-9_\-]+)\s*=", s)
        if m:
            out.setdefault((table, index, m.group(1)), lineno)
    return out


class _TomlContext:
    def __init__(self, path: Path, text: str):
        self.path = path
        self.lines = _key_lines(text)

    def error(self, message: str, table: str = "", index: int = 0, key: str | None = None) -> LogFormatError:
        line = self.lines.get((table, index, key)) or self.lines.get((table, index, None))
        where = key if not table else (f"{table}[{index}]" if table == "accelerometers" else table)
        if table and key:
            where += f".{key}"
        return LogFormatError(f"{where}: {message}" if where else message, self.path, line, where)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _vector(ctx: _TomlContext, value, n: int, table: str, index: int, key: str) -> np.ndarray:
    if not isinstance(value, list) or len(value) != n or not all(_is_number(v) for v in value):
        raise ctx.error(f"expected a list of {n} numbers, got {value!r}", table, index, key)
    out = np.array(value, dtype=float)
    if not np.all(np.isfinite(out)):
        raise ctx.error(f"values must be finite, got {value!r}", table, index, key)
    return out


def _optional_std(ctx: _TomlContext, table_value: dict, table: str, index: int, key: str) -> float | None:
    if key not in table_value:
        return None
    v = table_value[key]
    if not _is_number(v) or not math.isfinite(v) or v < 0:
        raise ctx.error(f"expected a finite number >= 0, got {v!r}", table, index, key)
    return float(v)


def _rotation(ctx: _TomlContext, value, index: int, name: str) -> np.ndarray:
    key = "rotation_body_sensor"
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(r, list) and len(r) == 3 and all(_is_number(v) for v in r) for r in value)):
        raise ctx.error(f"expected a 3x3 matrix written as three rows of three numbers, got {value!r}",
                        "accelerometers", index, key)
    rot = np.array(value, dtype=float)
    if not np.all(np.isfinite(rot)):
        raise ctx.error("values must be finite", "accelerometers", index, key)
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
        warnings.warn(str(err), LogFormatWarning, stacklevel=4)
        return fixed
    raise ctx.error(f"{rot.tolist()} is not a rotation matrix (R Rᵀ differs from the identity by {deviation:.3g}; "
                    f"expected orthonormal rows, determinant +1)", "accelerometers", index, key)


def parse_array_toml(text: str, path: str | os.PathLike = "array.toml") -> SensorArray:
    """A :class:`SensorArray` from the text of an ``array.toml``; errors name the key and line."""
    path = Path(path)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        raise LogFormatError(f"not valid TOML: {exc}", path, int(m.group(1)) if m else None) from None
    ctx = _TomlContext(path, text)
    fmt = doc.get("format")
    if fmt is None:
        raise ctx.error(f"key is missing; the first line should be format = \"{ARRAY_FORMAT}\"", key="format")
    if fmt != ARRAY_FORMAT:
        raise ctx.error(f"unknown format {fmt!r}; this version of gfimu reads {ARRAY_FORMAT!r}", key="format")
    name = doc.get("name", "array")
    if not isinstance(name, str):
        raise ctx.error(f"expected a string, got {name!r}", key="name")
    accs_doc = doc.get("accelerometers")
    if accs_doc is None:
        raise ctx.error("no [[accelerometers]] table; an array needs at least one accelerometer", key="accelerometers")
    if not isinstance(accs_doc, list) or not accs_doc or not all(isinstance(a, dict) for a in accs_doc):
        raise ctx.error("expected one or more [[accelerometers]] tables", key="accelerometers")
    accs = []
    seen: dict[str, int] = {}
    for i, a in enumerate(accs_doc):
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
        if "position_m" not in a:
            raise ctx.error(f"accelerometer {acc_name!r} has no position_m (3 numbers, in metres, in the body frame)",
                            t, i)
        position = _vector(ctx, a["position_m"], 3, t, i, "position_m")
        rot = _rotation(ctx, a["rotation_body_sensor"], i, acc_name) if "rotation_body_sensor" in a else np.eye(3)
        axes = a.get("axes", ["x", "y", "z"])
        if (not isinstance(axes, list) or not axes or not all(isinstance(x, str) for x in axes)
                or len(set(axes)) != len(axes) or any(x not in ("x", "y", "z") for x in axes)):
            raise ctx.error(f"expected a list of distinct axes among \"x\", \"y\", \"z\", got {axes!r}", t, i, "axes")
        noise = _optional_std(ctx, a, t, i, "noise_std_mps2")
        try:
            accs.append(Accelerometer(acc_name, position, rot, tuple(axes), noise))
        except ArrayModelError as exc:
            raise ctx.error(str(exc), t, i) from None
    gyro = inclinometer = body = None
    for table, cls, key in (("gyroscope", Gyroscope, "noise_std_radps"), ("inclinometer", Inclinometer, "noise_std_rad")):
        if table in doc:
            if not isinstance(doc[table], dict):
                raise ctx.error(f"expected a table [{table}]", key=table)
            obj = cls(_optional_std(ctx, doc[table], table, 0, key))
            if table == "gyroscope":
                gyro = obj
            else:
                inclinometer = obj
    if "body" in doc:
        b = doc["body"]
        if not isinstance(b, dict) or "principal_inertia_kgm2" not in b:
            raise ctx.error("[body] needs principal_inertia_kgm2 = [I1, I2, I3]", "body", 0)
        inertia = _vector(ctx, b["principal_inertia_kgm2"], 3, "body", 0, "principal_inertia_kgm2")
        try:
            body = Body(tuple(inertia))
        except ArrayModelError as exc:
            raise ctx.error(str(exc), "body", 0, "principal_inertia_kgm2") from None
    return SensorArray(tuple(accs), name, gyro, inclinometer, body)


def read_array_toml(path: str | os.PathLike) -> SensorArray:
    """Read ``array.toml`` (format ``gfimu-array/1``) into a :class:`SensorArray`."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise LogFormatError("file not found", path) from None
    try:
        text = raw.decode("utf-8").lstrip("\ufeff")
    except UnicodeDecodeError as exc:
        raise LogFormatError(f"not UTF-8 text (byte {exc.start})", path) from None
    if not text.strip():
        raise LogFormatError(f"file is empty; expected format = \"{ARRAY_FORMAT}\" and [[accelerometers]] tables", path)
    return parse_array_toml(text, path)


def _toml_str(s: str) -> str:
    out = ['"']
    for ch in s:
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\t":
            out.append("\\t")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _toml_float(x) -> str:
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot write the non-finite number {x!r} to array.toml")
    return repr(x)


def _toml_floats(values) -> str:
    return "[" + ", ".join(_toml_float(v) for v in np.asarray(values, dtype=float).reshape(-1)) + "]"


def format_array_toml(array: SensorArray) -> str:
    """Deterministic ``array.toml`` text of an array (floats round-trip exactly)."""
    lines = [f"format = {_toml_str(ARRAY_FORMAT)}", f"name = {_toml_str(array.name)}"]
    for a in array.accelerometers:
        lines += ["", "[[accelerometers]]", f"name = {_toml_str(a.name)}", f"position_m = {_toml_floats(a.position_m)}"]
        if not np.array_equal(a.rotation_body_sensor, np.eye(3)):
            rows = ", ".join(_toml_floats(r) for r in a.rotation_body_sensor)
            lines.append(f"rotation_body_sensor = [{rows}]")
        lines.append("axes = [" + ", ".join(_toml_str(x) for x in a.axes) + "]")
        if a.noise_std_mps2 is not None:
            lines.append(f"noise_std_mps2 = {_toml_float(a.noise_std_mps2)}")
    if array.gyroscope is not None:
        lines += ["", "[gyroscope]"]
        if array.gyroscope.noise_std_radps is not None:
            lines.append(f"noise_std_radps = {_toml_float(array.gyroscope.noise_std_radps)}")
    if array.inclinometer is not None:
        lines += ["", "[inclinometer]"]
        if array.inclinometer.noise_std_rad is not None:
            lines.append(f"noise_std_rad = {_toml_float(array.inclinometer.noise_std_rad)}")
    if array.body is not None:
        lines += ["", "[body]", f"principal_inertia_kgm2 = {_toml_floats(array.body.principal_inertia_kgm2)}"]
    return "\n".join(lines) + "\n"


def write_array_toml(array: SensorArray, path: str | os.PathLike) -> None:
    """Write ``array.toml`` atomically."""
    _atomic_write(path, [format_array_toml(array)])


# --- imu.csv ---------------------------------------------------------------------

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
    """Read ``imu.csv`` for ``array``: (timestamps_ns, accel_mps2, gyro_b_radps | None, tilt_rad | None)."""
    csv = _Csv(Path(path))
    wanted = imu_columns(array)
    indices = [csv.find(name) for name, _ in wanted]
    _missing_imu_columns(csv, array, array_path)
    factors = np.array([csv.factor(i, kind) for i, (_, kind) in zip(indices, wanted)])
    t = csv.timestamps_ns()
    values = csv.values(indices)
    values = values * factors if np.any(factors != 1.0) else values
    n_acc = array.n_axes
    accel = values[:, :n_acc]
    k = n_acc
    gyro = tilt = None
    if array.gyroscope is not None:
        gyro, k = values[:, k:k + 3], k + 3
    if array.inclinometer is not None:
        tilt = values[:, k:k + 2]
    return t, accel, gyro, tilt


def write_imu_csv(log: Log, path: str | os.PathLike) -> None:
    """Write the readings of ``log`` as ``imu.csv`` (atomic, exact floats)."""
    array = log.array
    header = [TIMESTAMP_HEADER] + [f"{c} [{UNITS[k][0]}]" for c, k in imu_columns(array)]
    parts = [log.accel_mps2]
    if array.gyroscope is not None:
        if log.gyro_b_radps is None:
            raise ValueError(f"{log.source}: the array has a gyroscope but the log has no gyro readings")
        parts.append(log.gyro_b_radps)
    if array.inclinometer is not None:
        if log.tilt_rad is None:
            raise ValueError(f"{log.source}: the array has an inclinometer but the log has no tilt readings")
        parts.append(log.tilt_rad)
    values = np.hstack(parts)
    _atomic_write(path, _csv_chunks(header, log.timestamps_ns, values, float.__repr__))


# --- motion CSV (truth, reference, estimates) --------------------------------------

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
        raise ValueError(f"{path}: the motion has no quantities to write")
    _atomic_write(path, _csv_chunks(header, motion.timestamps_ns, values, fmt, flags))


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
                    kinds[i] = _KIND_OF_UNIT[unit]
    valid_index = csv.find(VALID_COLUMN)
    if not groups and valid_index is None:
        known = ", ".join(f"{p}_{c[0]}" for p, _, c in QUANTITIES.values())
        raise LogFormatError(f"no motion columns (expected some of {known} ... with units)", path, 1)
    indices = [i for _, _, idx in groups for i in idx]
    factors = np.array([csv.factor(i, kinds[i]) for i in indices])
    t = csv.timestamps_ns()
    valid = None
    if valid_index is not None:
        unit = csv.columns[valid_index][1]
        if unit is not None and canonical_unit(unit) != "":
            raise LogFormatError(f"column 'valid' has unit [{unit}]; expected 'valid []' with 1 (valid) or 0 "
                                 "(invalid)", path, 1)
        raw = csv.values([valid_index])[:, 0]
        bad = np.flatnonzero((raw != 0) & (raw != 1))
        if bad.size:
            r = int(bad[0])
            raise LogFormatError(f"column 'valid' is {float(raw[r])!r}; expected 1 (valid) or 0 (invalid)", path,
                                 csv.line_of_row(r))
        valid = raw == 1
    values = csv.values(indices, allow_nan=allow_nan, rows=valid) * factors if indices else np.zeros((len(t), 0))
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


# --- whole logs --------------------------------------------------------------------

def _log_folder(path: str | os.PathLike) -> Path:
    p = Path(path)
    if p.is_file() and p.name in ("imu.csv", "array.toml"):
        p = p.parent
    if not p.exists():
        raise LogFormatError("log folder not found", p)
    if not p.is_dir():
        raise LogFormatError("not a log folder (expected a folder holding array.toml and imu.csv)", p)
    for name in ("array.toml", "imu.csv"):
        if not (p / name).is_file():
            raise LogFormatError(f"log folder has no {name} (a log holds array.toml and imu.csv)", p)
    return p


def _check_same_timestamps(motion: Motion, t_imu: np.ndarray, path: Path, imu_path: Path) -> None:
    if len(motion) != t_imu.size:
        raise LogFormatError(f"has {len(motion)} rows but {imu_path.name} has {t_imu.size}; it needs one row per "
                             f"{imu_path.name} row, with the same timestamps", path)
    diff = np.flatnonzero(motion.timestamps_ns != t_imu)
    if diff.size:
        r = int(diff[0])
        raise LogFormatError(f"timestamp {motion.timestamps_ns[r]} differs from {imu_path.name} line {r + 2} "
                             f"({t_imu[r]}); it needs the same timestamps as {imu_path.name}", path, r + 2)


def read_log(path: str | os.PathLike) -> Log:
    """Read a log folder (array.toml, imu.csv, and truth.csv / reference.csv when present).

    Gaps in time are reported with a :class:`LogGapWarning`.
    """
    folder = _log_folder(path)
    array_path = folder / "array.toml"
    imu_path = folder / "imu.csv"
    array = read_array_toml(array_path)
    t, accel, gyro, tilt = read_imu_csv(imu_path, array, array_path.name)
    truth = reference = invalid = None
    if (folder / "truth.csv").is_file():
        truth = read_motion_csv(folder / "truth.csv")
        _check_same_timestamps(truth, t, folder / "truth.csv", imu_path)
    if (folder / "reference.csv").is_file():
        reference, valid = read_motion_table(folder / "reference.csv")
        _check_same_timestamps(reference, t, folder / "reference.csv", imu_path)
        if valid is not None:
            invalid = ~valid
        if not reference.available():
            reference = None
    log = Log(array, t, accel, gyro, tilt, truth, reference, invalid, source=str(folder))
    gaps = log.gaps()
    if gaps:
        worst = max(gaps, key=lambda g: g.dt_s)
        warnings.warn(
            f"{imu_path}: {len(gaps)} gap(s) in time (steps over 1.5 x the median {worst.nominal_dt_s:.6g} s); the "
            f"largest, {worst.dt_s:.6g} s, is before line {worst.index + 2}; estimators restart at each gap",
            LogGapWarning, stacklevel=2)
    return log


def write_log(log: Log, path: str | os.PathLike) -> None:
    """Write a log folder: array.toml, imu.csv, and truth.csv / reference.csv when present.

    Each file is written atomically; the folder is created when needed.
    """
    folder = Path(path)
    folder.mkdir(parents=True, exist_ok=True)
    write_array_toml(log.array, folder / "array.toml")
    write_imu_csv(log, folder / "imu.csv")
    if log.truth is not None:
        _check_same_timestamps(log.truth, log.timestamps_ns, folder / "truth.csv", folder / "imu.csv")
        write_motion_csv(log.truth, folder / "truth.csv")
    if log.reference is not None or log.invalid_reference is not None:
        reference = log.reference if log.reference is not None else Motion(log.timestamps_ns)
        _check_same_timestamps(reference, log.timestamps_ns, folder / "reference.csv", folder / "imu.csv")
        valid = None if log.invalid_reference is None else ~np.asarray(log.invalid_reference, dtype=bool)
        write_motion_csv(reference, folder / "reference.csv", valid=valid)
