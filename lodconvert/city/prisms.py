"""The LOD1 prism of a city object that has no LoD 1 of its own.

A derived **prism** is the object's footprint — its lod0 surfaces, else the outline of its
finest geometry seen from above — simplified (shapely, topology kept) within a tolerance the
caller derives from the pixel size where the prism switches in, and extruded from the lowest
point to a percentile of the roof's heights (:data:`ROOF_PERCENTILE`, over the roof's
area seen from above), as 3D BAG's LoD1.2 blocks take a percentile of the roof points' heights
rather than the highest (an object with nothing but LoD 0 has no roof: ``measuredHeight``
where plausible). Its top takes the roof's colour and its walls the walls' (the finest
geometry's own, so source materials win over class colours as they do there), as vertex
colours of one part: one draw call. It has no floor: from a viewer's side of the ground the
underside of a building is never seen. Only objects that stand on the ground get one
(:data:`~lodconvert.model.lods.GROUND_COVERS` get none). Coordinates are z-up, as in CityGML and
CityJSON.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from ..bake.far_textures import in_source_textures
from ..components import components
from ..heap import return_freed_heap
from ..model import GREY, Mesh, Surface
from ..model.lods import source_levels

CLOSED_TOLERANCE = 1e-3
"""Downward-facing triangles covering this much less ground than the upward-facing ones still
make the footprint."""
SEAM_TOLERANCE = 1e-6
"""Corners of a footprint's outline less than this × its extent off the line through their
neighbours are dropped (the seams of a union of triangles)."""
STEEP = 0.5
"""A triangle whose ground projection is less than this fraction of its area (one steeper than
60°: a wall) is a sliver seen from above."""
ROOF_PERCENTILE = 60.0
"""The prism's top: this percentile of the roof's heights. Of 40, 50, 55, 60, 70, 80, 90, 95
and 100 it keeps the most prisms at silhouette F ≥ :data:`MIN_PRISM_F` over the guard's views
on TUM Munich (212 of 290; the 90th kept 123): a top at the eaves' side of a pitched roof
spills less, seen from above the horizon, than one near its ridge (``docs/cities.md``)."""
_POLYGON = 3
"""Shapely's type id of a polygon."""
TRIM_PARTS = 1 << 12
"""Footprint polygons from which, once they are found, the heap their shapely geometries took
is handed back (:func:`~lodconvert.heap.return_freed_heap`)."""
FOOTPRINT_TOLERANCE_PX = 0.5
"""The footprint's simplification tolerance, in pixels of the reference view where the prism
switches in."""
MIN_PRISM_F = 0.95
"""Least silhouette F of a prism against the finest level where it switches in."""
MORE_TRIANGLES = "no fewer triangles than"
"""How a prism left out for costing as much as the level before it is reported."""
LOW_F = "silhouette F"
"""How a prism left out for looking unlike the object is reported."""


class FootprintPart(NamedTuple):
    """One polygon of a footprint, ready to extrude: its ``points`` (n, 2) on the ground plane,
    the ``triangles`` (m, 3) covering it, clockwise seen from above, and its ``rings`` (each
    (k, 2), open, exterior first), along which the walls stand. As in shapely's output, exterior
    rings run clockwise and holes counter-clockwise."""

    points: np.ndarray
    triangles: np.ndarray
    rings: list[np.ndarray]


class Outline(NamedTuple):
    """A footprint before it is ear-clipped: its shapely ``polygons`` (exterior rings clockwise,
    holes counter-clockwise), and where triangles were traced into it (:func:`_merged`), the
    one ``traced`` part they make, which needs no ear-clipping."""

    polygons: list[Any]
    traced: FootprintPart | None = None


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

    n = len(points)
    first, second = corners, np.roll(corners, -1, axis=1)  # each triangle's edges, in turn
    edges = np.sort((first * n + second).ravel())
    if (edges[1:] == edges[:-1]).any():
        return None  # two triangles on one side of an edge: they overlap
    start, end = first.ravel(), second.ravel()
    reverse = end * n + start
    at = np.minimum(np.searchsorted(edges, reverse), len(edges) - 1)
    outer = edges[at] != reverse  # edges no other triangle shares
    start, end = start[outer], end[outer]
    following = np.full(n, -1)
    following[start] = end
    if len(np.unique(start)) < len(start):
        return None  # rings that meet at a point
    ahead = following.tolist()
    loops = []
    for point in np.sort(start).tolist():  # each loop from its least corner, followed round
        if ahead[point] >= 0:
            loops.append([])
            while ahead[point] >= 0:
                loops[-1].append(point)
                ahead[point], point = -1, ahead[point]  # this corner done, on to the next
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
) -> Outline:
    """The footprint of triangles ``corners`` (indices into ``points``) that :func:`_merged`
    traced into ``rings`` and ``polygon``; simplified as a union of triangles is
    (:func:`polygons`) where corners of its outline lie within :data:`SEAM_TOLERANCE` of a
    straight line."""
    import shapely

    simple = shapely.simplify(polygon, SEAM_TOLERANCE * extent)
    if shapely.get_num_coordinates(simple) < shapely.get_num_coordinates(polygon):
        return Outline(_oriented(simple))
    return Outline([polygon], FootprintPart(points, corners, rings))


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
) -> Outline | None:
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
    return _outline(_union(np.array([rest[1], *_closed(tri[slivers[outside]])])), extent)


def _outline(union: Any, extent: float) -> Outline:
    """The polygons of a shapely ``union`` of triangles, made valid where it is not, without
    the collinear seams of the union (:data:`SEAM_TOLERANCE`)."""
    import shapely

    valid = union if union.is_valid else shapely.make_valid(union).buffer(0)
    return Outline(_oriented(shapely.simplify(valid, SEAM_TOLERANCE * extent)))


def _oriented(outline: Any) -> list[Any]:
    """The polygons with area of shapely geometry ``outline``, exterior rings clockwise."""
    import shapely

    outline = shapely.orient_polygons(outline, exterior_cw=True)
    return [
        polygon
        for polygon in getattr(outline, "geoms", [outline])
        if isinstance(polygon, shapely.Polygon) and not polygon.is_empty and polygon.area > 0
    ]


def _ear_clipped(polygon: Any) -> FootprintPart:
    """Shapely ``polygon`` (exterior ring clockwise) ear-clipped into triangles."""
    import mapbox_earcut

    rings = [np.asarray(polygon.exterior.coords)[:-1]]
    rings += [np.asarray(ring.coords)[:-1] for ring in polygon.interiors]
    points = np.concatenate(rings)
    ends = np.cumsum([len(ring) for ring in rings]).astype(np.uint32)
    corners = mapbox_earcut.triangulate_float64(points - points[0], ends)
    corners = corners.astype(np.int64).reshape(-1, 3)
    return FootprintPart(points, _clockwise(corners, _doubled_areas(points[corners])), rings)


def polygons(outline: Any) -> list[FootprintPart]:
    """The polygons with area of shapely geometry ``outline``, ear-clipped into triangles."""
    return [_ear_clipped(polygon) for polygon in _oriented(outline)]


def footprint(lods: dict[str, Mesh], finest: Mesh) -> Outline:
    """The object's footprint as polygons to extrude: the union of its lod0 surfaces if it has
    any, else of its finest geometry, seen from above. Triangles that merge into one polygon
    (slivers of walls aside) are traced along their outer edges; shapely joins the others."""

    base = source_levels(lods).get(0, (None, finest))[1]
    extent = _extent(base)
    seen, tri, twice = _seen(base, extent)
    if len(tri) == 0:
        return Outline([])
    points, corners = _indexed(tri, twice)
    merged = _merged(points, corners, extent)
    if merged is not None:
        return _traced(points, corners, *merged, extent)
    parts = _without_slivers(_steep(base, seen, twice), tri, points, corners, extent)
    return parts if parts is not None else _outline(_union(_closed(tri)), extent)


def _union(polygons: np.ndarray) -> Any:
    """The union of shapely ``polygons``: where they fall into groups whose bounding boxes
    neither overlap nor touch across groups (a building's separate parts), the polygons of
    each group's union, in the order the groups first come, as one multipolygon (they are
    disjoint: shapely's union of many thousands of them took seconds); else the union of all
    at once."""
    import shapely

    groups = _apart(polygons)
    if len(groups) == 1:
        return shapely.union_all(polygons)
    parts = shapely.get_parts([shapely.union_all(group) for group in groups])
    return shapely.multipolygons(parts[shapely.get_type_id(parts) == _POLYGON])


def _apart(polygons: np.ndarray) -> list[np.ndarray]:
    """Shapely ``polygons`` in groups whose bounding boxes neither overlap nor touch across
    groups, in the order the groups first come, each in its polygons' order."""
    import shapely

    pairs = shapely.STRtree(polygons).query(polygons)  # bounding boxes that meet
    labels = components(pairs, len(polygons))
    order = np.argsort(labels, kind="stable")
    return np.split(polygons[order], np.cumsum(np.bincount(labels))[:-1])


def prism_height(
    lods: dict[str, Mesh], finest: Mesh, attributes: dict[str, object]
) -> tuple[float, float]:
    """Base and top height of the prism: the lowest point, and the :data:`ROOF_PERCENTILE` th
    percentile of the roof heights where the object has a solid LoD (1 or finer) with a roof;
    else the base plus ``measuredHeight`` when that is a plausible number (positive, at most
    twice the geometry's own height), else the highest point."""
    return standing_height(finest, attributes, bool(source_levels(lods).keys() - {0}))


def standing_height(
    finest: Mesh,
    attributes: dict[str, object],
    solid: bool = True,
    percentile: float = ROOF_PERCENTILE,
) -> tuple[float, float]:
    """Base and top height of a prism of ``finest`` as :func:`prism_height` finds them, the
    roof's ``percentile`` taken only where ``finest`` is ``solid`` (LoD 1 or finer)."""
    low, high = float(finest.bounds[0, 2]), float(finest.bounds[1, 2])
    if solid:
        roof = _slopes(finest).roofs
        if roof.any():
            tri = finest.triangles[roof]
            from .roof_heights import area_percentile  # compiled: numba loaded here

            top = area_percentile(tri[:, :, 2], np.abs(_doubled_areas(tri)), percentile / 100)
            if top > low:
                return low, top
    measured = attributes.get("measuredHeight")
    try:
        value = float(measured)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        value = math.nan
    if math.isfinite(value) and 0 < value <= 2 * max(high - low, value / 2):
        return low, low + value
    return low, high


class _Slopes(NamedTuple):
    """Which faces of a mesh are ``roofs`` (facing up, less steep than :data:`STEEP` allows)
    and which ``walls`` (steeper), and the faces' ``areas``, doubled."""

    roofs: np.ndarray
    walls: np.ndarray
    areas: np.ndarray


def _slopes(mesh: Mesh) -> _Slopes:
    """The roofs, walls and doubled areas of ``mesh``'s faces, found once per mesh; faces face
    outward, all turned over where they enclose a negative volume (wound inward)."""

    def compute() -> _Slopes:
        tri = mesh.triangles - (mesh.bounds[0] + mesh.bounds[1]) / 2
        side, other = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        across = np.empty((len(tri), 3))  # the faces' normals, as long as twice their areas
        across[:, 0] = side[:, 1] * other[:, 2] - side[:, 2] * other[:, 1]
        across[:, 1] = side[:, 2] * other[:, 0] - side[:, 0] * other[:, 2]
        across[:, 2] = side[:, 0] * other[:, 1] - side[:, 1] * other[:, 0]
        up = -across[:, 2] if float(np.einsum("ij,ij->", tri[:, 0], across)) < 0 else across[:, 2]
        areas = np.linalg.norm(across, axis=1)
        return _Slopes(up > STEEP * areas, np.abs(up) < STEEP * areas, areas)

    return mesh.derived("roofs-walls", compute)


def prism_colors(finest: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """The prism's roof and wall colours (RGBA): the mean colour of ``finest``'s roofs and of
    its walls, over their areas, textures included (grey where it has none)."""
    slopes = _slopes(finest)
    colors = []
    for faces in (np.flatnonzero(slopes.roofs), np.flatnonzero(slopes.walls)):
        weights = slopes.areas[faces]
        if weights.sum() <= 0:
            colors.append(GREY.copy())
            continue
        means = finest.face_colors(faces)
        colors.append(np.rint(weights @ means.astype(np.float64) / weights.sum()).astype(np.uint8))
    return colors[0], colors[1]


def in_texture_colours(coarse: Mesh, finest: Mesh, pixel: float) -> Mesh:
    """``coarse`` (a coarser source LoD without textures of its own, seen from where a pixel
    spans ``pixel`` metres) in a texture baked from ``finest``'s
    (:func:`~..bake.far_textures.in_source_textures`); itself where ``finest`` has no texture
    or ``coarse`` has one."""
    if any(p.texture is not None for p in coarse.parts):
        return coarse
    return in_source_textures(coarse, finest, pixel)


def simplified(outline: Outline, tolerance: float) -> list[FootprintPart]:
    """The footprint ``outline`` simplified within ``tolerance`` (shapely, topology kept),
    without the polygons and holes smaller than a ``tolerance`` square, as polygons to extrude;
    ``outline``'s own where that removes no corner."""
    import shapely

    if tolerance > 0 and outline.polygons:
        kept = simplified_polygons(outline.polygons, tolerance)
        fewer = shapely.get_num_coordinates(kept).sum()
        if kept and fewer < shapely.get_num_coordinates(outline.polygons).sum():
            return polygons(shapely.MultiPolygon(kept))
    if outline.traced is not None:
        return [outline.traced]
    return [_ear_clipped(polygon) for polygon in outline.polygons]


def simplified_polygons(outline: Any, tolerance: float) -> list[Any]:
    """The polygons of shapely geometry ``outline`` (or of a list of them) simplified within
    ``tolerance`` (topology kept), without the polygons and holes smaller than a ``tolerance``
    square."""
    import shapely

    least = tolerance * tolerance
    return [
        _without_holes(polygon, least)
        for polygon in _simplified_apart(shapely.get_parts(outline), tolerance)
        if isinstance(polygon, shapely.Polygon) and polygon.area >= least
    ]


def _without_holes(polygon: Any, least: float) -> Any:
    """Shapely ``polygon`` without its holes of area less than ``least``."""
    import shapely

    if not shapely.get_num_interior_rings(polygon):
        return polygon
    return shapely.Polygon(polygon.exterior, [h for h in polygon.interiors if _area(h) >= least])


def _simplified_apart(polygons: np.ndarray, tolerance: float) -> list[Any]:
    """Shapely ``polygons`` simplified within ``tolerance``, topology kept among those whose
    bounding boxes meet (simplified together, :func:`_apart`), each other one alone: its
    simplified rings keep some of its corners, so they stay in its box and cannot meet another
    polygon's. (GEOS keeps a multipolygon's topology by checking each ring against all the
    others: 10,000 disjoint squares took 16 times 2,500's time.)"""
    import shapely

    if not len(polygons):
        return []
    groups = _apart(polygons) if len(polygons) > 1 else [polygons]
    alone = [group[0] for group in groups if len(group) == 1]
    simple = iter(
        shapely.simplify(np.array(alone, dtype=object), tolerance, preserve_topology=True)
    )
    kept: list[Any] = []
    for group in groups:
        if len(group) == 1:
            kept.append(next(simple))
        else:
            together = shapely.simplify(
                shapely.multipolygons(group), tolerance, preserve_topology=True
            )
            kept.extend(shapely.get_parts(together))
    return kept


def _area(ring: Any) -> float:
    """The area a shapely ``ring`` bounds."""
    return abs(_doubled_area(np.asarray(ring.coords)[:-1])) / 2


def extruded(part: FootprintPart, base: float, top: float) -> tuple[Surface, Surface]:
    """``part`` extruded from ``base`` to ``top``: its top (facing up) and its walls (facing
    outward), no floor. Exterior rings run clockwise and holes counter-clockwise seen from
    above, so the solid lies to the right of every ring."""
    roof = Surface(
        np.column_stack([part.points, np.full(len(part.points), top)]),
        part.triangles[:, ::-1].copy(),
    )
    sizes = [len(ring) for ring in part.rings]
    wall = np.concatenate(part.rings)
    k = len(wall)
    vertices = np.column_stack([np.concatenate([wall, wall]), np.repeat([base, top], k)])
    i = np.arange(k)
    j = i + 1
    ends = np.cumsum(sizes)
    j[ends - 1] = ends - sizes  # each ring closes on its first corner
    faces = np.stack([i, j + k, j, i, i + k, j + k], axis=1).reshape(-1, 3)
    return roof, Surface(vertices, faces)


def prism(
    lods: dict[str, Mesh], finest: Mesh, attributes: dict[str, object], tolerance: float = 0.0
) -> Mesh | None:
    """The LOD1 prism of a city object, its footprint simplified within ``tolerance`` (scene
    units; see :func:`simplified`), its tops first, then its walls: one part (one draw call),
    coloured per vertex (``None`` when it has no footprint with area)."""
    base, top = prism_height(lods, finest, attributes)
    if not top > base:
        return None
    parts = simplified(footprint(lods, finest), tolerance)
    if len(parts) >= TRIM_PARTS:
        return_freed_heap()  # what shapely took for them, freed
    if not parts:
        return None
    solids = [extruded(part, base, top) for part in parts]
    roof_color, wall_color = prism_colors(finest)
    surfaces = [roof for roof, _ in solids] + [walls for _, walls in solids]
    return coloured(surfaces, [roof_color] * len(solids) + [wall_color] * len(solids))


def coloured(surfaces: list[Surface], colors: list[np.ndarray]) -> Mesh:
    """``surfaces`` as one part (one draw call), each in its colour (RGBA) per vertex."""
    offsets = np.cumsum([0] + [len(s.vertices) for s in surfaces[:-1]])
    return Mesh(
        [
            Surface(
                np.concatenate([s.vertices for s in surfaces]),
                np.concatenate([s.faces + o for s, o in zip(surfaces, offsets, strict=True)]),
                vertex_colors=np.concatenate(
                    [
                        np.tile(c, (len(s.vertices), 1))
                        for s, c in zip(surfaces, colors, strict=True)
                    ]
                ),
            )
        ]
    )
