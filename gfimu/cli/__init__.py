"""The ``gfimu`` command line: a thin layer over the library.

Each sub-command lives in its own module with ``register(subparsers)``,
which adds its parser and sets ``func`` to a function of the parsed args
returning an exit code.
"""

from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS = ("demo", "simulate", "estimate", "evaluate", "compare", "convert", "calibrate", "plot")


class CLIError(Exception):
    """A user error: printed as one line, exit status 2."""


def _version() -> str:
    """The installed distribution's version, or the source tree's from pyproject.toml."""
    from importlib import metadata

    try:
        return metadata.version("gfimu")
    except metadata.PackageNotFoundError:
        import tomllib
        from pathlib import Path

        pyproject = Path(__file__).resolve().parents[2] / "pyproject.toml"
        try:
            return tomllib.loads(pyproject.read_text())["project"]["version"]
        except (OSError, KeyError, tomllib.TOMLDecodeError):
            return "unknown"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gfimu",
        description="Angular velocity, angular acceleration and linear acceleration from accelerometer arrays.",
    )
    parser.add_argument("--version", action="version", version=f"gfimu {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"gfimu.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:  # output piped into a reader that stopped (e.g. head)
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (CLIError, ValueError, FileNotFoundError, KeyError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"gfimu {args.command}: error: {msg}", file=sys.stderr)
        return 2
