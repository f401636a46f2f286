"""Errors and warnings of reading and writing logs.

Every problem in a file raises :class:`LogFormatError` (a :class:`gfimu.errors.InputError`)
whose message starts with ``file:line`` (or names the TOML key) and says what
was expected. Problems that do not stop reading are warnings:
:class:`LogGapWarning` (gaps in time), :class:`LogFormatWarning` (a value
repaired while reading) and :class:`LogPlausibilityWarning` (a value that
reads but probably is not what the writer meant: a wrong unit or rate).
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputError


class LogFormatError(InputError):
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



MAX_TOML_DEPTH = 64
"""The deepest nesting of arrays and tables a TOML input may have (an ``array.toml`` needs 3)."""


def toml_nested_too_deep(text: str) -> str | None:
    """Why ``text`` cannot be a gfimu TOML input by its nesting (None when it is not too deep): TOML nested
    deeper than :data:`MAX_TOML_DEPTH` levels, or so deep that the TOML parser runs out of recursion."""
    import tomllib

    too_deep = f"nested deeper than {MAX_TOML_DEPTH} levels of arrays and tables (a gfimu TOML file needs a few); not read"
    try:
        doc = tomllib.loads(text)
    except RecursionError:
        return too_deep
    except tomllib.TOMLDecodeError:
        return None  # the caller names the syntax error
    stack = [(doc, 1)]
    while stack:
        value, depth = stack.pop()
        if depth > MAX_TOML_DEPTH:
            return too_deep
        children = value.values() if isinstance(value, dict) else value if isinstance(value, list) else ()
        stack.extend((c, depth + 1) for c in children if isinstance(c, (dict, list)))
    return None


def read_utf8_text(path: str | os.PathLike, missing: str = "file not found", folder: str | None = None,
                   line_of_bad_byte: bool = False) -> str:
    """The text of a UTF-8 file without its byte-order mark; a :class:`LogFormatError` naming the file
    when it is missing (message ``missing``), a folder (message ``folder``; None lets the OS error
    through) or not UTF-8 (with the line of the first bad byte when ``line_of_bad_byte``)."""
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise LogFormatError(missing, path) from None
    except IsADirectoryError:
        if folder is None:
            raise
        raise LogFormatError(folder, path) from None
    try:
        return raw.decode("utf-8").lstrip("\ufeff")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1 if line_of_bad_byte else None
        raise LogFormatError(f"not UTF-8 text (byte {exc.start})", path, line) from None

class OutputError(InputError, OSError):
    """An output cannot be written where asked (it is an input, or not a regular file): the user's
    mistake (an :class:`~gfimu.errors.InputError`), also an ``OSError``."""


class LogGapWarning(UserWarning):
    """The timestamps of a log have gaps (estimators restart at each gap)."""


class LogFormatWarning(UserWarning):
    """A value was repaired while reading (for example a nearly orthonormal rotation)."""


class LogPlausibilityWarning(UserWarning):
    """A log reads, but a value is implausible (likely a wrong unit, rate or size).

    The message names the file and the likely mistake.
    """
