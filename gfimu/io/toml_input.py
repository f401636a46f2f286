"""A gfimu TOML input (``array.toml``, a CSV column map, ``calibration.toml``), loaded one way.

:func:`load_toml` turns the text into the document and its :class:`TomlContext` (the line of each key), or
refuses it in one line naming the file and the line: nested too deep to be a gfimu file, or not TOML at
all. Every later check of a value raises :meth:`TomlContext.error`, which names ``file:line``, the table and
the key; :meth:`TomlContext.refuse_unknown` for a table whose keys are all known.
"""

from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path

from .errors import LogFormatError, toml_nested_too_deep


def load_toml(text: str, path: str | os.PathLike) -> tuple[dict, TomlContext]:
    """(document, context) of the TOML ``text`` read from ``path``; a :class:`LogFormatError` naming the file
    (and the line of a syntax error) when it is nested too deep or is not valid TOML."""
    too_deep = toml_nested_too_deep(text)
    if too_deep:
        raise LogFormatError(too_deep, path)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        raise LogFormatError(f"not valid TOML: {exc}", path, int(m.group(1)) if m else None) from None
    return doc, TomlContext(Path(path), text)


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


class TomlContext:
    """A TOML file's path and the line of each of its keys, for errors that name ``file:line`` and the key."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.lines = _key_lines(text)

    def error(self, message: str, table: str = "", index: int = 0, key: str | None = None) -> LogFormatError:
        line = self.lines.get((table, index, key)) or self.lines.get((table, index, None))
        where = key if not table else (f"{table}[{index}]" if table == "accelerometers" else table)
        if table and key:
            where += f".{key}"
        return LogFormatError(f"{where}: {message}" if where else message, self.path, line, where)

    def refuse_unknown(self, table_doc: dict, known: tuple[str, ...], table: str, index: int = 0) -> None:
        """Every key of ``table_doc`` (the table ``table``) is one of ``known``; else an error naming the first
        other one (in sorted order) and listing the known ones."""
        unknown = sorted(set(table_doc) - set(known))
        if unknown:
            raise self.error(f"unknown key {unknown[0]!r} (known: {', '.join(known)})", table, index, unknown[0])
