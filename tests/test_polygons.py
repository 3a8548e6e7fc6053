"""Triangulating city-model polygons: many at once gives what one at a time gives.

The batch path (:func:`triangulate_many`) fans strictly convex rings and ear-clips the rest;
its triangles must cover exactly the polygon that :func:`triangulate` covers, face the same
way, and call the same rings degenerate.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lodconvert.polygons import DegenerateRing, triangulate, triangulate_many


def _vector_area(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Sum of the triangles' area vectors (its length is the area, its direction the facing)."""
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    return np.cross(b - a, c - a).sum(axis=0) / 2.0


def _sliver(ring: np.ndarray) -> bool:
    """Whether ``ring`` is so close to a line that rounding may decide if it has area."""
    extent = float(np.ptp(ring, axis=0).max())
    centred = ring - ring[0]
    normal = np.cross(centred, np.roll(centred, -1, axis=0)).sum(axis=0)
    return float(np.linalg.norm(normal)) < 1e-9 * extent * extent


def _placed(flat: np.ndarray, seed: int) -> np.ndarray:
    """2-D points put on a random plane in space, far from the origin as in a city."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    offset = np.array([691_000.0, 5_336_000.0, 520.0])
    return np.column_stack([flat, np.zeros(len(flat))]) @ q.T + offset


@st.composite
def rings(draw: st.DrawFn) -> np.ndarray:
    """A ring: a star-shaped or convex polygon, sometimes closed, with repeated points or
    points a rounding error apart, or a degenerate one (collinear or too short)."""
    kind = draw(st.sampled_from(["convex", "star", "line", "short"]))
    count = draw(st.integers(3, 12))
    angles = np.sort(draw(st.lists(st.floats(0, 2 * np.pi), min_size=count, max_size=count)))
    if kind == "convex":
        flat = np.column_stack([np.cos(angles), np.sin(angles)]) * 10
    elif kind == "star":
        radius = np.array(draw(st.lists(st.floats(2, 10), min_size=count, max_size=count)))
        flat = np.column_stack([np.cos(angles), np.sin(angles)]) * radius[:, None]
    elif kind == "line":
        flat = np.column_stack([angles, 2 * angles])
    else:
        flat = np.array([[0.0, 0.0], [1.0, 1.0]])
    if draw(st.booleans()):
        flat = flat[::-1]
    if draw(st.booleans()) and len(flat):
        flat = np.concatenate([flat, flat[:1]])
    if draw(st.booleans()) and len(flat) > 1:
        flat = np.insert(flat, 1, flat[1], axis=0)
    placed = _placed(flat, draw(st.integers(0, 1000)))
    if draw(st.booleans()) and len(placed) > 2:  # a point a rounding error from another
        placed = np.insert(placed, 2, placed[2] + [0.0, 0.0, 1e-11], axis=0)
    return placed


@settings(max_examples=150, deadline=None)
@given(st.lists(rings(), min_size=1, max_size=8))
def test_many_at_once_covers_what_one_at_a_time_covers(polygons: list[np.ndarray]) -> None:
    together = triangulate_many([[ring] for ring in polygons])
    for ring, result in zip(polygons, together, strict=True):
        try:
            points, faces = triangulate([ring])
        except DegenerateRing:
            assert result is None or _sliver(ring)
            continue
        if result is None:
            assert _sliver(ring)
            continue
        many_points, many_faces = result
        expected, got = _vector_area(points, faces), _vector_area(many_points, many_faces)
        scale = max(float(np.linalg.norm(expected)), 1.0)
        assert np.allclose(got, expected, atol=1e-6 * scale)
        assert many_faces.min() >= 0 and many_faces.max() < len(many_points)


def test_polygons_with_holes_go_through_the_ear_clipper() -> None:
    square = _placed(np.array([[0, 0], [10, 0], [10, 10], [0, 10]], dtype=float), 1)
    hole = _placed(np.array([[4, 4], [4, 6], [6, 6], [6, 4]], dtype=float), 1)
    (points, faces), empty = triangulate_many([[square, hole], [square[:2]]])
    assert empty is None
    assert np.isclose(np.linalg.norm(_vector_area(points, faces)), 100 - 4)
