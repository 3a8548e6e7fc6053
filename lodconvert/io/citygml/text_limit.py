"""The ``xml_text_bytes`` limit on every text of an XML document, checked on its bytes as they
stream to the parser, before libxml2 holds a text node whole.

A text node runs from the end of one tag to the start of the next: between two ``<`` that
open a tag (``<name``, ``</name``). Comments, CDATA sections and processing instructions do
not end it (libxml2 joins the text around a comment it drops), and the ``<`` inside them opens
nothing, so they are skipped whole to the end marker. A run of bytes between two tags, the
first tag's own bytes (its attribute values) included, longer than the limit is refused: this
bounds every text node and attribute value of the document, not only coordinates. Runs are
found with numpy a chunk at a time; only comments, CDATA and processing instructions take a
step in Python each.
"""

from __future__ import annotations

from typing import IO, Protocol

import numpy as np

from ...errors import InputError

_LT, _BANG, _QUESTION = ord("<"), ord("!"), ord("?")
_SPECIAL = ((b"<!--", b"-->"), (b"<![CDATA[", b"]]>"), (b"<?", b"?>"), (b"<!", b">"))
"""Markup that a ``<`` inside does not end, and the bytes that end it (``<!`` alone: a
DOCTYPE, refused before it is parsed)."""
_LOOKAHEAD = 9
"""Bytes after a ``<`` needed to tell what it opens (``<![CDATA[``)."""


class _Readable(Protocol):
    def read(self, size: int = -1) -> bytes: ...

    def close(self) -> None: ...


class TextLimit:
    """A binary stream that raises :class:`InputError` once a text of the XML document it
    carries (see the module's docstring) is longer than ``limit`` bytes."""

    def __init__(self, stream: IO[bytes] | _Readable, limit: int, source: str) -> None:
        self.stream, self.limit, self.source = stream, limit, source
        self.run = 0
        """Bytes since the last tag's ``<``, up to :attr:`pending`."""
        self.closer: bytes | None = None
        """The end marker awaited inside a comment, CDATA section or instruction."""
        self.pending = b""
        """The last bytes read, not scanned yet (they may begin a marker)."""

    def read(self, size: int = -1) -> bytes:
        data = self.stream.read(size)
        self._scan(self.pending + data, final=not data)
        return data

    def close(self) -> None:
        self.stream.close()

    def _scan(self, buffer: bytes, final: bool) -> None:
        """Scan ``buffer`` (:attr:`pending` and the bytes just read) up to its last
        :data:`_LOOKAHEAD` bytes (all of it at the end of the stream), which wait for more."""
        stop = len(buffer) if final else max(0, len(buffer) - _LOOKAHEAD)
        bytes_ = np.frombuffer(buffer, dtype=np.uint8)
        opens = np.flatnonzero(bytes_[:stop] == _LT)
        following = bytes_[np.minimum(opens + 1, len(buffer) - 1)]
        markup = (following == _BANG) | (following == _QUESTION)
        tags, specials = opens[~markup], opens[markup]
        at = 0
        while at < stop:
            if self.closer is not None:
                end = buffer.find(self.closer, at)
                if end < 0 or end >= stop:
                    self._grow(stop - at)
                    at = stop
                    break
                end += len(self.closer)
                self._grow(end - at)
                at, self.closer = end, None
                continue
            ahead = specials[np.searchsorted(specials, at) :]
            special = int(ahead[0]) if len(ahead) else stop
            self._tags(
                tags[np.searchsorted(tags, at) : np.searchsorted(tags, special)], at, special
            )
            at = special
            if at < stop:
                opener, self.closer = next(
                    (o, c) for o, c in _SPECIAL if buffer.startswith(o, at) or o == b"<!"
                )
                self._grow(len(opener))
                at += len(opener)
        self.pending = buffer[at:]

    def _tags(self, tags: np.ndarray, start: int, end: int) -> None:
        """Account for bytes ``start`` to ``end`` of the buffer, holding tags opening at
        ``tags``."""
        if not len(tags):
            self._grow(end - start)
            return
        first = self.run + int(tags[0]) - start
        longest = max(first, int(np.diff(tags).max(initial=0)))
        if longest > self.limit:
            raise self._error()
        self.run = 0
        self._grow(end - int(tags[-1]))

    def _grow(self, count: int) -> None:
        """Add ``count`` bytes to the run since the last tag."""
        self.run += count
        if self.run > self.limit:
            raise self._error()

    def _error(self) -> InputError:
        return InputError(
            f"has an XML text or tag over the limit of {self.limit:,} bytes "
            "(xml_text_bytes; raise it with --limit xml_text_bytes=N)",
            self.source,
        )
