"""The ``gfimu`` command line: a thin layer over the library.

Each sub-command lives in its own module with ``register(subparsers)``,
which adds its parser and sets ``func`` to a function of the parsed args
returning an exit code.

Errors (:mod:`gfimu.errors`). A user mistake, data that cannot support the
request or a failure of the machine (a malformed or missing file, a log the
method cannot solve, a full disk) ends in one line ``gfimu COMMAND: error: ...``
naming the file, key, row or option, and a non-zero exit status: 2 for a
:class:`~gfimu.errors.GfimuError` of the input or data kind and for a path given that is not
there (or is too long to be one), 1 for a resource
(an ``OSError``: permission, no space, interrupted I/O), 130/143 when
interrupted by SIGINT/SIGTERM (temporary files are removed first). Any other
exception is a bug, not a mistake of the user: ``gfimu COMMAND: internal error:
TYPE: ... (run with --debug for the traceback)``, exit 1. ``--debug`` shows the
traceback instead of the one line.
Outputs follow :mod:`gfimu.io.outputs`: never over an input, never over
anything but a regular file.

Progress and messages, the same on every command: a long step shows a tqdm bar
on standard error when it is a terminal (:mod:`gfimu.progress`,
:func:`show_progress`); a status line (what was written, what was found) goes
through :func:`info`. ``--quiet`` (``-q``), added to every command by
:func:`build_parser`, silences both; ``--no-progress`` (:func:`add_no_progress`)
the bars alone. Warnings and errors are always shown.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import signal
import sys
import threading
import warnings

from ..errors import GfimuError, InputError

# One BLAS thread per process, as Dask workers run: the smoother's many small products are faster so
# (about 1.5x on 2 cores), and the command gives the same numbers as `gfimu batch` on a cluster.
# Effective when numpy is first imported after this point; the user's own setting wins.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

COMMANDS = ("demo", "simulate", "estimate", "evaluate", "compare", "convert", "calibrate", "plot", "batch", "live", "diagnose")

EXIT_USAGE = 2
EXIT_FAILURE = 1


class CLIError(InputError):
    """A user error: printed as one line, exit status 2."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse with one-line errors: ``gfimu simulate: error: argument --rate-hz: ...`` (exit 2)."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {shorten(message)} (see {self.prog} --help)\n")


LONGEST_WORD = 1000
"""A word (a run without spaces) of a message longer than this is cut (a value echoed at 129 kB; a path
is shorter)."""


def shorten(message: str) -> str:
    """``message`` with each word longer than :data:`LONGEST_WORD` characters cut to its first 80 and
    its length, ``aaaa…(129,000 characters)``: an error line quotes a value, never the whole of a huge one."""
    import re

    def cut(match):
        word = match.group(0)
        return f"{word[:80]}…({len(word):,} characters)"

    message = re.sub(r"\S{%d,}" % (LONGEST_WORD + 1), cut, message)
    if len(message) > 4 * LONGEST_WORD:
        message = f"{message[:4 * LONGEST_WORD]}…({len(message):,} characters)"
    return message


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


class _VersionAction(argparse.Action):
    """``--version``: the version looked up only when asked (the lookup reads package metadata)."""

    def __call__(self, parser, namespace, values, option_string=None):
        sys.stdout.write(f"gfimu {_version()}\n")
        parser.exit(0)


SUMMARIES = {
    "demo": "run every method on built-in data and print an accuracy table",
    "simulate": "write a simulated log (exact rigid-body motion, synthetic readings, truth)",
    "estimate": "estimate ω, ω̇ and acceleration from a log",
    "evaluate": "errors of an estimate against truth or a reference (RMSE, relative RMS, sign errors)",
    "compare": "run several methods on a log and tabulate their errors against truth or reference",
    "convert": "convert a recording into a log directory",
    "calibrate": "fit accelerometer biases and gains from still periods",
    "plot": "plot estimates against the log's truth or reference (needs the 'plot' extra)",
    "batch": "run one method on many logs, in parallel on Dask (this machine or a cluster)",
    "diagnose": "check a log before trusting it: rigid-body residual, noise, timing, units, positions, "
                "stuck or clipped channels, expected ω accuracy",
    "live": "estimate ω live from readings on standard input, UDP, TCP or a serial port (fixed-lag smoother)",
}
"""One line per command for ``gfimu --help`` (each command's own parser carries the same line)."""


def command_of(argv: list[str]) -> str | None:
    """The command named on a command line (the first word that is not an option), or None."""
    for word in argv:
        if word == "--":
            return None
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


def build_parser(command: str | None = "") -> argparse.ArgumentParser:
    """The parser of ``gfimu``: with every command's full parser (``command=""``), or with only ``command``'s
    (the others listed by their summary line, so that ``gfimu --help`` imports nothing heavy; ``None``: none)."""
    parser = ArgumentParser(
        prog="gfimu",
        description="Angular velocity, angular acceleration and linear acceleration from accelerometer arrays.",
    )
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error instead of a one-line message")
    parser.add_argument("--version", action=_VersionAction, nargs=0, help="show the version and exit")
    parser.add_argument("--quiet", "-q", action="store_true", help=QUIET_HELP)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        if command == "" or name == command:
            importlib.import_module(f"gfimu.cli.{name}").register(sub)
        else:
            sub.add_parser(name, help=SUMMARIES[name])
    _add_debug_everywhere(parser)
    return parser


QUIET_HELP = ("no progress bars and no status lines; the outputs, warnings and errors stay "
              "(default: off)")
NO_PROGRESS_HELP = ("no progress bars; the status lines stay (--quiet silences both; default: bars on standard "
                    "error when it is a terminal)")


def _add_debug_everywhere(parser: argparse.ArgumentParser) -> None:
    """Accept ``--debug`` and ``--quiet`` after the command too, on every command (defaults suppressed so
    that a value given before the command stands)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in set(action.choices.values()):
                if "--debug" not in child._option_string_actions:
                    child.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                       help="show the full traceback of an error")
                if "--quiet" not in child._option_string_actions:
                    names = ["--quiet"] + ([] if "-q" in child._option_string_actions else ["-q"])
                    child.add_argument(*names, action="store_true", default=argparse.SUPPRESS, help=QUIET_HELP)
                _add_debug_everywhere(child)


def add_no_progress(parser: argparse.ArgumentParser) -> None:
    """``--no-progress`` on a command that shows progress bars."""
    parser.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)


def quiet(args) -> bool:
    """True under ``--quiet``: no progress bars, no status lines."""
    return bool(getattr(args, "quiet", False))


def show_progress(args) -> bool:
    """Progress bars (tqdm on standard error) when standard error is a terminal, unless ``--quiet`` or
    ``--no-progress``: a log of the command redirected to a file gets no bars."""
    if quiet(args) or getattr(args, "no_progress", False):
        return False
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):
        return False


def info(args, *text, file=None) -> None:
    """A status line (what was written, what was found), left out under ``--quiet``; standard error by
    default, or ``file`` (a command whose data goes to a file reports on standard output)."""
    if not quiet(args):
        print(*text, file=sys.stderr if file is None else file)


_OS_HINTS = {
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.ENOENT: "no such file or folder",
    errno.EISDIR: "is a folder, a file was expected",
    errno.ENOTDIR: "a part of this path is a file, not a folder",
    errno.EEXIST: "already exists",
    errno.EBUSY: "device or resource busy",
    errno.ENOSPC: "no space left on the device",
    errno.EROFS: "read-only file system",
    errno.EXDEV: "cannot rename across file systems",
    errno.ENAMETOOLONG: "file name too long",
    errno.ELOOP: "too many levels of symbolic links",
    errno.EMFILE: "too many open files",
    errno.EIO: "input/output error",
    errno.EDQUOT: "disk quota exceeded",
}


def os_error_message(exc: OSError) -> str:
    """One line for an OSError: the path(s), then what went wrong in plain words."""
    from ..io.errors import OutputError

    if isinstance(exc, OutputError):
        return str(exc)
    what = _OS_HINTS.get(exc.errno) or exc.strerror or str(exc) or type(exc).__name__
    paths = [str(p) for p in (exc.filename, exc.filename2) if p is not None]
    if paths:
        return f"{' -> '.join(paths)}: {what}"
    return f"{what} ({exc})" if exc.strerror and str(exc) != exc.strerror else what


def _first_line(exc: BaseException) -> str:
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return " ".join(lines[:2]) if lines else type(exc).__name__


UNDER_DETERMINED = ("the estimation problem is under-determined ({}); likely causes: co-located or too few "
                    "accelerometers, a stretch of constant or missing readings, or options that leave a state free")


def _under_determined(exc: BaseException) -> bool:
    text = str(exc)
    return "Indeterminant" in text or "Indeterminate" in text


def error_message(exc: BaseException) -> tuple[str, int]:
    """(message, exit status) for an exception that ends a command.

    A :class:`gfimu.errors.GfimuError` is one of gfimu's own errors: its message, exit status 2
    (input, data) or 1 (resource). A path that is not there (or a loop of links) is a mistake in the
    command: exit 2. Any other ``OSError`` is the operating system refusing (a resource): the path
    and the reason, exit 1; so is running out of memory. GTSAM's "indeterminant linear
    system" is the data not determining the states (exit 2). Anything else is a bug: an internal
    error naming its type, exit 1."""
    if isinstance(exc, GfimuError):
        if isinstance(exc, OSError) and exc.errno is not None:
            return os_error_message(exc), exc.exit_status
        if _under_determined(exc):
            return UNDER_DETERMINED.format(_first_line(exc)), exc.exit_status
        return str(exc) or type(exc).__name__, exc.exit_status
    if isinstance(exc, (FileNotFoundError, NotADirectoryError)) or (
            isinstance(exc, OSError) and exc.errno in (errno.ELOOP, errno.ENAMETOOLONG)):
        return os_error_message(exc), EXIT_USAGE  # a path given on the command line that is not there (or cannot be)
    if isinstance(exc, OSError):
        return os_error_message(exc), EXIT_FAILURE
    if isinstance(exc, MemoryError):
        return "out of memory (try a shorter log, or fewer methods)", EXIT_FAILURE
    if isinstance(exc, RuntimeError) and _under_determined(exc):
        return UNDER_DETERMINED.format("GTSAM: " + _first_line(exc)), EXIT_USAGE
    return internal_error_message(exc), EXIT_FAILURE


def internal_error_message(exc: BaseException) -> str:
    """The line for an exception gfimu did not raise on purpose: a bug, not a mistake of the user."""
    return f"internal error: {type(exc).__name__}: {_first_line(exc)} (run with --debug for the traceback)"


def _warning_printer(command: str):
    """Warnings as one line each: ``gfimu COMMAND: warning: ...`` (the full form with --debug)."""

    def show(message, category, filename, lineno, file=None, line=None):  # noqa: ARG001
        try:
            print(f"gfimu {command}: warning: {message}", file=sys.stderr if file is None else file)
        except (OSError, ValueError):
            pass

    return show


_SIGNALLED: list[int] = []
"""The signal that is ending this run (empty while none came)."""


def _remove_temporaries() -> None:
    """Remove the temporary files and folders being written (only if the atomic writer was loaded: importing
    it would import numpy)."""
    atomic = sys.modules.get("gfimu.io.atomic")
    if atomic is not None:
        atomic.remove_temporaries()


def _on_signal(signum, frame) -> None:  # noqa: ARG001
    """SIGINT / SIGTERM: remove the temporary files, one line, exit 130 / 143. A second signal while the
    first is ending the run changes nothing (no traceback, the same status)."""
    if _SIGNALLED:
        return
    _SIGNALLED.append(signum)
    if _PROGRAM:  # the process ends: a later signal, even during the interpreter's teardown, is ignored
        _ignore_signals()
    _remove_temporaries()
    try:
        sys.stderr.write(f"gfimu: stopped by {signal.Signals(signum).name}; no output was left half-written\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    raise SystemExit(128 + signum)


_PROGRAM: list[bool] = []
"""Set while :func:`main` runs as the program (no ``argv`` given)."""


def _ignore_signals() -> None:
    """SIGINT and SIGTERM ignored from now on. The interpreter's teardown puts a Python handler back to
    the default (death by the signal, exit -2); an ignored signal stays ignored."""
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)


def _install_signal_handlers() -> dict:
    """:func:`_on_signal` for SIGINT and SIGTERM (from the main thread only); the previous handlers."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    _SIGNALLED.clear()
    return {sig: signal.signal(sig, _on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}


def main(argv: list[str] | None = None) -> int:
    """The command line. ``argv`` None: the program's own (``sys.argv``); the SIGINT/SIGTERM handler is
    installed first, before any import of the command, and once the command is done (or a signal is ending
    it) SIGINT and SIGTERM are ignored to the end of the process, so that a signal at any time, once or
    twice, ends in one line and 130 / 143. Given an ``argv`` (a call from
    Python), the previous handlers are put back on return."""
    _PROGRAM[:] = [argv is None]
    previous = _install_signal_handlers()
    try:
        return _main(argv)
    except BaseException:
        if _SIGNALLED:  # a signal is ending the run: its status, never a traceback (raised inside a C
            # extension's import, the handler's SystemExit comes back as an ImportError)
            raise SystemExit(128 + _SIGNALLED[0]) from None
        raise
    finally:
        if argv is None:
            _ignore_signals()  # the command is done: its exit status stands
        else:
            for sig, old in previous.items():
                if old is not None:
                    signal.signal(sig, old)


def _main(argv: list[str] | None) -> int:
    parser = build_parser(command_of(sys.argv[1:] if argv is None else list(argv)))
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a malformed command line (argparse printed why)
        if _SIGNALLED:
            raise
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    try:
        with warnings.catch_warnings():
            if not args.debug:
                warnings.showwarning = _warning_printer(args.command)
            return int(args.func(args) or 0)
    except BrokenPipeError:  # output piped into a reader that stopped (e.g. head)
        _remove_temporaries()
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        _remove_temporaries()
        print(f"gfimu {args.command}: interrupted; no output was left half-written", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - every error becomes one line unless --debug
        _remove_temporaries()
        if _SIGNALLED:  # the signal's own exit, already said (main)
            raise
        if args.debug:
            raise
        message, status = error_message(exc)
        message = shorten(message)
        kind = "" if message.startswith("internal error: ") else "error: "
        print(f"gfimu {args.command}: {kind}{message}", file=sys.stderr)
        return status
