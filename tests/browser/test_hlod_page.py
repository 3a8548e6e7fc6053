"""The viewer page of a city with LOD parents (``--hlod 250``: TUM Munich's 290 buildings, most
in seven 250 m cells, the others beside them), as X3D in X_ITE and as glTF in three.js, driven
by hlod.mjs in headless Chromium: near the district no cell is merged, farther some are, at the
slider's far end all are, and the page says so (its state and its cells readout); every cell
shows the state of its distance and every object in an open cell (or in none) the level of its
own; a LOD scale from the URL or the page's field multiplies the cutoffs. A prism-switched
file's page shows its object's level, read from the Switches (an object of one level has
none: that level). Every wait is on page state."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lodconvert import convert
from lodconvert.chain import ChainOptions
from lodconvert.city.hlod import HlodOptions
from lodconvert.io import read_chains
from lodconvert.viewer import LIBRARIES, page_config, write_page

from ..conftest import SAMPLE, SHARED
from .conftest import Chain, Drive, Driver, console_text
from .test_prism_switching import _box_level
from .test_viewers import _errors

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SOURCE = SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip"
LISTED = 8
"""Objects the page's readout lists (the first ones)."""


@pytest.fixture(scope="module")
def hlod(driver: Driver) -> Drive:
    """Run hlod.mjs's scenario ``stops``."""
    return driver("hlod.mjs")


def _make(site: Path, source: Path, name: str, **options: Any) -> Chain:
    """Convert ``source`` into ``site/name`` (numpy backend, ``options`` for
    :func:`~lodconvert.pipeline.convert`) and write its viewer page with the npm-installed
    library."""
    out = site / name
    report = convert(source, out, backend="numpy", **options)
    kind = "x3d" if out.suffix == ".x3d" else "gltf"
    write_page(out, library=str(site / "node_modules" / LIBRARIES[kind].package))
    return Chain(name, out.stat().st_size, report)


@pytest.fixture(scope="module")
def district(site: Path) -> dict[str, Chain]:
    """TUM Munich in 250 m cells as .x3d and .glb in the test site, with their pages."""
    if not SOURCE.exists():
        pytest.skip(f"{SOURCE} is absent (shared test data not checked out)")
    hlod = HlodOptions((250.0,))
    return {s: _make(site, SOURCE, f"hlod_tum.{s}", hlod=hlod) for s in ("x3d", "glb")}


def _viewer(config: dict[str, Any], distance: float) -> np.ndarray:
    """Where the page puts the viewer for ``distance``: that far along its view direction from
    the middle of the objects' centres (in the file's scene coordinates)."""
    centres = np.array([o["center"] for o in config["objects"]])
    middle = (centres.min(axis=0) + centres.max(axis=0)) / 2
    return middle + distance * np.asarray(config["view"]["direction"])


def _switch_heights(config: dict[str, Any], scale: float = 1.0) -> list[float]:
    """Per cell, how far along the viewer's line (the view direction from the middle of the
    objects' centres) it merges at LOD scale ``scale``: where its distance reaches its scaled
    cutoff (0 where it does all along)."""
    heights = []
    direction = np.asarray(config["view"]["direction"])
    for cell in config["cells"]:
        offset = np.asarray(cell["center"]) - _viewer(config, 0.0)
        along = float(offset @ direction)
        cutoff, off = scale * cell["cutoffs"][0], float(np.linalg.norm(offset - along * direction))
        heights.append(along + math.sqrt(cutoff**2 - off**2) if cutoff > off else 0.0)
    return heights


def _check_stop(stop: dict[str, Any], config: dict[str, Any], scale: float, message: str) -> None:
    """The page at ``stop`` (at LOD scale ``scale``): each cell at its distance from the viewer,
    hidden inside a cell that is not open, else open or merged by its scaled cutoff; each object
    in a cell that is not open drawn by it, else at the level of its distance; the merged cells
    counted in the state and the readout."""
    viewer = _viewer(config, stop["distance"])
    for cell in config["cells"]:
        seen = stop["cells"][cell["id"]]
        distance = float(np.linalg.norm(viewer - cell["center"]))
        assert seen["distance"] == pytest.approx(distance, rel=1e-4), message
        parent = cell["parent"]
        if parent is not None and stop["cells"][config["cells"][parent]["id"]]["state"] != "open":
            assert seen["state"] == "hidden", message
        else:
            merged = distance >= scale * cell["cutoffs"][0]
            assert seen["state"] == ("merged" if merged else "open"), message
    for obj, seen in zip(config["objects"], stop["objects"], strict=True):
        holder = config["cells"][obj["cell"]] if obj["cell"] is not None else None
        if holder is not None and stop["cells"][holder["id"]]["state"] != "open":
            assert seen["cell"] is not None and seen["level"] is None, message
            assert stop["cells"][seen["cell"]]["state"] in ("merged", "culled"), message
        else:
            level = sum(scale * c <= seen["distance"] for c in obj["cutoffs"])
            assert seen["cell"] is None and seen["levelIndex"] == level, message
    merged = sum(seen["state"] == "merged" for seen in stop["cells"].values())
    assert stop["merged"] == merged, message
    text = f"cells: {merged} of {len(config['cells'])} merged"
    assert stop["cellText"].startswith(text), message


@pytest.mark.parametrize("suffix", ["x3d", "glb"])
def test_cells_merge_beyond_their_cutoff_and_the_page_says_so(
    district: dict[str, Chain], hlod: Drive, site: Path, suffix: str
) -> None:
    chain = district[suffix]
    config = page_config(site / chain.name)
    cells = config["cells"]
    held = [o["cell"] is not None for o in config["objects"]]
    assert len(cells) == 13 and sum(held) > len(held) / 2  # 7 cells, 6 gather those left out
    heights = sorted(_switch_heights(config))
    # a small cell beside the viewer's line may be merged all along (height 0): the first stop
    # comes before every other cell merges, the middle one between the others' middle two
    always = sum(height == 0.0 for height in heights)
    later = heights[always:]
    half = len(later) // 2  # of the others, some merge before the middle, the rest after
    stops = [{"distance": later[0] / 2}, {"distance": sum(later[half - 1 : half + 1]) / 2}]
    stops.append({"key": "End"})
    out = hlod("stops", page=chain.page, stops=stops)
    first, *seen = out["result"]["stops"]
    message = f"{seen}\n{console_text(out)}"
    for stop in [first, *seen]:
        _check_stop(stop, config, 1.0, message)
    at_near, middle, far = seen
    assert at_near["merged"] == always < len(cells), message
    assert at_near["merged"] < middle["merged"] < len(cells), message
    assert far["distance"] > max(c["cutoffs"][0] for c in cells), message
    assert far["merged"] == len(cells), message
    assert [o["cell"] is not None for o in far["objects"]] == held, message
    listed = far["objects"][:LISTED]
    first_held = next(o for o in listed if o["cell"] is not None)
    assert f"{first_held['id']}: merged with {first_held['cell']}" in far["readout"], message
    assert not _errors(out), message


@pytest.mark.parametrize("suffix", ["x3d", "glb"])
def test_lod_scale_from_the_url_and_the_field_multiplies_every_cutoff(
    district: dict[str, Chain], hlod: Drive, site: Path, suffix: str
) -> None:
    """Between where a cell merges at LOD scale 1 and at 2, the page opened with
    ``?lodscale=2`` shows it open; the scale typed back to 1, merged."""
    chain = district[suffix]
    config = page_config(site / chain.name)
    at_one, at_two = _switch_heights(config), _switch_heights(config, 2.0)
    k = next(k for k, height in enumerate(at_one) if height > 0)
    cell, distance = config["cells"][k], (at_one[k] + at_two[k]) / 2
    stops = [{"distance": distance}, {"lodScale": 1, "typed": True}]
    out = hlod("stops", page=f"{chain.page}?lodscale=2", stops=stops)
    _, scaled, plain = out["result"]["stops"]
    message = f"{[scaled, plain]}\n{console_text(out)}"
    assert (scaled["lodScale"], plain["lodScale"]) == (2, 1), message
    _check_stop(scaled, config, 2.0, message)
    _check_stop(plain, config, 1.0, message)
    assert scaled["cells"][cell["id"]]["state"] == "open", message
    assert plain["cells"][cell["id"]]["state"] == "merged", message
    assert not _errors(out), message


def test_prism_page_shows_the_objects_level_from_its_switches(site: Path, hlod: Drive) -> None:
    """The torus knot with prism switching: at a distance inside each of its ranges and beyond
    (culled), the readout shows the level of the box the viewer is in, also at LOD scale 3."""
    options = {"options": ChainOptions(cull=1.5), "write_options": {"switching": "prism"}}
    chain = _make(site, SAMPLE, "prism_knot.x3d", **options)
    (written,) = read_chains(site / chain.name)
    config = page_config(site / chain.name)
    stops = chain.stops()
    out = hlod("stops", page=chain.page, stops=[*stops, {"lodScale": 3}])
    _, *seen, scaled = out["result"]["stops"]
    message = f"{[*seen, scaled]}\n{console_text(out)}"
    names = chain.level_names()
    for stop, at in zip(stops, seen, strict=True):
        expected = names[_box_level(written, _viewer(config, stop["distance"]))]
        (obj,) = at["objects"]
        assert obj["level"] == expected, message
        assert f"{obj['id']}: {expected} at distance" in at["readout"], message
    assert [at["objects"][0]["level"] for at in seen] == names, message
    larger = replace(written, cutoffs=[3 * c for c in written.cutoffs])
    assert scaled["distance"] == pytest.approx(stops[-1]["distance"]), message
    expected = names[_box_level(larger, _viewer(config, scaled["distance"]))]
    assert scaled["objects"][0]["level"] == expected != names[-1], message
    assert not _errors(out), message


def test_prism_page_shows_the_level_of_single_level_objects(site: Path, hlod: Drive) -> None:
    """Potsdam's LoD1 buildings, one level each (no cutoff, so no Switch), with prism
    switching: near and at the slider's far end every object shows LOD1, and each line of the
    readout says so at the distance of the move, with no cutoff (it said '…' for ever)."""
    source = SHARED / "data" / "citygml" / "potsdam_lod1_v1.gml"
    if not source.exists():
        pytest.skip(f"{source} is absent (shared test data not checked out)")
    chain = _make(site, source, "prism_potsdam.x3d", write_options={"switching": "prism"})
    assert {len(obj["levels"]) for obj in chain.report["objects"]} == {1}
    out = hlod("stops", page=chain.page, stops=[{"key": "Home"}, {"key": "End"}])
    _, near, far = out["result"]["stops"]
    message = f"{[near['readout'], far['readout']]}\n{console_text(out)}"
    for at in (near, far):
        assert {obj["level"] for obj in at["objects"]} == {"LOD1"}, message
        lines = at["readout"].splitlines()[:LISTED]
        for obj, line in zip(at["objects"][:LISTED], lines, strict=True):
            start, distance = line.removesuffix(" (no cutoff)").rsplit(" ", 1)
            assert start == f"{obj['id']}: LOD1 at distance", message
            assert float(distance) == pytest.approx(obj["distance"], rel=1e-3), message
    assert far["objects"][0]["distance"] > 10 * near["objects"][0]["distance"], message
    assert not _errors(out), message
