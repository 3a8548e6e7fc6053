"""The lines of a CityJSONSeq file, read in chunks: blank lines are skipped without a Python
step per line (a chunk of nothing but white space at once, shorter runs by a regular
expression), a ``.gz`` or ``.zip`` stops once it inflates past ``decompressed_bytes``, and a
line once it passes ``sequence_line_bytes``."""

from __future__ import annotations

import re
import zlib
from collections.abc import Iterator
from pathlib import Path

from ...errors import InputError
from ...limits import Limits
from ..archive import open_compressed
from .source import CHUNK, unreadable

_BLANK = re.compile(rb"[ \t\r\n]*")


def sequence_lines(path: Path, limits: Limits) -> Iterator[tuple[int, bytes]]:
    """Each line of ``path`` (what it inflates to, for ``.gz``/``.zip``) that holds more than
    white space, with its number (from 1), without its line break. :class:`InputError` for a
    file that cannot be read, one that inflates past ``limits.decompressed_bytes``
    (:func:`..archive.open_compressed`) and a line longer than ``limits.sequence_line_bytes``."""
    longest = limits.sequence_line_bytes
    pending = bytearray()
    number = 1
    try:
        with open_compressed(path, limits) as stream:
            while chunk := stream.read(CHUNK):
                if not pending and chunk.isspace():  # blank lines, skipped at C speed
                    number += chunk.count(b"\n")
                    continue
                pending += chunk
                at = 0
                while True:
                    start = _BLANK.match(pending, at).end()
                    number += pending.count(b"\n", at, start)
                    end = pending.find(b"\n", start)
                    if end < 0:
                        break
                    _check_length(end - start, number, longest, path)
                    yield number, bytes(pending[start:end])
                    number, at = number + 1, end + 1
                del pending[:start]
                _check_length(len(pending), number, longest, path)
    except (OSError, EOFError, zlib.error) as exc:
        raise unreadable(path, exc) from None
    if pending:
        yield number, bytes(pending)


def _check_length(length: int, number: int, longest: int, path: Path) -> None:
    """:class:`InputError` for line ``number`` when ``length`` passes ``longest`` bytes."""
    if length > longest:
        raise InputError(
            f"has a line (line {number}) longer than the limit of {longest:,} bytes "
            "(sequence_line_bytes; raise it with --limit sequence_line_bytes=N)",
            str(path),
        )
