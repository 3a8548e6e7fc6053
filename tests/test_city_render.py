"""Walks and flights through a city: range against prism switching, the line-of-sight LOD
scale, LOD parents replacing their members, and the per-frame counts (GL only where marked)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator

import numpy as np
import pytest

from lodconvert.analysis.city_cameras import (
    Camera,
    flight_cameras,
    forward_vector,
    random_walks,
    walk_cameras,
)
from lodconvert.analysis.city_draw import CityDraw, city_draw
from lodconvert.analysis.city_render import CityRenderer, walk
from lodconvert.analysis.city_select import Mode, prism_levels, range_levels, select
from lodconvert.analysis.line_of_sight import (
    REFERENCE_ALTITUDE,
    REFERENCE_FOV_DEG,
    REFERENCE_PITCH_DEG,
    lod_scale,
    los_average,
)
from lodconvert.bake import get_backend
from lodconvert.bakery import iter_chains
from lodconvert.chain import ChainOptions
from lodconvert.city.hlod import HlodOptions
from lodconvert.context import RunContext
from lodconvert.model import CellChain, LodChain, Mesh, Node, Scene, Surface

from .conftest import gl_renderer

LONG_BOX = np.array([[[-15.0, -3.0, 0.0], [15.0, 3.0, 10.0]]])
"""A 30 m × 6 m × 10 m building, its centre at (0, 0, 5)."""
CUTOFFS = np.array([[50.0, 100.0]])


def box_mesh(low: tuple[float, float, float], high: tuple[float, float, float]) -> Mesh:
    """A closed box as one part."""
    corners = np.array([[i & 1, i >> 1 & 1, i >> 2 & 1] for i in range(8)], dtype=float)
    vertices = np.asarray(low) + corners * (np.asarray(high) - np.asarray(low))
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return Mesh([Surface(vertices, faces)])


def town(side: int, spacing: float = 20.0) -> Scene:
    """``side``² LoD2 box buildings (10 m wide, 8–14 m tall) on a square lattice."""
    nodes = []
    for k in range(side * side):
        row, column = divmod(k, side)
        x, y = column * spacing, row * spacing
        mesh = box_mesh((x, y, 0.0), (x + 10.0, y + 10.0, 8.0 + 2.0 * (k % 4)))
        nodes.append(Node(f"b{k}", geometry=mesh, type="Building", lods={"lod2": mesh}))
    return Scene("town", nodes)


def baked(
    scene: Scene, sizes: tuple[float, ...] | None, gamma: float | None = None
) -> list[LodChain | CellChain]:
    """The scene's chains (γ = ``gamma`` for all when given), grouped in LOD parents of
    ``sizes`` (merged-mesh far levels)."""
    hlod = HlodOptions(sizes, "mesh") if sizes is not None else None
    return list(
        iter_chains(
            scene, ChainOptions(gamma=gamma), RunContext.here(get_backend("numpy")), hlod=hlod
        )
    )


@pytest.fixture(scope="module")
def block() -> CityDraw:
    """A 3×3 town in one 250 m LOD parent (small plots: every building reaches its prism
    before the cell's switch, so the cell admits all nine)."""
    return city_draw(baked(town(3), (250.0,), gamma=2.0))


def looking_at(city: CityDraw, distance: float) -> Camera:
    """A camera ``distance`` from the first cell's centre, 30° up, looking at it."""
    centre = city.cell_centres[0]
    direction = np.array([0.0, -math.cos(math.radians(30)), math.sin(math.radians(30))])
    return Camera(centre + distance * direction, -direction)


# --- level selection ----------------------------------------------------------------------------


def distance(eye: np.ndarray) -> np.ndarray:
    """The viewer's distance (1,) to the long box's centre."""
    return np.array([np.linalg.norm(eye - LONG_BOX.mean(axis=1)[0])])


def test_prisms_tell_a_long_side_from_a_short_end_that_ranges_do_not() -> None:
    side = np.array([0.0, 60.0, 5.0])  # 60 m from the centre, off the 30 m long side
    end = np.array([60.0, 0.0, 5.0])  # 60 m from the centre, off the 6 m short end
    ranges = [range_levels(distance(eye), CUTOFFS)[0] for eye in (side, end)]
    prisms = [prism_levels(eye, LONG_BOX, CUTOFFS)[0] for eye in (side, end)]
    assert ranges == [1, 1]
    assert prisms == [1, 0]  # off the end, the box grown by 50 m still holds the viewer


def test_prisms_never_pick_a_coarser_level_than_ranges() -> None:
    rng = np.random.default_rng(3)
    eyes = rng.uniform(-300.0, 300.0, (500, 3))
    for eye in eyes:
        by_range = range_levels(distance(eye), CUTOFFS)[0]
        assert prism_levels(eye, LONG_BOX, CUTOFFS)[0] <= by_range


def test_levels_count_the_cutoffs_reached_and_ignore_padding() -> None:
    cutoffs = np.array([[10.0, 20.0, math.inf], [5.0, math.inf, math.inf]])
    np.testing.assert_array_equal(range_levels(np.array([20.0, 99.0]), cutoffs), [2, 1])


# --- line-of-sight LOD scale --------------------------------------------------------------------


def test_lod_scale_is_one_at_its_reference() -> None:
    scale = lod_scale(REFERENCE_ALTITUDE, REFERENCE_PITCH_DEG, REFERENCE_FOV_DEG)
    assert scale == pytest.approx(1.0, rel=1e-12)


def test_lod_scale_grows_with_altitude() -> None:
    altitudes = [5.0, 50.0, 100.0, 300.0, 600.0, 1200.0, 5000.0]
    for pitch in (20.0, 45.0, 90.0):
        scales = [lod_scale(h, pitch) for h in altitudes]
        assert all(b > a for a, b in itertools.pairwise(scales)), (pitch, scales)


@pytest.mark.parametrize(("altitude", "pitch"), [(300.0, 45.0), (50.0, 10.0), (800.0, 80.0)])
def test_los_average_is_the_mean_ray_length_over_the_field_of_view(
    altitude: float, pitch: float
) -> None:
    fov, cap = 45.0, 20_000.0
    phi = np.radians(np.linspace(pitch - fov / 2, pitch + fov / 2, 200_001))
    with np.errstate(divide="ignore"):
        length = np.where(phi > 0, altitude / np.sin(phi), cap)
    expected = np.minimum(length, cap).mean()
    assert los_average(altitude, pitch, fov, cap) == pytest.approx(expected, rel=1e-4)


def test_los_average_refuses_what_has_no_ground_distance() -> None:
    with pytest.raises(ValueError, match="positive altitude"):
        los_average(0.0, 45.0)
    with pytest.raises(ValueError, match="behind"):
        los_average(100.0, 170.0)


# --- cameras ------------------------------------------------------------------------------------


def test_walks_stay_in_their_area_and_step_one_frame_of_travel_apart() -> None:
    area = np.array([[0.0, 0.0], [600.0, 600.0]])
    walks = random_walks(np.random.default_rng(1), area, 5, 400.0, 50.0, ground=-3.0)
    for start, end in walks:
        assert np.linalg.norm(end - start) == pytest.approx(400.0)
        assert np.all(start[:2] >= 0) and np.all(end[:2] <= 600.0)
        assert start[2] == end[2] == 47.0
    cameras = walk_cameras(*walks[0], speed=20.0, frame_step=1 / 30, pitch_deg=15.0, fov_y_deg=75)
    assert len(cameras) == 601
    steps = np.linalg.norm(np.diff([c.eye for c in cameras], axis=0), axis=1)
    np.testing.assert_allclose(steps, 20.0 / 30.0)
    assert cameras[0].forward[2] == pytest.approx(-math.sin(math.radians(15.0)))


def test_a_flight_keeps_its_altitude_and_sweeps_the_area_with_its_view_centre() -> None:
    area = np.array([[0.0, 0.0], [1000.0, 400.0]])
    cameras = flight_cameras(area, 300.0, 45.0, 5, 45.0, ground=10.0)
    hits = [c.eye + c.forward * (c.eye[2] - 10.0) / -c.forward[2] for c in cameras]
    np.testing.assert_allclose([h[0] for h in hits], [0, 250, 500, 750, 1000], atol=1e-9)
    assert all(c.eye[2] == 310.0 and c.eye[1] == 200.0 for c in cameras)
    np.testing.assert_allclose(forward_vector(np.array([0.0, 2.0]), 0.0), [0, 1, 0])


# --- LOD parents --------------------------------------------------------------------------------


def test_a_cell_beyond_its_switch_draws_one_call_instead_of_its_members(block: CityDraw) -> None:
    switch = float(block.cell_cutoffs[0, 0])
    far, near = looking_at(block, 1.5 * switch), looking_at(block, 150.0)
    parent, lod = Mode("parent", tiers=1), Mode("lod")
    beyond = select(block, far, parent)
    assert beyond.calls == 1 and beyond.far_cells.tolist() == [0]
    assert select(block, far, lod).calls == 9  # nine prisms, one part each
    assert select(block, near, parent).calls == select(block, near, lod).calls == 9
    assert len(select(block, near, parent).far_cells) == 0


def test_a_cell_behind_the_camera_is_culled_whole(block: CityDraw) -> None:
    camera = looking_at(block, 1.5 * float(block.cell_cutoffs[0, 0]))
    behind = Camera(camera.eye, -camera.forward)
    assert select(block, behind, Mode("parent", tiers=1)).calls == 0
    assert select(block, behind, Mode("no culling", culling=False, tiers=1)).calls == 1


def test_the_lod_scale_moves_every_switch(block: CityDraw) -> None:
    camera = looking_at(block, 1.5 * float(block.cell_cutoffs[0, 0]))
    scaled = Mode("scaled", tiers=1, los_scale=True)
    assert select(block, camera, scaled, scale=1.0).calls == 1
    assert select(block, camera, scaled, scale=2.0).calls == 9  # cells and buildings finer


def test_one_tier_cells_are_the_two_tier_bakes_finest_cells() -> None:
    scene = town(6)
    # the cells gathering what no cell admits are the coarsest tier's: not among a finer one's
    one = [
        c
        for c in baked(scene, (50.0,))
        if isinstance(c, CellChain) and not c.cell_id.endswith("_beside")
    ]
    two = [c for c in baked(town(6), (50.0, 200.0)) if isinstance(c, CellChain)]
    finest = sorted((c for top in two for c in top.cells() if c.tier == 1), key=lambda c: c.cell_id)
    assert len(one) > 1
    assert [c.cell_id for c in sorted(one, key=lambda c: c.cell_id)] == [c.cell_id for c in finest]
    for a, b in zip(sorted(one, key=lambda c: c.cell_id), finest, strict=True):
        assert a.cutoffs == pytest.approx(b.cutoffs)
        assert a.far.count == b.far.count and a.facts["kind"] == b.facts["kind"]


# --- a whole flight, counted --------------------------------------------------------------------


def test_a_flight_counts_what_each_mode_submits_without_gl() -> None:
    city = city_draw(baked(town(5), (50.0, 100.0)))
    modes = [
        Mode("no LOD", culling=False, lod=False),
        Mode("culling", lod=False),
        Mode("lod"),
        Mode("prism", switching="prism"),
        Mode("parent", tiers=2),
    ]
    cameras = flight_cameras(city.bounds[:, :2], 300.0, 45.0, 6, 45.0, city.bounds[0, 2])
    stats = walk(city, cameras, modes, scale=1.0)
    finest = int(city.geometry.size[city.level_first[:, 0]].sum())
    assert stats["no LOD"].vertices == [finest] * 6
    assert stats["no LOD"].calls == [city.objects] * 6
    for a, b in (("culling", "no LOD"), ("lod", "culling"), ("lod", "prism")):
        assert all(x <= y for x, y in zip(stats[a].vertices, stats[b].vertices, strict=True))
    assert all(p <= q for p, q in zip(stats["parent"].calls, stats["lod"].calls, strict=True))
    record = stats["lod"].record()
    assert record["frames"] == 6 and record["median_ms"] is None and record["low_ms"] is None


# --- drawing ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def renderer() -> Iterator[CityRenderer]:
    """One renderer; skips (or fails under LODCONVERT_REQUIRE_GL=1) without an EGL context."""
    yield from gl_renderer(CityRenderer)


@pytest.mark.gl
def test_a_drawn_frame_shows_the_selected_parts(block: CityDraw, renderer: CityRenderer) -> None:
    renderer.load(block)
    camera = looking_at(block, 60.0)
    seconds = renderer.draw(select(block, camera, Mode("lod")), camera)
    drawn = (renderer.read_image() != renderer.read_image()[0, 0]).any(axis=2).mean()
    away = Camera(camera.eye, -camera.forward)
    renderer.draw(select(block, away, Mode("lod")), away)
    empty = (renderer.read_image() != renderer.read_image()[0, 0]).any(axis=2).mean()
    assert seconds > 0 and drawn > 0.01 and empty == 0.0
    cameras = [camera, looking_at(block, 5000.0)]
    stats = walk(block, cameras, [Mode("parent", tiers=1)], 1.0, renderer)
    assert len(stats["parent"].frame_seconds) == 2


def test_one_tier_draws_the_objects_only_a_coarser_cell_admitted() -> None:
    city = city_draw(baked(town(4), (50.0, 200.0)))
    # some building no 50 m cell admits (its prism is far out) is held by its 200 m cell
    held = city.object_cell[city.object_cell >= 0]
    assert (city.cell_tier[held] == 2).any()
    camera = looking_at(city, 100.0)
    lod = select(city, camera, Mode("lod", culling=False))
    for tiers in (1, 2):
        near = select(city, camera, Mode("parent", culling=False, tiers=tiers))
        # near every cell, LOD parents draw what per-building LOD draws: every object
        assert near.calls == lod.calls == city.objects
