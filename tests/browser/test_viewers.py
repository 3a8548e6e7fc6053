"""Real viewers in headless Chromium: X_ITE and X3DOM load our X3D, Babylon.js and three.js our
glb, and lodconvert's own viewer page switches levels at the cutoffs. Also the time to first
frame and the .x3d / .glb sizes of the same chain (printed under "viewer measurements")."""

from __future__ import annotations

from pathlib import Path

import pytest

from ..conftest import stanford
from .conftest import Chain, Drive, console_text, make_chain

pytestmark = pytest.mark.browser

MIN_VISIBLE = 20
"""Pixels an object shows at least (the coarsest level is a few dozen pixels across)."""


def _errors(out: dict) -> list[str]:
    return [line for line in out["console"] if line.startswith(("error", "pageerror", "HTTP"))]


def test_x_ite_switches_levels_at_the_cutoffs(knot: dict[str, Chain], drive: Drive) -> None:
    chain = knot["x3d"]
    stops = chain.stops()
    out = drive(
        "x_ite",
        file=chain.name,
        lod=f"{chain.obj['id']}_LOD",
        center=chain.obj["origin"],
        stops=stops,
    )
    seen = out["result"]["stops"]
    message = f"{seen}\n{console_text(out)}"
    assert [s["level"] for s in seen] == [s["level"] for s in stops], message
    assert all(s["foreground"] >= MIN_VISIBLE for s in seen[:-1]), message
    assert seen[-1]["foreground"] == 0, message  # beyond the last cutoff: gone
    assert not _errors(out), message


def test_x3dom_loads_the_x3d_without_errors(knot: dict[str, Chain], drive: Drive) -> None:
    out = drive("x3dom", file=knot["x3d"].name)
    assert out["result"]["problems"] == [], console_text(out)
    assert not _errors(out), console_text(out)


def test_x3dom_draws_the_nearest_level(knot: dict[str, Chain], drive: Drive) -> None:
    out = drive("x3dom", file=knot["x3d"].name)
    assert out["result"]["foreground"] >= MIN_VISIBLE, console_text(out)


def test_babylon_loads_the_glb_and_shows_points(knot: dict[str, Chain], drive: Drive) -> None:
    # Babylon.js loads MSFT_lod levels coarsest first; stopping after one leaves the points.
    out = drive("babylon", file=knot["glb"].name, maxLods=1)
    result = out["result"]
    message = f"{result}\n{console_text(out)}"
    assert result["meshes"] and all(m["points"] for m in result["meshes"]), message
    coarsest = knot["glb"].obj["levels"][-1]["count"]
    assert sum(m["vertices"] for m in result["meshes"]) == coarsest, message
    assert result["foreground"] >= MIN_VISIBLE, message
    assert not _errors(out), message


def test_three_loads_the_glb_and_shows_points(knot: dict[str, Chain], drive: Drive) -> None:
    # three.js ignores MSFT_lod: its scene holds the root; a point level is fetched by index.
    out = drive("three", file=knot["glb"].name, node=2)  # nodes: root, LOD4, LOD3, ...
    result = out["result"]
    message = f"{result}\n{console_text(out)}"
    assert result["scene"] == [knot["glb"].obj["id"]], message
    (points,) = result["points"]
    assert points["count"] == knot["glb"].obj["levels"][1]["count"] and points["colored"], message
    assert result["foreground"] >= MIN_VISIBLE, message
    assert not _errors(out), message


@pytest.mark.parametrize("suffix", ["glb", "x3d"])
def test_viewer_page_switches_levels_at_the_cutoffs(
    knot: dict[str, Chain], drive: Drive, suffix: str
) -> None:
    chain = knot[suffix]
    names = chain.level_names()
    stops = [{**s, "level": names[s["level"]]} for s in chain.stops()]
    out = drive("viewer", page=f"knot_{suffix}.html", stops=stops)
    seen = out["result"]["stops"]
    message = f"{seen}\n{console_text(out)}"
    assert [s["level"] for s in seen] == names, message
    for stop, shown in zip(stops, seen, strict=True):
        assert shown["distance"] == pytest.approx(stop["distance"], rel=1e-3), message
        assert f"{chain.obj['id']}: {shown['level']}" in shown["readout"], message
    assert all(s["foreground"] >= MIN_VISIBLE for s in seen[:-1]), message
    assert seen[-1]["foreground"] == 0, message
    assert not _errors(out), message


def _time_to_first_frame(
    site: Path, drive: Drive, measure, source: Path, name: str, timeout_s: float
) -> None:
    """Convert ``source`` with default options to .x3d and .glb, record both sizes and the
    time from starting to load each to its first drawn frame in X_ITE and Babylon.js."""
    x3d = make_chain(site, source, f"{name}.x3d")
    glb = make_chain(site, source, f"{name}.glb")
    measure(
        f"{name}: file size .x3d / .glb",
        f"{x3d.size / 1e6:.2f} MB / {glb.size / 1e6:.2f} MB ({x3d.size / glb.size:.2f}x)",
    )
    x_ite = drive("x_ite", timeout_s=timeout_s, file=x3d.name)
    measure(f"{name}: X_ITE first frame (.x3d)", f"{x_ite['result']['firstFrameMs']:.0f} ms")
    babylon = drive("babylon", timeout_s=timeout_s, file=glb.name)["result"]
    loaded = f"all MSFT_lod levels loaded at {babylon['completeMs']:.0f} ms"
    measure(f"{name}: Babylon.js first frame (.glb)", f"{babylon['firstMs']:.0f} ms ({loaded})")
    measure("WebGL renderer", x_ite["renderer"])
    assert not _errors(x_ite), console_text(x_ite)


def test_time_to_first_frame_bunny(site: Path, drive: Drive, measure) -> None:
    _time_to_first_frame(
        site, drive, measure, stanford("bunny_bun_zipper.ply"), "bunny", timeout_s=60
    )


@pytest.mark.slow
def test_time_to_first_frame_dragon(site: Path, drive: Drive, measure) -> None:
    _time_to_first_frame(
        site, drive, measure, stanford("dragon_vrip.ply.gz"), "dragon", timeout_s=300
    )
