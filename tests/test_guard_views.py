"""The guard that judges a city object's derived levels (a LOD1 prism, a cell's far level) over
the upper hemisphere (:mod:`lodconvert.views`), as a viewer sees a city from the street to high
above it: a level that looks right along the axes but not from above the horizon is dropped,
and the F it states is the F a GL render of those views gives."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend, spans
from lodconvert.chain import ChainOptions
from lodconvert.city.prisms import LOW_F, prism
from lodconvert.errors import LodConvertError
from lodconvert.model import Mesh, Node
from lodconvert.plan import GUARD_MARGIN, view_estimate
from lodconvert.plans import bake_chain
from lodconvert.ranges import REFERENCE_VIEW
from lodconvert.views import GUARD_BASES, guard_views, towards_camera, view_basis

from .conftest import require
from .test_plan import gabled_house
from .test_prisms import house_of


def diagonal_house() -> Mesh:
    """A 20 m high wall 6 m thick along the diagonal of a 20 m square, and a 5 m high hall
    filling the triangle on one side of it: half its roof stands at 20 m, so its prism is a
    20 m block over both. Seen along x or y the wall stands in every column, and from above the
    block covers what they cover: only a camera at 45° to the axes sees the wall end on and the
    block spill far beyond it."""
    from shapely.geometry import Polygon

    wall = Polygon([(-2.1, 2.1), (2.1, -2.1), (22.1, 17.9), (17.9, 22.1)])
    hall = Polygon([(2.0, 0.0), (20.0, 0.0), (20.0, 18.0)])
    return Mesh(
        [
            house_of(trimesh.creation.extrude_polygon(p, h)).single
            for p, h in ((wall, 20.0), (hall, 5.0))
        ]
    )


def _view_f(source: Mesh, level: Mesh, distance: float, basis: np.ndarray) -> float:
    """Silhouette F of ``level`` against ``source`` in one view (``basis``)."""
    ((wanted, drawn, both),) = spans.overlap_counts(
        source.vertices,
        source.faces.astype(np.int64),
        level.vertices,
        level.faces.astype(np.int64),
        0.0,
        basis[None],
        distance,
        REFERENCE_VIEW.focal_px,
    )
    return 2 * both / (wanted + drawn)


def test_a_prism_that_looks_right_along_the_axes_but_not_from_45_degrees_is_dropped() -> None:
    house = diagonal_house()
    shape = prism({"lod2": house}, house, {})
    assert shape is not None and shape.bounds[1, 2] == pytest.approx(20.0)
    distance = 400.0
    along_axes = [view_basis(0, 0), view_basis(90, 0), view_basis(0, 90)]
    assert min(_view_f(house, shape, distance, b) for b in along_axes) > 0.95
    assert _view_f(house, shape, distance, view_basis(45, 0)) < 0.95
    assert _view_f(house, shape, distance, view_basis(45, 30)) < 0.95

    chain = bake_chain(
        Node("c", house, "Building", lods={"lod2": house}), ChainOptions(), NumpyBackend()
    )
    assert [lv.name for lv in chain.levels] == ["LOD2"]
    assert chain.dropped["LOD1"].startswith(LOW_F) and "below 0.95" in chain.dropped["LOD1"]


def test_the_guard_judges_the_worst_of_its_views() -> None:
    """The estimate is the view with the least F: a gabled house's prism at its eaves-high box
    loses most from the side that shows the gable."""
    house = house_of(gabled_house(10, 8, 6, 10))
    eaves_box = house_of(gabled_house(10, 8, 6, 6.001))
    estimate = view_estimate(house, eaves_box, 300.0)
    each = [_view_f(house, eaves_box, 300.0, view_basis(a, e)) for a, e in guard_views()]
    assert estimate.f == pytest.approx(min(each))
    assert len(guard_views()) == 24


@pytest.mark.gl
def test_the_stated_f_is_the_f_a_render_of_the_views_gives() -> None:
    """Rendered with GL in perspective (1080 px tall, 45° field of view) from the guard's 24
    views at the distances where prisms switch in, the worst view's F is the one the guard
    states, within 0.005."""
    from lodconvert.analysis.silhouette import SilhouetteRenderer

    try:
        renderer = SilhouetteRenderer(1080)
    except LodConvertError as exc:
        require(False, str(exc), env="LODCONVERT_REQUIRE_GL")
    directions = np.stack([towards_camera(a, e) for a, e in guard_views()])
    cases = [
        (house_of(gabled_house(10, 8, 6, 10)), 9.6),
        (house_of(gabled_house(14, 9, 7, 12)), 11.0),
        (diagonal_house(), 20.0),
    ]
    try:
        for source, top in cases:
            level = prism({"lod2": source}, source, {"measuredHeight": top})
            assert level is not None
            for distance in (200.0, 400.0):
                rendered = renderer.least_f(source, level, distance, directions)
                stated = view_estimate(source, level, distance).f
                assert abs(stated - rendered) <= 0.005, (distance, stated, rendered)
    finally:
        renderer.release()


def test_a_candidate_below_what_it_must_beat_stops_at_its_first_view_below_it() -> None:
    """A cell's candidate that neither reaches the F asked for nor beats the best so far is
    drawn only up to its first view below that F: its F is then some F below it (never above
    the F of every view), and one at or above it is the F of all 24 views."""
    house = house_of(gabled_house(10, 8, 6, 10))
    eaves_box = house_of(gabled_house(10, 8, 6, 6.001))
    exact = view_estimate(house, eaves_box, 300.0, keep=True).f
    assert view_estimate(house, eaves_box, 300.0, keep=True, stop_below=exact - 0.01).f == exact
    stopped = view_estimate(house, eaves_box, 300.0, keep=True, stop_below=exact + 0.01).f
    assert exact <= stopped < exact + 0.01

    frames, bits = spans.silhouettes(
        house.vertices, house.faces.astype(np.int64), GUARD_BASES, 300.0,
        REFERENCE_VIEW.focal_px, GUARD_MARGIN,
    )  # fmt: skip
    args = (eaves_box.vertices, eaves_box.faces.astype(np.int64), 0.0, GUARD_BASES, 300.0)
    every = spans.counts_against(frames, bits, *args, REFERENCE_VIEW.focal_px, 0.0)
    assert (every >= 0).all()
    each = 2 * every[:, 2] / (every[:, 0] + every[:, 1])
    first_below = int(np.argmax(each < exact + 0.01))
    cut = spans.counts_against(frames, bits, *args, REFERENCE_VIEW.focal_px, exact + 0.01)
    assert (cut[: first_below + 1] == every[: first_below + 1]).all()
    assert (cut[first_below + 1 :, 0] == -2).all() and first_below + 1 < len(GUARD_BASES)
