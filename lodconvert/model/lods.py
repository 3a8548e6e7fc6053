"""The LoD vocabulary both city readers use: a source LoD label names its slot by its integer
part (CityGML ``lod2`` and CityJSON ``"2.2"`` both fill LOD2; of several labels for one slot the
highest wins), LOD4 (nearest, finest) to LOD1 (farthest, coarsest). ``lod0`` (footprints, roof
edges) fills no slot: it is the footprint of a derived prism (:mod:`lodconvert.city.prisms`).
Terrain and the surfaces that cover the ground (:data:`GROUND_COVERS`) get no prism."""

from __future__ import annotations

import functools
import re

from .geometry import Mesh

SLOTS = (4, 3, 2, 1)
"""Source LoD of each level, finest first (``LOD4`` … ``LOD1``)."""
_LABEL = re.compile(r"(?:lod)?\s*(\d+)(?:\.(\d+))?", re.IGNORECASE)


@functools.cache
def lod_rank(label: str) -> tuple[int, int] | None:
    """``(slot LoD, sub-level)`` of a source LoD label (``"lod2"`` → (2, 0), ``"1.3"`` →
    (1, 3)); ``None`` for a label that names no LoD."""
    match = _LABEL.fullmatch(label.strip())
    return (int(match.group(1)), int(match.group(2) or 0)) if match else None


def finest(lods: dict[str, Mesh]) -> Mesh | None:
    """The geometry of the finest of ``lods`` (by :func:`lod_rank`: CityGML ``lod3`` over
    ``lod2``, CityJSON ``"2.2"`` over ``"2"``; labels naming no LoD lowest), the one a city
    object stands for where one geometry is wanted; ``None`` for none. Both readers use it."""
    if not lods:
        return None
    return lods[max(lods, key=lambda label: (lod_rank(label) or (-1, -1), label))]


def source_levels(lods: dict[str, Mesh]) -> dict[int, tuple[str, Mesh]]:
    """Slot LoD (0–4) → (label, geometry) of the source LoDs that have faces, the highest label
    of each slot."""
    return _sorted(lods)[0]


def unused_levels(lods: dict[str, Mesh]) -> dict[str, str]:
    """Label → why, of the source LoDs that :func:`source_levels` puts in no slot: a lower
    label of a slot (``"1.2"``: ``"slot LOD1 taken by LoD 1.3"``), a label that names no LoD
    0–4, or a LoD without faces."""
    return _sorted(lods)[1]


def _sorted(lods: dict[str, Mesh]) -> tuple[dict[int, tuple[str, Mesh]], dict[str, str]]:
    """:func:`source_levels` and :func:`unused_levels` of ``lods``."""
    ranks = {label: lod_rank(label) for label in lods}
    best: dict[int, tuple[tuple[int, int], str]] = {}
    for label, rank in ranks.items():
        if rank is None or rank[0] > 4 or not lods[label].face_count:
            continue
        if rank[0] not in best or rank > best[rank[0]][0]:
            best[rank[0]] = (rank, label)
    unused: dict[str, str] = {}
    for label, rank in ranks.items():
        if rank is None or rank[0] > 4:
            unused[label] = "names no LoD 0–4"
        elif not lods[label].face_count:
            unused[label] = "has no faces"
        elif best[rank[0]][1] != label:
            unused[label] = f"slot LOD{rank[0]} taken by {lod_name(best[rank[0]][1])}"
    return {slot: (label, lods[label]) for slot, (_, label) in best.items()}, unused


def lod_name(label: str) -> str:
    """A source LoD label as messages name it: ``"1.3"`` → ``"LoD 1.3"``, ``"lod2"`` as it is."""
    return f"LoD {label}" if label[:1].isdigit() else label


GROUND_COVERS = frozenset(
    {
        "ReliefFeature",
        "TINRelief",
        "LandUse",
        "Road",
        "Railway",
        "Track",
        "Square",
        "TransportSquare",
        "TransportationComplex",
        "Waterway",
    }
)
"""Object types (CityGML, CityJSON) that cover the ground rather than stand on it: no prism."""
