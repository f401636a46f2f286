"""The output policy of every gfimu command.

One rule for every file a command writes:

- it is written through :func:`gfimu.io.atomic.atomic_path` (temporary file
  in the destination folder, fsync, rename; the temporary file is removed on
  any error and on SIGINT/SIGTERM);
- it never replaces one of the command's inputs, nor a file of an input
  log (``array.toml``, ``imu.csv``, ``truth.csv``, ``reference.csv``; other
  files in a log folder, an earlier estimate, are no input): paths are
  compared after resolving links, and by device and inode (hard links);
- it never replaces anything that is not a regular file (a folder, a device
  such as ``/dev/null``, a FIFO, a socket);
- ``-`` means standard output where the command allows it (tables, estimates);
- a file written inside a command's own output folder (``batch``) never goes through a link in that
  folder nor outside it (:func:`check_output_within`);
- a file written as a stream goes (``live``) has one writer at a time
  (:func:`gfimu.io.atomic.output_lock`: a second writer is refused).

Log folders (``convert``, ``simulate``) are written by
:func:`prepare_log_folder` + :func:`gfimu.io.write_log`: an existing
non-empty folder is refused unless ``force``, and then only the files a log
owns (:data:`gfimu.io.log_dir.LOG_FILES`) are replaced or removed, so no
stale truth or reference of an earlier run stays next to the new log. The
folder is swapped in whole (:func:`gfimu.io.atomic.atomic_folder`): an
interrupted or failed run leaves the old log as it was. A folder given as a
symbolic link is refused, and links inside it are never written through.
"""

from __future__ import annotations

import os
import stat
import sys
from collections.abc import Iterable
from pathlib import Path

from .atomic import atomic_write, destination, file_kind, folder_destination, stat_or_none
from .errors import OutputError
from .log_dir import LOG_FILES

STDOUT = "-"

STDOUT_CLOSED = "--out -: standard output is closed (started with it shut); give --out a file name"


def input_files(paths: Iterable[str | os.PathLike | None]) -> list[Path]:
    """The files that stand behind a command's inputs.

    A log folder (one holding ``array.toml`` and ``imu.csv``) stands for the
    files a log owns (:data:`LOG_FILES`): an estimate, figure or calibration
    written next to them is no input and may be written again. Any other
    folder stands for every file in it (a folder of recordings). A file of a
    log folder also stands for the other files of that log. ``None`` and
    ``-`` are skipped; paths that do not exist are kept (compared by name).
    """
    out: list[Path] = []
    for p in paths:
        if p is None or str(p) == STDOUT:
            continue
        p = Path(p)
        out.append(p)
        if p.is_dir():
            if (p / "array.toml").is_file() and (p / "imu.csv").is_file():
                out.extend(p / name for name in LOG_FILES if (p / name).exists())
            else:
                out.extend(c for c in p.iterdir() if c.is_file())
        elif p.name in LOG_FILES and p.parent.is_dir():
            out.extend(p.parent / name for name in LOG_FILES if (p.parent / name).exists())
    return out


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True when ``a`` and ``b`` are the same file: same resolved path, or same device and inode."""
    try:
        if os.path.samefile(a, b):
            return True
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def _input_refusal(path: str | os.PathLike, shown: str, inputs: list[Path], what: str) -> OutputError | None:
    """The error that refuses an output to ``path`` (``shown`` as given) when it is one of the ``inputs`` (links
    resolved, hard links compared by inode: the same answer for a link as for the file it names), else None."""
    for inp in inputs:
        if same_file(path, inp):
            same = "" if os.path.realpath(inp) == os.path.realpath(path) else f" ({inp}, the same file)"
            return OutputError(f"{what} {shown}: is an input of this command{same}; refusing to overwrite it "
                               "(write the output elsewhere)")
    return None


def _refuse_inputs(path: Path, shown: str, inputs: list[Path], what: str) -> None:
    refused = _input_refusal(path, shown, inputs, what)
    if refused is not None:
        raise refused


def check_output(path: str | os.PathLike | None, inputs: Iterable[str | os.PathLike | None] = (),
                 what: str = "--out", stdout: bool = False) -> Path | None:
    """Check one output file before any work is done; ``None`` means standard output.

    Refused with :class:`OutputError` naming ``what`` (the option): ``-``
    where ``stdout`` is not allowed; one of the ``inputs`` or a file of an
    input log folder; an existing destination that is not a regular file; a
    missing output folder.
    """
    if path is None:
        return None
    if str(path) == STDOUT:
        if not stdout:
            raise OutputError(f"{what} -: this output cannot go to standard output; give a file name")
        if sys.stdout is None:
            raise OutputError(STDOUT_CLOSED.replace("--out", what, 1))
        return None
    # an input compares the same through a link as the file it names; the destination's own refusal comes first
    refused = _input_refusal(path, str(path), input_files(inputs), what)
    try:
        target = destination(path)
    except OutputError as exc:
        hint = "; use - for standard output" if stdout and "refusing to replace it" in str(exc) else ""
        raise OutputError(f"{what} {exc}{hint}") from None
    if refused is not None:
        raise refused
    return target


def check_outputs(paths: dict, inputs: Iterable[str | os.PathLike | None] = (), stdout: str | None = None) -> list:
    """:func:`check_output` of each of ``paths`` (option -> path or None), in order, and no two the same file;
    ``stdout``: the option that may be ``-``. Returns the checked targets in the same order."""
    out = []
    seen: list[tuple[str, Path]] = []
    for what, path in paths.items():
        target = check_output(path, inputs, what, stdout=what == stdout)
        for other, earlier in seen:
            if target is not None and same_file(target, earlier):
                raise OutputError(f"{what} {path}: the same file as {other} {earlier}; give each output its own name")
        if target is not None:
            seen.append((what, target))
        out.append(target)
    return out


def write_output(target: Path | None, chunks: Iterable[str]) -> None:
    """Write text chunks to ``target`` atomically, or to standard output when ``target`` is ``None``."""
    if target is None:
        if sys.stdout is None:
            raise OutputError(STDOUT_CLOSED)
        try:
            for chunk in chunks:
                sys.stdout.write(chunk)
            sys.stdout.flush()
        except BrokenPipeError:  # its reader stopped (head): the command line ends quietly
            raise
        except OSError as exc:  # a full disk behind the redirection: name where it was going
            from .atomic import resource_error

            raise resource_error(exc, "standard output (--out -)") from None
        return
    atomic_write(target, chunks)


def prepare_log_folder(folder: str | os.PathLike, inputs: Iterable[str | os.PathLike | None] = (),
                       force: bool = False, what: str = "--out") -> Path:
    """Check the folder a command writes a log into, before any work is done.

    Refused with :class:`OutputError`: ``-``; a path that exists and is not
    a folder; a folder holding one of the command's inputs under a name the
    log writes; a non-empty folder unless ``force``; with ``force``, a log
    file name that is not a regular file. A missing folder is fine
    (:func:`gfimu.io.write_log` creates it).
    """
    if str(folder) == STDOUT:
        raise OutputError(f"{what} -: a log is a folder; give its path")
    p = folder_destination(folder, what)
    st = stat_or_none(p, f"{what} {p}")
    ins = input_files(inputs)
    for name in LOG_FILES:
        _refuse_inputs(p / name, str(p / name), ins, what)
    if st is None:  # created by write_log, once there is a log to write
        return p
    entries = sorted(c.name for c in p.iterdir())
    if entries and not force:
        shown = ", ".join(entries[:6]) + (", ..." if len(entries) > 6 else "")
        raise OutputError(f"{what} {p}: the folder is not empty ({shown}); use --force to replace the log in it "
                          f"({', '.join(LOG_FILES)} are replaced or removed, other files are kept)")
    for name in LOG_FILES:
        try:
            mode = os.lstat(p / name).st_mode
        except FileNotFoundError:
            continue
        if stat.S_ISDIR(mode):
            raise OutputError(f"{what} {p / name}: exists and is a folder; refusing to replace it with a file")
    return p


def check_output_within(root: str | os.PathLike, rel: str | os.PathLike, inputs: Iterable[str | os.PathLike | None] = (),
                        what: str = "--out") -> Path:
    """Check the file ``root/rel`` a command writes inside its output folder ``root``, before it is written.

    Besides :func:`check_output`'s refusals: no part of ``rel`` may be a symbolic link (a link planted in the
    output folder would take the file outside it), ``..`` or absolute, and every part but the last that
    exists must be a folder. Missing folders are fine (the caller creates them). Returns the path.
    """
    rel = Path(rel)
    if rel.is_absolute() or any(part in ("", ".", "..") for part in rel.parts):
        raise OutputError(f"{what} {root}: {rel} is not a name inside the output folder")
    cur = Path(root)
    for k, part in enumerate(rel.parts):
        cur = cur / part
        try:
            st = os.lstat(cur)
        except FileNotFoundError:
            break
        except NotADirectoryError:
            raise OutputError(f"{what} {cur}: a part of this path is a file, not a folder") from None
        if stat.S_ISLNK(st.st_mode):
            raise OutputError(f"{what} {cur}: is a symbolic link (to {os.readlink(cur)}) in the output folder; "
                              f"refusing to write through it (remove it, or give another --out)")
        if k < len(rel.parts) - 1 and not stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{what} {cur}: exists and is {file_kind(st.st_mode)}, not a folder")
    target = Path(root) / rel
    if Path(os.path.realpath(root)) / rel != Path(os.path.realpath(target)):
        raise OutputError(f"{what} {target}: resolves to {os.path.realpath(target)}, outside the output folder "
                          f"{root}; refusing to write there")
    try:
        destination_ok = stat_or_none(target.parent, f"{what} {target}") is None
    except OutputError:
        raise
    if destination_ok:
        _refuse_inputs(target, str(target), input_files(inputs), what)
        return target
    check_output(target, inputs, what)
    return target
