"""Planar polygons with holes (city models' rings) to triangles.

A polygon is its exterior ring and any interior rings, each an (k, 3) array of float64 points
(closed or not: a repeated last point is dropped). It is triangulated on its best-fit plane
(Newell's normal, so slightly non-planar rings from surveys still work) by ear clipping with
holes (``mapbox-earcut``). Rings with fewer than three distinct points or without area are
degenerate: :class:`DegenerateRing` says why, for the reader to report and skip.

Polygons are handled in batches: opening, normals, plane axes, projection to the plane and
the facing of the triangles are computed for all of a batch's rings at once, leaving only the
ear clipper's call per polygon.
"""

from __future__ import annotations

from collections.abc import Sequence

import mapbox_earcut
import numpy as np

AREA_EPSILON = 1e-12
"""A ring whose area is below this × (its extent)² has no area."""

Triangles = tuple[np.ndarray, np.ndarray]
"""A polygon's vertices (n, 3) and triangles (m, 3) indexing them."""


class DegenerateRing(ValueError):
    """A ring that cannot bound a polygon: fewer than 3 distinct points, or no area."""


def triangulate(rings: Sequence[np.ndarray]) -> Triangles:
    """Vertices (n, 3) and triangles (m, 3) of the polygon whose exterior ring is ``rings[0]``
    and interior rings (holes) the rest. Triangles wind like the exterior ring (their normals
    point where its Newell normal does). Degenerate interior rings are left out; a degenerate
    exterior ring raises :class:`DegenerateRing`."""
    points, lengths = _opened_rings(rings)
    normals, area, extents = _ring_measures(points, lengths)
    with_area = _with_area(lengths, area, extents)
    if lengths[0] < 3:
        raise DegenerateRing(f"a ring of {lengths[0]} distinct point(s); a polygon needs 3")
    if not with_area[0]:
        raise DegenerateRing("a ring without area (its points lie on a line)")
    if len(rings) == 1 and lengths[0] == 3:
        return points, np.array([[0, 1, 2]], dtype=np.int64)
    vertices = points[with_area.repeat(lengths)]
    faces, _ = _ear_clipped(
        vertices,
        np.array([len(vertices)]),
        lengths[with_area],
        np.array([np.count_nonzero(with_area)]),
        normals[:1] / area[:1, None],
    )
    return vertices, faces


def triangulate_many(
    polygons: Sequence[Sequence[np.ndarray]], fan: bool = True
) -> list[Triangles | None]:
    """:func:`triangulate` of each polygon, ``None`` where it is degenerate (also where it has
    no rings), except that (with ``fan``) a convex polygon without holes is fanned from its
    first corner rather than ear-clipped; without ``fan`` every triangle is the one
    :func:`triangulate` gives. The polygons are measured and projected together, so a batch
    of many costs far less per polygon than one at a time."""
    every_ring = [ring for rings in polygons for ring in rings]
    if not every_ring:
        return [None] * len(polygons)
    counts = np.fromiter(map(len, polygons), dtype=np.int64, count=len(polygons))
    points, lengths = _opened_rings(every_ring)
    normals, area, extents = _ring_measures(points, lengths)
    with_area = _with_area(lengths, area, extents)
    first_ring = counts.cumsum() - counts
    ids = np.flatnonzero(counts > 0)
    ids = ids[with_area[first_ring[ids]]]  # the polygons whose exterior ring has area
    outer = first_ring[ids]
    usable = np.zeros(len(polygons), dtype=bool)
    usable[ids] = True
    kept = with_area & usable.repeat(counts)  # their rings with area
    owner = (usable.cumsum() - 1)[np.arange(len(polygons)).repeat(counts)[kept]]  # in ids
    vertices = points[kept.repeat(lengths)]
    vertex_counts = np.bincount(owner, weights=lengths[kept], minlength=len(ids)).astype(np.int64)
    vertex_starts = vertex_counts.cumsum() - vertex_counts
    single = counts[ids] == 1
    fanned = single & (vertex_counts == 3)
    corner = fanned.repeat(vertex_counts)
    candidate = single & (vertex_counts > 3)
    if fan and candidate.any():
        at = candidate.repeat(vertex_counts)
        ring = outer[candidate]
        fanned[candidate], corner[at] = _convex_corners(
            vertices[at], vertex_counts[candidate], normals[ring], area[ring], extents[ring]
        )
    results: list[Triangles | None] = [None] * len(polygons)
    if fanned.any():
        fans = _fans(corner[fanned.repeat(vertex_counts)], vertex_counts[fanned])
        _place(results, fanned, ids, vertices, vertex_starts, vertex_counts, *fans)
    clipped = ~fanned
    if clipped.any():
        in_clipped = clipped[owner]
        ring = outer[clipped]
        clips = _ear_clipped(
            vertices[clipped.repeat(vertex_counts)],
            vertex_counts[clipped],
            lengths[kept][in_clipped],
            np.bincount(owner[in_clipped], minlength=len(ids))[clipped],
            normals[ring] / area[ring, None],
        )
        _place(results, clipped, ids, vertices, vertex_starts, vertex_counts, *clips)
    return results


def _with_area(lengths: np.ndarray, area: np.ndarray, extents: np.ndarray) -> np.ndarray:
    """Per ring, whether it bounds a polygon: 3 points or more and an ``area`` (its Newell
    normal's length) of at least :data:`AREA_EPSILON` × its extent²."""
    return (lengths >= 3) & (area > 2 * AREA_EPSILON * extents * extents)


def _place(
    results: list[Triangles | None],
    chosen: np.ndarray,
    ids: np.ndarray,
    vertices: np.ndarray,
    vertex_starts: np.ndarray,
    vertex_counts: np.ndarray,
    faces: np.ndarray,
    face_counts: np.ndarray,
) -> None:
    """Put the ``chosen`` polygons' vertices (``vertex_counts`` from ``vertex_starts`` in
    ``vertices``) and faces (``face_counts`` of them, laid end to end in ``faces``) at their
    ``ids`` in ``results``, as slices."""
    starts = vertex_starts[chosen]
    face_ends = face_counts.cumsum()
    for i, v0, v1, f0, f1 in zip(
        ids[chosen].tolist(),
        starts.tolist(),
        (starts + vertex_counts[chosen]).tolist(),
        (face_ends - face_counts).tolist(),
        face_ends.tolist(),
        strict=True,
    ):
        results[i] = (vertices[v0:v1], faces[f0:f1])


def _opened_rings(rings: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """All ``rings`` (at least one, each (k, 3)) without a repeated closing point and without
    repeated neighbours, concatenated, and their lengths."""
    lengths = np.fromiter(map(len, rings), dtype=np.int64, count=len(rings))
    points = np.concatenate(rings, dtype=np.float64)
    owner = np.arange(len(rings)).repeat(lengths)
    ends = lengths.cumsum()
    longer = lengths > 1
    last = ends[longer] - 1
    keep = np.ones(len(points), dtype=bool)
    keep[last[(points[last] == points[(ends - lengths)[longer]]).all(axis=1)]] = False
    keep[1:] &= ~((points[1:] == points[:-1]).all(axis=1) & (owner[1:] == owner[:-1]))
    return points[keep], np.bincount(owner[keep], minlength=len(rings))


def _neighbours(lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For rings of ``lengths`` laid end to end: the first point of each ring that has any,
    and per point the index of the point before it and of the point after it in its ring."""
    total = int(lengths.sum())
    filled = lengths > 0
    first = (lengths.cumsum() - lengths)[filled]
    last = first + lengths[filled] - 1
    before, after = np.arange(-1, total - 1), np.arange(1, total + 1)
    before[first], after[last] = last, first
    return first, before, after


def _ring_measures(
    points: np.ndarray, lengths: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per ring of ``lengths`` (laid end to end in ``points``): its Newell normal (twice its
    vector area, taken about its first point whatever its position in space; zero for fewer
    than 3 points), the length of that, and its extent (largest side of its bounding box).
    Each component is a strided BLAS dot product over one ring's points, as ``np.dot`` of
    two of its columns gives it, to the last bit."""
    first, _, after = _neighbours(lengths)
    local = points - points[first].repeat(lengths[lengths > 0], axis=0)
    a, b = local - local[after], local + local[after]
    order, point_order, groups = _length_groups(lengths)
    a, b = a[point_order].take(_NEXT, axis=1), b[point_order].take(_AFTER, axis=1)
    ordered = np.zeros((len(lengths), 3))
    for length, i0, i1, p0, p1 in groups:
        if length >= 3:  # (rings, 3 components, points): the points strided as in one ring
            x = a[p0:p1].reshape(i1 - i0, length, 3).transpose(0, 2, 1)
            y = b[p0:p1].reshape(i1 - i0, length, 3).transpose(0, 2, 1)
            ordered[i0:i1] = _dots(x, y)
    normals = np.empty_like(ordered)
    normals[order] = ordered
    extents = np.zeros(len(lengths))
    if len(first):
        spans = np.maximum.reduceat(points, first) - np.minimum.reduceat(points, first)
        extents[lengths > 0] = spans.max(axis=1)
    return normals, _lengths(normals), extents


def _length_groups(
    lengths: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int, int, int, int]]]:
    """Items of ``lengths`` (at least one; their points laid end to end) gathered by length,
    so that the items of one length go to numpy together as one (count, length, …) array: the
    item order that does it, the point order that follows, and per length (length, first
    item, end item, first point, end point) in those orders."""
    order = lengths.argsort(kind="stable")
    ordered = lengths[order]
    ends = ordered.cumsum()
    starts = ends - ordered
    shift = (lengths.cumsum() - lengths)[order] - starts
    point_order = np.arange(int(ends[-1])) + shift.repeat(ordered)
    first = np.ones(len(ordered), dtype=bool)
    np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
    first = first.nonzero()[0]
    end = np.empty_like(first)
    end[:-1], end[-1] = first[1:], len(ordered)
    groups = zip(
        ordered[first].tolist(),
        first.tolist(),
        end.tolist(),
        starts[first].tolist(),
        ends[end - 1].tolist(),
        strict=True,
    )
    return order, point_order, list(groups)


def _lengths(vectors: np.ndarray) -> np.ndarray:
    """The length of each row of C-ordered ``vectors`` (n, 3), as ``np.linalg.norm`` gives
    one vector's."""
    return np.sqrt(_dots(vectors, vectors))


def _dots(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Dot products of the rows of ``x`` and ``y`` (…, k), each one BLAS call over the rows'
    own strides, so the same as ``np.dot`` of the two rows, to the last bit."""
    return (x[..., None, :] @ y[..., :, None])[..., 0, 0]


def _convex_corners(
    points: np.ndarray,
    lengths: np.ndarray,
    normals: np.ndarray,
    area: np.ndarray,
    extents: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per ring (of ``lengths``, laid end to end in ``points``, with their Newell ``normals``,
    its length ``area`` and ``extents``), whether it is convex seen from its normal (it turns
    left by a clear margin or goes straight on at every point), and per point whether it is a
    corner (turns left). A fan over a convex ring's corners is a valid triangulation; the
    points in between lie on its edges, as the ear clipper would leave them."""
    owner = np.arange(len(lengths)).repeat(lengths)
    unit = normals / np.where(area > 0, area, 1.0)[:, None]
    _, before, after = _neighbours(lengths)
    incoming, outgoing = points - points[before], points[after] - points
    turn = np.einsum("ij,ij->i", _cross(incoming, outgoing), unit[owner])
    margin = 1e-9 * extents[owner] ** 2
    corner = turn > margin
    # a point in line with its neighbours, between them, and clear of both: an edge point
    clear = 1e-6 * extents[owner]
    step = np.linalg.norm(incoming, axis=1)
    apart = (step > clear) & (step[after] > clear)
    straight = (np.abs(turn) <= margin) & (np.einsum("ij,ij->i", incoming, outgoing) > 0) & apart
    bent = np.bincount(owner[~(corner | straight)], minlength=len(lengths)) > 0
    corners = np.bincount(owner[corner], minlength=len(lengths))
    return ~bent & (corners >= 3), corner


def _fans(corner: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (c0, cj, cj+1) over the corners of convex rings (of ``lengths``, laid end to
    end; ``corner`` per point), indexing each ring's points, and how many each ring has."""
    at = np.flatnonzero(corner)
    owner = np.arange(len(lengths)).repeat(lengths)[at]
    relative = at - (lengths.cumsum() - lengths)[owner]
    found = np.bincount(owner, minlength=len(lengths))
    made = found - 2
    face_owner = np.arange(len(lengths)).repeat(made)
    first = (found.cumsum() - found)[face_owner]
    middle = np.arange(len(face_owner)) - (made.cumsum() - made)[face_owner] + first + 1
    return np.column_stack([relative[first], relative[middle], relative[middle + 1]]), made


def _ear_clipped(
    vertices: np.ndarray,
    vertex_counts: np.ndarray,
    ring_lengths: np.ndarray,
    ring_counts: np.ndarray,
    normals: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of polygons (their ``vertex_counts`` points laid end to end in ``vertices``;
    in each, ``ring_counts`` rings of ``ring_lengths``, the exterior first; their exterior
    rings' unit ``normals``) by ear clipping on their planes, each polygon's indexing its own
    points and facing along its normal, and how many each polygon has. The projection to a
    plane is one BLAS matrix product per polygon, as ``points @ axes.T`` gives it."""
    starts = vertex_counts.cumsum() - vertex_counts
    local = vertices - vertices[starts].repeat(vertex_counts, axis=0)
    order, point_order, groups = _length_groups(vertex_counts)
    local, axes = local[point_order], _plane_axes(normals)[order].transpose(0, 2, 1)
    ordered = np.empty((len(local), 2))
    for length, i0, i1, p0, p1 in groups:
        ordered[p0:p1] = (local[p0:p1].reshape(i1 - i0, length, 3) @ axes[i0:i1]).reshape(-1, 2)
    flat = np.empty_like(ordered)
    flat[point_order] = ordered
    ends = (ring_lengths.cumsum() - starts.repeat(ring_counts)).astype(np.uint32)
    ring_ends = ring_counts.cumsum()
    clip = mapbox_earcut.triangulate_float64
    found = [
        clip(flat[v0:v1], ends[r0:r1])
        for v0, v1, r0, r1 in zip(
            starts.tolist(),
            (starts + vertex_counts).tolist(),
            (ring_ends - ring_counts).tolist(),
            ring_ends.tolist(),
            strict=True,
        )
    ]
    face_counts = np.fromiter(map(len, found), dtype=np.int64, count=len(found)) // 3
    faces = np.concatenate(found).astype(np.int64).reshape(-1, 3)
    a, b, c = flat[faces + starts.repeat(face_counts)[:, None]].transpose(1, 0, 2)
    turn = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    faces[turn < 0] = faces[turn < 0][:, ::-1]  # face along the exterior ring's normal
    return faces, face_counts


def _plane_axes(normals: np.ndarray) -> np.ndarray:
    """Per unit normal (n, 3), two orthonormal axes (n, 2, 3) spanning its plane, right-handed
    with it, so that a counter-clockwise ring seen from the normal stays counter-clockwise."""
    u = _cross(normals, _AXES[np.abs(normals).argmin(axis=1)])
    u /= _lengths(u)[:, None]
    return np.concatenate([u, _cross(normals, u)], axis=1).reshape(-1, 2, 3)


_AXES = np.eye(3)
_NEXT, _AFTER = np.array([1, 2, 0]), np.array([2, 0, 1])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products (n, 3), C-ordered, of (n, 3) arrays (``np.cross`` costs more
    for small ones)."""
    return a.take(_NEXT, axis=1) * b.take(_AFTER, axis=1) - a.take(_AFTER, axis=1) * b.take(
        _NEXT, axis=1
    )


def points_surface(points: np.ndarray, max_length: float | None = None) -> Triangles | None:
    """The surface through ``points`` ((n, 3), a terrain's control points) as a 2.5-D
    triangulation: Delaunay in plan (x, y), each triangle turned to face up; triangles with a
    side longer than ``max_length`` left out (GML's ``Tin`` rule). ``None`` when the points
    span no area in plan or no triangle is left."""
    from scipy.spatial import Delaunay, QhullError

    vertices = np.unique(np.asarray(points, dtype=np.float64), axis=0)
    vertices = vertices[np.unique(vertices[:, :2], axis=0, return_index=True)[1]]
    if len(vertices) < 3:
        return None
    try:
        faces = Delaunay(vertices[:, :2] - vertices[0, :2]).simplices.astype(np.int64)
    except QhullError:  # all points on a line
        return None
    corners = vertices[faces]
    if max_length is not None:
        sides = corners - np.roll(corners, 1, axis=1)
        faces = faces[_lengths(sides).max(axis=1) <= max_length]
        corners = vertices[faces]
    if not len(faces):
        return None
    up = _cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, 2] > 0
    return vertices, np.where(up[:, None], faces, faces[:, ::-1])
