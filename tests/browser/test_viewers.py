"""Real viewers in headless Chromium: X_ITE and X3DOM load our X3D, Babylon.js and three.js our
glb, and lodconvert's own viewer page switches levels at the cutoffs (also served with a library
from elsewhere), its slider spans every object's ranges and its points are lit like its meshes;
its panel folds, and it says what failed to load (an unreachable library, a moved model).
Also the time to first frame and the .x3d / .glb sizes of the same chain (printed under "viewer
measurements", as measurements only: no test has a time limit)."""

from __future__ import annotations

import itertools
import math
import os
import shutil
import socket
from pathlib import Path

import numpy as np
import pytest
import trimesh

from lodconvert.io import OutputInfo
from lodconvert.io.x3d import write_x3d
from lodconvert.model import Level, LodChain, Surface
from lodconvert.viewer import LIBRARIES, write_page

from ..conftest import stanford
from ..test_viewer import view_served
from .conftest import Chain, Drive, Driver, console_text, make_chain

pytestmark = [pytest.mark.browser, pytest.mark.slow]

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


def _check_viewer_page_stops(chain: Chain, out: dict) -> None:
    """The viewer page ``out`` of ``chain``, moved to :meth:`Chain.stops`, showed each level
    there (in its state and readout), and nothing beyond the last cutoff."""
    names = chain.level_names()
    seen = out["result"]["stops"]
    message = f"{seen}\n{console_text(out)}"
    shown = [s["objects"][0] for s in seen]
    assert [s["level"] for s in shown] == names, message
    for stop, state, obj in zip(chain.stops(), seen, shown, strict=True):
        assert obj["distance"] == pytest.approx(stop["distance"], rel=1e-3), message
        assert f"{chain.obj['id']}: {obj['level']}" in state["readout"], message
    assert all(s["foreground"] >= MIN_VISIBLE for s in seen[:-1]), message
    assert seen[-1]["foreground"] == 0, message
    assert not _errors(out), message


@pytest.mark.parametrize("suffix", ["glb", "x3d"])
def test_viewer_page_switches_levels_at_the_cutoffs(
    knot: dict[str, Chain], drive: Drive, suffix: str
) -> None:
    chain = knot[suffix]
    assert chain.page == f"knot.{suffix}.html"
    _check_viewer_page_stops(chain, drive("viewer", page=chain.page, stops=chain.stops()))


@pytest.mark.parametrize("suffix", ["glb", "x3d"])
def test_viewer_page_works_served_with_a_library_outside_its_folder(
    knot: dict[str, Chain], site: Path, drive: Drive, tmp_path: Path, suffix: str
) -> None:
    """``lodconvert view OUT --serve --viewer-lib DIR`` with DIR (the npm package, through
    its real path) outside the page's folder serves DIR too, and the page works."""
    chain = knot[suffix]
    asset = tmp_path / chain.name
    shutil.copyfile(site / chain.name, asset)
    package = LIBRARIES["x3d" if suffix == "x3d" else "gltf"].package
    library = (site / "node_modules" / package).resolve()
    with view_served(asset, "--viewer-lib", library) as url:
        base, page = url.rsplit("/", 1)
        assert page == chain.page
        out = drive("viewer", base=base, page=page, stops=chain.stops())
    _check_viewer_page_stops(chain, out)


@pytest.mark.parametrize("suffix", ["glb", "x3d"])
def test_viewer_page_slider_reaches_beyond_every_objects_last_cutoff(
    pair: dict[str, Chain], drive: Drive, suffix: str
) -> None:
    """With a small object first and a large one 16× its size beside it, the slider's far end
    (End pressed on it) takes the viewer beyond both objects' last cutoffs: nothing shows."""
    chain = pair[suffix]
    out = drive("viewer", page=chain.page, stops=[{"key": "End"}])
    (seen,) = out["result"]["stops"]
    message = f"{seen}\n{console_text(out)}"
    objects = chain.report["objects"]
    assert [o["id"] for o in seen["objects"]] == ["a_small", "b_large"], message
    for obj, shown in zip(objects, seen["objects"], strict=True):
        assert shown["distance"] > obj["cutoffs"][-1], message
        assert shown["level"] == "nothing (culled)", message
    assert seen["foreground"] == 0, message
    assert not _errors(out), message


@pytest.fixture(scope="module")
def page_ui(driver: Driver) -> Drive:
    """Run a scenario of page.mjs: the viewer page's own panel and alert box."""
    return driver("page.mjs")


def test_viewer_page_panel_folds_by_its_heading(knot: dict[str, Chain], page_ui: Drive) -> None:
    """A click on the readout panel's heading folds it to that line: the view shows where the
    readout was. Another click unfolds it, its readout current (the viewer moved meanwhile)."""
    chain = knot["glb"]
    stop = chain.stops()[1]
    out = page_ui("panel", page=chain.page, distance=stop["distance"])
    first, folded, unfolded = (out["result"][k] for k in ("first", "folded", "unfolded"))
    message = f"{out['result']}\n{console_text(out)}"
    assert first["open"] and first["readoutShown"] and not first["view"], message
    assert not folded["open"] and not folded["readoutShown"] and folded["view"], message
    assert unfolded["open"] and unfolded["readoutShown"] and not unfolded["view"], message
    assert unfolded["height"] > 2 * folded["height"], message
    level = chain.level_names()[stop["level"]]
    assert f"{chain.obj['id']}: {level} at distance" in unfolded["readout"], message
    assert not _errors(out), message


def _words(text: str) -> str:
    """``text`` with its line breaks and runs of spaces as single spaces."""
    return " ".join(text.split())


def _closed_port() -> int:
    """A port of 127.0.0.1 that nothing listens on (free a moment ago)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.parametrize("suffix", ["glb", "x3d"])
def test_viewer_page_names_an_unreachable_library(
    knot: dict[str, Chain], site: Path, page_ui: Drive, suffix: str
) -> None:
    """Offline, the CDN cannot be reached (here: a library URL on a port nothing listens on):
    over the view the page names the module that failed and says to re-run with
    ``--viewer-lib DIR``, a local copy of the npm package it names."""
    chain = knot[suffix]
    library = LIBRARIES["x3d" if suffix == "x3d" else "gltf"]
    base = f"http://127.0.0.1:{_closed_port()}/lib"
    page = write_page(site / chain.name, site / f"offline_{chain.page}", library=base)
    out = page_ui("alert", page=page.name)
    result = out["result"]
    message, text = f"{result}\n{console_text(out)}", _words(result["text"])
    module = next(path for name, path in library.imports if not name.endswith("/"))
    assert not result["ready"] and result["shown"], message
    assert f"Could not load the viewer library {base}/{module}" in text, message
    assert "Re-run lodconvert with --viewer-lib DIR" in text, message
    assert f"npm package {library.package}@{library.version}" in text, message
    assert f"lodconvert view {chain.name} --serve --viewer-lib DIR" in text, message


def test_viewer_page_says_where_it_waits_for_a_library(
    knot: dict[str, Chain], site: Path, page_ui: Drive
) -> None:
    """A library host that takes the connection and never answers (as behind a firewall that
    drops packets): after a while the page says which module it still waits for and how to
    do without the CDN, and has no error."""
    chain = knot["glb"]
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        base = f"http://127.0.0.1:{silent.getsockname()[1]}/lib"
        page = write_page(site / chain.name, site / f"waiting_{chain.page}", library=base)
        out = page_ui("alert", page=page.name)
    result = out["result"]
    message, text = f"{result}\n{console_text(out)}", _words(result["text"])
    assert not result["ready"] and not result["error"] and result["shown"], message
    assert f"Still waiting for the viewer library {base}/build/three.module.js" in text, message
    assert "Re-run lodconvert with --viewer-lib DIR" in text, message


@pytest.mark.parametrize("suffix", ["glb", "x3d"])
def test_viewer_page_names_a_missing_model(
    knot: dict[str, Chain], site: Path, page_ui: Drive, suffix: str
) -> None:
    """The output moved away after its page was written: over the view the page names its URL
    and the HTTP status it got."""
    asset = site / f"moved_knot.{suffix}"
    shutil.copyfile(site / knot[suffix].name, asset)
    package = LIBRARIES["x3d" if suffix == "x3d" else "gltf"].package
    page = write_page(asset, library=str(site / "node_modules" / package))
    asset.unlink()
    out = page_ui("alert", page=page.name)
    result = out["result"]
    message, text = f"{result}\n{console_text(out)}", _words(result["text"])
    assert not result["ready"] and result["shown"], message
    assert "Could not load the model http://127.0.0.1:" in text, message
    assert f"/{asset.name} (HTTP 404 " in text, message


BRIGHTNESS_STEP = 5.0
"""How much the mean brightness (Rec. 709 luma, 0-255) of an object's pixels may change when it
switches from the mesh to its first point level (3 % nearer and farther than the cutoff). Lit
alike, it changed by 1.3 for the knot (98.6 → 97.3) and 0.7 for the Stanford bunny (different
samples, edge pixels); unlit points showed their full colour instead, 16.7 brighter for the
knot (98.6 → 115.3) and 29.7 for the bunny. 5 is 4× the one and under a third of the other."""


def test_viewer_page_lights_points_like_the_mesh(
    knot: dict[str, Chain], drive: Drive, measure
) -> None:
    """Just before and just after the first cutoff of the glTF page (mesh, then points) the
    object's pixels are about as bright: the points are shaded with their normals too."""
    chain = knot["glb"]
    first = chain.obj["cutoffs"][0]
    stops = [{"distance": 0.97 * first}, {"distance": 1.03 * first}]
    out = drive("viewer", page=chain.page, stops=stops)
    seen = out["result"]["stops"]
    message = f"{seen}\n{console_text(out)}"
    names = chain.level_names()
    assert [s["objects"][0]["level"] for s in seen] == names[:2], message
    assert all(s["foreground"] >= MIN_VISIBLE for s in seen), message
    mesh, points = (s["brightness"] for s in seen)
    measure(
        "viewer page: mean brightness at the first cutoff (mesh → points)",
        f"{mesh:.1f} → {points:.1f} (allowed change {BRIGHTNESS_STEP:g})",
    )
    assert abs(points - mesh) < BRIGHTNESS_STEP, message
    assert not _errors(out), message


def _time_to_first_frame(site: Path, drive: Drive, measure, source: Path, name: str) -> None:
    """Convert ``source`` with default options to .x3d and .glb, record both sizes and the
    time from starting to load each to its first drawn frame in X_ITE and Babylon.js."""
    x3d = make_chain(site, source, f"{name}.x3d")
    glb = make_chain(site, source, f"{name}.glb")
    measure(
        f"{name}: file size .x3d / .glb",
        f"{x3d.size / 1e6:.2f} MB / {glb.size / 1e6:.2f} MB ({x3d.size / glb.size:.2f}x)",
    )
    x_ite = drive("x_ite", file=x3d.name)
    measure(f"{name}: X_ITE first frame (.x3d)", f"{x_ite['result']['firstFrameMs']:.0f} ms")
    babylon = drive("babylon", file=glb.name)["result"]
    loaded = f"all MSFT_lod levels loaded at {babylon['completeMs']:.0f} ms"
    measure(f"{name}: Babylon.js first frame (.glb)", f"{babylon['firstMs']:.0f} ms ({loaded})")
    measure("WebGL renderer", x_ite["renderer"])
    assert not _errors(x_ite), console_text(x_ite)


def test_time_to_first_frame_bunny(site: Path, drive: Drive, measure) -> None:
    _time_to_first_frame(site, drive, measure, stanford("bunny_bun_zipper.ply"), "bunny")


@pytest.mark.slow
def test_time_to_first_frame_dragon(site: Path, drive: Drive, measure) -> None:
    _time_to_first_frame(site, drive, measure, stanford("dragon_vrip.ply.gz"), "dragon")


def test_x_ite_draws_the_texture_of_a_textured_mesh(site: Path, drive: Drive) -> None:
    """A 2 × 2 quad in z = 0 with a black 4 × 4 texture whose top-left texel is white: seen from
    +z around that texel's place (x, y in [-1, -0.5] × [0.5, 1]), only the white texel shows.
    Per-vertex colours would show black only, and a texture upside down or mirrored would lie
    outside the view."""
    texture = np.zeros((4, 4, 4), dtype=np.uint8)
    texture[..., 3] = 255
    texture[0, 0, :3] = 255
    quad = Surface(
        vertices=np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=np.float64),
        faces=np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64),
        uv=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64),
        texture=texture,
    )
    chain = LodChain(
        object_id="quad",
        levels=[Level(name="LOD4", kind="mesh", mesh=quad)],
        cutoffs=[],
        origin=np.zeros(3),
        center=np.zeros(3),
        alpha=2 * 2**0.5,
        beta=1.0,
        gamma=1.0,
        xs=[],
        culled=False,
    )
    with (site / "textured_quad.x3d").open("wb") as handle:
        write_x3d([chain], handle, OutputInfo(generator="lodconvert tests", source="quad"))
    distance = 1.2
    out = drive(
        "x_ite",
        file="textured_quad.x3d",
        lod="quad_LOD",
        center=[-0.75, 0.75, 0.0],
        stops=[{"distance": distance, "level": 0}],
    )
    (seen,) = out["result"]["stops"]
    message = f"{seen}\n{console_text(out)}"
    # the texel is 0.5 units wide; the 300 px high canvas shows 2·d·tan(π/8) units
    side_px = 0.5 / (2 * distance * math.tan(math.pi / 8)) * 300
    assert seen["level"] == 0, message
    assert 0.5 * side_px**2 <= seen["foreground"] <= 2 * side_px**2, message
    assert not _errors(out), message


def low_poly_scenes(folder: Path) -> dict[str, Path]:
    """GLB inputs a user would try first: a box, a lone triangle and a 10×10 district of box
    buildings 8–20 m tall on 25 m lots."""
    scenes = {
        "box": trimesh.Scene([trimesh.creation.box((10.0, 10.0, 20.0))]),
        "triangle": trimesh.Scene(
            [trimesh.Trimesh([[0, 0, 0], [4, 0, 0], [0, 3, 0]], [[0, 1, 2]])]
        ),
        "district": trimesh.Scene(),
    }
    for i, j in itertools.product(range(10), range(10)):
        height = 8.0 + 12.0 * ((3 * i + 7 * j) % 10) / 9
        house = trimesh.creation.box((12.0, 16.0, height))
        house.apply_translation((25.0 * i, 25.0 * j, height / 2))
        scenes["district"].add_geometry(house, node_name=f"b{i}_{j}")
    paths = {}
    for name, scene in scenes.items():
        paths[name] = folder / f"{name}_source.glb"
        scene.export(paths[name])
    return paths


@pytest.mark.parametrize("suffix", ["x3d", "glb"])
def test_low_poly_objects_keep_their_mesh_near_and_far(
    site: Path, drive: Drive, suffix: str
) -> None:
    """A box, a triangle and a box district keep their mesh as their only level: near and far
    (beyond every object's last slot, 45 diagonals away) the page shows LOD4 and draws the
    objects; no point sprites. ``LODCONVERT_SHOTS=DIR`` keeps the screenshots there."""
    shots = os.environ.get("LODCONVERT_SHOTS")
    for name, source in low_poly_scenes(site).items():
        chain = make_chain(site, source, f"{name}.{suffix}")
        objects = chain.report["objects"]
        assert all([lv["kind"] for lv in o["levels"]] == ["mesh"] for o in objects), objects
        alpha = max(o["alpha"] for o in objects)
        stops = [{"distance": d} for d in (1.5 * alpha, 45.0 * alpha)]
        for stop, where in zip(stops, ("near", "far"), strict=True):
            if shots:
                stop["shot"] = str(Path(shots).resolve() / f"{name}_{suffix}_{where}.png")
        out = drive("viewer", page=chain.page, stops=stops)
        for seen in out["result"]["stops"]:
            message = f"{name} at {seen['distance']:.4g}: {seen}\n{console_text(out)}"
            assert {o["level"] for o in seen["objects"]} == {"LOD4"}, message
            assert seen["foreground"] > 0, message
        assert not _errors(out), console_text(out)


def test_x_ite_shows_a_district_and_a_building_switches_at_its_cutoffs(
    site: Path, drive: Drive
) -> None:
    """TUM Munich (290 CityGML LoD2 buildings) in X_ITE: the district is drawn, and its first
    building with a prism shows its LoD2 nearer than its cutoff and its LOD1 prism beyond."""
    from lodconvert.io import read_chains
    from lodconvert.io.frame import ROTATION
    from lodconvert.io.x3d import read_frame

    from ..conftest import SHARED

    source = SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip"
    if not source.exists():
        pytest.skip(f"{source} is absent (shared test data not checked out)")
    chain = make_chain(site, source, "tum.x3d")
    kinds = [[lv["kind"] for lv in obj["levels"]] for obj in chain.report["objects"]]
    chain.index = kinds.index(["source", "prism"])
    (written,) = [
        c for c in read_chains(site / chain.name, geometry=False) if c.object_id == chain.obj["id"]
    ]
    stops = chain.stops()
    frame = read_frame(site / chain.name)  # the district is y-up about its scene origin
    assert frame is not None
    out = drive(
        "x_ite",
        file=chain.name,
        lod=written.metadata["x3d"]["lod"],
        center=(ROTATION @ (np.asarray(chain.obj["origin"]) - frame.origin)).tolist(),
        stops=stops,
    )
    seen = out["result"]["stops"]
    message = f"{seen}\n{console_text(out)}"
    assert [s["level"] for s in seen] == [s["level"] for s in stops], message
    assert all(s["foreground"] >= MIN_VISIBLE for s in seen), message
    assert not _errors(out), message
