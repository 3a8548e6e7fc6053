"""CityJSON reader: CityJSON 1.1 and 2.0 (``.json``, ``.city.json``; 1.0 read the same way) and
CityJSONSeq (``.city.jsonl``, read line by line, :mod:`.sequence`), each also in a ``.gz`` or
the one city model file of a ``.zip`` (:mod:`..archive`).

Every CityObject with geometry or with children becomes a :class:`Node` keyed by its id, its
1st-level parts' LoDs merged into its own (:mod:`.objects`); every LoD is one :class:`Mesh` in
``node.lods`` with a part per semantic class and material, polygons triangulated
:data:`~.document.BATCH` objects at a time; vertices are scaled by ``transform`` into float64
(:mod:`.vertices`), geometry templates read once and shared (:mod:`.templates`); a geographic
CRS is projected onto a local transverse Mercator. Broken objects are reported and left out
(:mod:`..geometry_checks`). In full: ``docs/readers.md`` (CityJSON and CityJSONSeq).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from ...errors import InputError
from ...limits import DEFAULT_LIMITS, Limits
from ...model import Scene
from ...semantics import DEFAULT_PALETTE, Palette
from .. import Format
from ..archive import member_name
from .document import read_document, read_sequence

if TYPE_CHECKING:
    from ...context import RunContext

__all__ = ["FORMAT", "read_cityjson"]


def _types(types: Iterable[str] | None) -> frozenset[str] | None:
    return frozenset(types) if types is not None else None


def read_cityjson(
    path: Path,
    limits: Limits = DEFAULT_LIMITS,
    types: Iterable[str] | None = None,
    colors: Palette = DEFAULT_PALETTE,
    crs: str | None = None,
    context: RunContext | None = None,
    appearance_theme: str | None = None,
) -> Scene:
    """Read a CityJSON (``.json``) or CityJSONSeq (``.jsonl``) file, plain, ``.gz`` or in a
    ``.zip``, into a Scene (see the module docstring); :class:`InputError` with a one-line
    reason when it cannot be. ``types``: keep only CityObjects of these types (and their
    descendants); ``colors``: the semantic classes' colours (:mod:`lodconvert.semantics`);
    ``crs`` replaces the CRS the file declares; with ``context``, the objects are read by the
    workers of its executor; ``appearance_theme``: the theme of textures and materials read
    (else each geometry's first).
    The scene carries an :class:`~..geometry_checks.InputTally` of dropped faces and skipped
    objects."""
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file" if not path.exists() else "is not a file", str(path))
    if path.stat().st_size == 0:
        raise InputError("is empty", str(path))
    name = (member_name(path) if path.name.lower().endswith(".zip") else path.name).lower()
    name = name.removesuffix(".gz")
    if name.endswith(".jsonl"):
        return read_sequence(path, limits, _types(types), colors, crs, context, appearance_theme)
    return read_document(path, limits, _types(types), colors, crs, context, appearance_theme)


FORMAT = Format(
    name="cityjson",
    suffixes=(".json", ".jsonl", ".zip"),
    read=read_cityjson,
    read_options=("limits", "types", "colors", "crs", "appearance_theme"),
    reads_on_workers=True,
)
