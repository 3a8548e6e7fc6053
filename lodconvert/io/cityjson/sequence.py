"""The lines of a CityJSONSeq file, read in chunks: blank lines are skipped without a Python
step per line (a chunk of nothing but white space at once, shorter runs by a regular
expression), a ``.gz`` or ``.zip`` stops once it inflates past ``decompressed_bytes``, and a
line longer than ``sequence_line_bytes`` is passed over as it streams (never held whole)."""

from __future__ import annotations

import re
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from ...limits import Limits
from ..archive import open_compressed
from .source import CHUNK, unreadable

_BLANK = re.compile(rb"[ \t\r\n]*")
Line = tuple[int, "bytes | None"]
"""A line's number (from 1) and its bytes (``None``: longer than ``sequence_line_bytes``)."""


def sequence_lines(path: Path, limits: Limits) -> Iterator[Line]:
    """Each line of ``path`` (what it inflates to, for ``.gz``/``.zip``) that holds more than
    white space, with its number (from 1), without its line break; ``None`` for a line longer
    than ``limits.sequence_line_bytes``, whose bytes past the limit are read and dropped up to
    its end (:func:`long_line` says why). :class:`InputError` for a file that
    cannot be read, and one that inflates past ``limits.decompressed_bytes``
    (:func:`..archive.open_compressed`)."""
    try:
        with open_compressed(path, limits) as stream:
            for number, line, _ in stream_lines(stream, limits):
                yield number, line
    except (OSError, EOFError, zlib.error) as exc:
        raise unreadable(path, exc) from None


def stream_lines(
    stream: IO[bytes], limits: Limits, number: int = 1, at: int = 0
) -> Iterator[tuple[int, bytes | None, int]]:
    """The lines of ``stream`` as :func:`sequence_lines` gives them, each with where it starts
    (after the line break before it): ``stream`` starts at a line start, ``at`` bytes into its
    file, whose number is ``number``."""
    longest = limits.sequence_line_bytes
    pending = bytearray()
    base = start_of_line = at  # where pending starts in the file; where its line starts
    scanned, passing = 0, False  # passing over a long line
    while chunk := stream.read(CHUNK):
        if passing:
            end = chunk.find(b"\n")
            if end < 0:
                base += len(chunk)
                continue
            yield number, None, start_of_line
            number, passing, chunk = number + 1, False, chunk[end + 1 :]
            base = start_of_line = base + end + 1
        if not pending and chunk.isspace():  # blank lines, skipped at C speed
            if (last := chunk.rfind(b"\n")) >= 0:
                number += chunk.count(b"\n")
                start_of_line = base + last + 1
            base += len(chunk)
            continue
        pending += chunk
        begin = 0
        while True:
            start = _BLANK.match(pending, begin).end()
            if (last := pending.rfind(b"\n", begin, start)) >= 0:
                number += pending.count(b"\n", begin, start)
                start_of_line = base + last + 1
            end = pending.find(b"\n", max(start, scanned))
            if end < 0:
                break
            line = bytes(pending[start:end]) if end - start <= longest else None
            yield number, line, start_of_line
            number, begin, start_of_line = number + 1, end + 1, base + end + 1
        del pending[:start]
        base += start
        scanned = len(pending)  # holds no line break: not searched again
        if scanned > longest:
            pending.clear()
            base += scanned
            scanned, passing = 0, True
    if passing:
        yield number, None, start_of_line
    elif pending:
        yield number, bytes(pending), start_of_line


def long_line(limits: Limits) -> str:
    """Why a line longer than ``limits.sequence_line_bytes`` is not read."""
    return (
        f"is longer than the limit of {limits.sequence_line_bytes:,} bytes "
        "(sequence_line_bytes; raise it with --limit sequence_line_bytes=N)"
    )
