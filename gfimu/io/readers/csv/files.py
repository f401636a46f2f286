"""Where a table's bytes come from: a file, a folder, or a zip archive (phyphox and Sensor Logger
exports), each member read with a limit on its inflated size (:class:`Source`).
"""

from __future__ import annotations

from pathlib import Path
import zipfile

from ...errors import LogFormatError


ZIP_MEMBER_BYTES = 1 << 30
"""Largest zip member read, inflated [bytes]."""


ZIP_BOMB_BYTES = 64 << 20
"""A member inflating beyond this many bytes ..."""


ZIP_BOMB_RATIO = 100
"""... to more than this many times its compressed size is refused as a zip bomb (sensor tables compress 3 to
20 times)."""


def _zip_member(archive: Path, member: str, shown: Path) -> bytes:
    """The bytes of ``member`` of ``archive``, inflated a block at a time and refused (a :class:`LogFormatError`
    naming ``shown``) as soon as they pass :data:`ZIP_MEMBER_BYTES`, or :data:`ZIP_BOMB_BYTES` at more than
    :data:`ZIP_BOMB_RATIO` times the member's compressed size: a small archive never takes the memory of what it
    claims to hold."""
    try:
        with zipfile.ZipFile(archive) as z:
            info = z.getinfo(member)
            packed = max(int(info.compress_size), 1)
            limit = min(ZIP_MEMBER_BYTES, max(ZIP_BOMB_BYTES, ZIP_BOMB_RATIO * packed))
            if info.file_size > limit:
                raise LogFormatError(_zip_too_big(info.file_size, packed, limit), shown)
            blocks, size = [], 0
            with z.open(info) as fh:
                while True:
                    block = fh.read(1 << 20)
                    if not block:
                        break
                    size += len(block)
                    if size > limit:
                        raise LogFormatError(_zip_too_big(size, packed, limit, more=True), shown)
                    blocks.append(block)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError, NotImplementedError) as exc:
        if isinstance(exc, LogFormatError):
            raise
        raise LogFormatError(f"cannot read this member of the zip archive {archive}: {exc}", shown) from None
    return b"".join(blocks)


def _zip_too_big(size: int, packed: int, limit: int, more: bool = False) -> str:
    return (f"inflates to {'more than ' if more else ''}{size / 2**20:.1f} MiB from {packed / 2**10:.1f} KiB in the zip "
            f"archive, beyond the {limit / 2**20:.0f} MiB read from a member of that size (a zip bomb?); unpack it "
            "and give the folder if it is a real recording")


class Source:
    """The files of a recording: a file, a folder, or a zip archive (its members read in memory)."""

    def __init__(self, input_path: Path):
        self.input = input_path
        self.members: dict[str, str] | None = None  # zip: name inside the archive's top folder -> member
        if input_path.is_file() and zipfile.is_zipfile(input_path):
            try:
                with zipfile.ZipFile(input_path) as z:
                    names = [n for n in z.namelist() if not n.endswith("/")]
            except (zipfile.BadZipFile, OSError) as exc:
                raise LogFormatError(f"cannot read this zip archive: {exc}", input_path) from None
            twice = sorted({n for n in names if names.count(n) > 1})
            if twice:  # which of the two is read would depend on the zip library
                raise LogFormatError(f"the zip archive holds {twice[0]!r} {names.count(twice[0])} times; which one is "
                                     "the recording is not known (keep one)", input_path)
            tops = {n.split("/", 1)[0] for n in names if "/" in n}
            strip = (next(iter(tops)) + "/") if len(tops) == 1 and all("/" in n for n in names) else ""
            self.members = {n[len(strip):]: n for n in names}
        self.is_folder = input_path.is_dir() or self.members is not None
        self.folder = input_path if self.is_folder else input_path.parent

    def exists(self, path: Path) -> bool:
        if self.members is not None and self.input in path.parents:
            return path.relative_to(self.input).as_posix() in self.members
        return path.is_file()

    def text(self, path: Path) -> str | None:
        """The text of a zip member (None for a file on disk, which :func:`read_table` reads itself)."""
        if self.members is None or self.input not in path.parents:
            return None
        raw = _zip_member(self.input, self.members[path.relative_to(self.input).as_posix()], path)
        try:
            return raw.decode("utf-8").lstrip("\ufeff")
        except UnicodeDecodeError as exc:
            raise LogFormatError(f"not UTF-8 text (byte {exc.start})", path,
                                 raw[: exc.start].count(b"\n") + 1) from None
