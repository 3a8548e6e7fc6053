"""A city glb stands upright in a plain three.js page (GLTFLoader, no lodconvert code): glTF is
+Y up, so the district's world bounding box is as high as its buildings along +Y, and a camera
straight above it sees roofs. A city X3D starts in X_ITE at its own Viewpoint, the district in
view, and its prism switching, inside the turned frame, follows each building's boxes in the
source CRS."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lodconvert import convert
from lodconvert.io import read_chains
from lodconvert.io.frame import ROTATION
from lodconvert.io.x3d import prism_boxes, read_frame
from lodconvert.viewer import LIBRARIES, write_page
from lodconvert.viewer.config import page_config

from ..conftest import SHARED
from .conftest import Drive, Driver, console_text
from .test_viewers import _errors

pytestmark = [pytest.mark.browser, pytest.mark.slow]

TUM = SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip"


def _tum(site: Path, suffix: str, **options: Any) -> str:
    """TUM Munich (EPSG:31468, LoD2 roofs, walls and ground) converted into the test site."""
    if not TUM.exists():
        pytest.skip(f"{TUM} is absent (shared test data not checked out)")
    name = f"upright_tum{'_'.join(['', *options.values()])}{suffix}"
    convert(TUM, site / name, backend="numpy", write_options=options or None)
    return name


@pytest.fixture(scope="module")
def tum_glb(site: Path) -> str:
    return _tum(site, ".glb")


def test_three_shows_a_city_glb_upright_with_its_roofs_on_top(
    tum_glb: str, drive: Drive, measure
) -> None:
    out = drive("three_upright", file=tum_glb)
    seen = out["result"]
    message = f"{seen}\n{console_text(out)}"
    size = np.subtract(seen["max"], seen["min"])
    # Up (+Y) spans the buildings' heights (tens of metres), the ground plane the district's
    # hundreds; every value stays small enough for float32 (no millions in the world box).
    assert size[1] < 100.0 < min(size[0], size[2]), message
    assert np.abs([*seen["min"], *seen["max"]]).max() < 1e5, message
    # From above, the district fills much of the view, and mostly with roof red.
    assert seen["drawn"] > 0.1 * seen["pixels"], message
    assert seen["red"] > 0.5 * seen["drawn"], message
    assert not _errors(out), message
    measure(
        "three.js, TUM Munich glb from above",
        f"world box {size[0]:.0f} × {size[1]:.0f} (up) × {size[2]:.0f} m; "
        f"{seen['drawn'] / seen['pixels']:.0%} of the view drawn, "
        f"{seen['red'] / seen['drawn']:.0%} of it roof red",
    )


def test_x_ite_starts_with_the_district_in_view(site: Path, drive: Drive, measure) -> None:
    """No "view all" needed: X_ITE binds the file's Viewpoint at load and draws the district
    (before, with no Viewpoint, it started at (0, 0, 10), 4.5 million metres from TUM's
    buildings: black). test_scene_frame checks that every building lies in its view."""
    out = drive("x_ite", file=_tum(site, ".x3d"), start=True)
    start = out["result"]["start"]
    message = f"{start}\n{console_text(out)}"
    assert start["foreground"] > 0.05 * 400 * 300, message  # the test page's canvas
    assert not _errors(out), message
    measure("X_ITE, TUM Munich x3d at its Viewpoint", f"{start['foreground']} pixels drawn")


def test_prism_switching_in_the_frame_follows_the_buildings_boxes(
    site: Path, driver: Driver
) -> None:
    """The viewer page over TUM Munich with prism switching, 120, 300 and 700 m from the
    district's middle (from the south, above the horizon): every building shows the level of
    the first of its boxes, computed in the source CRS, that holds the viewer."""
    name = _tum(site, ".x3d", switching="prism")
    path = site / name
    write_page(path, library=str(site / "node_modules" / LIBRARIES["x3d"].package))
    config, frame = page_config(path), read_frame(path)
    assert frame is not None
    centres = np.array([o["center"] for o in config["objects"]])
    middle = (centres.min(axis=0) + centres.max(axis=0)) / 2
    distances = [120.0, 300.0, 700.0]
    stops = [{"distance": d} for d in distances]
    out = driver("drive.mjs")("viewer", page=f"{name}.html", stops=stops)
    chains = read_chains(path)
    levels_seen = set()
    for distance, stop in zip(distances, out["result"]["stops"], strict=True):
        viewer = middle + distance * np.asarray(config["view"]["direction"])
        source = frame.origin + ROTATION.T @ viewer
        for chain, seen in zip(chains, stop["objects"], strict=True):
            local = source - chain.origin
            boxes = prism_boxes(chain)
            inside = [k for k, (c, size) in enumerate(boxes) if np.all(abs(local - c) < size / 2)]
            expected = inside[0] if inside else len(boxes)
            assert seen["levelIndex"] == expected, (distance, chain.object_id, seen)
            levels_seen.add(expected)
    assert levels_seen == {0, 1}, levels_seen  # near and far buildings at each stop
    assert not _errors(out), console_text(out)
