"""A textured city in real browsers: the PLATEAU building's texture, read from its CityGML
appearance, is decoded and drawn by three.js and Babylon.js from the ``.glb``, and by CesiumJS
from the tileset's atlas page, which shows the texture's colours, not the class colours.
docs/textures.md; the screenshot in docs/textures_cesium.png comes from this test."""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from lodconvert.io.gltf.texture_copies import BASISU, COPIES, WEBP
from lodconvert.io.tiles.check import glb_parts
from lodconvert.semantics import DEFAULT_CLASS_COLORS
from lodconvert.viewer import write_page

from ..conftest import ROOT, SHARED, basisu_encoder, require
from ..test_cli import run
from .conftest import REQUIRE, Drive, Driver, console_text
from .test_tiles_cesium import CESIUM, _page

pytestmark = [pytest.mark.browser, pytest.mark.slow]

PLATEAU = SHARED / "data" / "citygml" / "plateau_53394517_bldg_lod012_v2.gml"
ATLAS = SHARED / "data" / "citygml" / "53394517_bldg_6697_appearance" / "stad0158.jpg"
MIN_VISIBLE = 0.02
"""Least share of the view the building covers."""


@pytest.fixture(scope="module")
def plateau(site: Path) -> dict[str, Path]:
    """The PLATEAU building as a ``.glb``, a tileset (with its CesiumJS page) and an ``.x3d``,
    and as an ``.x3d`` without its texture (a theme it lacks)."""
    require(PLATEAU.exists(), f"{PLATEAU} is absent (shared data not checked out)")
    made = {
        "glb": site / "plateau.glb",
        "tiles": site / "plateau_tiles" / "tileset.json",
        "x3d": site / "plateau.x3d",
        "plain": site / "plateau_plain.x3d",
        "webp_glb": site / "plateau_webp.glb",
        "webp_tiles": site / "plateau_webp_tiles" / "tileset.json",
        "ktx2_glb": site / "plateau_ktx2.glb",
        "ktx2_tiles": site / "plateau_ktx2_tiles" / "tileset.json",
    }
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("LODCONVERT_BASISU", basisu_encoder())
        for name, out in made.items():
            theme = ("--appearance-theme", "none") if name == "plain" else ()
            kind = name.partition("_")[0]
            copy = ("--texture-format", kind) if kind in COPIES else ()
            result = run(PLATEAU, "-o", out, "-q", *theme, *copy)
            assert result.returncode == 0, result.stderr
    for kind in COPIES:
        for glb in (made[f"{kind}_glb"], *(made[f"{kind}_tiles"].parent / "tiles").glob("*.glb")):
            _break_fallbacks(glb)
    for name in ("tiles", "webp_tiles", "ktx2_tiles"):
        write_page(made[name], library=CESIUM)
    return made


def _break_fallbacks(glb: Path) -> None:
    """Zero the bytes of every image that a texture's copy (WebP or KTX2) stands in for, so
    that only a viewer taking the copy shows the texture."""
    document, _ = glb_parts(glb.read_bytes())
    data = bytearray(glb.read_bytes())
    start = 20 + struct.unpack_from("<I", data, 12)[0] + 8  # the BIN chunk's data
    for texture in document.get("textures", []):
        if texture.get("extensions", {}).keys() & {WEBP, BASISU}:
            view = document["bufferViews"][document["images"][texture["source"]]["bufferView"]]
            at = start + view["byteOffset"]
            data[at : at + view["byteLength"]] = bytes(view["byteLength"])
    glb.write_bytes(bytes(data))


def test_three_decodes_the_buildings_texture(plateau: dict[str, Path], drive: Drive) -> None:
    """three.js's loader gives the LoD2 level's mesh its decoded image and coordinates (the
    test page has no light, so its lit material is not judged by its pixels)."""
    out = drive("three", file=plateau["glb"].name, node=1)  # the LoD2 level
    result = out["result"]
    message = f"{result}\n{console_text(out)}"
    assert result["textures"], message
    assert all(t["width"] > 0 and t["height"] > 0 and t["uv"] for t in result["textures"]), message


def test_x_ite_draws_the_buildings_texture(plateau: dict[str, Path], drive: Drive) -> None:
    """From the file's own viewpoint X_ITE draws the textured building in its photograph's
    colours: the mean colour of its pixels lies near the photograph's (7.5 apart when
    measured), the same building in class colours far from it (23)."""
    seen = {}
    for name in ("x3d", "plain"):
        out = drive("x_ite", file=plateau[name].name, start=True)
        start = out["result"]["start"]
        message = f"{out['result']}\n{console_text(out)}"
        assert start["foreground"] >= MIN_VISIBLE * 400 * 300, message
        assert not [line for line in out["console"] if line.startswith(("error", "pageerror"))], (
            message
        )
        seen[name] = np.asarray(start["mean"])
    photograph = np.asarray(Image.open(ATLAS).convert("RGB")).reshape(-1, 3).mean(axis=0)
    textured, plain = (float(np.linalg.norm(seen[k] - photograph)) for k in ("x3d", "plain"))
    assert textured <= 12 and textured <= plain - 8, (textured, plain, seen)


def test_babylon_draws_the_buildings_texture(plateau: dict[str, Path], drive: Drive) -> None:
    out = drive("babylon", file=plateau["glb"].name)
    result = out["result"]
    message = f"{result}\n{console_text(out)}"
    textured = [m for m in result["meshes"] if m["texture"] and m["texture"]["width"] > 0]
    assert textured, message
    assert result["foreground"] >= MIN_VISIBLE, message


def test_three_and_babylon_take_a_textures_webp_copy(
    plateau: dict[str, Path], drive: Drive
) -> None:
    """With ``--texture-format webp`` and the JPEG each WebP copy stands in for zeroed, both
    still decode the texture: they read ``EXT_texture_webp``."""
    out = drive("three", file=plateau["webp_glb"].name, node=1)
    message = f"{out['result']}\n{console_text(out)}"
    assert any(t["width"] > 0 and t["uv"] for t in out["result"]["textures"]), message
    out = drive("babylon", file=plateau["webp_glb"].name)
    message = f"{out['result']}\n{console_text(out)}"
    assert any(m["texture"] and m["texture"]["width"] > 0 for m in out["result"]["meshes"]), message


def test_three_takes_a_textures_ktx2_copy(plateau: dict[str, Path], drive: Drive) -> None:
    """With ``--texture-format ktx2`` and the JPEG each KTX2 copy stands in for zeroed,
    three.js (its KTX2Loader, Basis Universal's transcoder) draws the LoD2 level with a
    compressed texture of the copy's size."""
    out = drive("three", file=plateau["ktx2_glb"].name, node=1)
    message = f"{out['result']}\n{console_text(out)}"
    textures = out["result"]["textures"]
    assert textures and all(t["compressed"] and t["uv"] for t in textures), message
    assert all(t["width"] % 4 == 0 and t["height"] % 4 == 0 for t in textures), message


def test_the_viewer_page_draws_the_ktx2_copy(
    plateau: dict[str, Path], site: Path, drive: Drive
) -> None:
    """lodconvert's own page for the ``--texture-format ktx2`` ``.glb`` (each JPEG zeroed)
    draws the building in its photograph's colours, through three.js's KTX2Loader, and says
    nothing failed; in the class colours it would stand far from them."""
    page = write_page(plateau["ktx2_glb"], library=str(site / "node_modules" / "three"))
    out = drive("viewer", page=page.name, stops=[{"distance": 60.0}])
    [seen] = out["result"]["stops"]
    message = f"{seen}\n{console_text(out)}"
    assert not [line for line in out["console"] if line.startswith(("error", "pageerror"))], message
    assert seen["foreground"] > 0, message
    photograph = np.asarray(Image.open(ATLAS).convert("RGB")).reshape(-1, 3).mean(axis=0)
    drawn = float(np.linalg.norm(np.asarray(seen["mean"]) - photograph))
    plain = float(np.linalg.norm(np.asarray(DEFAULT_CLASS_COLORS["wall"][:3]) - photograph))
    assert drawn <= plain - 8, (drawn, plain, seen)


@pytest.mark.parametrize("name", ["tiles", "webp_tiles", "ktx2_tiles"])
def test_cesium_shows_the_texture_from_the_atlas(
    plateau: dict[str, Path],
    driver: Driver,
    site: Path,
    tmp_path: Path,
    measure: Callable[[str, str], None],
    name: str,
) -> None:
    """From 300 m at 50° above, the building shows the atlas's colours: its pixels' median
    is near the texture's and far from the roof and wall class colours, and they vary as a
    photograph does (a flat class colour, even lit, varies far less). With
    ``--texture-format webp`` or ``ktx2`` (each page's JPEG zeroed) CesiumJS takes the copy."""
    package = ROOT / "node_modules" / "cesium" / "package.json"
    require(package.exists(), f"{package} is absent (scripts/test.sh installs it)", REQUIRE)
    look = driver("tiles.mjs")
    shot = tmp_path / "plateau.png"
    camera = {"name": "plateau", "range": 300.0, "pitch": -50, "shot": str(shot)}
    out = look("cameras", page=_page(site, plateau[name]), cameras=[camera])
    [seen] = out["result"]["cameras"]
    message = f"{seen}\n{console_text(out)}"
    assert seen["failed"] == [] and seen["tilesSelected"] > 0, message
    assert any("_finest" in t["uri"] for t in seen["tiles"]), message
    view = np.asarray(Image.open(shot).convert("RGB")).astype(float)
    pixels = view[130:-50].reshape(-1, 3)  # below the page's panel, above CesiumJS's logo
    background = np.median(pixels, axis=0)  # the bare globe, around the building
    building = pixels[np.abs(pixels - background).max(axis=1) > 24]
    assert len(building) >= MIN_VISIBLE * len(pixels), message
    texture = np.asarray(Image.open(ATLAS).convert("RGB")).reshape(-1, 3).astype(float)
    seen_median, texture_median = np.median(building, axis=0), np.median(texture, axis=0)
    copy = {"webp_tiles": ", WebP", "ktx2_tiles": ", KTX2"}.get(name, "")
    what = "CesiumJS PLATEAU textured" + copy
    measure(f"{what}, median colour", f"{seen_median.astype(int).tolist()}")
    assert np.abs(seen_median - texture_median).max() <= 60, (seen_median, texture_median)
    for kind in ("roof", "wall"):
        assert np.abs(seen_median - DEFAULT_CLASS_COLORS[kind][:3]).max() > 40, seen_median
    assert building.std(axis=0).mean() > 12, building.std(axis=0)
