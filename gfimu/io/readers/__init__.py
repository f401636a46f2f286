"""Registry of the readers that turn a recording into a :class:`gfimu.log.Log`.

Each module of this package is one source format and defines ``READER``, a
:class:`Reader`. A new format is one new module here: ``gfimu convert`` and
:func:`read_recording` find it by name without any other change. Reader
modules import their heavy dependencies inside ``read`` so that listing the
formats stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ...errors import InputError


@dataclass(frozen=True)
class Conversion:
    """What a reader returns: the log and the lines that describe what it found."""

    log: Any
    """The :class:`gfimu.log.Log` read."""
    report: tuple[str, ...] = ()
    """Human-readable lines: packets, gaps, dropped or repaired samples, alignment."""
    unplaced: tuple[str, ...] = ()
    """Accelerometers whose position and rotation the recording does not give (placed at the origin,
    unrotated): ``gfimu convert`` refuses to write them unless ``--extrinsics`` gives their places."""


@dataclass(frozen=True)
class Reader:
    """One source format.

    ``add_arguments(parser)`` adds the format's own options (the input path
    and ``--out`` are added by the command line); ``read(path, **options)``
    returns a :class:`Conversion`, with ``options`` named as the arguments'
    destinations. Options whose value names an existing file are inputs,
    which ``gfimu convert`` never lets the output replace.
    """

    name: str
    summary: str
    read: Callable[..., Conversion]
    add_arguments: Callable[[argparse.ArgumentParser], None] = field(default=lambda parser: None)
    input_help: str = "the recording to read"


def reader_names() -> list[str]:
    """Names of every registered format, sorted."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def get_reader(name: str) -> Reader:
    """The reader of format ``name``; ValueError naming the known formats otherwise."""
    if name not in reader_names():
        raise InputError(f"unknown recording format {name!r}; formats: {', '.join(reader_names())}")
    reader = importlib.import_module(f"{__name__}.{name}").READER
    if reader.name != name:  # pragma: no cover - a module must register its own name
        raise RuntimeError(f"reader module {name!r} registers the name {reader.name!r}")
    return reader


def read_recording(name: str, path, **options) -> Conversion:
    """Read ``path`` with the reader of format ``name``."""
    return get_reader(name).read(path, **options)
