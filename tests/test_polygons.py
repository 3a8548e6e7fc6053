"""Triangulating city-model polygons: many at once gives what one at a time gives.

The batch path (:func:`triangulate_many`) fans convex rings without holes and ear-clips the
rest; it must call the same polygons degenerate as :func:`triangulate`, give the same
vertices, and the same triangles wherever it ear-clips (a fan covers the same area, facing
the same way). Neither may depend on what else is in the batch.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lodconvert.polygons import (
    DegenerateRing,
    _ring_measures,
    points_surface,
    triangulate,
    triangulate_many,
)


def _vector_area(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Sum of the triangles' area vectors (its length is the area, its direction the facing)."""
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    return np.cross(b - a, c - a).sum(axis=0) / 2.0


def _placed(flat: np.ndarray, seed: int) -> np.ndarray:
    """2-D points put on a random plane in space, far from the origin as in a city."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    offset = np.array([691_000.0, 5_336_000.0, 520.0])
    return np.column_stack([flat, np.zeros(len(flat))]) @ q.T + offset


@st.composite
def flat_rings(draw: st.DrawFn) -> np.ndarray:
    """A 2-D ring: a star-shaped or convex polygon with collinear points on its edges, or a
    degenerate one (collinear or too short); sometimes closed, with a repeated point."""
    kind = draw(st.sampled_from(["convex", "star", "line", "short"]))
    count = draw(st.integers(3, 12))
    angles = np.sort(draw(st.lists(st.floats(0, 2 * np.pi), min_size=count, max_size=count)))
    if kind == "convex":
        flat = np.column_stack([np.cos(angles), np.sin(angles)]) * 10
        if draw(st.booleans()):  # a point halfway along an edge
            flat = np.insert(flat, 1, (flat[0] + flat[1]) / 2, axis=0)
    elif kind == "star":
        radius = np.array(draw(st.lists(st.floats(2, 10), min_size=count, max_size=count)))
        flat = np.column_stack([np.cos(angles), np.sin(angles)]) * radius[:, None]
    elif kind == "line":
        flat = np.column_stack([angles, 2 * angles])
    else:
        flat = np.array([[0.0, 0.0], [1.0, 1.0]])
    if draw(st.booleans()):
        flat = flat[::-1]
    if draw(st.booleans()):
        flat = np.concatenate([flat, flat[:1]])
    if draw(st.booleans()):
        flat = np.insert(flat, 1, flat[1], axis=0)
    return flat


@st.composite
def polygons(draw: st.DrawFn) -> list[np.ndarray]:
    """A polygon on a random plane: an exterior ring and up to two holes (small rings near its
    middle, some of them degenerate), with a point sometimes a rounding error from another."""
    rings = [draw(flat_rings())]
    rings += [draw(flat_rings()) * 0.2 for _ in range(draw(st.integers(0, 2)))]
    seed = draw(st.integers(0, 1000))
    placed = [_placed(flat, seed) for flat in rings]
    if draw(st.booleans()) and len(placed[0]) > 2:
        placed[0] = np.insert(placed[0], 2, placed[0][2] + [0.0, 0.0, 1e-11], axis=0)
    return placed


def _same(a: tuple[np.ndarray, np.ndarray] | None, b: tuple[np.ndarray, np.ndarray] | None) -> bool:
    """Whether two results are both None or hold equal arrays."""
    if a is None or b is None:
        return a is b
    return all(np.array_equal(x, y) and x.dtype == y.dtype for x, y in zip(a, b, strict=True))


@settings(max_examples=200, deadline=None)
@given(st.lists(polygons(), min_size=1, max_size=8))
def test_many_at_once_gives_what_one_at_a_time_gives(batch: list[list[np.ndarray]]) -> None:
    together = triangulate_many(batch)
    for polygon, result in zip(batch, together, strict=True):
        assert _same(result, triangulate_many([polygon])[0])
        try:
            points, faces = triangulate(polygon)
        except DegenerateRing:
            assert result is None
            continue
        assert result is not None
        exterior = polygon[0] - polygon[0][0]
        facing = np.cross(exterior, np.roll(exterior, -1, axis=0)).sum(axis=0)
        assert len(faces) == 0 or _vector_area(points, faces) @ facing > 0
        many_points, many_faces = result
        assert np.array_equal(many_points, points)
        assert many_faces.dtype == faces.dtype == np.int64
        if np.array_equal(many_faces, faces):
            continue
        assert len(polygon) == 1 and np.all(many_faces[:, 0] == many_faces[0, 0])  # a fan
        expected, got = _vector_area(points, faces), _vector_area(many_points, many_faces)
        assert np.allclose(got, expected, atol=1e-6 * max(float(np.linalg.norm(expected)), 1.0))


@settings(max_examples=200, deadline=None)
@given(st.lists(polygons(), min_size=1, max_size=8))
def test_without_fans_many_at_once_gives_exactly_one_at_a_time(
    batch: list[list[np.ndarray]],
) -> None:
    """Without fans the batch is :func:`triangulate` polygon by polygon, to the last bit (the
    CityJSON reader relies on it to keep its output)."""
    together = triangulate_many(batch, fan=False)
    for polygon, result in zip(batch, together, strict=True):
        try:
            expected = triangulate(polygon)
        except DegenerateRing:
            assert result is None
            continue
        assert _same(result, expected)


def test_without_fans_a_convex_quad_is_ear_clipped() -> None:
    quad = _placed(np.array([[0, 0], [10, 0], [12, 8], [1, 9]], dtype=float), 3)
    (fanned,), (clipped,) = triangulate_many([[quad]]), triangulate_many([[quad]], fan=False)
    assert fanned is not None and clipped is not None
    assert np.array_equal(clipped[1], triangulate([quad])[1])
    assert not np.array_equal(fanned[1], clipped[1])  # the ear clipper starts elsewhere


@settings(max_examples=100, deadline=None)
@given(st.lists(flat_rings(), min_size=1, max_size=6), st.integers(0, 1000))
def test_ring_normals_are_those_of_one_ring_at_a_time(rings: list[np.ndarray], seed: int) -> None:
    """Each ring's Newell normal is what ``np.dot`` over its own points gives, to the last
    bit, so that results do not depend on the batch."""
    placed = [_placed(flat, seed) for flat in rings]
    normals, _, _ = _ring_measures(np.concatenate(placed), np.array([len(r) for r in placed]))
    for ring, normal in zip(placed, normals, strict=True):
        if len(ring) < 3:
            assert not normal.any()
            continue
        local = ring - ring[0]
        nxt = np.roll(local, -1, axis=0)
        a, b = local - nxt, local + nxt
        expected = [np.dot(a[:, 1], b[:, 2]), np.dot(a[:, 2], b[:, 0]), np.dot(a[:, 0], b[:, 1])]
        assert np.array_equal(normal, expected)


def test_polygons_with_holes_go_through_the_ear_clipper() -> None:
    square = _placed(np.array([[0, 0], [10, 0], [10, 10], [0, 10]], dtype=float), 1)
    hole = _placed(np.array([[4, 4], [4, 6], [6, 6], [6, 4]], dtype=float), 1)
    (points, faces), empty = triangulate_many([[square, hole], [square[:2]]])
    assert empty is None
    assert np.isclose(np.linalg.norm(_vector_area(points, faces)), 100 - 4)


def test_degenerate_rings_say_why() -> None:
    square = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]], dtype=float)
    line = np.array([[2, 2, 0], [3, 3, 0], [4, 4, 0], [2, 2, 0]], dtype=float)
    with pytest.raises(DegenerateRing, match="a ring of 2 distinct point"):
        triangulate([square[[0, 0, 1, 0]]])
    with pytest.raises(DegenerateRing, match="without area"):
        triangulate([line])
    points, faces = triangulate([square, line])  # a degenerate hole is left out
    assert np.array_equal(points, square) and len(faces) == 2
    assert triangulate_many([]) == []
    assert triangulate_many([[], [line], [square[:2]]]) == [None, None, None]


def test_points_surface_faces_up_and_refuses_points_without_plan_area() -> None:
    """Control points of a terrain: triangulated in plan, facing up, repeated points once;
    points on a line (or one point repeated) give no surface."""
    grid = np.array([[x, y, (x * y) % 3] for x in range(4) for y in range(4)], dtype=float)
    vertices, faces = points_surface(np.concatenate([grid, grid[:5]]))
    assert len(vertices) == 16 and len(faces) == 18  # 2 (n - 1)² triangles of a 4 × 4 grid
    corners = vertices[faces]
    up = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, 2]
    assert (up > 0).all() and up.sum() / 2 == pytest.approx(9.0)
    assert points_surface(np.array([[0, 0, 0], [1, 1, 1], [2, 2, 5.0]])) is None
    assert points_surface(np.zeros((5, 3))) is None
