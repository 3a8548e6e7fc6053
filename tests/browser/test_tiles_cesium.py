"""3D Tiles in CesiumJS (npm ``cesium``, served from 127.0.0.1, headless Chromium, no Ion
token, no imagery, no terrain) through lodconvert's tileset page (``lodconvert view
DIR/tileset.json``), driven by tiles.mjs: TUM Munich in 250 m and 1 km cells loads with no
tile failing; from near, clicking a known building picks its feature in a leaf tile, with the
source's id and attributes, and the inspect panel shows them; a roof shows in its own colour;
from far, the cells show their far levels, not their buildings' tiles. A small city with point
far levels loads and shows them from afar. Without CesiumJS the page says where it failed to
load it. Each camera's tiles selected and bytes requested are recorded (and printed in the
viewer measurements). Every wait is on page state."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from lodconvert.io.gltf.binary import accessor_values as accessor
from lodconvert.io.tiles.check import frame_points, read_glb
from lodconvert.semantics import DEFAULT_CLASS_COLORS
from lodconvert.viewer import write_page

from ..conftest import ROOT, require
from ..test_tiles import convert, features, tiles
from .conftest import REQUIRE, Drive, Driver, console_text
from .test_inspect import EXPOSED, _source_attributes, roof_point

pytestmark = [pytest.mark.browser, pytest.mark.slow]

VIEWPORT = (640, 480)
"""The drivers' view (harness.mjs), CSS pixels."""
CESIUM = "/node_modules/cesium"
"""The npm package as the test site serves it (a URL path: the page lies in the tileset's
folder, the package outside it)."""
NEAR_M = 150.0
"""How far the near camera stands from the clicked roof: the building's block tile (geometric
error about 7 m or more) refines to its leaf within some 250 m in a 480 px high view."""
SSE_DENOMINATOR = 2 * math.tan(math.radians(30)) / (VIEWPORT[0] / VIEWPORT[1])
"""2·tan(fov_y / 2) of CesiumJS's default camera (60° across the wider side) in the test's
view; a tile of geometric error GE refines within GE·height/(sse·this) of the camera."""


@pytest.fixture(scope="module")
def look(driver: Driver) -> Drive:
    """Run tiles.mjs's scenario ``cameras``, once the npm package cesium is known to be there."""
    package = ROOT / "node_modules" / "cesium" / "package.json"
    require(package.exists(), f"{package} is absent (scripts/test.sh installs it)", REQUIRE)
    return driver("tiles.mjs")


def _tileset(site: Path, name: str, *flags: str) -> Path:
    """Sample ``name`` converted into ``site/name_tiles`` with its CesiumJS page."""
    tileset = convert(name, site / f"{name}_tiles", *flags)
    write_page(tileset, library=CESIUM)
    return tileset


@pytest.fixture(scope="module")
def tum(site: Path) -> Path:
    """TUM Munich in 250 m and 1 km cells, in the test site."""
    return _tileset(site, "tum", "--hlod", "250,1000")


def _page(site: Path, tileset: Path) -> str:
    return f"{tileset.parent.relative_to(site)}/tileset.json.html"


def _roof(tileset: Path, gml_id: str) -> tuple[list[float], str]:
    """A point (ECEF) on the roof of building ``gml_id`` in its leaf tile, safe to click (of
    its upward-facing triangles, the centre of the largest inscribed circle), and the tile's
    content URI."""
    root = json.loads(tileset.read_text())["root"]
    for tile, frame, base in tiles(root, np.eye(4), tileset):
        uri = tile.get("content", {}).get("uri", "")
        if not uri.endswith("_finest.glb"):
            continue
        document, blob = read_glb(base.parent / uri)
        ids = [row.get("id") for row in features(document, blob)]
        if gml_id not in ids:
            continue
        (primitive,) = document["meshes"][0]["primitives"]
        attributes = primitive["attributes"]
        ecef = frame_points(frame, accessor(document, blob, attributes["POSITION"]))
        feature = accessor(document, blob, attributes["_FEATURE_ID_0"])
        faces = accessor(document, blob, primitive["indices"]).reshape(-1, 3)
        faces = faces[(feature[faces] == ids.index(gml_id)).all(axis=1)]
        local = (ecef - frame[:3, 3]) @ frame[:3, :3]  # east, north, up at the tile
        centre, _ = roof_point(local[faces])
        return (frame[:3, :3] @ centre + frame[:3, 3]).tolist(), uri
    raise AssertionError(f"no leaf tile of {tileset} holds {gml_id}")


def _far(tileset: Path) -> float:
    """A camera range (from the root box's centre) at which CesiumJS refines the root (no
    content) but none of its children with a far level: the geometric mean of the two switch
    distances in the test's view, from the nearest side of the root's box (CesiumJS measures
    to a tile's volume)."""
    root = json.loads(tileset.read_text())["root"]
    cells = [c for c in root["children"] if "_beside" not in c["content"]["uri"]]
    mean = math.sqrt(root["geometricError"] * max(c["geometricError"] for c in cells))
    half_axes = np.asarray(root["boundingVolume"]["box"][3:]).reshape(3, 3)
    return mean * VIEWPORT[1] / (16 * SSE_DENOMINATOR) + float(
        np.linalg.norm(half_axes.sum(axis=0))
    )


def _record(measure: Callable[[str, str], None], city: str, cameras: list[dict]) -> None:
    for camera in cameras:
        what = f"CesiumJS {city} {camera['name']}"
        measure(what, f"{camera['tilesSelected']} tiles, {camera['bytes']:,} bytes requested")


def test_cesium_picks_a_building_near_and_shows_far_levels_far(
    tum: Path, look: Drive, site: Path, tmp_path: Path, measure: Callable[[str, str], None]
) -> None:
    roof, leaf = _roof(tum, EXPOSED)
    near = {"name": "near", "target": roof, "range": NEAR_M, "pitch": -60, "click": True}
    far = {"name": "far", "range": _far(tum), "pitch": -35}
    for camera in (near, far):
        camera["shot"] = str(tmp_path / f"tiles_{camera['name']}.png")
    out = look("cameras", page=_page(site, tum), cameras=[near, far])
    seen_near, seen_far = out["result"]["cameras"]
    message = f"{out['result']}\n{console_text(out)}"
    assert seen_near["failed"] == [] and seen_far["failed"] == [], message
    picked = seen_near["picked"]
    source = _source_attributes(EXPOSED)
    assert picked["id"] == EXPOSED and picked["uri"] == leaf, message
    assert picked["kind"] == "leaves" and picked["properties"]["type"] == "Building", message
    height = picked["properties"]["measuredHeight"]
    assert height == pytest.approx(float(source["measuredHeight"])), message
    assert picked["properties"]["function"] == source["function"], message
    panel = seen_near["panel"]
    assert not panel["hidden"] and panel["heading"] == EXPOSED, message
    assert float(dict(panel["rows"])["measuredHeight"]) == pytest.approx(height), message
    assert any(t["uri"] == leaf for t in seen_near["tiles"]), message
    # from far, every cell shows its far level: no tile of a cell's buildings is selected
    kinds = {t["kind"] for t in seen_far["tiles"] if "_beside_" not in t["uri"]}
    assert kinds == {"far level"}, message
    assert all(Path(camera["shot"]).stat().st_size > 10_000 for camera in (near, far))
    _record(measure, "TUM", [seen_near, seen_far])


ROOF_TOLERANCE = 24
"""How far (in a channel, 0-255) a lit roof's colour may lie from its own: the three.js page shows
TUM's roofs at (178, 92, 76), CesiumJS's default light (the sun at the clock's time) at
(77, 27, 25) in a night-time run."""


def _colour_at(shot: Path, at: dict[str, float]) -> np.ndarray:
    """The median colour of the 9×9 pixels around CSS pixel ``at`` of screenshot ``shot``."""
    x, y = round(at["x"]), round(at["y"])
    pixels = np.asarray(Image.open(shot).convert("RGB"))[y - 4 : y + 5, x - 4 : x + 5]
    return np.median(pixels.reshape(-1, 3), axis=0)


def test_cesium_shows_a_roof_in_its_own_colour(
    tum: Path, look: Drive, site: Path, tmp_path: Path, measure: Callable[[str, str], None]
) -> None:
    """A flat roof seen from 35° and 60° above, whatever the time of day, shows about the roof
    colour its tile holds, as three.js shows it: the page's light comes from above the camera."""
    roof, _ = _roof(tum, EXPOSED)
    cameras = [
        {"name": f"roof {-pitch}°", "target": roof, "range": NEAR_M, "pitch": pitch}
        for pitch in (-35, -60)
    ]
    for camera in cameras:
        camera["shot"] = str(tmp_path / f"roof{-camera['pitch']}.png")
    out = look("cameras", page=_page(site, tum), cameras=cameras)
    expected = DEFAULT_CLASS_COLORS["roof"][:3]
    for camera, seen in zip(cameras, out["result"]["cameras"], strict=True):
        colour = _colour_at(Path(camera["shot"]), seen["at"])
        measure(f"CesiumJS TUM {camera['name']}, roof colour", f"{colour.astype(int).tolist()}")
        message = f"{camera['name']}: {colour} against {expected}\n{console_text(out)}"
        assert np.abs(colour - expected).max() <= ROOF_TOLERANCE, message


@pytest.fixture(scope="module")
def small(site: Path) -> Path:
    """The ten buildings of multi_lod with point far levels, in the test site."""
    return _tileset(site, "multi_lod", "--hlod-kind", "points")


def test_cesium_shows_point_far_levels_of_a_small_city(
    small: Path, look: Drive, site: Path, measure: Callable[[str, str], None]
) -> None:
    tileset = small
    far = {"name": "far", "range": _far(tileset), "pitch": -35}
    out = look("cameras", page=_page(site, tileset), cameras=[{"name": "overview"}, far])
    message = f"{out['result']}\n{console_text(out)}"
    overview, seen_far = out["result"]["cameras"]
    assert overview["failed"] == [] and seen_far["failed"] == [], message
    assert overview["tilesSelected"] > 0 and seen_far["tilesSelected"] > 0, message
    cells = [t for t in seen_far["tiles"] if "_beside" not in t["uri"]]
    assert cells and {t["kind"] for t in cells} == {"far level"}, message
    for uri in {t["uri"] for t in cells}:
        document, _ = read_glb(tileset.parent / uri)
        assert document["meshes"][0]["primitives"][0]["mode"] == 0, message  # POINTS
    _record(measure, "multi_lod", [overview, seen_far])


def test_the_page_names_an_unreachable_cesium(small: Path, driver: Driver, site: Path) -> None:
    """CesiumJS from a server that does not answer: the page's alert box names its URL and says
    how to give the page a local copy."""
    page = write_page(small, small.parent / "offline.html", library="http://127.0.0.1:9/cesium")
    out = driver("page.mjs")("alert", page=str(page.relative_to(site)))
    alert = out["result"]
    message = f"{alert}\n{console_text(out)}"
    assert alert["shown"] and not alert["ready"], message
    assert "Could not load the viewer library" in alert["text"], message
    assert "http://127.0.0.1:9/cesium/Build/Cesium/" in alert["text"], message
    assert "--viewer-lib DIR" in alert["text"] and "cesium@1.145.0" in alert["text"], message
