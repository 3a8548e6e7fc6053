"""Compressed ``.glb`` files (``--compress meshopt`` and ``quantize``, docs/compression.md) in
real browsers: three.js (with its copy of meshoptimizer's decoder) and Babylon.js (with the
npm package's) draw the torus knot's levels as they draw the uncompressed file, the
textured PLATEAU building keeps its texture, and lodconvert's viewer page switches the
compressed file's levels at the cutoffs. CesiumJS draws meshopt tiles in every tileset test
(the tileset default)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lodconvert.viewer import write_page

from ..conftest import SAMPLE, SHARED, require
from ..test_cli import run
from .conftest import Chain, Drive, console_text
from .test_viewers import _check_viewer_page_stops

pytestmark = [pytest.mark.browser, pytest.mark.slow]

WAYS = ("none", "meshopt", "quantize")
PLATEAU = SHARED / "data" / "citygml" / "plateau_53394517_bldg_lod012_v2.gml"


def _convert(site: Path, source: Path, name: str, how: str) -> Chain:
    """``source`` as ``site/name`` compressed ``how``, with its viewer page."""
    out, report = site / name, site / f"{name}.report.json"
    result = run(source, "-o", out, "--compress", how, "--report", report, "-q", "--cull", "1.5")
    assert result.returncode == 0, result.stderr
    write_page(out, library=str(site / "node_modules" / "three"))
    return Chain(name, out.stat().st_size, json.loads(report.read_text()))


@pytest.fixture(scope="module")
def knots(site: Path) -> dict[str, Chain]:
    """The bundled torus knot as a ``.glb`` each way."""
    return {how: _convert(site, SAMPLE, f"knot_{how}.glb", how) for how in WAYS}


def _errors(out: dict) -> list[str]:
    return [line for line in out["console"] if line.startswith(("error", "pageerror", "HTTP"))]


@pytest.mark.parametrize("how", ["meshopt", "quantize"])
def test_three_draws_a_compressed_glb_as_the_plain_one(
    knots: dict[str, Chain], drive: Drive, how: str
) -> None:
    """The point levels (the page has no light: only unlit points are judged by their
    pixels) have every point, coloured, and cover the same pixels within 2 %."""
    assert knots[how].size < knots["none"].size
    for node in (2, 3):  # nodes: root, finest (mesh), then the coarser ones (points)
        plain, packed = (drive("three", file=knots[k].name, node=node) for k in ("none", how))
        message = f"{packed['result']}\n{console_text(packed)}"
        assert packed["result"]["points"] == plain["result"]["points"], message
        assert packed["result"]["foreground"] > 0, message
        share = packed["result"]["foreground"] / plain["result"]["foreground"]
        assert abs(share - 1) <= 0.02, message
        assert not _errors(packed), message


@pytest.mark.parametrize("how", ["meshopt", "quantize"])
def test_babylon_draws_a_compressed_glb_as_the_plain_one(
    knots: dict[str, Chain], drive: Drive, how: str
) -> None:
    """Every level loaded (MSFT_lod, progressively, lit): the same meshes drawn with the same
    vertices, in the same mean colour within 3 (the page frames its camera on the levels
    loaded when the import resolves, which decoding may change: the pixels covered are not
    compared)."""
    plain, packed = (drive("babylon", file=knots[k].name) for k in ("none", how))
    message = f"{packed['result']}\n{console_text(packed)}"
    shapes = [(m["name"], m["vertices"], m["points"]) for m in packed["result"]["meshes"]]
    assert shapes == [(m["name"], m["vertices"], m["points"]) for m in plain["result"]["meshes"]]
    assert packed["result"]["foreground"] > 0, message
    gap = np.abs(np.subtract(packed["result"]["mean"], plain["result"]["mean"])).max()
    assert gap <= 3, message
    assert not _errors(packed), message


@pytest.mark.parametrize("how", ["meshopt", "quantize"])
def test_the_viewer_page_switches_a_compressed_glbs_levels(
    knots: dict[str, Chain], drive: Drive, how: str
) -> None:
    """Each level where it belongs (quantized positions: each level node scaled and moved
    back)."""
    chain = knots[how]
    _check_viewer_page_stops(chain, drive("viewer", page=chain.page, stops=chain.stops()))


@pytest.mark.parametrize("how", ["meshopt", "quantize"])
def test_a_compressed_textured_glb_keeps_its_texture(site: Path, drive: Drive, how: str) -> None:
    """The PLATEAU building's LoD2 level, its texture coordinates stored as 16-bit fractions,
    is drawn textured by three.js and Babylon.js."""
    require(PLATEAU.exists(), f"{PLATEAU} is absent (shared data not checked out)")
    name = f"plateau_{how}.glb"
    result = run(PLATEAU, "-o", site / name, "--compress", how, "-q")
    assert result.returncode == 0, result.stderr
    out = drive("three", file=name, node=1)
    message = f"{out['result']}\n{console_text(out)}"
    textures = out["result"]["textures"]
    assert textures and all(t["width"] > 0 and t["uv"] for t in textures), message
    out = drive("babylon", file=name)
    message = f"{out['result']}\n{console_text(out)}"
    assert any(m["texture"] and m["texture"]["width"] > 0 for m in out["result"]["meshes"]), message
    assert not _errors(out), message
