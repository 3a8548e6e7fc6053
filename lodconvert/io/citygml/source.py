"""Opening a CityGML document: the file, or what its ``.gz`` or ``.zip`` inflates to (capped),
and a first look at its root element before the document is streamed."""

from __future__ import annotations

import gzip
import re
import zipfile
import zlib
from pathlib import Path, PurePosixPath
from typing import IO

from lxml import etree

from ...errors import InputError
from ...limits import Limits

CHUNK = 1 << 16
"""Bytes read from the file at a time."""


class _Capped:
    """A binary stream that raises :class:`InputError` once more than ``limit`` bytes came
    out of it (what a compressed input inflates to)."""

    def __init__(self, stream: IO[bytes], limit: int, source: str) -> None:
        self.stream, self.limit, self.source, self.total = stream, limit, source, 0

    def read(self, size: int = -1) -> bytes:
        data = self.stream.read(CHUNK if size is None or size < 0 else size)
        self.total += len(data)
        if self.total > self.limit:
            raise _inflation_error(self.limit, self.source)
        return data

    def close(self) -> None:
        self.stream.close()


def _inflation_error(limit: int, source: str) -> InputError:
    return InputError(
        f"inflates past the limit of {limit:,} bytes (decompressed_bytes; "
        "raise it with --limit decompressed_bytes=N)",
        source,
    )


def _zip_member(archive: zipfile.ZipFile, limits: Limits, source: str) -> zipfile.ZipInfo:
    """The one CityGML file of a zip; :class:`InputError` for unsafe names (``..``, absolute
    paths), a member declared larger than ``limits.decompressed_bytes``, or not exactly one
    ``.gml``/``.xml`` member."""
    members = []
    for info in archive.infolist():
        name = info.filename.replace("\\", "/")
        parts = PurePosixPath(name).parts
        if name.startswith("/") or ".." in parts or re.match(r"[A-Za-z]:", name):
            raise InputError(f"holds an unsafe member name {info.filename!r}", source)
        if not info.is_dir() and name.lower().endswith((".gml", ".xml")):
            members.append(info)
    if len(members) != 1:
        names = ", ".join(repr(m.filename) for m in members[:3])
        raise InputError(
            f"holds {len(members)} CityGML (.gml/.xml) files{': ' + names if names else ''}; "
            "a .zip input must hold exactly one",
            source,
        )
    if members[0].file_size > limits.decompressed_bytes:
        raise _inflation_error(limits.decompressed_bytes, source)
    return members[0]


_ZIP_METHODS = frozenset(
    {zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA}
)
"""Compression methods a ``.zip`` member may be packed with."""


def open_document(path: Path, limits: Limits) -> IO[bytes] | _Capped:
    """The document's bytes as a stream: the file, or what its ``.gz`` or ``.zip`` inflates
    to, capped at ``limits.decompressed_bytes`` (never written to disk)."""
    source = str(path)
    name = path.name.lower()
    if name.endswith(".zip.gz"):
        raise InputError("is a .zip inside a .gz: give the .zip itself", source)
    if name.endswith(".gz"):
        return _Capped(gzip.open(path, "rb"), limits.decompressed_bytes, source)
    if name.endswith(".zip"):
        try:
            archive = zipfile.ZipFile(path)
            member = _zip_member(archive, limits, source)
            if member.flag_bits & 0x1:
                raise InputError(f"holds {member.filename!r} encrypted (not read)", source)
            if member.compress_type not in _ZIP_METHODS:
                raise InputError(
                    f"holds {member.filename!r} packed with compression method "
                    f"{member.compress_type}, which is not read",
                    source,
                )
            return _Capped(archive.open(member), limits.decompressed_bytes, source)
        except (zipfile.BadZipFile, zlib.error, OSError, EOFError) as exc:
            raise InputError(f"is not a valid zip file ({exc})", source) from None
    return path.open("rb")


_LIBXML_TEXT_LIMIT = 10_000_000
"""Bytes of one text node libxml2 accepts without ``huge_tree``."""
_LIBXML_DEPTH_LIMIT = 256
"""Nesting depth libxml2 accepts without ``huge_tree``."""


def parser_options(limits: Limits) -> dict[str, bool]:
    """The hardened lxml parser options: no DTD loaded, no entity resolved, no network; huge
    text nodes and deep nesting only as far as ``limits`` needs them."""
    huge = limits.xml_text_bytes > _LIBXML_TEXT_LIMIT or limits.xml_depth > _LIBXML_DEPTH_LIMIT
    return {
        "resolve_entities": False,
        "no_network": True,
        "load_dtd": False,
        "huge_tree": huge,
        "remove_comments": True,
        "remove_pis": True,
    }


class _Replay:
    """A binary stream that gives ``head`` (bytes already read) before the rest of ``stream``."""

    def __init__(self, head: bytes, stream: IO[bytes] | _Capped) -> None:
        self.head, self.stream = head, stream

    def read(self, size: int = -1) -> bytes:
        if self.head:
            data, self.head = self.head, b""
            return data
        return self.stream.read(size)

    def close(self) -> None:
        self.stream.close()


def first_look(
    stream: IO[bytes] | _Capped, limits: Limits, source: str
) -> tuple[_Replay, etree._Element]:
    """The document's root element (parsed from as few chunks as it takes, without children)
    and a stream that reads the whole document again from its start. :class:`InputError` for
    a document with a DOCTYPE, before any of its content is read (entities are a security
    risk); :class:`lxml.etree.XMLSyntaxError` when the document ends or breaks before its
    root."""
    parser = etree.XMLPullParser(events=("start",), **parser_options(limits))
    head: list[bytes] = []
    try:
        while chunk := stream.read(CHUNK):
            head.append(chunk)
            parser.feed(chunk)
            for _, root in parser.read_events():
                if root.getroottree().docinfo.doctype:
                    raise _doctype_error(source)
                return _Replay(b"".join(head), stream), root
        parser.close()
    except etree.XMLSyntaxError:
        if _DOCTYPE.match(b"".join(head)):
            raise _doctype_error(source) from None
        raise
    raise etree.XMLSyntaxError("the document has no root element", None, 0, 0)


_DOCTYPE = re.compile(rb"(?:[^<]|<[?!](?!DOCTYPE))*<!DOCTYPE")
"""Bytes that hold a DOCTYPE before the first element (a prolog may hold declarations,
comments and processing instructions before it)."""


def _doctype_error(source: str) -> InputError:
    return InputError("XML with a DOCTYPE is not read (entities are a security risk)", source)
