"""Errors and warnings of reading and writing logs.

Every problem in a file raises :class:`LogFormatError` (a ``ValueError``)
whose message starts with ``file:line`` (or names the TOML key) and says what
was expected. Problems that do not stop reading are warnings:
:class:`LogGapWarning` (gaps in time), :class:`LogFormatWarning` (a value
repaired while reading) and :class:`LogPlausibilityWarning` (a value that
reads but probably is not what the writer meant: a wrong unit or rate).
"""

from __future__ import annotations

import os


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


class OutputError(OSError):
    """An output cannot be written where asked (it is an input, or not a regular file)."""


class LogGapWarning(UserWarning):
    """The timestamps of a log have gaps (estimators restart at each gap)."""


class LogFormatWarning(UserWarning):
    """A value was repaired while reading (for example a nearly orthonormal rotation)."""


class LogPlausibilityWarning(UserWarning):
    """A log reads, but a value is implausible (likely a wrong unit, rate or size).

    The message names the file and the likely mistake.
    """
