"""Clicking an object on the viewer page shows its id and attributes and highlights it (its roof
changes colour until another building or empty space is clicked), clicking empty space clears
both: the TUM Munich district (CityGML LoD2) as X3D in X_ITE and as glTF in three.js,
clicked by inspect.mjs in headless Chromium where the page itself says a roof shows; the SIG3D
LoD4 house shows the attributes of its parts (its room and the furniture in it)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from lodconvert.io import own_format, read_chains
from lodconvert.io.frame import ROTATION

from ..conftest import SHARED
from .conftest import Chain, Drive, Driver, console_text, make_chain
from .test_viewers import _errors

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SOURCE = SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip"
HOUSE = SHARED / "data" / "citygml" / "sig3d_house_lod0-4" / "Building_LOD4-EPSG25832.gml"
HOUSE_ID = "GML_7b1a5a6f-ddad-4c3d-a507-3eb9ee0a8e68"
NAMESPACES = {
    "gml": "http://www.opengis.net/gml",
    "bldg": "http://www.opengis.net/citygml/building/2.0",
}
SKY = [0.02, 0.98]
"""Where empty space is clicked: near the bottom-left corner of the view. The page first shows
every object within the sphere of radius ``reach`` around its focus from 2.5 ``reach`` away, so
no object shows beyond asin(1 / 2.5) = 23.6° off the axis; the corner of a 4:3 view at 45° is
34.6° off it."""


@pytest.fixture(scope="module")
def inspect(driver: Driver) -> Drive:
    """Run inspect.mjs's scenario ``clicks``."""
    return driver("inspect.mjs")


@pytest.fixture(scope="module")
def district(site: Path) -> dict[str, Chain]:
    """TUM Munich converted to .x3d and .glb in the test site, each with its viewer page."""
    if not SOURCE.exists():
        pytest.skip(f"{SOURCE} is absent (shared test data not checked out)")
    return {s: make_chain(site, SOURCE, f"inspect_tum.{s}") for s in ("x3d", "glb")}


def roof_point(corners: np.ndarray) -> tuple[np.ndarray, float]:
    """Of the upward-facing (z-up) triangles among ``corners`` ((n, 3, 3)), the centre of the
    largest inscribed circle and its radius (0 where none faces up): a point safe to click."""
    sides = np.linalg.norm(corners[:, [1, 2, 0]] - corners[:, [2, 0, 1]], axis=2)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    twice_area = np.linalg.norm(normals, axis=1)
    upward = normals[:, 2] > 0.5 * twice_area
    radii = np.where(upward, twice_area / np.maximum(sides.sum(axis=1), 1e-12), 0.0)
    k = int(np.argmax(radii))
    return (sides[k] @ corners[k]) / sides[k].sum(), float(radii[k])


def _roof(path: Path, object_id: str | None = None) -> tuple[str, list[float]]:
    """An object of ``path`` (``object_id`` where given) and a point on its roof, safe to
    click, in the file's scene coordinates (where the page draws): of all upward-facing
    triangles of the objects' finest levels, the centre of the largest inscribed circle (from
    above the horizon, as the page first shows the district, a roof shows, its edges farthest
    away)."""
    best = (0.0, "", [0.0, 0.0, 0.0])
    for chain in read_chains(path):
        if object_id is not None and chain.object_id != object_id:
            continue
        centre, radius = roof_point(chain.levels[0].mesh.vertices[chain.levels[0].mesh.faces])
        if radius > best[0]:
            best = (radius, chain.object_id, (chain.origin + centre).tolist())
    frame = own_format(path).read_frame(path)
    point = best[2] if frame is None else (ROTATION @ (best[2] - frame.origin)).tolist()
    return best[1], point


def _source_attributes(gml_id: str) -> dict[str, str]:
    """The ``bldg:`` attributes of the building ``gml_id`` in the source file, as text, by
    local name."""
    with zipfile.ZipFile(SOURCE) as archive:
        (member,) = [n for n in archive.namelist() if n.endswith(".gml")]
        with archive.open(member) as handle:
            tree = etree.parse(handle)
    (building,) = tree.xpath(f"//bldg:Building[@gml:id='{gml_id}']", namespaces=NAMESPACES)
    children = building.iterchildren(f"{{{NAMESPACES['bldg']}}}*")
    return {etree.QName(child).localname: (child.text or "").strip() for child in children}


@pytest.mark.parametrize("suffix", ["x3d", "glb"])
def test_clicking_a_building_shows_its_id_and_attributes(
    district: dict[str, Chain], inspect: Drive, site: Path, suffix: str
) -> None:
    chain = district[suffix]
    gml_id, roof = _roof(site / district["x3d"].name)
    out = inspect("clicks", page=chain.page, clicks=[{"point": roof}, {"at": SKY}])
    building, sky = out["result"]["clicks"]
    message = f"{out['result']}\n{console_text(out)}"
    assert building["selected"] == gml_id and building["heading"] == gml_id, message
    assert not building["hidden"], message
    rows = dict(building["rows"])
    source = _source_attributes(gml_id)
    assert float(rows["measuredHeight"]) == pytest.approx(float(source["measuredHeight"])), message
    assert rows["function"] == source["function"] and rows["type"] == "Building", message
    assert sky["selected"] is None and sky["hidden"], message
    assert sky["heading"] is None and sky["rows"] == [], message
    assert not _errors(out), message


EXPOSED = "DEBY_LOD2_4959457"
"""A TUM Munich building whose largest roof (4.6 m inscribed circle, 545 m high) lies highest of
all the buildings' largest roofs: nothing near rises above it to hide it, from any view above
the horizon."""
TINTED = 40.0
"""How much (in a channel, 0-255) a highlighted roof's colour differs at least from before."""
UNCHANGED = 6.0
"""How much at most a roof's colour may differ from before when it is not highlighted."""


def _change(colour: list[float], before: list[float]) -> float:
    return max(abs(a - b) for a, b in zip(colour, before, strict=True))


@pytest.mark.parametrize("suffix", ["x3d", "glb"])
def test_clicking_a_building_highlights_it_until_another_is_clicked(
    district: dict[str, Chain], inspect: Drive, site: Path, suffix: str
) -> None:
    """Clicking a building tints its roof and no other; clicking a second building moves the
    tint there (the first shows its own colour again); the inspect panel's close button clears
    it, and so does clicking empty space."""
    path = site / district["x3d"].name
    first, roof = _roof(path)
    second, other = _roof(path, EXPOSED)
    clicks = [{"point": roof}, {"point": other}, {"close": True}, {"point": roof}, {"at": SKY}]
    out = inspect("clicks", page=district[suffix].page, clicks=clicks, probes=[roof, other])
    result = out["result"]
    message = f"{result['probes']} then {[c['probes'] for c in result['clicks']]}"
    message += f"\n{console_text(out)}"
    selected = [c["selected"] for c in result["clicks"]]
    assert selected == [first, second, None, first, None], message
    assert [c["hidden"] for c in result["clicks"]] == [False, False, True, False, True], message
    before = result["probes"]
    # per click: is each roof tinted?
    expected = [[True, False], [False, True], [False, False], [True, False], [False, False]]
    for click, tints in zip(result["clicks"], expected, strict=True):
        for colour, was, tinted in zip(click["probes"], before, tints, strict=True):
            change = _change(colour, was)
            assert change >= TINTED if tinted else change <= UNCHANGED, message
    assert not _errors(out), message


@pytest.mark.parametrize("suffix", ["x3d", "glb"])
def test_clicking_a_house_shows_its_parts(inspect: Drive, site: Path, suffix: str) -> None:
    """The house's room and furniture, merged into its levels, each show as a group of rows
    of their own (``parts 1``, ``parts 2``), not as one row of JSON."""
    if not HOUSE.exists():
        pytest.skip(f"{HOUSE} is absent (shared test data not checked out)")
    chain = make_chain(site, HOUSE, f"inspect_house.{suffix}")
    _, roof = _roof(site / chain.name, HOUSE_ID)
    out = inspect("clicks", page=chain.page, clicks=[{"point": roof}])
    (house,) = out["result"]["clicks"]
    message = f"{out['result']}\n{console_text(out)}"
    assert house["selected"] == HOUSE_ID and house["heading"] == HOUSE_ID, message
    rows = house["rows"]
    assert ["parts 1", None] in rows and ["parts 2", None] in rows, message
    second = rows[rows.index(["parts 2", None]) :]
    assert ["type", "BuildingFurniture"] in second and ["name", "Rocking Chair"] in second
    first = rows[rows.index(["parts 1", None]) : rows.index(["parts 2", None])]
    assert ["type", "Room"] in first, message
    assert not any(header == "parts" for header, _ in rows), message
    assert not _errors(out), message
