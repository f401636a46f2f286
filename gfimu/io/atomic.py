"""The one atomic writer of gfimu.

Every file gfimu writes goes through :func:`atomic_path`: the content is
written to a temporary file in the destination folder, flushed to disk
(``fsync``), then renamed over the destination, so a failure or an
interruption never leaves a half-written file and never loses the old one.
The temporary file is removed on any error; while it exists it is listed in
a registry that :func:`remove_temporaries` empties (the command line calls it
from its SIGINT/SIGTERM handler, see :func:`install_signal_cleanup`).

A destination that exists and is not a regular file (a folder, a device such
as ``/dev/null``, a FIFO, a socket) is refused with :class:`OutputError`,
never replaced. A destination that is a symbolic link is written through:
the file it points to is replaced and the link is kept.
"""

from __future__ import annotations

import os
import signal
import stat
import sys
import tempfile
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from .errors import OutputError

_PENDING: set[str] = set()
_LOCK = threading.Lock()


def file_kind(mode: int) -> str:
    """Plain words for the type of a file from its ``st_mode``."""
    for test, name in ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a folder"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def stat_or_none(path: str | os.PathLike, name: str) -> os.stat_result | None:
    """``os.stat(path)``, None when nothing is there; :class:`OutputError` (naming ``name``) when a part
    of the path is a file."""
    try:
        return os.stat(path)
    except FileNotFoundError:
        return None
    except NotADirectoryError:
        raise OutputError(f"{name}: a part of this path is a file, not a folder") from None


def destination(path: str | os.PathLike) -> Path:
    """The file an output to ``path`` replaces, after checks; :class:`OutputError` otherwise.

    Symbolic links are followed (the link is kept, its target replaced). The
    destination must not exist, or be a regular file; its folder must exist.
    """
    p = Path(path)
    if str(p) in ("", "."):
        raise OutputError(f"{str(path)!r}: not a file name")
    target = Path(os.path.realpath(p)) if p.is_symlink() else p
    st = stat_or_none(target, str(p))
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise OutputError(f"{p}: exists and is {file_kind(st.st_mode)}; refusing to replace it with a file")
    folder = target.parent
    if not folder.is_dir():
        if folder.exists():
            raise OutputError(f"{p}: {folder} is not a folder")
        raise OutputError(f"{p}: the output folder {folder} does not exist")
    return target


def _register(tmp: str) -> None:
    with _LOCK:
        _PENDING.add(tmp)


def _unregister(tmp: str) -> None:
    with _LOCK:
        _PENDING.discard(tmp)


def pending_temporaries() -> list[str]:
    """Temporary files being written now (for tests and the signal handler)."""
    with _LOCK:
        return sorted(_PENDING)


def remove_temporaries() -> int:
    """Remove every temporary file still being written; returns how many were removed."""
    with _LOCK:
        names = list(_PENDING)
        _PENDING.clear()
    n = 0
    for name in names:
        try:
            os.unlink(name)
            n += 1
        except OSError:
            pass
    return n


def _naming(exc: OSError, target: Path) -> OSError:
    """The same error, naming the destination instead of the temporary file."""
    if isinstance(exc, OutputError):
        return exc
    if exc.errno is None:
        return exc
    return type(exc)(exc.errno, exc.strerror or str(exc), str(target))


def _remove(tmp: str) -> None:
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass


def _fsync_folder(folder: Path) -> None:
    try:  # make the rename itself durable
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[Path]:
    """Path of a temporary file to write; on a normal exit it is synced and renamed over ``path``.

    Use it for writers that take a file name (for example a figure's
    ``savefig``); :func:`atomic_write` wraps it for text and bytes. On an
    exception the temporary file is removed and ``path`` is left as it was.
    """
    target = destination(path)
    folder = target.parent
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix, dir=folder)
    except OSError as exc:  # name the destination, not the temporary file
        raise _naming(exc, target) from None
    os.close(fd)
    _register(tmp)
    try:
        yield Path(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        destination(path)  # still a regular file (or absent) right before the rename
        os.replace(tmp, target)
    except OSError as exc:
        _remove(tmp)
        if exc.filename in (None, tmp) or exc.filename2 == tmp:
            raise _naming(exc, target) from None
        raise
    except BaseException:
        _remove(tmp)
        raise
    finally:
        _unregister(tmp)
    _fsync_folder(folder)


def atomic_write(path: str | os.PathLike, chunks: Iterable[str] | Iterable[bytes], binary: bool = False) -> None:
    """Write text (or, with ``binary``, bytes) chunks to ``path`` atomically.

    If producing a chunk raises, the temporary file is removed and an existing
    ``path`` is left untouched.
    """
    with atomic_path(path) as tmp:
        if binary:
            with open(tmp, "wb") as fh:
                for chunk in chunks:
                    fh.write(chunk)
        else:
            with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
                for chunk in chunks:
                    fh.write(chunk)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (never a half-written file)."""
    atomic_write(path, [text])


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    atomic_write(path, [data], binary=True)


def install_signal_cleanup() -> dict:
    """On SIGINT or SIGTERM: remove the temporary files being written, then exit 130 or 143.

    Only from the main thread (signal handlers can be set nowhere else);
    elsewhere this does nothing. Returns the previous handlers, for
    :func:`restore_signal_handlers`.
    """
    if threading.current_thread() is not threading.main_thread():
        return {}

    def handler(signum, frame):  # noqa: ARG001
        remove_temporaries()
        name = signal.Signals(signum).name
        try:
            sys.stderr.write(f"gfimu: stopped by {name}; no output was left half-written\n")
            sys.stderr.flush()
        except (OSError, ValueError):
            pass
        raise SystemExit(128 + signum)

    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, handler)
    return previous


def restore_signal_handlers(previous: dict) -> None:
    """Put back the handlers :func:`install_signal_cleanup` replaced."""
    for sig, old in previous.items():
        if old is not None:
            signal.signal(sig, old)
