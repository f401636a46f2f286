"""The one atomic writer of gfimu.

Every file gfimu writes goes through :func:`atomic_path`: the content is
written to a temporary file in the destination folder, flushed to disk
(``fsync``), then renamed over the destination, so a failure or an
interruption never leaves a half-written file and never loses the old one.
The temporary file is removed on any error; while it exists it is listed in
a registry that :func:`remove_temporaries` empties (the command line calls it
from its SIGINT/SIGTERM handler, :func:`gfimu.cli.main`).

A destination that exists and is not a regular file (a folder, a device such
as ``/dev/null``, a FIFO, a socket) is refused with :class:`OutputError`,
never replaced; so is a name ending in ``/`` (it names a folder). A
destination that is a symbolic link is written through: the file it points
to is replaced and the link is kept.

A whole folder (a log) is written with :func:`atomic_folder`: into a sibling
temporary folder, then swapped in at once (the old folder renamed aside, the
new one renamed in, the old one removed); on any failure or interruption the
old folder stays as it was and the temporary one is removed. Nothing in the
old folder is followed or written through: its links stay links.

Temporary names are ``.NAME.XXXXXXXX.tmp`` with ``NAME`` cut to
:data:`TEMP_NAME_BYTES` bytes, so that they fit the file system's limit
(255 bytes) whatever the length of the destination's name.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import stat
import tempfile
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from .errors import OutputError

_PENDING: set[str] = set()
_LOCK = threading.Lock()

TEMP_NAME_BYTES = 64
"""Bytes of the destination's name kept in a temporary name (the rest of it is random)."""


def temp_prefix(name: str) -> str:
    """``.NAME.`` with ``NAME`` cut to :data:`TEMP_NAME_BYTES` bytes of UTF-8 (never inside a character)."""
    cut = name.encode("utf-8", "surrogateescape")[:TEMP_NAME_BYTES].decode("utf-8", "ignore")
    return f".{cut}."


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
    text = os.fspath(path)
    if isinstance(text, str) and (text.endswith(("/", os.sep)) or text.endswith(("/.", "/.."))):
        raise OutputError(f"{text}: ends with '/', which names a folder; give a file name (without the '/')")
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
            if os.path.isdir(name) and not os.path.islink(name):
                shutil.rmtree(name)
            else:
                os.unlink(name)
            n += 1
        except OSError:
            pass
    return n


RESOURCE_ERRNOS = frozenset(getattr(errno, name) for name in (
    "ENOSPC", "EDQUOT", "EIO", "EROFS", "EACCES", "EPERM", "EMFILE", "ENFILE", "ENOMEM", "EFBIG", "EXDEV")
    if hasattr(errno, name))
"""Errors of writing that are the machine refusing (a full disk, no permission, ...): raised as
:class:`gfimu.errors.ResourceError`."""

_RESOURCE_TYPES: dict[type, type] = {}


def resource_error(exc: OSError, filename: str | os.PathLike | None = None) -> OSError:
    """``exc`` (naming ``filename`` when given) as a :class:`gfimu.errors.ResourceError` when its errno is one
    of :data:`RESOURCE_ERRNOS`: also still an instance of its own type (``PermissionError``, ...), so that
    code catching that goes on working. Other errors come back as they are (renamed when asked)."""
    from ..errors import GfimuError, ResourceError

    name = exc.filename if filename is None else filename
    if exc.errno is None or isinstance(exc, OutputError):
        return exc
    if isinstance(exc, GfimuError):
        return exc if filename is None else type(exc)(exc.errno, exc.strerror or str(exc), str(name))
    if exc.errno not in RESOURCE_ERRNOS:
        return exc if filename is None else type(exc)(exc.errno, exc.strerror or str(exc), str(name))
    kind = _RESOURCE_TYPES.get(type(exc))
    if kind is None:
        kind = _RESOURCE_TYPES[type(exc)] = type(type(exc).__name__, (ResourceError, type(exc)),
                                                 {"__module__": ResourceError.__module__})
    out = kind(exc.errno, exc.strerror or str(exc), None if name is None else str(name))
    return out


def _naming(exc: OSError, target: Path) -> OSError:
    """The same error, naming the destination instead of the temporary file (a :class:`ResourceError` for a
    full disk, no permission, ...: :func:`resource_error`)."""
    if isinstance(exc, OutputError):
        return exc
    if exc.errno is None:
        return exc
    return resource_error(exc, target)


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
        fd, tmp = tempfile.mkstemp(prefix=temp_prefix(target.name), suffix=suffix, dir=folder)
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
        raise resource_error(exc) from None
    except BaseException:
        _remove(tmp)
        raise
    finally:
        _unregister(tmp)
    _fsync_folder(folder)


def folder_destination(path: str | os.PathLike, what: str = "") -> Path:
    """The folder :func:`atomic_folder` writes, after checks; :class:`OutputError` (its message starting
    with ``what`` and the path) when it is a symbolic link or exists and is not a folder."""
    p = Path(path)
    shown = f"{what} {p}" if what else str(p)
    if str(p) in ("", ".", "..") or p.name in ("", ".", ".."):
        raise OutputError(f"{shown}: the folder is replaced whole, so it must be named from outside it "
                          f"(for example ../NAME, not . or ..)")
    try:
        st = os.lstat(p)
    except FileNotFoundError:
        return p
    except NotADirectoryError:
        raise OutputError(f"{shown}: a part of this path is a file, not a folder") from None
    if stat.S_ISLNK(st.st_mode):
        raise OutputError(f"{shown}: is a symbolic link (to {os.readlink(p)}); refusing to write through it "
                          "(give the folder itself)")
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{shown}: exists and is {file_kind(st.st_mode)}; a log is written into a folder")
    return p


def _keep(src: Path, dst: Path) -> None:
    """``src`` again as ``dst`` without touching ``src``: a hard link (a copy where the file system has
    none); links are recreated as links, never followed; folders entry by entry."""
    st = os.lstat(src)
    if stat.S_ISLNK(st.st_mode):
        os.symlink(os.readlink(src), dst)
    elif stat.S_ISDIR(st.st_mode):
        os.mkdir(dst)
        for child in os.listdir(src):
            _keep(src / child, dst / child)
        shutil.copystat(src, dst, follow_symlinks=False)
    else:
        try:
            os.link(src, dst, follow_symlinks=False)
        except OSError:
            if not stat.S_ISREG(st.st_mode):
                raise
            shutil.copy2(src, dst, follow_symlinks=False)


def _in_place_of(exc: OSError, tmp: str, target: Path) -> OSError:
    """The same error, naming the path in ``target`` rather than in the temporary folder ``tmp``."""
    if isinstance(exc, OutputError) or exc.errno is None:
        return exc
    name = exc.filename
    if name is None or name == tmp:
        return _naming(exc, target)
    name = os.fspath(name)
    if isinstance(name, str) and name.startswith(tmp + os.sep):
        return resource_error(exc, str(target) + name[len(tmp):])
    return resource_error(exc)


def _blocked_signals():
    """Block SIGINT and SIGTERM in this thread (returns the previous mask, None where it cannot)."""
    try:
        return signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    except (AttributeError, OSError, ValueError):
        return None


@contextmanager
def atomic_folder(path: str | os.PathLike, replaced: Iterable[str] = (), what: str = "") -> Iterator[Path]:
    """A temporary folder next to ``path`` to write a whole folder into; on a normal exit it replaces
    ``path`` at once.

    The entries of an existing ``path`` not named in ``replaced`` are kept (hard
    links, or copies; links stay links): the new folder gets them too. Then
    the old folder is renamed aside, the new one renamed in (SIGINT and SIGTERM
    held meanwhile) and the old one removed. On an exception (or SIGINT /
    SIGTERM through the command line's handler) the temporary folder is
    removed and ``path`` is left exactly as it was. ``path`` must not be a
    symbolic link, and must be a folder if it exists (:func:`folder_destination`).
    The folder above it is created when missing.
    """
    target = folder_destination(path, what)
    parent = target.parent
    parent.mkdir(parents=True, exist_ok=True)
    replaced = set(replaced)
    try:
        tmp = tempfile.mkdtemp(prefix=temp_prefix(target.name), suffix=".tmp", dir=parent)
    except OSError as exc:
        shown = f"{what} {target}" if what else str(target)
        raise OutputError(f"{shown}: cannot create a folder next to it in {parent} "
                          f"({(exc.strerror or str(exc)).lower()}); the new folder is written there first, then "
                          "swapped in whole") from None
    _register(tmp)
    new = Path(tmp)
    aside = None
    try:
        yield new
        folder_destination(path, what)  # still no link planted meanwhile
        if target.is_dir():
            for name in sorted(os.listdir(target)):
                if name not in replaced and not (new / name).exists() and not os.path.islink(new / name):
                    _keep(target / name, new / name)
        if target.is_dir():  # the old folder's permissions
            os.chmod(new, stat.S_IMODE(os.stat(target).st_mode))
        else:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(new, 0o777 & ~umask)
        mask = _blocked_signals()
        try:
            if target.is_dir():
                aside = tempfile.mktemp(prefix=temp_prefix(target.name), suffix=".old", dir=parent)
                os.rename(target, aside)
                _register(aside)
                try:
                    os.rename(new, target)
                except BaseException:
                    os.rename(aside, target)
                    _unregister(aside)
                    aside = None
                    raise
            else:
                os.rename(new, target)
            _unregister(tmp)
        finally:
            if mask is not None:
                signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        _unregister(tmp)
        raise _in_place_of(exc, tmp, target) from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        _unregister(tmp)
        raise
    if aside is not None:
        shutil.rmtree(aside, ignore_errors=True)
        _unregister(aside)
    _fsync_folder(parent)


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


LOCK_SUFFIX = ".lock"
"""Suffix of the companion lock file of an output being written (``.NAME.lock`` next to it)."""


def lock_name(target: Path) -> Path:
    """The companion lock file of ``target``: ``.NAME.lock`` in its folder (``NAME`` cut as in temporary names)."""
    return target.parent / (temp_prefix(target.name)[:-1] + LOCK_SUFFIX)


@contextmanager
def output_lock(path: str | os.PathLike, what: str = "--out") -> Iterator[Path]:
    """Hold the one writer's lock of the output ``path`` while the block runs; a second writer is refused.

    The lock is an exclusive ``flock`` on the companion file ``.NAME.lock`` next to ``path`` (created
    without following a link); the kernel releases it when the process ends however it ends (SIGKILL
    included), so a lock is never left stale. Another process holding it: :class:`OutputError` naming
    ``what`` and the path, before anything is written. The file is removed when the block ends.
    """
    import fcntl

    target = Path(path)
    lock = lock_name(target)
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0), 0o644)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise OutputError(f"{what} {target}: its lock file {lock} is a symbolic link; refusing to "
                                  "follow it") from None
            raise _naming(exc, lock) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OutputError(f"{what} {target}: another gfimu process is writing this file now (it holds "
                              f"{lock}); give this one another output") from None
        except OSError:
            os.close(fd)
            raise
        try:  # the file locked is still the one under that name (not removed by a writer just ending)
            same = os.path.samestat(os.fstat(fd), os.lstat(lock))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        yield lock
    finally:
        try:
            os.unlink(lock)
        except OSError:
            pass
        os.close(fd)
