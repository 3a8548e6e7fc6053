"""Properties of the numpy baker on small random meshes (hypothesis).

Meshes are scaled so that their bounding box is the unit cube: every side is then a whole number
of pitches, so the grid (anchored at the box's least corner, ``T3`` cells along every side)
maps onto itself under a 90° rotation about an axis. That is what makes the rotation property
exact: for a box whose sides are not whole multiples of the pitch, the rotated grid overhangs
the box on the other side and its cells, hence its points, differ.
"""

from __future__ import annotations

import numpy as np
import trimesh
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from lodconvert.bake import Grid, NumpyBackend, bake_points
from lodconvert.model import BakeParams, PointCloud, Surface

SETTINGS = settings(max_examples=60, deadline=None, derandomize=True)
ON_SURFACE = 1e-9
"""Distance (in units of the unit box) within which a point counts as on a face."""


@st.composite
def meshes(draw: st.DrawFn) -> Surface:
    """4 to 9 vertices scaled onto the unit cube, 2 to 10 triangles among them (one at least
    not a sliver). Coordinates come from a seeded generator, not from hypothesis's simple
    values: a plane through pixel centres at exactly a cell boundary is a tie that ``floor``
    breaks upwards on one side and downwards on the mirrored one (see the rotation test)."""
    n = draw(st.integers(4, 9))
    corners = st.lists(st.integers(0, n - 1), min_size=3, max_size=3, unique=True)
    faces = np.array(draw(st.lists(corners, min_size=2, max_size=10)), dtype=np.int64)
    used, faces = np.unique(faces, return_inverse=True)  # the box is that of used vertices
    vertices = np.random.default_rng(draw(st.integers(0, 2**32 - 1))).random((len(used), 3))
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    assume(((hi - lo) > 0.05).all())
    vertices = (vertices - lo) / (hi - lo)
    faces = faces.reshape(-1, 3)
    surface = Surface(vertices=vertices, faces=faces)
    tri = surface.triangles
    areas = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assume(areas.max() > 0.01)
    return surface


def bake(surface: Surface, resolution: int, kind: str = "median") -> tuple[PointCloud, Grid]:
    """One point level at ``resolution`` (slabs as thick as the pitch)."""
    return bake_points(surface, BakeParams(resolution, resolution, 1.0, kind), NumpyBackend())


def surface_distance(surface: Surface, points: np.ndarray) -> np.ndarray:
    """Distance of each point to the nearest face."""
    tri = surface.triangles
    pairs = np.repeat(tri, len(points), axis=0)
    nearest = trimesh.triangles.closest_point(pairs, np.tile(points, (len(tri), 1)))
    gaps = np.linalg.norm(nearest - np.tile(points, (len(tri), 1)), axis=1)
    return gaps.reshape(len(tri), len(points)).min(axis=0)


@SETTINGS
@given(meshes(), st.integers(3, 24))
def test_points_lie_on_the_surface_and_fills_within_a_pitch(surface: Surface, res: int) -> None:
    """Unfilled, every point is a ray hit or a surface sample, so on a face. A median-filled
    pixel is covered on at least one side (5 of its 8 neighbours are covered, at most 4 of them
    corners) by a hit one pitch away in the image and in the same slab, one pitch thick: it lies
    within √2 pitches of the surface."""
    plain, grid = bake(surface, res, "none")
    assert len(plain) > 0
    assert surface_distance(surface, plain.positions).max() <= ON_SURFACE
    filled, _ = bake(surface, res)
    assert surface_distance(surface, filled.positions).max() <= np.sqrt(2) * grid.pitch + 1e-9


@SETTINGS
@given(meshes(), st.integers(3, 24))
def test_points_stay_in_the_box_grown_by_a_pitch(surface: Surface, res: int) -> None:
    cloud, grid = bake(surface, res)
    lo, hi = surface.bounds
    assert (cloud.positions >= lo - grid.pitch).all()
    assert (cloud.positions <= hi + grid.pitch).all()


@SETTINGS
@given(meshes(), st.integers(3, 12))
def test_counts_fall_with_resolution(surface: Surface, res: int) -> None:
    """Halving the pitch splits every cell in 8 (the grids nest): each occupied coarse cell
    holds a surface point that some fine cell keeps, so counts do not fall as it grows."""
    coarse, _ = bake(surface, res, "none")
    fine, _ = bake(surface, 2 * res, "none")
    assert len(fine) >= len(coarse)


@SETTINGS
@given(meshes(), st.integers(3, 24))
def test_the_same_input_gives_the_same_points(surface: Surface, res: int) -> None:
    a, _ = bake(surface, res)
    copy = Surface(vertices=surface.vertices.copy(), faces=surface.faces.copy())
    b, _ = bake(copy, res)
    for field in ("positions", "colors", "normals"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


ROTATIONS = {
    0: lambda p: np.stack([p[:, 0], 1 - p[:, 2], p[:, 1]], axis=1),
    1: lambda p: np.stack([p[:, 2], p[:, 1], 1 - p[:, 0]], axis=1),
    2: lambda p: np.stack([1 - p[:, 1], p[:, 0], p[:, 2]], axis=1),
}
"""90° about x, y or z, within the unit cube (so the bounding box and its grid map onto
themselves)."""


@SETTINGS
@given(meshes(), st.integers(3, 24), st.sampled_from(sorted(ROTATIONS)))
def test_a_quarter_turn_turns_the_points(surface: Surface, res: int, axis: int) -> None:
    """Rotated mesh, rotated points: the same cells, and in each the same point, up to the
    rounding of the rotation (1 - y is not exact) — a point whose cell or nearest-to-centre
    choice hangs on that last bit is vanishingly rare with random coordinates."""
    turn = ROTATIONS[axis]
    cloud, _ = bake(surface, res)
    turned, _ = bake(Surface(vertices=turn(surface.vertices), faces=surface.faces), res)
    expected = turn(cloud.positions)
    assert len(turned) == len(expected)
    gaps = np.linalg.norm(turned.positions[:, None] - expected[None], axis=2).min(axis=1)
    assert gaps.max() <= ON_SURFACE
