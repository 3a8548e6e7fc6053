"""The GL backend (FBO slab rendering through EGL) against the numpy backend.

Both must give the same occupied cells, and the same depth wherever both hit the same
(direction, slab, pixel). Skipped when no EGL context can be made, unless
``LODCONVERT_REQUIRE_GL=1`` (as CI sets after installing Mesa), which turns the skip into a
failure.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator

import numpy as np
import pytest
import trimesh

from lodconvert.bake import SOFTWARE_RENDERERS, NumpyBackend, bake_points, get_backend
from lodconvert.bake.gl import GLBackend, gl_unavailable_reason
from lodconvert.bake.grid import Grid, SlabHits
from lodconvert.bake.pcd import occupied_hits
from lodconvert.errors import LodConvertError
from lodconvert.model import BakeParams, Surface

from .conftest import require

pytestmark = pytest.mark.gl

RESOLUTIONS = (64, 128)


@pytest.fixture(scope="module", autouse=True)
def _needs_gl() -> None:
    reason = gl_unavailable_reason()
    require(reason is None, str(reason), env="LODCONVERT_REQUIRE_GL")


@pytest.fixture(scope="module")
def gl() -> Iterator[GLBackend]:
    backend = GLBackend()
    yield backend
    backend.release()


def centred(mesh: trimesh.Trimesh) -> Surface:
    """A Surface of ``mesh`` with vertices relative to its bounding-box centre."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    return Surface(v - (v.min(axis=0) + v.max(axis=0)) / 2, np.asarray(mesh.faces, np.int64))


@pytest.fixture(scope="module")
def torus_surface() -> Surface:
    return centred(trimesh.creation.torus(major_radius=1.0, minor_radius=0.3))


@pytest.fixture(scope="module")
def bunny_surface(bunny_mesh: trimesh.Trimesh) -> Surface:
    return centred(bunny_mesh)


@pytest.fixture(params=["torus", "bunny"])
def surface(request: pytest.FixtureRequest) -> Surface:
    return request.getfixturevalue(f"{request.param}_surface")


def params(resolution: int) -> BakeParams:
    """Level parameters with as many slices as cells and no hole filling."""
    return BakeParams(resolution=resolution, slices=resolution, point_size=2.0, filter="none")


def jaccard(a: np.ndarray, b: np.ndarray) -> float:
    """|A ∩ B| / |A ∪ B| of two sets of keys."""
    a, b = np.unique(a), np.unique(b)
    return len(np.intersect1d(a, b)) / len(np.union1d(a, b))


def matched(a: SlabHits, b: SlabHits, grid: Grid) -> tuple[np.ndarray, np.ndarray, int]:
    """Indices of the hits of ``a`` and ``b`` (same direction) at the same (slab, pixel), and
    the size of the union of their (slab, pixel) sets."""
    assert (a.axis, a.sign) == (b.axis, b.sign)
    rows, cols = grid.image_shape(a.axis)
    ka = (a.slab * rows + a.iv) * cols + a.iu
    kb = (b.slab * rows + b.iv) * cols + b.iu
    _, ia, ib = np.intersect1d(ka, kb, assume_unique=True, return_indices=True)
    return ia, ib, len(np.union1d(ka, kb))


def by_direction(hits: list[SlabHits]) -> list[SlabHits]:
    """The 6 directions in a fixed order (+x, -x, +y, -y, +z, -z)."""
    return sorted(hits, key=lambda h: (h.axis, -h.sign))


@pytest.mark.parametrize("resolution", RESOLUTIONS)
def test_gl_and_numpy_occupy_the_same_cells(
    surface: Surface, gl: GLBackend, resolution: int
) -> None:
    cells = {}
    for backend in (NumpyBackend(), gl):
        grid, positions, _ = occupied_hits(surface, params(resolution), backend)
        cloud, _ = bake_points(surface, params(resolution), backend)
        cells[backend.name] = (grid.cell_keys(positions), grid.cell_keys(cloud.positions))
    assert len(cells["gl"][0]) > 1000
    assert jaccard(cells["gl"][0], cells["numpy"][0]) >= 0.999
    assert jaccard(cells["gl"][1], cells["numpy"][1]) >= 0.999


@pytest.mark.parametrize("resolution", RESOLUTIONS)
def test_gl_and_numpy_hits_have_the_same_depths(
    surface: Surface, gl: GLBackend, resolution: int
) -> None:
    grid = Grid.for_bounds(surface.bounds, resolution, resolution)
    tolerance = 1e-4 * grid.pitch * max(grid.cells)
    reference = by_direction(NumpyBackend().rasterize(surface, grid))
    result = by_direction(gl.rasterize(surface, grid))
    assert [(h.axis, h.sign) for h in result] == [(h.axis, h.sign) for h in reference]
    same_face_error, error, same_face, union = [], [], [], 0
    for a, b in zip(reference, result, strict=True):
        ia, ib, n = matched(a, b, grid)
        union += n
        err = np.abs(a.depth[ia] - b.depth[ib])
        same = a.face[ia] == b.face[ib]
        error.append(err)
        same_face.append(same)
        same_face_error.append(err[same])
    error = np.concatenate(error)
    # The same (slab, pixel) is hit by both backends, nearly always on the same face (a pixel
    # centre on an edge or corner is covered by one face in GL, by all of them in numpy)...
    assert len(error) >= 0.995 * union
    assert np.concatenate(same_face).mean() >= 0.98
    # ... with the same depth on the same face; where a pixel centre lies on the edge between
    # two faces seen almost edge-on, the rasteriser's vertex snapping may pick the other face.
    assert np.concatenate(same_face_error).max() <= tolerance
    assert np.mean(error <= tolerance) >= 0.999


@pytest.mark.parametrize("scale", [1.0, 0.8])
def test_surfaces_on_or_beyond_the_outer_slabs_are_hit(gl: GLBackend, scale: float) -> None:
    """A box's faces lie on the grid's bounds (scale 1) or beyond them (scale 0.8): the first
    and last slabs take them in, as numpy clamps depths into the slab range."""
    box = trimesh.creation.box(extents=(1.0, 0.7, 0.4))
    surface = Surface(np.asarray(box.vertices, np.float64), np.asarray(box.faces, np.int64))
    grid = Grid.for_bounds(surface.bounds * scale, 16, 16)
    reference = by_direction(NumpyBackend().rasterize(surface, grid))
    result = by_direction(gl.rasterize(surface, grid))
    for a, b in zip(reference, result, strict=True):
        ia, ib, union = matched(a, b, grid)
        assert len(ia) == len(a) == len(b) == union > 0
        np.testing.assert_allclose(b.depth[ib], a.depth[ia], rtol=0, atol=1e-6)


@pytest.fixture(scope="module")
def gl_listing() -> Iterator[GLBackend]:
    """A GL backend that lists covered pixels with a compute shader (OpenGL 4.3)."""
    import moderngl

    try:
        backend = GLBackend(compact=True)
    except moderngl.Error as exc:
        pytest.skip(f"no OpenGL 4.3 compute shaders: {exc}")
    yield backend
    backend.release()


def test_listing_and_scanning_give_the_same_hits(
    gl_listing: GLBackend, torus_surface: Surface
) -> None:
    grid = Grid.for_bounds(torus_surface.bounds, 64, 64)
    scanning = GLBackend(compact=False)
    try:
        expected = scanning.rasterize(torus_surface, grid)
    finally:
        scanning.release()
    for a, b in zip(expected, gl_listing.rasterize(torus_surface, grid), strict=True):
        assert (a.axis, a.sign) == (b.axis, b.sign)
        for field in ("slab", "iu", "iv", "depth", "face"):
            np.testing.assert_array_equal(getattr(b, field), getattr(a, field))


@pytest.mark.parametrize("listing", [False, True])
def test_a_flat_square_covers_its_whole_image(
    request: pytest.FixtureRequest, listing: bool
) -> None:
    """Every pixel of the one slab is covered (more than the covered-pixel list first holds)."""
    gl = request.getfixturevalue("gl_listing" if listing else "gl")
    square = Surface(
        np.array([[0.0, 0, 0.25], [1, 0, 0.25], [1, 1, 0.25], [0, 1, 0.25]]),
        np.array([[0, 1, 2], [0, 2, 3]]),
    )
    grid = Grid.for_bounds(square.bounds, 64, 64)
    hits = {(h.axis, h.sign): h for h in gl.rasterize(square, grid)}
    for sign in (1, -1):
        h = hits[(2, sign)]
        assert len(h) == 64 * 64
        assert len(np.unique(h.iv * 64 + h.iu)) == 64 * 64
        np.testing.assert_array_equal(h.slab, 0)
        np.testing.assert_allclose(h.depth, 0.25, rtol=0, atol=1e-7)
    assert sum(len(hits[(a, s)]) for a in (0, 1) for s in (1, -1)) == 0


def test_faces_covering_no_pixel_centre_give_no_hits(gl: GLBackend) -> None:
    corner = Surface(np.array([[0.0, 0, 0.5], [0.2, 0, 0.5], [0, 0.2, 0.5]]), np.array([[0, 1, 2]]))
    grid = Grid.for_bounds(np.array([[0.0, 0, 0], [1, 1, 1]]), 4, 4)
    assert [len(h) for h in gl.rasterize(corner, grid)] == [0] * 6


def test_auto_uses_gl_only_on_a_hardware_renderer(gl: GLBackend) -> None:
    software = any(s in gl.renderer.lower() for s in SOFTWARE_RENDERERS)
    backend = get_backend("auto")
    assert backend.name == ("numpy" if software else "gl")
    if isinstance(backend, GLBackend):
        backend.release()


def test_gl_backend_names_its_renderer() -> None:
    backend = get_backend("gl")
    assert isinstance(backend, GLBackend)
    try:
        assert backend.name == "gl"
        assert backend.renderer.strip()
        assert backend.renderer != NumpyBackend.renderer
    finally:
        backend.release()
    triangle = Surface(np.eye(3), np.array([[0, 1, 2]]))
    with pytest.raises(LodConvertError, match="release"):
        backend.rasterize(triangle, Grid.for_bounds(triangle.bounds, 4, 4))


def test_missing_moderngl_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "moderngl", None)
    with pytest.raises(LodConvertError) as error:
        GLBackend()
    message = str(error.value)
    assert "\n" not in message
    assert "pip install moderngl" in message


def test_failed_context_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    import moderngl

    def fail(**_: object) -> None:
        raise RuntimeError("eglInitialize failed\n(no display)")

    monkeypatch.setattr(moderngl, "create_standalone_context", fail)
    with pytest.raises(LodConvertError) as error:
        GLBackend()
    message = str(error.value)
    assert "\n" not in message
    assert "eglInitialize failed (no display)" in message
    assert "apt-get install -y --no-install-recommends libegl1 libgl1 libgl1-mesa-dri" in message
