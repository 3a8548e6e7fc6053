"""City objects' own levels of detail, and the LOD1 prism derived where a source lacks one.

The CityGML-style hierarchy has four levels, LOD4 (nearest, finest) to LOD1 (farthest,
coarsest), in the slots of the ProxyPrismLOD paper's ranges. A source LoD label names its slot
by its integer part: CityGML ``lod2`` and CityJSON ``"2.2"`` both fill LOD2 (of several labels
for one slot the highest wins: CityJSON ``"1.3"`` over ``"1.2"``). ``lod0`` (footprints, roof
edges) fills no slot; it is the footprint of a derived prism (:mod:`.prisms`). Only objects
that stand on the ground get one: terrain and the surfaces that cover the ground
(:data:`GROUND_COVERS`: land use, roads, squares, waterways) would become blocks from their
lowest to their highest point.
"""

from __future__ import annotations

import functools
import re

from .model import Mesh

SLOTS = (4, 3, 2, 1)
"""Source LoD of each level, finest first (``LOD4`` … ``LOD1``)."""
_LABEL = re.compile(r"(?:lod)?\s*(\d+)(?:\.(\d+))?", re.IGNORECASE)


@functools.cache
def lod_rank(label: str) -> tuple[int, int] | None:
    """``(slot LoD, sub-level)`` of a source LoD label (``"lod2"`` → (2, 0), ``"1.3"`` →
    (1, 3)); ``None`` for a label that names no LoD."""
    match = _LABEL.fullmatch(label.strip())
    return (int(match.group(1)), int(match.group(2) or 0)) if match else None


def source_levels(lods: dict[str, Mesh]) -> dict[int, tuple[str, Mesh]]:
    """Slot LoD (0–4) → (label, geometry) of the source LoDs that have faces, the highest label
    of each slot."""
    best: dict[int, tuple[tuple[int, int], str, Mesh]] = {}
    for label, mesh in lods.items():
        rank = lod_rank(label)
        if rank is None or rank[0] > 4 or mesh.face_count == 0:
            continue
        if rank[0] not in best or rank > best[rank[0]][0]:
            best[rank[0]] = (rank, label, mesh)
    return {slot: (label, mesh) for slot, (_, label, mesh) in best.items()}


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
