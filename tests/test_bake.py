"""Properties of baked point levels that a user would notice (numpy backend)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend, bake_points, get_backend, gl
from lodconvert.bake.grid import SlabHits
from lodconvert.bake.pcd import occupied_hits
from lodconvert.model import BakeParams, Node, Surface

from .conftest import surface_of


def params(resolution: int, kind: str = "median", slices: int | None = None) -> BakeParams:
    return BakeParams(
        resolution=resolution, slices=slices or resolution, point_size=2.0, filter=kind
    )


def distances_to(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    return trimesh.proximity.closest_point(mesh, points)[1]


@pytest.mark.parametrize("resolution", [24, 64])
def test_points_lie_within_one_pitch_of_the_torus(torus: Node, resolution: int) -> None:
    mesh = trimesh.Trimesh(torus.geometry.vertices, torus.geometry.faces, process=False)
    cloud, grid = bake_points(torus.geometry, params(resolution), NumpyBackend())
    assert len(cloud) > 100
    assert distances_to(mesh, cloud.positions).max() <= grid.pitch


def test_points_cover_the_whole_extent(torus: Node) -> None:
    cloud, grid = bake_points(torus.geometry, params(32), NumpyBackend())
    bounds = torus.geometry.bounds
    assert np.all(cloud.positions.min(axis=0) <= bounds[0] + grid.pitch)
    assert np.all(cloud.positions.max(axis=0) >= bounds[1] - grid.pitch)


def test_one_point_per_cell_and_counts_fall_with_resolution(torus: Node) -> None:
    counts = []
    for resolution in (96, 48, 24, 12):
        cloud, grid = bake_points(torus.geometry, params(resolution), NumpyBackend())
        keys = grid.cell_keys(cloud.positions)
        assert len(np.unique(keys)) == len(keys)
        counts.append(len(cloud))
    assert counts == sorted(counts, reverse=True) and len(set(counts)) == 4


def test_hole_filters_only_add_points(bunny: Node) -> None:
    backend = NumpyBackend()
    grid, plain, _ = occupied_hits(bunny.geometry, params(64, "none"), backend)
    plain_cells = set(grid.cell_keys(plain).tolist())
    for kind in ("median", "gaussian"):
        _, filled, _ = occupied_hits(bunny.geometry, params(64, kind), backend)
        cells = set(grid.cell_keys(filled).tolist())
        assert plain_cells <= cells
        assert len(cells) > len(plain_cells)  # the bunny's holes and slab edges get filled


def test_colours_come_from_the_surface(torus: Node) -> None:
    cloud, _ = bake_points(torus.geometry, params(48), NumpyBackend())
    x = cloud.positions[:, 0]
    red, blue = cloud.colors[:, 0].astype(float), cloud.colors[:, 2].astype(float)
    # the torus fixture runs from blue (low x) to red (high x)
    assert np.corrcoef(x, red)[0, 1] > 0.95
    assert np.corrcoef(x, blue)[0, 1] < -0.95
    assert np.all(cloud.colors[:, 1] == 128)


def test_normals_are_unit_and_point_away_from_the_torus_core(torus: Node) -> None:
    cloud, _ = bake_points(torus.geometry, params(48), NumpyBackend())
    assert np.allclose(np.linalg.norm(cloud.normals, axis=1), 1.0, atol=1e-5)
    p = cloud.positions
    ring = p.copy()
    ring[:, 2] = 0
    ring *= (1.0 / np.linalg.norm(ring, axis=1))[:, None]
    outward = p - ring
    outward /= np.linalg.norm(outward, axis=1, keepdims=True)
    # trimesh's torus is wound outward; face normals must agree almost everywhere
    assert np.mean(np.einsum("ij,ij->i", outward, cloud.normals) > 0.5) > 0.98


def test_baking_is_deterministic(bunny: Node) -> None:
    a, _ = bake_points(bunny.geometry, params(48), NumpyBackend())
    b, _ = bake_points(bunny.geometry, params(48), NumpyBackend())
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.colors, b.colors)


def test_flat_square_bakes_onto_its_plane() -> None:
    square = Surface(
        vertices=np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64),
        faces=np.array([[0, 1, 2], [0, 2, 3]]),
    )
    cloud, _grid = bake_points(square, params(16), NumpyBackend())
    assert len(cloud) == 16 * 16
    assert np.all(cloud.positions[:, 2] == 0)


def test_thin_rod_is_not_lost() -> None:
    """A rod far thinner than the pitch: no pixel centre may hit it, the rescue keeps it."""
    rod = trimesh.creation.cylinder(radius=0.002, height=1.0, sections=8)
    cloud, grid = bake_points(surface_of(rod), params(40), NumpyBackend())
    z = np.sort(cloud.positions[:, 2])
    assert len(cloud) >= 35
    assert z[0] < -0.45 and z[-1] > 0.45
    assert np.diff(z).max() <= 2 * grid.pitch  # no gap along the rod


@pytest.mark.slow
def test_bunny_points_lie_on_the_scan(bunny_mesh: trimesh.Trimesh, bunny: Node) -> None:
    for resolution in (128, 64, 32):
        cloud, grid = bake_points(bunny.geometry, params(resolution), NumpyBackend())
        assert distances_to(bunny_mesh, cloud.positions).max() <= grid.pitch


def test_a_texture_without_uvs_falls_back_to_the_material_colour() -> None:
    square = Surface(
        vertices=np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64),
        faces=np.array([[0, 1, 2], [0, 2, 3]]),
        texture=np.zeros((4, 4, 4), dtype=np.uint8),
        base_color=np.array([10, 20, 30, 255], dtype=np.uint8),
    )
    cloud, _ = bake_points(square, params(8), NumpyBackend())
    assert np.all(cloud.colors == [10, 20, 30, 255])


def test_georeferenced_coordinates_bake_like_centred_ones(torus: Node) -> None:
    """Far from the origin (UTM-sized values) the baker keeps its precision."""
    offset = np.array([5.0e6, 3.0e5, 400.0])
    moved = Surface(torus.geometry.vertices + offset, torus.geometry.faces)
    near, grid = bake_points(torus.geometry, params(64, "none"), NumpyBackend())
    far, _ = bake_points(moved, params(64, "none"), NumpyBackend())
    assert len(far) == len(near)
    error = np.abs(far.positions - offset - near.positions).max(axis=1)
    # the same hits up to rounding; a near-tie for a cell's representative may flip
    assert np.mean(error < 1e-6) > 0.99
    assert error.max() < grid.pitch


@pytest.mark.parametrize("kind", ["median", "gaussian"])
def test_hole_filters_match_opencv(kind: str) -> None:
    """The filters evaluate OpenCV's 3×3 median and Gaussian blurs on the pixels next to covered
    ones only; on random masks they add exactly the pixels OpenCV's blurs would."""
    cv2 = pytest.importorskip("cv2")
    from lodconvert.bake.filters import _filled

    rng = np.random.default_rng(7)
    for density in (0.1, 0.5, 0.8):
        mask = np.zeros((66, 82), dtype=np.uint8)  # one-pixel padding ring stays empty
        mask[1:-1, 1:-1] = (rng.random((64, 80)) < density) * 255
        y, x = np.nonzero(mask)
        if kind == "median":
            grown = cv2.medianBlur(mask, 3) > 0
        else:
            grown = cv2.GaussianBlur(mask.astype(np.float32) / 255.0, (3, 3), 0) >= 0.5
        grown &= mask == 0
        grown[[0, -1], :] = False
        grown[:, [0, -1]] = False
        ey, ex = np.nonzero(grown)
        fy, fx = _filled(mask, kind, y, x)
        assert (fy.tolist(), fx.tolist()) == (ey.tolist(), ex.tolist())


@pytest.mark.parametrize("stack", [1, 5_000, 1 << 20])
def test_slab_images_filtered_together_fill_as_each_alone(
    monkeypatch: pytest.MonkeyPatch, stack: int
) -> None:
    """Slab images filtered stacked (one at a time, a few, all of them) add the same pixels,
    depths and faces, to the last bit, as each slab filtered alone: on the torus knot, where
    many slab images gain a pixel or two."""
    from lodconvert.bake import filters
    from lodconvert.bake.grid import Grid
    from lodconvert.io import read_scene

    from .conftest import SAMPLE

    (node,) = read_scene(SAMPLE).nodes
    grid = Grid.for_bounds(node.geometry.bounds, 96, 3)
    monkeypatch.setattr(filters, "STACK_PIXELS", stack)
    for hits in NumpyBackend().rasterize(node.geometry, grid):
        for kind in ("median", "gaussian"):
            together = filters.fill_holes(hits, grid, kind)
            alone = [_added(filters.fill_holes(slab, grid, kind), slab) for slab in _slabs(hits)]
            for name in ("slab", "iu", "iv", "depth", "face"):
                expected = np.concatenate([getattr(added, name) for added in alone])
                assert getattr(_added(together, hits), name).tobytes() == expected.tobytes()


def _slabs(hits: SlabHits) -> list[SlabHits]:
    """``hits`` slab by slab."""
    return [_taken(hits, hits.slab == slab) for slab in np.unique(hits.slab)]


def _added(filled: SlabHits, hits: SlabHits) -> SlabHits:
    """What filling ``hits`` added."""
    return _taken(filled, np.arange(len(filled)) >= len(hits))


def _taken(hits: SlabHits, keep: np.ndarray) -> SlabHits:
    arrays = (hits.slab, hits.iu, hits.iv, hits.depth, hits.face)
    return SlabHits(hits.axis, hits.sign, *(a[keep] for a in arrays))


@pytest.mark.parametrize("resolution", [3, 16, 61])
def test_coverage_is_the_silhouette_the_axis_rays_hit(resolution: int) -> None:
    """The silhouette masks the planner scores (one span per face and pixel row) are exactly
    the pixels where the axis rasteriser finds a hit, from either side: on the torus knot,
    curved and self-occluding."""
    from lodconvert.bake.grid import Grid
    from lodconvert.bake.numpy import silhouettes
    from lodconvert.io import read_scene

    from .conftest import SAMPLE

    (node,) = read_scene(SAMPLE).nodes
    mesh = node.geometry
    grid = Grid.for_bounds(mesh.bounds, resolution, 1)
    hits = list(NumpyBackend().rasterize(mesh, grid))
    (masks,) = silhouettes([mesh], grid)
    for axis in range(3):
        expected = np.zeros(grid.image_shape(axis), dtype=bool)
        for h in hits:
            if h.axis == axis:
                expected[h.iv, h.iu] = True
        assert expected.any()
        assert np.array_equal(masks[axis], expected)


def test_silhouettes_of_several_surfaces_are_each_ones_own() -> None:
    """Surfaces rasterised together on one grid get the silhouettes each gets alone: the torus
    knot and a copy of it shifted by a third of its extent, clipped at the grid's edge."""
    from lodconvert.bake.grid import Grid
    from lodconvert.bake.numpy import silhouettes
    from lodconvert.io import read_scene

    from .conftest import SAMPLE

    (node,) = read_scene(SAMPLE).nodes
    mesh = node.geometry
    shifted = mesh.translated(np.ptp(mesh.bounds, axis=0) / 3)
    grid = Grid.for_bounds(mesh.bounds, 40, 1)
    together = silhouettes([mesh, shifted], grid)
    alone = [silhouettes([mesh], grid)[0], silhouettes([shifted], grid)[0]]
    for masks, own in zip(together, alone, strict=True):
        for axis in range(3):
            assert masks[axis].shape == grid.image_shape(axis)
            assert np.array_equal(masks[axis], own[axis])
    assert not np.array_equal(together[0][0], together[1][0])


def test_auto_makes_no_gl_context_where_no_gpu_device_exists(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def refuse(purpose: str, require: int = 330) -> None:
        raise AssertionError("auto made a GL context on a machine with no GPU device")

    backends = sys.modules["lodconvert.bake"]  # the package, not lodconvert.bake()
    monkeypatch.setattr(backends, "GPU_DEVICES", ("/nonexistent/renderD*",))
    monkeypatch.setattr(gl, "create_context", refuse)
    assert not backends.gpu_device_present()
    assert get_backend("auto").name == "numpy"
