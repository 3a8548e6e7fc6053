"""City objects' own levels of detail, and the LOD1 prism derived where a source lacks one.

The CityGML-style hierarchy has four levels, LOD4 (nearest, finest) to LOD1 (farthest,
coarsest), in the slots of the ProxyPrismLOD paper's ranges. A source LoD label names its slot
by its integer part: CityGML ``lod2`` and CityJSON ``"2.2"`` both fill LOD2 (of several labels
for one slot the highest wins: CityJSON ``"1.3"`` over ``"1.2"``). ``lod0`` (footprints, roof
edges) fills no slot; it is the footprint of a derived prism.

A derived **prism** is the object's footprint — its lod0 surfaces, else the outline of its
finest geometry seen from above — extruded from the lowest point to the object's height
(``measuredHeight`` where the source gives a plausible one). Coordinates are z-up, as in
CityGML and CityJSON.
"""

from __future__ import annotations

import math
import re

import numpy as np

from .model import GREY, Mesh, Surface
from .polygons import DegenerateRing, triangulate

SLOTS = (4, 3, 2, 1)
"""Source LoD of each level, finest first (``LOD4`` … ``LOD1``)."""
_LABEL = re.compile(r"(?:lod)?\s*(\d+)(?:\.(\d+))?", re.IGNORECASE)


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


CLOSED_TOLERANCE = 1e-3
"""Downward-facing triangles covering this much less ground than the upward-facing ones still
make the footprint."""


def _outline(mesh: Mesh) -> object:
    """The footprint of ``mesh`` seen from above: the union of its triangles projected on the
    ground plane (a shapely geometry). A closed surface's downward-facing triangles cover as
    much of the ground as its upward-facing ones, so when they do, only they are joined."""
    import shapely

    tri = mesh.triangles[:, :, :2]
    twice = (tri[:, 1, 0] - tri[:, 0, 0]) * (tri[:, 2, 1] - tri[:, 0, 1]) - (
        tri[:, 1, 1] - tri[:, 0, 1]
    ) * (tri[:, 2, 0] - tri[:, 0, 0])
    extent = float(np.ptp(tri.reshape(-1, 2), axis=0).max()) or 1.0
    seen = np.abs(twice) > 1e-9 * extent * extent
    down = seen & (twice < 0)
    if -twice[down].sum() >= (1 - CLOSED_TOLERANCE) * twice[seen & ~down].sum():
        seen = down
    flat = tri[seen]
    if len(flat) == 0:
        return shapely.Polygon()
    polygons = shapely.polygons(np.concatenate([flat, flat[:, :1]], axis=1))
    outline = shapely.make_valid(shapely.union_all(polygons)).buffer(0)
    return shapely.simplify(outline, 1e-6 * extent)  # drop the collinear seams of the union


def footprint(lods: dict[str, Mesh], finest: Mesh) -> list[list[np.ndarray]]:
    """The object's footprint as polygons, each a list of 2-D rings (exterior first): the
    outline of its lod0 surfaces if it has any, else of its finest geometry."""
    import shapely

    base = source_levels(lods).get(0, (None, finest))[1]
    shape = _outline(base)
    polygons = list(getattr(shape, "geoms", [shape]))
    rings = []
    for polygon in polygons:
        if not isinstance(polygon, shapely.Polygon) or polygon.is_empty or polygon.area <= 0:
            continue
        exterior = np.asarray(polygon.exterior.coords)
        interiors = [np.asarray(ring.coords) for ring in polygon.interiors]
        rings.append([exterior, *interiors])
    return rings


def prism_height(finest: Mesh, attributes: dict[str, object]) -> tuple[float, float]:
    """Base and top height of the prism: the lowest point, and the base plus
    ``measuredHeight`` when that is a plausible number (positive, at most twice the geometry's
    own height), else the highest point."""
    low, high = float(finest.bounds[0, 2]), float(finest.bounds[1, 2])
    measured = attributes.get("measuredHeight")
    try:
        value = float(measured)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        value = math.nan
    if math.isfinite(value) and 0 < value <= 2 * max(high - low, value / 2):
        return low, low + value
    return low, high


def prism(lods: dict[str, Mesh], finest: Mesh, attributes: dict[str, object]) -> Mesh | None:
    """The LOD1 prism of a city object (``None`` when it has no footprint with area)."""
    base, top = prism_height(finest, attributes)
    if not top > base:
        return None
    vertices: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    count = 0
    for rings in footprint(lods, finest):
        try:
            roof, tri = triangulate([np.column_stack([r, np.full(len(r), top)]) for r in rings])
        except DegenerateRing:
            roof, tri = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
        floor = np.column_stack([roof[:, :2], np.full(len(roof), base)])
        vertices += [roof, floor]
        faces += [tri + count, tri[:, ::-1] + count + len(roof)]  # the floor faces down
        count += 2 * len(roof)
        for ring in rings:
            ring = ring[:-1] if np.array_equal(ring[0], ring[-1]) else ring
            k = len(ring)
            low = np.column_stack([ring, np.full(k, base)])
            high = np.column_stack([ring, np.full(k, top)])
            i = np.arange(k)
            j = (i + 1) % k
            quads = np.stack([i, j, j + k, i, j + k, i + k], axis=1).reshape(-1, 3)
            vertices.append(np.concatenate([low, high]))
            faces.append(quads + count)
            count += 2 * k
    if not faces:
        return None
    surface = Surface(np.concatenate(vertices), np.concatenate(faces), base_color=GREY.copy())
    return Mesh([surface])
