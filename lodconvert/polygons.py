"""Planar polygons with holes (city models' rings) to triangles.

A polygon is its exterior ring and any interior rings, each an (k, 3) array of float64 points
(closed or not: a repeated last point is dropped). It is triangulated on its best-fit plane
(Newell's normal, so slightly non-planar rings from surveys still work) by ear clipping with
holes (``mapbox-earcut``). Rings with fewer than three distinct points or without area are
degenerate: :class:`DegenerateRing` says why, for the reader to report and skip.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

AREA_EPSILON = 1e-12
"""A ring whose area is below this × (its extent)² has no area."""


class DegenerateRing(ValueError):
    """A ring that cannot bound a polygon: fewer than 3 distinct points, or no area."""


def _open_ring(ring: np.ndarray) -> np.ndarray:
    """``ring`` (k, 3) without a repeated closing point and without repeated neighbours."""
    ring = np.asarray(ring, dtype=np.float64).reshape(-1, 3)
    if len(ring) > 1 and np.array_equal(ring[0], ring[-1]):
        ring = ring[:-1]
    if len(ring) > 1:
        keep = np.r_[True, np.any(ring[1:] != ring[:-1], axis=1)]
        ring = ring[keep]
    return ring


def newell_normal(ring: np.ndarray) -> np.ndarray:
    """The (unnormalised) Newell normal of a ring: twice its vector area."""
    nxt = np.concatenate([ring[1:], ring[:1]])
    a, b = ring - nxt, ring + nxt
    return np.array(
        [
            np.dot(a[:, 1], b[:, 2]),
            np.dot(a[:, 2], b[:, 0]),
            np.dot(a[:, 0], b[:, 1]),
        ]
    )


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross product of two 3-vectors (``np.cross`` costs more for one pair)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _plane_axes(normal: np.ndarray) -> np.ndarray:
    """Two orthonormal axes (2, 3) spanning the plane of unit ``normal``, right-handed with it,
    so that a counter-clockwise ring seen from the normal stays counter-clockwise."""
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = _cross(normal, helper)
    u /= np.linalg.norm(u)
    return np.stack([u, _cross(normal, u)])


def _area_normal(ring: np.ndarray) -> np.ndarray | None:
    """The unit Newell normal of an opened ring, or None when it has fewer than 3 points or
    no area (below :data:`AREA_EPSILON` × its extent²), whatever its position in space."""
    if len(ring) < 3:
        return None
    normal = newell_normal(ring - ring[0])
    extent = float(np.ptp(ring, axis=0).max())
    length = float(np.linalg.norm(normal))
    return normal / length if length > 2 * AREA_EPSILON * extent * extent else None


def triangulate(rings: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and triangles (m, 3) of the polygon whose exterior ring is ``rings[0]``
    and interior rings (holes) the rest. Triangles wind like the exterior ring (their normals
    point where its Newell normal does). Degenerate interior rings are left out; a degenerate
    exterior ring raises :class:`DegenerateRing`."""
    import mapbox_earcut

    exterior = _open_ring(rings[0])
    if len(exterior) < 3:
        raise DegenerateRing(f"a ring of {len(exterior)} distinct point(s); a polygon needs 3")
    normal = _area_normal(exterior)
    if normal is None:
        raise DegenerateRing("a ring without area (its points lie on a line)")
    if len(exterior) == 3 and len(rings) == 1:
        return exterior, np.array([[0, 1, 2]], dtype=np.int64)
    holes = [hole for hole in map(_open_ring, rings[1:]) if _area_normal(hole) is not None]
    points = np.concatenate([exterior, *holes]) if holes else exterior
    flat = (points - points[0]) @ _plane_axes(normal).T
    ends = np.cumsum([len(exterior), *(len(h) for h in holes)]).astype(np.uint32)
    index = mapbox_earcut.triangulate_float64(flat, ends).astype(np.int64).reshape(-1, 3)
    if len(index):
        a, b, c = flat[index[:, 0]], flat[index[:, 1]], flat[index[:, 2]]
        turn = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        index[turn < 0] = index[turn < 0][:, ::-1]  # face along the exterior ring's normal
    return points, index


def triangulate_many(
    polygons: Sequence[Sequence[np.ndarray]],
) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """:func:`triangulate` of each polygon, ``None`` where it is degenerate. Polygons without
    holes (nearly all of a city model's) are opened, measured and tested together; a convex
    one is fanned from its first point, the others are ear-clipped one at a time."""
    results: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(polygons)
    simple = [i for i, rings in enumerate(polygons) if len(rings) == 1]
    for i in sorted(set(range(len(polygons))) - set(simple)):
        results[i] = _triangulated_or_none(polygons[i])
    if not simple:
        return results
    points, lengths = _opened_rings([polygons[i][0] for i in simple])
    starts = np.cumsum(lengths) - lengths
    usable = lengths >= 3
    normals = np.zeros((len(simple), 3))
    extents = np.zeros(len(simple))
    if usable.any():
        nxt = np.arange(1, len(points) + 1)
        nxt[starts[lengths > 0] + lengths[lengths > 0] - 1] = starts[lengths > 0]
        first = np.minimum(starts, len(points) - 1)  # a ring opened to nothing repeats none
        local = points - np.repeat(points[first], lengths, axis=0)
        a, b = local - local[nxt], local + local[nxt]
        terms = np.column_stack([a[:, 1] * b[:, 2], a[:, 2] * b[:, 0], a[:, 0] * b[:, 1]])
        at = starts[usable]
        normals[usable] = np.add.reduceat(terms, at)
        spans = np.maximum.reduceat(points, at) - np.minimum.reduceat(points, at)
        extents[usable] = spans.max(axis=1)
    area = np.linalg.norm(normals, axis=1)
    usable &= area > 2 * AREA_EPSILON * extents * extents
    convex, corner = _convex_corners(points, lengths, starts, normals, area, extents, usable)
    for j, i in enumerate(simple):
        if not usable[j]:
            continue
        ring = slice(starts[j], starts[j] + lengths[j])
        if lengths[j] == 3:
            results[i] = (points[ring], np.array([[0, 1, 2]], dtype=np.int64))
        elif convex[j]:
            results[i] = (points[ring], _fan(np.flatnonzero(corner[ring])))
        else:
            results[i] = _triangulated_or_none([points[ring]])
    return results


def _triangulated_or_none(rings: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
    try:
        return triangulate(rings)
    except DegenerateRing:
        return None


def _opened_rings(rings: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """All ``rings`` opened as :func:`_open_ring` opens one, concatenated, and their lengths."""
    raw = [np.asarray(ring, dtype=np.float64).reshape(-1, 3) for ring in rings]
    lengths = np.array([len(ring) for ring in raw], dtype=np.int64)
    points = np.concatenate(raw) if raw else np.zeros((0, 3))
    owner = np.repeat(np.arange(len(raw)), lengths)
    starts = np.cumsum(lengths) - lengths
    keep = np.ones(len(points), dtype=bool)
    longer = lengths > 1
    last = starts[longer] + lengths[longer] - 1
    closing = np.all(points[last] == points[starts[longer]], axis=1)
    keep[last[closing]] = False
    keep[1:] &= ~(np.all(points[1:] == points[:-1], axis=1) & (owner[1:] == owner[:-1]))
    return points[keep], np.bincount(owner[keep], minlength=len(raw)).astype(np.int64)


def _convex_corners(
    points: np.ndarray,
    lengths: np.ndarray,
    starts: np.ndarray,
    normals: np.ndarray,
    area: np.ndarray,
    extents: np.ndarray,
    usable: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per ring, whether it is convex seen from its Newell normal (it turns left by a clear
    margin or goes straight on at every point), and per point whether it is a corner (turns
    left). A fan over a convex ring's corners is a valid triangulation; the points in between
    lie on its edges, as the ear clipper would leave them."""
    owner = np.repeat(np.arange(len(lengths)), lengths)
    unit = normals / np.where(area > 0, area, 1.0)[:, None]
    ends = starts[lengths > 0] + lengths[lengths > 0] - 1
    prev = np.arange(-1, len(points) - 1)
    prev[starts[lengths > 0]] = ends
    nxt = np.arange(1, len(points) + 1)
    nxt[ends] = starts[lengths > 0]
    incoming, outgoing = points - points[prev], points[nxt] - points
    turn = np.einsum("ij,ij->i", np.cross(incoming, outgoing), unit[owner])
    margin = 1e-9 * extents[owner] ** 2
    corner = turn > margin
    # a point in line with its neighbours, between them, and clear of both: an edge point
    clear = 1e-6 * extents[owner]
    apart = (np.linalg.norm(incoming, axis=1) > clear) & (np.linalg.norm(outgoing, axis=1) > clear)
    straight = (np.abs(turn) <= margin) & (np.einsum("ij,ij->i", incoming, outgoing) > 0) & apart
    bent = np.bincount(owner[~(corner | straight)], minlength=len(lengths)) > 0
    corners = np.bincount(owner[corner], minlength=len(lengths))
    return usable & ~bent & (corners >= 3), corner


def _fan(corners: np.ndarray) -> np.ndarray:
    """Triangles (c0, cj, cj+1) over a convex ring's ``corners`` (indices into the ring)."""
    corners = corners.astype(np.int64)
    return np.column_stack([np.full(len(corners) - 2, corners[0]), corners[1:-1], corners[2:]])
