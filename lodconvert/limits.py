"""Limits on what one run may read and bake, so that memory and time follow what a file holds,
not what it claims. Every limit can be raised (``--limit NAME=VALUE`` on the command line,
``Limits(...)`` in the library); docs/bad-input.md has the table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

from .errors import UsageError

KIB, MIB, GIB = 1 << 10, 1 << 20, 1 << 30


@dataclass(frozen=True)
class Limits:
    """The limits of one run (docs/bad-input.md: what each bounds and why)."""

    decompressed_bytes: int = 2 * GIB
    """Bytes a compressed input (``.gz``, ``.zip``) may inflate to; inflation stops there."""
    vertices: int = 50_000_000
    """Vertices one input file may hold."""
    faces: int = 100_000_000
    """Triangles one input file may hold."""
    grid_cells: int = 1 << 30
    """Cells of one point level's grid (T3 × T3 × T1 along the object's sides)."""
    memory_bytes: int = 1 * GIB
    """Working memory the baker may take at once; larger work is done in chunks."""
    xml_depth: int = 256
    """Nesting depth of an XML input (city models)."""
    xml_text_bytes: int = 256 * MIB
    """Bytes of every text (a ``posList``, a description, an attribute value) of an XML
    input."""
    sequence_line_bytes: int = 64 * MIB
    """Bytes of one line of a CityJSONSeq input (its header or one feature)."""
    image_bytes: int = 64 * MIB
    """Bytes of one texture image a city model's appearance names (read no further)."""
    image_pixels: int = 1 << 26
    """Pixels of one texture image (8,192²), checked from its header before it is decoded."""
    tileset_json_bytes: int = 16 * MIB
    """Bytes of one tileset JSON that ``validate`` and ``view`` read (the top file and each
    external tileset); a larger file is refused before it is read."""

    def check(self) -> None:
        """Raise :class:`UsageError` unless every limit is a positive whole number."""
        for field in fields(self):
            value = getattr(self, field.name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise UsageError(f"must be a positive whole number, got {value!r}", field.name)

    def with_text(self, assignments: list[str]) -> Limits:
        """These limits with ``NAME=VALUE`` assignments applied (``VALUE`` a whole number, or
        with a ``K``/``M``/``G`` suffix for KiB/MiB/GiB of byte limits)."""
        names = {field.name for field in fields(self)}
        changes: dict[str, int] = {}
        for text in assignments:
            name, _, value = text.partition("=")
            name = name.strip().replace("-", "_")
            if name not in names:
                raise UsageError(f"has no {name!r}; known: {', '.join(sorted(names))}", "limit")
            changes[name] = _whole(value.strip(), name)
        limits = replace(self, **changes)
        limits.check()
        return limits


def _whole(text: str, name: str) -> int:
    """``text`` as a whole number, ``K``/``M``/``G`` suffixes as powers of 1024."""
    scale = {"K": KIB, "M": MIB, "G": GIB}.get(text[-1:].upper(), 1)
    digits = text[:-1] if scale > 1 else text
    try:
        value = float(digits)
    except ValueError:
        raise UsageError(f"{name} needs a whole number, got {text!r}", "limit") from None
    if not math.isfinite(value) or value <= 0 or value * scale > 2**62:
        raise UsageError(f"{name} must be a positive number below 2^62, got {text!r}", "limit")
    return int(value * scale)


DEFAULT_LIMITS = Limits()
