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


def triangulate(rings: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and triangles (m, 3) of the polygon whose exterior ring is ``rings[0]``
    and interior rings (holes) the rest. Triangles wind like the exterior ring (their normals
    point where its Newell normal does). Degenerate interior rings are left out; a degenerate
    exterior ring raises :class:`DegenerateRing`."""
    import mapbox_earcut

    exterior = _open_ring(rings[0])
    if len(exterior) < 3:
        raise DegenerateRing(f"a ring of {len(exterior)} distinct point(s); a polygon needs 3")
    normal = newell_normal(exterior)
    extent = float(np.ptp(exterior, axis=0).max())
    length = float(np.linalg.norm(normal))
    if not length > 2 * AREA_EPSILON * extent * extent:
        raise DegenerateRing("a ring without area (its points lie on a line)")
    if len(exterior) == 3 and len(rings) == 1:
        return exterior, np.array([[0, 1, 2]], dtype=np.int64)
    normal /= length
    holes = []
    for ring in rings[1:]:
        hole = _open_ring(ring)
        if len(hole) >= 3 and np.linalg.norm(newell_normal(hole)) > 0:
            holes.append(hole)
    points = np.concatenate([exterior, *holes]) if holes else exterior
    flat = (points - points[0]) @ _plane_axes(normal).T
    ends = np.cumsum([len(exterior), *(len(h) for h in holes)]).astype(np.uint32)
    index = mapbox_earcut.triangulate_float64(flat, ends).astype(np.int64).reshape(-1, 3)
    if len(index):
        a, b, c = flat[index[:, 0]], flat[index[:, 1]], flat[index[:, 2]]
        turn = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        index[turn < 0] = index[turn < 0][:, ::-1]  # face along the exterior ring's normal
    return points, index
