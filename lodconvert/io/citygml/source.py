"""A CityGML document's bytes (the file, or what its ``.gz`` or ``.zip`` inflates to, capped:
:func:`..archive.open_compressed`; every text held to the text limit), its parser options, and
a first look at its root element before the document is streamed."""

from __future__ import annotations

import re
from pathlib import Path
from typing import IO

from lxml import etree

from ...errors import InputError
from ...limits import Limits
from ..archive import Capped, open_compressed
from .text_limit import TextLimit

CHUNK = 1 << 16
"""Bytes read from the file at a time."""
Stream = IO[bytes] | Capped | TextLimit
"""A document's bytes as :func:`open_document` gives them."""


def open_document(path: Path, limits: Limits) -> Stream:
    """The document's bytes as a stream (:func:`..archive.open_compressed`), every text in
    them held to ``limits.xml_text_bytes`` (:mod:`.text_limit`) unless the file is a plain
    one no longer than that."""
    stream = open_compressed(path, limits)
    if isinstance(stream, Capped) or path.stat().st_size > limits.xml_text_bytes:
        return TextLimit(stream, limits.xml_text_bytes, str(path))
    return stream


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

    def __init__(self, head: bytes, stream: Stream) -> None:
        self.head, self.stream = head, stream

    def read(self, size: int = -1) -> bytes:
        if self.head:
            data, self.head = self.head, b""
            return data
        return self.stream.read(size)

    def close(self) -> None:
        self.stream.close()


def first_look(stream: Stream, limits: Limits, source: str) -> tuple[_Replay, etree._Element]:
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
