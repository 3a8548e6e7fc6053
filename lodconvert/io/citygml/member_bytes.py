"""A CityGML document's ``appearanceMember`` elements told apart from the rest by a byte
search, without parsing either: the members alone, inside a root that declares the document's
namespaces (:func:`appearance_members`: what :func:`.appearance.read_global` parses), and the
document without them (:func:`without_appearance_members`: what the city objects are read
from), so that each is parsed once."""

from __future__ import annotations

import re
from collections.abc import Iterator
from xml.sax.saxutils import quoteattr

from lxml import etree

from .source import CHUNK, Stream

NAME = b"appearanceMember"
"""The local name of the elements picked (a child of the root only, in every CityGML version)."""
_SKIPPED = ((b"<!--", b"-->"), (b"<![CDATA[", b"]]>"), (b"<?", b"?>"))
"""Openers and ends of what may hold the name without being markup: comments, CDATA
sections and processing instructions."""
_TAG_HEAD = re.compile(rb"</?(?:[A-Za-z_][\w.\-]*:)?")
"""What comes before the name in its start or end tag: ``<`` or ``</``, and a prefix."""
_AFTER_NAME = frozenset(b" \t\r\n/>")
"""Bytes that may follow the name in a tag."""
_DECLARED = re.compile(rb"""<\?xml\s[^>]*?encoding\s*=\s*["']([A-Za-z][\w.\-]*)["']""")
"""The encoding an XML declaration names."""
_PROBE = "<appearanceMember/>-?]![CDATA["
"""The characters searched for, which an encoding must write as ASCII."""
_LOOK_BACK = 1024
"""Bytes before the name searched for its tag's ``<``."""


def appearance_members(replay: Stream, head: bytes, root: etree._Element) -> Stream | None:
    """A stream of the document ``replay`` (read from its start, which is ``head``; ``root``
    its root element) with only its ``appearanceMember`` elements inside a root declaring the
    same namespaces, each after the line breaks of what was left out before it (so that a
    parser's line numbers are the document's); None where its encoding does not write ASCII
    as ASCII (UTF-16, UTF-32)."""
    encoding = _encoding(head)
    if encoding is None:
        return None
    names = " ".join(
        f"xmlns{'' if prefix is None else ':' + prefix}={quoteattr(uri)}"
        for prefix, uri in root.nsmap.items()
    )
    start = f'<?xml version="1.0" encoding="{encoding}"?><root {names}>'.encode(encoding)

    def chunks() -> Iterator[bytes]:
        yield start
        for inside, data in _runs(replay):
            yield data if inside else b"\n" * data.count(b"\n")
        yield b"</root>"

    return _Chunks(chunks())


def without_appearance_members(replay: Stream, head: bytes) -> Stream | None:
    """A stream of the document ``replay`` (read from its start, which is ``head``) with its
    ``appearanceMember`` elements left out but for their line breaks: what the city objects
    are read from once the appearances are, so that they are not parsed (nor held) again;
    None where its encoding does not write ASCII as ASCII."""
    if _encoding(head) is None:
        return None
    return _Chunks(
        data if not inside else b"\n" * data.count(b"\n") for inside, data in _runs(replay)
    )


def _encoding(head: bytes) -> str | None:
    """The encoding of a document that starts with ``head``, where it writes ASCII as ASCII
    (what the byte search needs); else None."""
    head = head.removeprefix(b"\xef\xbb\xbf")  # UTF-8's byte order mark
    if head[:1] not in (b"<", b" ", b"\t", b"\r", b"\n") or b"\x00" in head[:4]:
        return None
    declared = _DECLARED.match(head)
    encoding = declared.group(1).decode("ascii") if declared else "UTF-8"
    try:
        return encoding if _PROBE.encode(encoding) == _PROBE.encode("ascii") else None
    except LookupError:
        return None


class _Chunks:
    """A binary stream of the chunks an iterator gives (empty ones passed over)."""

    def __init__(self, chunks: Iterator[bytes]) -> None:
        self.chunks = chunks

    def read(self, size: int = -1) -> bytes:
        return next((chunk for chunk in self.chunks if chunk), b"")

    def close(self) -> None:
        return None


def _runs(stream: Stream) -> Iterator[tuple[bool, bytes]]:
    """Every byte of ``stream`` in runs, each with whether it is (part of) one of its
    ``appearanceMember`` elements."""
    data = b""
    pos = 0  # where the search goes on in data
    given = 0  # the bytes of data given so far
    member = False  # whether they end inside a member
    ended = False
    while True:
        tag, pos = _next_tag(data, pos)
        if tag is None:  # more bytes are needed, from pos on
            if ended:
                yield member, data[given:]
                return
            if pos > given:
                yield member, data[given:pos]
            data, pos, given = data[pos:], 0, 0
            chunk = stream.read(CHUNK)
            ended = not chunk
            data += chunk
            continue
        closing, start = tag
        if not member and not closing:
            yield False, data[given:start]
            if data[pos - 2 : pos] == b"/>":
                yield True, data[start:pos]
                given = pos
            else:
                member, given = True, start
        elif member and closing:
            yield True, data[given:pos]
            member, given = False, pos


def _next_tag(data: bytes, pos: int) -> tuple[tuple[bool, int] | None, int]:
    """The next ``appearanceMember`` tag in ``data`` from ``pos``, outside comments, CDATA and
    processing instructions (whether it is an end tag, and where it starts), and where it
    ends; or None, and the first byte still needed where ``data`` ends first."""
    while True:
        at = data.find(NAME, pos)
        limit = len(data) if at < 0 else at
        skipped = _skipped(data, pos, limit)
        if skipped is not None:
            where, opener, end = skipped
            close = data.find(end, where + len(opener))
            if close < 0:
                return None, where
            pos = close + len(end)
            continue
        if at < 0:
            return None, max(pos, len(data) - _LOOK_BACK - len(NAME))
        start = data.rfind(b"<", max(pos, at - _LOOK_BACK), at)
        after = at + len(NAME)
        if after >= len(data):
            return None, max(pos, at - _LOOK_BACK)
        if start < 0 or _TAG_HEAD.fullmatch(data, start, at) is None:
            pos = after  # the name in text or in a longer name
            continue
        if data[after] not in _AFTER_NAME:
            pos = after
            continue
        end = _tag_end(data, after)
        if end is None:
            return None, start
        return (data[start + 1] == ord("/"), start), end


def _skipped(data: bytes, pos: int, limit: int) -> tuple[int, bytes, bytes] | None:
    """The first comment, CDATA section or processing instruction that opens in ``data``
    from ``pos`` before ``limit``: where, its opener and its end. Searched for by their
    second byte (``!`` or ``?``: rare in a city, where ``<`` is everywhere)."""
    first = None
    for mark in (b"!", b"?"):
        at = pos + 1
        while (at := data.find(mark, at, limit)) >= 0 and (first is None or at <= first[0]):
            opener = next((o for o in _SKIPPED if data.startswith(o[0], at - 1)), None)
            if opener is not None:
                first = (at - 1, *opener)
                break
            at += 1
    return first


def _tag_end(data: bytes, pos: int) -> int | None:
    """Where the tag going on at ``pos`` in ``data`` ends (after its ``>``; quoted attribute
    values may hold one), or None where ``data`` ends first."""
    quote = None
    for k in range(pos, len(data)):
        byte = data[k]
        if quote is not None:
            if byte == quote:
                quote = None
        elif byte in b"\"'":
            quote = byte
        elif byte == ord(">"):
            return k + 1
    return None
