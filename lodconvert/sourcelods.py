"""City objects' own levels of detail, and the LOD1 prism derived where a source lacks one.

The CityGML-style hierarchy has four levels, LOD4 (nearest, finest) to LOD1 (farthest,
coarsest), in the slots of the ProxyPrismLOD paper's ranges. A source LoD label names its slot
by its integer part: CityGML ``lod2`` and CityJSON ``"2.2"`` both fill LOD2 (of several labels
for one slot the highest wins: CityJSON ``"1.3"`` over ``"1.2"``). ``lod0`` (footprints, roof
edges) fills no slot; it is the footprint of a derived prism.

A derived **prism** is the object's footprint — its lod0 surfaces, else the outline of its
finest geometry seen from above — extruded from the lowest point to the object's height
(``measuredHeight`` where the source gives a plausible one). Only objects that stand on the
ground get one: terrain and the surfaces that cover the ground (:data:`GROUND_COVERS`: land
use, roads, squares, waterways) would become blocks from their lowest to their highest point.
Coordinates are z-up, as in CityGML and CityJSON.
"""

from __future__ import annotations

import functools
import math
import re
from typing import Any, NamedTuple

import numpy as np

from .model import GREY, Mesh, Surface

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
CLOSED_TOLERANCE = 1e-3
"""Downward-facing triangles covering this much less ground than the upward-facing ones still
make the footprint."""
SEAM_TOLERANCE = 1e-6
"""Corners of a footprint's outline less than this × its extent off the line through their
neighbours are dropped (the seams of a union of triangles)."""
STEEP = 0.5
"""A triangle whose ground projection is less than this fraction of its area (one steeper than
60°: a wall) is a sliver seen from above."""


class FootprintPart(NamedTuple):
    """One polygon of a footprint, ready to extrude: its ``points`` (n, 2) on the ground plane,
    the ``triangles`` (m, 3) covering it, clockwise seen from above, and its ``rings`` (each
    (k, 2), open, exterior first), along which the walls stand. As in shapely's output, exterior
    rings run clockwise and holes counter-clockwise."""

    points: np.ndarray
    triangles: np.ndarray
    rings: list[np.ndarray]


def _extent(mesh: Mesh) -> float:
    """The longer side of ``mesh``'s bounding rectangle seen from above (1 where it has none)."""
    return float((mesh.bounds[1, :2] - mesh.bounds[0, :2]).max()) or 1.0


def _doubled_areas(tri: np.ndarray) -> np.ndarray:
    """Twice the signed areas of triangles ``tri`` ((m, 3, 2) or more coordinates, of which x and
    y count): positive where they run counter-clockwise seen from above."""
    side, other = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    return side[:, 0] * other[:, 1] - side[:, 1] * other[:, 0]


def _clockwise(corners: np.ndarray, twice: np.ndarray) -> np.ndarray:
    """Triangles ``corners`` (m, 3) turned clockwise seen from above (``twice`` their doubled
    signed areas)."""
    return np.where((twice > 0)[:, None], corners[:, ::-1], corners)


def _seen(mesh: Mesh, extent: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triangles of ``mesh`` that make its footprint: which ones (a mask), their corners
    projected on the ground plane ((m, 3, 2)) and their doubled signed areas there. Triangles
    seen edge-on are left out. A closed surface's downward-facing triangles cover as much of
    the ground as its upward-facing ones, so when they do, only they are kept."""
    tri = mesh.triangles[:, :, :2]
    twice = _doubled_areas(tri)
    seen = np.abs(twice) > 1e-9 * extent * extent
    down = seen & (twice < 0)
    if -twice[down].sum() >= (1 - CLOSED_TOLERANCE) * twice[seen & ~down].sum():
        seen = down
    return seen, tri[seen], twice[seen]


def _steep(mesh: Mesh, seen: np.ndarray, twice: np.ndarray) -> np.ndarray:
    """Which of ``mesh``'s ``seen`` triangles (``twice`` their doubled areas seen from above,
    their normals' z components) are steeper than :data:`STEEP` allows."""
    corner = mesh.triangles[seen]
    side, other = corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]
    across = (side[:, 1] * other[:, 2] - side[:, 2] * other[:, 1]) ** 2 + (
        side[:, 2] * other[:, 0] - side[:, 0] * other[:, 2]
    ) ** 2  # the normals' x and y components, squared
    return twice**2 < STEEP**2 * (twice**2 + across)


def _indexed(tri: np.ndarray, twice: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct corners (n, 2) of triangles ``tri`` ((m, 3, 2), contiguous; ``twice`` their
    doubled signed areas) and the triangles as clockwise indices into them (m, 3)."""
    keys, corners = np.unique(tri.reshape(-1, 2).view(np.complex128), return_inverse=True)
    return keys.view(np.float64).reshape(-1, 2), _clockwise(corners.reshape(-1, 3), twice)


def _merged(
    points: np.ndarray, corners: np.ndarray, extent: float
) -> tuple[list[np.ndarray], Any] | None:
    """The rings (exterior first) of the polygon that clockwise triangles ``corners`` (indices
    into ``points``) cover together, traced along the edges they do not share, and it as a
    shapely polygon; or ``None`` unless those edges make one clockwise exterior ring and
    counter-clockwise holes that bound a valid polygon. The triangles then cover that polygon
    exactly once (their edges add up to its boundary), so it is their union."""
    import shapely

    edges: set[tuple[int, int]] = set()
    for a, b, c in corners.tolist():
        for edge in ((a, b), (b, c), (c, a)):
            if edge in edges:
                return None  # two triangles on one side of an edge: they overlap
            edges.add(edge)
    following: dict[int, int] = {}
    for a, b in edges:
        if (b, a) not in edges:
            if a in following:
                return None  # rings that meet at a point
            following[a] = b
    loops = []
    for first in sorted(following):
        if first in following:
            loop, point = [first], following.pop(first)
            while point != first:
                loop.append(point)
                point = following.pop(point)
            loops.append(loop)
    rings = [points[loop] for loop in loops]
    if len(rings) > 1:  # a single loop bounds what clockwise triangles cover: it runs clockwise
        areas = np.array([_doubled_area(ring - points[0]) for ring in rings])
        exterior = np.flatnonzero(areas < 0)
        if len(exterior) != 1 or (np.abs(areas) <= 1e-9 * extent * extent).any():
            return None
        rings.insert(0, rings.pop(int(exterior[0])))
    polygon = shapely.Polygon(rings[0], rings[1:])
    return (rings, polygon) if polygon.is_valid else None


def _doubled_area(ring: np.ndarray) -> float:
    """Twice the signed area of ``ring`` ((k, 2), open; positive: counter-clockwise)."""
    return float(np.dot(ring[:, 0], np.roll(ring[:, 1], -1) - np.roll(ring[:, 1], 1)))


def _traced(
    points: np.ndarray, corners: np.ndarray, rings: list[np.ndarray], polygon: Any, extent: float
) -> list[FootprintPart]:
    """The footprint of triangles ``corners`` (indices into ``points``) that :func:`_merged`
    traced into ``rings`` and ``polygon``; simplified as a union of triangles is
    (:func:`_polygons`) where corners of its outline lie within :data:`SEAM_TOLERANCE` of a
    straight line."""
    import shapely

    simple = shapely.simplify(polygon, SEAM_TOLERANCE * extent)
    if shapely.get_num_coordinates(simple) < shapely.get_num_coordinates(polygon):
        return _polygons(simple)
    return [FootprintPart(points, corners, rings)]


def _used(points: np.ndarray, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ``points`` that triangles ``corners`` use, and the triangles as indices into them."""
    used = np.zeros(len(points), dtype=bool)
    used[corners] = True
    return points[used], (np.cumsum(used) - 1)[corners]


def _closed(tri: np.ndarray) -> Any:
    """Triangles ``tri`` ((m, 3, 2)) as shapely polygons."""
    import shapely

    return shapely.polygons(np.concatenate([tri, tri[:, :1]], axis=1))


def _without_slivers(
    steep: np.ndarray, tri: np.ndarray, points: np.ndarray, corners: np.ndarray, extent: float
) -> list[FootprintPart] | None:
    """The union of triangles ``tri`` (``corners`` into ``points`` as :func:`_merged` takes
    them) where the slivers of the ``steep`` ones keep them from merging; ``None`` unless the
    others merge. A sliver inside their polygon adds nothing; those outside merge with it where
    they only touch it, else shapely joins them to it."""
    import shapely

    if steep.all() or not steep.any():
        return None
    rest = _merged(points, corners[~steep], extent)
    if rest is None:
        return None
    slivers = np.flatnonzero(steep)
    relations = shapely.relate(_closed(tri[slivers]), rest[1]).tolist()  # DE-9IM matrices
    outside = [r[2:6:3] != "FF" for r in relations]  # parts of them outside the polygon
    if not any(outside):
        return _traced(*_used(points, corners[~steep]), *rest, extent)
    if all(r[0] == "F" for r, out in zip(relations, outside, strict=True) if out):  # they touch
        keep = ~steep
        keep[slivers[outside]] = True
        merged = _merged(points, corners[keep], extent)
        if merged is not None:
            return _traced(*_used(points, corners[keep]), *merged, extent)
    return _outline(shapely.union_all([rest[1], *_closed(tri[slivers[outside]])]), extent)


def _outline(union: Any, extent: float) -> list[FootprintPart]:
    """The polygons of a shapely ``union`` of triangles, made valid where it is not, without
    the collinear seams of the union (:data:`SEAM_TOLERANCE`)."""
    import shapely

    valid = union if union.is_valid else shapely.make_valid(union).buffer(0)
    return _polygons(shapely.simplify(valid, SEAM_TOLERANCE * extent))


def _polygons(outline: Any) -> list[FootprintPart]:
    """The polygons with area of shapely geometry ``outline``, ear-clipped into triangles."""
    import mapbox_earcut
    import shapely

    outline = shapely.orient_polygons(outline, exterior_cw=True)
    parts = []
    for polygon in getattr(outline, "geoms", [outline]):
        if not isinstance(polygon, shapely.Polygon) or polygon.is_empty or polygon.area <= 0:
            continue
        rings = [np.asarray(polygon.exterior.coords)[:-1]]
        rings += [np.asarray(ring.coords)[:-1] for ring in polygon.interiors]
        points = np.concatenate(rings)
        ends = np.cumsum([len(ring) for ring in rings]).astype(np.uint32)
        corners = mapbox_earcut.triangulate_float64(points - points[0], ends)
        corners = corners.astype(np.int64).reshape(-1, 3)
        parts.append(
            FootprintPart(points, _clockwise(corners, _doubled_areas(points[corners])), rings)
        )
    return parts


def footprint(lods: dict[str, Mesh], finest: Mesh) -> list[FootprintPart]:
    """The object's footprint as polygons to extrude: the union of its lod0 surfaces if it has
    any, else of its finest geometry, seen from above. Triangles that merge into one polygon
    (slivers of walls aside) are traced along their outer edges; shapely joins the others."""
    import shapely

    base = source_levels(lods).get(0, (None, finest))[1]
    extent = _extent(base)
    seen, tri, twice = _seen(base, extent)
    if len(tri) == 0:
        return []
    points, corners = _indexed(tri, twice)
    merged = _merged(points, corners, extent)
    if merged is not None:
        return _traced(points, corners, *merged, extent)
    parts = _without_slivers(_steep(base, seen, twice), tri, points, corners, extent)
    return parts if parts is not None else _outline(shapely.union_all(_closed(tri)), extent)


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


def _extruded(part: FootprintPart, base: float, top: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of ``part`` extruded from ``base`` to ``top``: its roof, its floor
    (the roof turned over) and its walls, each with vertices of their own, facing outward."""
    n = len(part.points)
    sizes = [len(ring) for ring in part.rings]
    wall = np.concatenate(part.rings)
    k = len(wall)
    plan = np.concatenate([part.points, part.points, wall, wall])
    vertices = np.column_stack([plan, np.repeat([top, base, base, top], [n, n, k, k])])
    i = np.arange(k)
    j = i + 1
    ends = np.cumsum(sizes)
    j[ends - 1] = ends - sizes  # each ring closes on its first corner
    walls = np.stack([i, j, j + k, i, j + k, i + k], axis=1).reshape(-1, 3) + 2 * n
    faces = np.concatenate([part.triangles, part.triangles[:, ::-1] + n, walls])
    return vertices, faces if _encloses(vertices, faces) else faces[:, ::-1]


def _encloses(vertices: np.ndarray, faces: np.ndarray) -> bool:
    """Whether the closed ``faces`` face outward: the volume they enclose is positive (measured
    about the first vertex, so that georeferenced coordinates keep their precision)."""
    local = (vertices - vertices[0])[faces]  # (m, 3 corners, 3)
    a, b, c = local[:, 0].T, local[:, 1].T, local[:, 2].T
    across = b[1] * c[2] - b[2] * c[1], b[2] * c[0] - b[0] * c[2], b[0] * c[1] - b[1] * c[0]
    return float((a[0] @ across[0]) + (a[1] @ across[1]) + (a[2] @ across[2])) >= 0.0


def prism(lods: dict[str, Mesh], finest: Mesh, attributes: dict[str, object]) -> Mesh | None:
    """The LOD1 prism of a city object (``None`` when it has no footprint with area)."""
    base, top = prism_height(finest, attributes)
    if not top > base:
        return None
    vertices: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    count = 0
    for part in footprint(lods, finest):
        corners, triangles = _extruded(part, base, top)
        vertices.append(corners)
        faces.append(triangles + count)
        count += len(corners)
    if not faces:
        return None
    surface = Surface(np.concatenate(vertices), np.concatenate(faces), base_color=GREY.copy())
    return Mesh([surface])
