"""The byte ranges of a CityGML document's root children, found without parsing the document:
its prolog (everything up to the end of the root's start tag: declarations, namespaces) and
each child of the root as bytes, so that workers can parse a run of members inside the root
(:mod:`.parallel`).

The scan looks for markup only: a child's end is the first ``</name`` after its start tag
when nothing between them opens markup that could hide or nest one (a comment, CDATA, a
processing instruction or another ``<name``); otherwise that child is scanned tag by tag,
comments, CDATA and processing instructions passed whole. A ``<`` cannot stand in an
attribute value or in text, so nothing else can fool it; a document that is not well-formed
XML ends the scan (:class:`NotSplit`), and its reader says what is wrong with it.

A scan may also start inside the root, at a child's start tag (its offset in the document
given), and stop before the first member that starts at or after a given offset: a byte range
of the document's members (:mod:`.ranges`). :func:`member_after` finds where a member may start
from any offset, by its start tag alone (which a comment or CDATA could hold: :mod:`.ranges`
checks each such guess against the scan before it).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Protocol

from .names import MEMBERS

CHUNK = 1 << 20
"""Bytes read from the document at a time."""

_MARKUP = re.compile(
    rb"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>|<!DOCTYPE[^>]*>"
    rb"|</(?P<end>[^\s>]+)\s*>"
    rb"|<(?P<start>[^\s/>!?]+)(?:[^>\"']|\"[^\"]*\"|'[^']*')*?(?P<empty>/?)>",
    re.DOTALL,
)
"""One piece of markup: a comment, CDATA, a processing instruction, a DOCTYPE, an end tag or a
start tag (``empty``: ``/`` for an element without content)."""
_MEMBER_TAG = re.compile(
    rb"<(?:[A-Za-z_][\w.-]*:)?(?:" + b"|".join(n.encode() for n in sorted(MEMBERS)) + rb")[\s/>]"
)
"""The start tag of a member, whatever its prefix."""
_TAG_BYTES = 64
"""Bytes of a member's start tag up to its name's end (at most; for a search across chunks)."""


class Readable(Protocol):
    def read(self, size: int = -1, /) -> bytes: ...


class NotSplit(Exception):
    """The document could not be cut into its root's children (it is not well-formed)."""


class Members:
    """A document's prolog, the root's end tag and its children, scanned from ``stream`` as
    they are asked for (:meth:`__iter__`), a :data:`CHUNK` at a time. With ``offset``,
    ``stream`` starts at that offset of the document, at a child of its root (no prolog);
    with ``stop``, the scan ends before the first member starting at or after that offset."""

    def __init__(self, stream: Readable, offset: int | None = None, stop: int | None = None):
        self.stream = stream
        self.buffer = bytearray()
        self.position = self.kept = 0
        self.base = offset or 0
        """The document's offset of the buffer's first byte."""
        self.stop = stop
        self.start = -1
        """The document's offset of the child last given."""
        self.end = -1
        """Where the scan ended: the offset of the root's end tag, or of the member at ``stop``."""
        self.closed = False
        """Whether the scan reached the root's end tag."""
        if offset is not None:
            self.prolog = self.root_end = b""
            self.empty = False
            return
        piece = self._markup(start_only=True)
        self.prolog = bytes(self.buffer[: piece.end()])
        self.root_end = b"</" + piece["start"] + b">"
        self.empty = bool(piece["empty"])
        self.kept = self.position

    def __iter__(self) -> Iterator[tuple[str, bytes]]:
        """Each child of the root: its local name and its bytes, in document order."""
        if self.empty:
            return
        while True:
            self.kept = self.position  # what came before is done with
            piece = self._markup()
            if piece["end"] is not None:
                self.end, self.closed = self.base + piece.start(), True
                return
            if piece["start"] is None:
                continue
            name, start = piece["start"], piece.start()
            local = name.rpartition(b":")[2].decode("ascii", "replace")
            if self.stop is not None and self.base + start >= self.stop and local in MEMBERS:
                self.end = self.base + start
                return
            if not piece["empty"]:
                start, self.position = self._end_of(name, start, piece.end())
            self.start = self.base + start
            yield local, bytes(self.buffer[start : self.position])

    def _more(self) -> int:
        """Read more (dropping what is done with, before :attr:`kept`): a chunk, or as much
        as is kept, so that markup looked at again as it grows (a long comment) is looked at
        a few times, not once per chunk; how far the bytes kept moved back.
        :class:`NotSplit` when the document has ended."""
        dropped, self.kept = self.kept, 0
        del self.buffer[:dropped]
        chunk = self.stream.read(max(CHUNK, len(self.buffer)))
        if not chunk:
            raise NotSplit("the document ends inside its root element")
        self.buffer += chunk  # in place: a long member is read in time linear in its bytes
        self.position -= dropped
        self.base += dropped
        return dropped

    def _markup(self, start_only: bool = False) -> re.Match[bytes]:
        """The next piece of markup from :attr:`position` (text before it, which the reader
        does not read, passed; with ``start_only``, the first start tag), moving past it."""
        while True:
            at = self.buffer.find(b"<", self.position)
            piece = _MARKUP.match(self.buffer, at) if at >= 0 else None
            if piece is None:
                self._more()
                continue
            self.position = piece.end()
            if start_only and piece["start"] is None:
                continue
            return piece

    def _end_of(self, name: bytes, start: int, after: int) -> tuple[int, int]:
        """Where the element ``name`` whose start tag spans ``start`` to ``after`` starts and
        ends (past its end tag), reading on as it takes (which moves the bytes kept)."""
        close = b"</" + name
        nested = re.compile(rb"<" + re.escape(name) + rb"[\s/>]|<!|<\?")
        searched = after  # where the end tag is looked for (each byte once, chunk by chunk)
        while True:
            at = self.buffer.find(close, searched)
            end = self.buffer.find(b">", at) if at >= 0 else -1
            if end < 0:
                searched = at if at >= 0 else max(after, len(self.buffer) - len(close))
                moved = self._more()
                start, after, searched = start - moved, after - moved, searched - moved
                continue
            if nested.search(self.buffer, after, at) is None:
                return start, end + 1
            return self._scanned(start, after)

    def _scanned(self, start: int, after: int) -> tuple[int, int]:
        """:meth:`_end_of`, tag by tag."""
        depth, position = 1, after
        while True:
            at = self.buffer.find(b"<", position)
            piece = _MARKUP.match(self.buffer, at) if at >= 0 else None
            if piece is None:
                moved = self._more()
                start, position = start - moved, position - moved
                continue
            position = piece.end()
            if piece["end"] is not None:
                depth -= 1
            elif piece["start"] is not None and not piece["empty"]:
                depth += 1
            if depth == 0:
                return start, position


def member_after(stream: Readable, offset: int) -> int | None:
    """The offset of the first member start tag at or after ``offset`` (``stream`` starting
    there), by its bytes alone (it may stand in a comment or CDATA); None where none follows."""
    buffer = b""
    while chunk := stream.read(CHUNK):
        buffer += chunk
        found = _MEMBER_TAG.search(buffer)
        if found is not None:
            return offset + found.start()
        kept = buffer[-_TAG_BYTES:]
        offset += len(buffer) - len(kept)
        buffer = kept
    found = _MEMBER_TAG.search(buffer)
    return offset + found.start() if found is not None else None
