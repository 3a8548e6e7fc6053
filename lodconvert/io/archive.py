"""Compressed city models: what a ``.gz`` or a ``.zip`` inflates to, capped at the run's
``decompressed_bytes`` (never written to disk), and the one city model file a ``.zip`` holds.

A ``.zip`` input holds exactly one file of :data:`ZIP_MEMBERS` (CityGML ``.gml``/``.xml``,
CityJSON ``.json``, CityJSONSeq ``.jsonl``), in any folder; other files (a licence, a readme)
are ignored, and so is a ``__MACOSX/`` folder. The registry reads it with that file's format
(:func:`~lodconvert.io.input_format`). A zip holding none, or several (of one kind or of
several), is refused naming up to three of them, as are unsafe member names (``..``, absolute
paths), an encrypted member, one packed by a method zipfile does not read, and one declared
larger than the limit.
"""

from __future__ import annotations

import gzip
import io
import re
import zipfile
import zlib
from pathlib import Path, PurePosixPath
from typing import IO

from ..errors import InputError
from ..limits import Limits

ZIP_MEMBERS = (".gml", ".xml", ".json", ".jsonl")
"""Suffixes of the files a ``.zip`` input is read for: CityGML, CityJSON, CityJSONSeq."""
_ZIP_METHODS = frozenset(
    {zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA}
)
"""Compression methods a ``.zip`` member may be packed with."""


class Capped(io.RawIOBase):
    """A binary stream that raises :class:`InputError` once more than ``limit`` bytes came
    out of it (what a compressed input inflates to), or when what it inflates is broken (a
    gzip trailer whose size or CRC does not match included), whoever reads it."""

    def __init__(self, stream: IO[bytes], limit: int, source: str) -> None:
        super().__init__()
        self.stream, self.limit, self.source, self.total = stream, limit, source, 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: memoryview | bytearray) -> int:
        try:
            data = self.stream.read(len(buffer))
        except (zlib.error, zipfile.BadZipFile, gzip.BadGzipFile, EOFError) as exc:
            raise InputError(f"cannot be read ({exc})", self.source) from None
        self.total += len(data)
        if self.total > self.limit:
            raise inflation_error(self.limit, self.source)
        buffer[: len(data)] = data
        return len(data)

    def close(self) -> None:
        self.stream.close()
        super().close()


def inflation_error(limit: int, source: str) -> InputError:
    """The error of an input that inflates past ``limit`` bytes."""
    return InputError(
        f"inflates past the limit of {limit:,} bytes (decompressed_bytes; "
        "raise it with --limit decompressed_bytes=N)",
        source,
    )


def member_name(path: Path) -> str:
    """The name of the one city model file of zip ``path`` (:class:`InputError` otherwise)."""
    with _opened(path) as archive:
        return _member(archive, str(path)).filename


def open_member(path: Path, limits: Limits) -> Capped:
    """The bytes of the one city model file of zip ``path``, capped at
    ``limits.decompressed_bytes``."""
    source = str(path)
    archive = _opened(path)
    try:
        member = _member(archive, source)
        if member.file_size > limits.decompressed_bytes:
            raise inflation_error(limits.decompressed_bytes, source)
        if member.flag_bits & 0x1:
            raise InputError(f"holds {member.filename!r} encrypted (not read)", source)
        if member.compress_type not in _ZIP_METHODS:
            raise InputError(
                f"holds {member.filename!r} packed with compression method "
                f"{member.compress_type}, which is not read",
                source,
            )
        return Capped(archive.open(member), limits.decompressed_bytes, source)
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError) as exc:
        archive.close()
        raise InputError(f"is not a valid zip file ({exc})", source) from None
    except InputError:
        archive.close()
        raise


def open_compressed(path: Path, limits: Limits) -> IO[bytes] | Capped:
    """The bytes of ``path``: the file, or what its ``.gz`` or ``.zip`` (its one city model
    file) inflates to, capped at ``limits.decompressed_bytes``."""
    source = str(path)
    name = path.name.lower()
    _not_zip_in_gz(path)
    if name.endswith(".gz"):
        return Capped(gzip.open(path, "rb"), limits.decompressed_bytes, source)
    if name.endswith(".zip"):
        return open_member(path, limits)
    return path.open("rb")


def inflated_size(path: Path) -> int:
    """The bytes ``path`` holds once inflated, as it declares them: its one city model file's
    size in a ``.zip``, the size a ``.gz`` gives in its last four bytes (modulo 4 GiB), else the
    file's size; 0 where they cannot be read (its reader says why). For sizing work, never
    for limits or buffers."""
    name = path.name.lower()
    try:
        if name.endswith(".zip"):
            with zipfile.ZipFile(path) as archive:
                return _member(archive, str(path)).file_size
        if name.endswith(".gz"):
            with path.open("rb") as handle:
                handle.seek(-4, io.SEEK_END)
                return int.from_bytes(handle.read(4), "little")
        return path.stat().st_size
    except (OSError, InputError, zipfile.BadZipFile, zlib.error, EOFError):
        return 0


def _opened(path: Path) -> zipfile.ZipFile:
    """``path`` opened as a zip (:class:`InputError` where it is not one)."""
    _not_zip_in_gz(path)
    try:
        return zipfile.ZipFile(path)
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError) as exc:
        raise InputError(f"is not a valid zip file ({exc})", str(path)) from None


def _not_zip_in_gz(path: Path) -> None:
    """Refuse a ``.zip.gz``: a zip is compressed already."""
    if path.name.lower().endswith(".zip.gz"):
        raise InputError("is a .zip inside a .gz: give the .zip itself", str(path))


def _member(archive: zipfile.ZipFile, source: str) -> zipfile.ZipInfo:
    """The one file of :data:`ZIP_MEMBERS` in ``archive``; :class:`InputError` for unsafe
    names (``..``, absolute paths) or not exactly one such file."""
    members = []
    for info in archive.infolist():
        name = info.filename.replace("\\", "/")
        parts = PurePosixPath(name).parts
        if name.startswith("/") or ".." in parts or re.match(r"[A-Za-z]:", name):
            raise InputError(f"holds an unsafe member name {info.filename!r}", source)
        if not parts or name.endswith("/") or parts[0] == "__MACOSX":
            continue  # no name, a folder, or macOS resource forks
        if name.lower().endswith(ZIP_MEMBERS):
            members.append(info)
    if len(members) != 1:
        names = ", ".join(repr(m.filename) for m in members[:3])
        raise InputError(
            f"holds {len(members)} city model files (CityGML .gml/.xml, CityJSON .json, "
            f"CityJSONSeq .jsonl){': ' + names if names else ''}; a .zip input must hold "
            "exactly one",
            source,
        )
    return members[0]
