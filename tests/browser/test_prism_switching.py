"""X_ITE switches prism-written levels on boxes, not spheres: with an elongated building, two
viewpoints at the same distance from its centre, one off its long side and one off its short
end, show different levels, as its boxes predict (its LOD ranges would show one level at both).
Moving far away reaches the coarsest level, moving in the finest; a viewer already inside the
boxes when the file loads (at the file's Viewpoint) gets the finest level, one outside keeps the
coarsest. Levels are read from the Switches' ``whichChoice`` through X_ITE's scripting API
(tests/browser/prism.mjs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from lxml import etree

from lodconvert.io import OutputInfo
from lodconvert.io.x3d import prism_boxes, write_x3d
from lodconvert.model import Level, LodChain, Surface
from lodconvert.ranges import cutoffs

from .conftest import Drive, Driver

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BUILDING = (60.0, 10.0, 10.0)
"""A 60 m × 10 m × 10 m building, long along x."""
BETA, GAMMA = 0.5, 2.0
"""Ranges Y = α·β·γˣ of 39, 49 and 62 m, comparable to the building, so its shape shows."""
LEVELS = ("LOD4", "LOD3", "LOD2", "LOD1")
DISTANCE = 60.0
"""From the building's centre, off its long side and off its short end."""


def _building(object_id: str, origin: tuple[float, float, float], beta: float = BETA) -> LodChain:
    """A city-like chain of the building: four levels (the same box) switching at Y(0.33),
    Y(0.66) and Y(1.0) (with ``beta``), placed at ``origin``."""
    box = trimesh.creation.box(extents=BUILDING)
    surface = Surface(np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces))
    alpha = float(np.linalg.norm(BUILDING))
    xs = [0.33, 0.66, 1.0]
    return LodChain(
        object_id=object_id,
        levels=[Level(name, "source", mesh=surface) for name in LEVELS],
        cutoffs=cutoffs(alpha, beta, GAMMA, xs),
        origin=np.asarray(origin, dtype=np.float64),
        center=np.zeros(3),
        alpha=alpha,
        beta=beta,
        gamma=GAMMA,
        xs=xs,
    )


def _box_level(chain: LodChain, position: tuple[float, float, float]) -> int:
    """The level prism switching shows a viewer at ``position`` (world): that of the first box
    holding it, the coarsest outside every box."""
    local = np.asarray(position) - chain.origin
    boxes = prism_boxes(chain)
    inside = [k for k, (centre, size) in enumerate(boxes) if np.all(abs(local - centre) < size / 2)]
    return inside[0] if inside else len(boxes)


def _sphere_level(chain: LodChain, position: tuple[float, float, float]) -> int:
    """The level an X3D LOD with the chain's ranges shows a viewer at ``position``."""
    distance = float(np.linalg.norm(np.asarray(position) - chain.origin - chain.center))
    return sum(cutoff <= distance for cutoff in chain.cutoffs)


@pytest.fixture(scope="module")
def block(site: Path) -> tuple[str, list[LodChain], tuple[float, ...]]:
    """The building at the origin, again 2 km away, and at the origin with ranges of kilometres
    (the file's Viewpoint, framing the scene from a few kilometres, lies inside the boxes of
    the last alone), written with prism switching into the test site."""
    chains = [
        _building("near", (0.0, 0.0, 0.0)),
        _building("far", (2000.0, 0.0, 0.0)),
        _building("wide", (0.0, 0.0, 0.0), beta=100 * BETA),
    ]
    name = "prism_block.x3d"
    with (site / name).open("wb") as handle:
        write_x3d(chains, handle, OutputInfo("lodconvert tests", "building"), switching="prism")
    viewpoint = etree.parse(str(site / name)).getroot().find("Scene/Viewpoint")
    start = tuple(float(v) for v in viewpoint.get("position").split())
    return name, chains, start  # start: where X_ITE puts the viewer, the file's Viewpoint


@pytest.fixture(scope="module")
def prism(driver: Driver) -> Drive:
    """Run prism.mjs (no scenario on its command line)."""
    return driver("prism.mjs")


def test_x_ite_switches_levels_on_boxes(
    block: tuple[str, list[LodChain], tuple[float, ...]], prism: Drive, measure
) -> None:
    name, chains, start = block
    near = chains[0]
    side, end = (0.0, 0.0, DISTANCE), (DISTANCE, 0.0, 0.0)
    # the premise: spheres give both viewpoints one level, boxes two
    assert _sphere_level(near, side) == _sphere_level(near, end)
    assert _box_level(near, side) != _box_level(near, end)
    far_away, close = (0.0, 0.0, 400.0), (0.0, 0.0, 20.0)
    places = [start, side, end, far_away, close, (0.0, 0.0, 48.0), side]
    expected = [[_box_level(chain, place) for chain in chains] for place in places]
    stops = [{"expected": expected[0]}]  # the viewer X_ITE starts with, before any move
    stops += [{"position": p, "expected": e} for p, e in zip(places[1:], expected[1:], strict=True)]
    objects = [{"base": chain.object_id, "switches": len(chain.cutoffs)} for chain in chains]
    seen = prism(file=name, objects=objects, stops=stops)["result"]["stops"]
    levels = [[obj["level"] for obj in stop] for stop in seen]
    message = f"expected {expected}, saw {seen}"
    assert levels == expected, message
    coarsest, finest = len(LEVELS) - 1, 0
    assert levels[0] == [coarsest, coarsest, finest], message  # at load: inside wide's boxes
    assert levels[3][0] == coarsest and levels[4][0] == finest, message
    assert levels[1][0] != levels[2][0], message
    measure(
        f"X_ITE prism switching {DISTANCE:g} m from a {BUILDING[0]:g} m × {BUILDING[1]:g} m "
        "building's centre",
        f"off its long side {LEVELS[levels[1][0]]}, off its short end {LEVELS[levels[2][0]]}",
    )
