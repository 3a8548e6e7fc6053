"""Quadric decimation (``lodconvert.bake.qem``) from several threads at once: each call gets
its own mesh's result, as it does alone (``fast-simplification`` keeps its mesh in module
state between calls)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
import trimesh

from lodconvert.bake.qem import decimate, simplify_within
from lodconvert.model import Mesh, Surface


@pytest.fixture
def often_switching_threads() -> Iterator[None]:
    """Threads switched every microsecond, so that calls interleave wherever they can."""
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    yield
    sys.setswitchinterval(interval)


def _sphere(radius: float, subdivisions: int) -> Mesh:
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    colour = np.array([200, 100, 50, 255], dtype=np.uint8)
    faces = np.asarray(sphere.faces, dtype=np.int64)
    return Mesh([Surface(np.asarray(sphere.vertices), faces, base_color=colour)])


@pytest.mark.usefixtures("often_switching_threads")
def test_threads_simplifying_at_once_get_what_each_gets_alone() -> None:
    meshes = [_sphere(10.0, 4), _sphere(3.0, 3)]

    def both(i: int) -> tuple[bytes, bytes]:
        mesh = meshes[i % 2]
        return (
            simplify_within(mesh, 0.2).vertices.tobytes(),
            decimate(mesh, 100).vertices.tobytes(),
        )

    alone = [both(i) for i in range(2)]
    with ThreadPoolExecutor(4) as pool:
        together = list(pool.map(both, range(24)))
    assert together == [alone[i % 2] for i in range(24)]


def test_distances_to_triangles_are_those_of_trimesh_closest_points() -> None:
    """The compiled distances a far mesh's colours are matched by equal, bit for bit, the
    distances to trimesh's closest points: in every region of a triangle (corners, edges,
    inside), on whole-number ties, and for triangles collapsed to a segment or a point."""
    from lodconvert.bake.closest import distances

    rng = np.random.default_rng(5)
    triangles = rng.normal(size=(300, 3, 3)) * 3
    triangles[:20, 1] = triangles[:20, 0]  # a segment AC
    triangles[20:30, 2] = triangles[20:30, 0]  # a segment AB
    triangles[30:40] = triangles[30:40, :1]  # a point
    triangles[40:80] = np.round(triangles[40:80])
    points = rng.normal(size=(400, 3)) * 4
    points[:100] = np.round(points[:100])
    near = rng.integers(0, len(triangles), (len(points), 8))
    closest = trimesh.triangles.closest_point(
        triangles[near.ravel()], np.repeat(points, 8, axis=0)
    ).reshape(len(points), 8, 3)
    expected = np.linalg.norm(closest - points[:, None], axis=2)
    assert np.array_equal(distances(triangles, near, points), expected)
