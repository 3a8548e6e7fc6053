"""The viewer page without a browser: what it is told about an output, which library it loads,
the ``--html`` and ``lodconvert view`` commands, and the local server. The page at work in real
browsers is tested in tests/browser."""

from __future__ import annotations

import contextlib
import json
import re
import signal
import subprocess
import sys
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lodconvert.errors import InputError, UsageError
from lodconvert.io.gltf import read_lod_gltf
from lodconvert.viewer import (
    LIBRARIES,
    LIBRARY_MOUNT,
    page_config,
    page_path,
    render_page,
    serve,
    write_page,
)

from .conftest import SAMPLE
from .test_cli import assert_one_line_error, run

CDN = "https://cdn.jsdelivr.net/npm/"
FAST = ("--resolution", "24,12,6")


@pytest.fixture(scope="module")
def outputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The sample as .x3d, .glb and .gltf of the same chain, culled."""
    folder = tmp_path_factory.mktemp("outputs")
    paths = {}
    for suffix in ("x3d", "glb", "gltf"):
        paths[suffix] = folder / f"knot.{suffix}"
        result = run(SAMPLE, "-o", paths[suffix], *FAST, "--cull", "1.5", "-q")
        assert result.returncode == 0, result.stderr
    return paths


def _embedded(page: str, element_id: str) -> Any:
    match = re.search(rf'<script [^>]*id="{element_id}">(.*?)</script>', page, re.S)
    assert match, element_id
    return json.loads(match.group(1))


def _import_map(page: str) -> dict[str, str]:
    match = re.search(r'<script type="importmap">(.*?)</script>', page, re.S)
    assert match
    return json.loads(match.group(1))["imports"]


# --- what the page is told ----------------------------------------------------------------------


def test_x3d_and_gltf_configs_describe_the_same_chain(outputs: dict[str, Path]) -> None:
    x3d, glb, gltf = (page_config(outputs[s]) for s in ("x3d", "glb", "gltf"))
    assert (x3d["format"], glb["format"]) == ("x3d", "gltf")
    assert glb["objects"] == gltf["objects"]
    (a,), (b,) = x3d["objects"], glb["objects"]
    for key in ("id", "attributes", "cutoffs", "culled", "levels", "alpha"):
        assert a[key] == b[key], key
    np.testing.assert_allclose(a["center"], b["center"])
    assert a["lod"] == "torus_knot_LOD" and a["culled"] and a["levels"][-1] == "LOD1"
    (obj,) = read_lod_gltf(outputs["glb"])
    np.testing.assert_array_equal(b["center"], obj.origin + np.array(obj.extras["center"]))
    assert b["cutoffs"] == obj.extras["cutoffs"] and len(b["ids"]) == len(b["levels"]) - 1
    assert b["points"][0] is None  # the mesh level
    for level, points in zip(obj.levels[1:], b["points"][1:], strict=True):
        assert points == {
            "px": level.extras["point_size_px"],
            "distance": level.extras["design_distance"],
        }
    # a mesh: its own axes, viewed first from +z
    view = {"height_px": 1080, "fov_y_deg": 45.0, "direction": [0.0, 0.0, 1.0]}
    assert glb["view"] == view == x3d["view"]
    assert glb["rotation"] == np.eye(3).tolist() == x3d["rotation"]


def test_config_reads_chain_metadata_inside_the_lod_too(
    outputs: dict[str, Path], tmp_path: Path
) -> None:
    """The writer puts the chain's MetadataSet on the Transform; one inside the LOD (as the
    X3D LOD node also allows) reads the same."""
    text = outputs["x3d"].read_text()
    lod = text.index("<LOD")
    start = text.rindex("<MetadataSet", 0, lod)
    end = text.index("</MetadataSet>", start) + len("</MetadataSet>")
    metadata, rest = text[start:end], text[:start] + text[end:]
    lod_end = rest.index(">", rest.index("<LOD")) + 1
    moved = tmp_path / "moved.x3d"
    moved.write_text(rest[:lod_end] + metadata + rest[lod_end:])
    assert page_config(moved) == page_config(outputs["x3d"])


def test_config_keeps_transform_offsets(outputs: dict[str, Path], tmp_path: Path) -> None:
    text = outputs["x3d"].read_text()
    shifted = tmp_path / "shifted.x3d"
    shifted.write_text(
        text.replace("<Scene>", '<Scene><Transform translation="500000 5400000 10">', 1).replace(
            "</Scene>", "</Transform></Scene>", 1
        )
    )
    (before,) = page_config(outputs["x3d"])["objects"]
    (after,) = page_config(shifted)["objects"]
    np.testing.assert_allclose(np.subtract(after["center"], before["center"]), [5e5, 5.4e6, 10])


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("model.ply", "ply", "is not a file lodconvert writes"),
        ("missing.glb", None, "no such file"),
        ("page.x3d", "<X3D><Scene/></X3D>", "is not an X3D file written by lodconvert"),
        ("broken.x3d", "<X3D><Scene>", "is not well-formed X3D"),
        ("broken.glb", "glTF", "truncated GLB"),
        ("other.gltf", '{"asset": {"version": "2.0"}}', "not a glTF written by lodconvert"),
    ],
)
def test_config_refuses_files_it_cannot_show(
    tmp_path: Path, name: str, content: str | None, message: str
) -> None:
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    with pytest.raises(InputError, match=message):
        page_config(path)


# --- the page and its library -------------------------------------------------------------------


@pytest.mark.parametrize(("suffix", "package"), [("x3d", "x_ite"), ("glb", "three")])
def test_page_uses_the_cdn_by_default(outputs: dict[str, Path], suffix: str, package: str) -> None:
    page = outputs[suffix].with_suffix(".html")
    text = render_page(outputs[suffix], page)
    library = LIBRARIES["x3d" if suffix == "x3d" else "gltf"]
    imports = _import_map(text)
    assert imports == {name: f"{library.cdn}/{path}" for name, path in library.imports}
    assert all(url.startswith(f"{CDN}{package}@{library.version}/") for url in imports.values())
    config = _embedded(text, "lodconvert-config")
    assert config["asset"] == f"./knot.{suffix}"
    named = {"package": package, "version": library.version}  # for the page's messages
    assert config == {**page_config(outputs[suffix]), "asset": f"./knot.{suffix}", "library": named}
    assert "<title>knot." in text and "lodconvertViewer" in text


def _package(root: Path, package: str) -> Path:
    """A fake npm package folder with the files the page imports."""
    folder = root / "node_modules" / package
    kind = "x3d" if package == "x_ite" else "gltf"
    for _, path in LIBRARIES[kind].imports:
        target = folder / path
        if path.endswith("/"):
            target.mkdir(parents=True, exist_ok=True)
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text("// stub")
    return folder


def test_page_uses_a_local_library_by_relative_url(
    outputs: dict[str, Path], tmp_path: Path
) -> None:
    folder = _package(tmp_path / "pages", "three")
    text = render_page(outputs["glb"], tmp_path / "pages" / "knot.html", str(folder))
    assert _import_map(text) == {
        "three": "./node_modules/three/build/three.module.js",
        "three/addons/": "./node_modules/three/examples/jsm/",
    }
    beside = render_page(outputs["glb"], tmp_path / "knot.html", str(folder))
    assert _import_map(beside)["three"] == "./pages/node_modules/three/build/three.module.js"


def test_library_outside_the_page_folder_is_served_or_refused(
    outputs: dict[str, Path], tmp_path: Path
) -> None:
    """A server of the page's folder cannot give a library outside it: only a page that
    :func:`serve` serves with the library mounted may use one."""
    folder = _package(tmp_path, "three")
    page = tmp_path / "pages" / "knot.html"
    with pytest.raises(UsageError, match=r"--viewer-lib .*: outside the page's folder"):
        render_page(outputs["glb"], page, str(folder))
    served = render_page(outputs["glb"], page, str(folder), served=True)
    assert _import_map(served) == {
        "three": f"{LIBRARY_MOUNT}/build/three.module.js",
        "three/addons/": f"{LIBRARY_MOUNT}/examples/jsm/",
    }


def test_page_uses_a_library_url_as_given(outputs: dict[str, Path]) -> None:
    text = render_page(outputs["x3d"], outputs["x3d"].with_suffix(".html"), "/libs/x_ite/")
    assert _import_map(text) == {"x_ite": "/libs/x_ite/dist/x_ite.min.mjs"}


@pytest.mark.parametrize("library", ["no/such/folder", "node_modules/x_ite"])
def test_bad_library_is_a_usage_error(
    outputs: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, library: str
) -> None:
    monkeypatch.chdir(tmp_path)
    _package(tmp_path, "x_ite")
    with pytest.raises(UsageError, match="--viewer-lib"):
        render_page(outputs["glb"], tmp_path / "page.html", library)


def test_embedded_text_cannot_close_its_script(outputs: dict[str, Path], tmp_path: Path) -> None:
    asset = tmp_path / "x<b>&{{config}}.x3d"
    asset.write_text(outputs["x3d"].read_text().replace("torus_knot", "a&lt;/script&gt;b"))
    text = render_page(asset, tmp_path / "page.html")
    assert text.count("</script>") == 3  # import map, config and page script only
    config = _embedded(text, "lodconvert-config")
    assert config["objects"][0]["id"] == "a</script>b"
    assert config["asset"] == "./x%3Cb%3E%26%7B%7Bconfig%7D%7D.x3d"
    assert "<title>x&lt;b&gt;&amp;{{config}}.x3d" in text  # placeholders are filled once


def test_page_scripts_do_not_close_their_element() -> None:
    from importlib import resources

    folder = resources.files("lodconvert.viewer")
    for name in ("viewer.js", "gltf.js", "x3d.js"):
        assert "</script" not in folder.joinpath(name).read_text(), name


# --- commands -----------------------------------------------------------------------------------


def test_html_option_writes_the_page_beside_the_output(tmp_path: Path) -> None:
    out = tmp_path / "model.glb"
    result = run(SAMPLE, "-o", out, *FAST, "--html")
    assert result.returncode == 0, result.stderr
    page = tmp_path / "model.glb.html"
    assert result.stderr.splitlines()[-1].endswith(f" and {page}")
    assert _embedded(page.read_text(), "lodconvert-config")["asset"] == "./model.glb"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.glb", "model.glb.html"]


def test_viewer_lib_needs_html(tmp_path: Path) -> None:
    result = run(SAMPLE, "-o", tmp_path / "m.x3d", "--viewer-lib", "https://example.org/x_ite")
    assert_one_line_error(result, 2, "--viewer-lib", "--html")


def test_bad_viewer_lib_fails_before_baking(tmp_path: Path) -> None:
    result = run(SAMPLE, "-o", tmp_path / "m.x3d", "--html", "--viewer-lib", str(tmp_path))
    assert_one_line_error(result, 2, "--viewer-lib", "dist/x_ite.min.mjs")
    assert list(tmp_path.iterdir()) == []


def test_viewer_lib_outside_the_page_folder_fails_before_writing(
    outputs: dict[str, Path], tmp_path: Path
) -> None:
    """Without --serve, a library folder outside the page's folder is refused, in one line,
    before anything is written: by the main command before baking, by view before the page."""
    library = _package(tmp_path / "elsewhere", "x_ite")
    out = tmp_path / "out"
    out.mkdir()
    result = run(SAMPLE, "-o", out / "m.x3d", *FAST, "--html", "--viewer-lib", library)
    assert_one_line_error(result, 2, f"--viewer-lib {library}", "outside the page's folder")
    assert list(out.iterdir()) == []
    asset = out / "knot.x3d"
    asset.write_bytes(outputs["x3d"].read_bytes())
    result = run("view", asset, "--viewer-lib", library)
    assert_one_line_error(result, 2, f"--viewer-lib {library}", "--serve")
    assert list(out.iterdir()) == [asset]


def test_view_command_writes_a_page(outputs: dict[str, Path], tmp_path: Path) -> None:
    page = tmp_path / "view.html"
    result = run("view", outputs["x3d"], "-o", page, "--viewer-lib", "https://example.org/x")
    assert result.returncode == 0, result.stderr
    assert f"wrote {page}" in result.stderr
    assert _import_map(page.read_text()) == {"x_ite": "https://example.org/x/dist/x_ite.min.mjs"}


def test_view_command_on_bad_input(tmp_path: Path) -> None:
    truncated = tmp_path / "t.glb"
    truncated.write_bytes(b"glTF\x02\x00\x00\x00")
    assert_one_line_error(run("view", truncated), 1, str(truncated), "truncated GLB")
    assert_one_line_error(run("view", tmp_path / "x.ply"), 1, "is not a file lodconvert writes")
    assert list(tmp_path.iterdir()) == [truncated]


def test_write_page_default_path(outputs: dict[str, Path]) -> None:
    page = write_page(outputs["gltf"])
    assert page == outputs["gltf"].parent / "knot.gltf.html" == page_path(outputs["gltf"])
    assert page.stat().st_size > 1000


def test_views_of_two_formats_of_one_name_keep_both_pages(
    outputs: dict[str, Path], tmp_path: Path
) -> None:
    """``lodconvert view a.x3d`` then ``lodconvert view a.glb``: two pages, each of its own."""
    for suffix in ("x3d", "glb"):
        asset = tmp_path / f"a.{suffix}"
        asset.write_bytes(outputs[suffix].read_bytes())
        result = run("view", asset)
        assert result.returncode == 0, result.stderr
    for suffix in ("x3d", "glb"):
        config = _embedded((tmp_path / f"a.{suffix}.html").read_text(), "lodconvert-config")
        assert config["asset"] == f"./a.{suffix}"
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "a.glb",
        "a.glb.html",
        "a.x3d",
        "a.x3d.html",
    ]


# --- serving ------------------------------------------------------------------------------------


def test_serve_gives_files_with_module_and_model_types(outputs: dict[str, Path]) -> None:
    folder = outputs["glb"].parent
    (folder / "lib.mjs").write_text("export default 1;\n")
    with serve(folder) as base:
        assert base.startswith("http://127.0.0.1:")
        for name, kind in (("knot.glb", "model/gltf-binary"), ("lib.mjs", "text/javascript")):
            with urllib.request.urlopen(f"{base}/{name}") as response:
                assert response.headers["Content-Type"] == kind
                assert response.read() == (folder / name).read_bytes()


@contextlib.contextmanager
def view_served(*args: str | Path) -> Iterator[str]:
    """Run ``lodconvert view ARGS --serve`` while the ``with`` block runs; yields the URL it
    prints, then stops it with Ctrl-C (SIGINT) and checks that it reports the interruption."""
    command = [sys.executable, "-m", "lodconvert", "view", *map(str, args), "--serve"]
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    ) as proc:
        assert proc.stdout is not None
        url = proc.stdout.readline().strip()
        try:
            if not url:
                pytest.fail(f"lodconvert view --serve printed no URL:\n{proc.communicate()[1]}")
            yield url
        finally:
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate()
    assert proc.returncode == 130 and "interrupted" in err, err


def test_view_serve_prints_a_local_url_until_interrupted(outputs: dict[str, Path]) -> None:
    with view_served(outputs["glb"]) as url:
        assert url.startswith("http://127.0.0.1:") and url.endswith("/knot.glb.html")
        with urllib.request.urlopen(url) as response:
            assert b"lodconvert-config" in response.read()


def test_view_serve_serves_a_library_outside_the_page_folder(
    outputs: dict[str, Path], tmp_path: Path
) -> None:
    """The page imports the library from the URL path that the server maps to its folder."""
    library = _package(tmp_path / "elsewhere", "three")
    (library / "build" / "three.module.js").write_text("export const REVISION = 'stub';\n")
    asset = tmp_path / "out" / "knot.glb"
    asset.parent.mkdir()
    asset.write_bytes(outputs["glb"].read_bytes())
    with view_served(asset, "--viewer-lib", library) as url:
        base = url.rsplit("/", 1)[0]
        with urllib.request.urlopen(url) as response:
            imports = _import_map(response.read().decode())
        assert imports["three"] == f"{LIBRARY_MOUNT}/build/three.module.js"
        with urllib.request.urlopen(base + imports["three"]) as response:
            assert response.headers["Content-Type"] == "text/javascript"
            assert response.read() == (library / "build" / "three.module.js").read_bytes()
        with urllib.request.urlopen(f"{base}/knot.glb") as response:  # the page's folder too
            assert response.read() == asset.read_bytes()
    assert sorted(p.name for p in asset.parent.iterdir()) == ["knot.glb", "knot.glb.html"]


def test_html_option_writes_a_cesium_page_inside_a_tileset(tmp_path: Path) -> None:
    """A tileset's page goes inside its folder (served with it), loads CesiumJS (the CDN by
    default) and tells it the tileset's --sse and point shading; the folder still checks, and a
    later run replaces it, page and all."""
    from .test_tiles import FAST as TILES_FAST
    from .test_tiles import RD_NAP, inputs

    tileset = tmp_path / "tiles" / "tileset.json"
    flags = (*RD_NAP, *TILES_FAST, "--hlod-kind", "points", "--sse", "12")
    result = run(*inputs("multi_lod"), "-o", tileset, *flags, "--html")
    assert result.returncode == 0, result.stderr
    page = tileset.parent / "tileset.json.html"
    text = page.read_text()
    config = _embedded(text, "lodconvert-config")
    extras = json.loads(tileset.read_text())["asset"]["extras"]["lodconvert"]
    assert config["asset"] == "./tileset.json" and config["sse"] == 12.0
    assert config["pointCloudShading"] == extras["point_cloud_shading"]
    assert config["pointCloudShading"]["geometricErrorScale"] == pytest.approx(1.5 / 12)
    assert _import_map(text) == {"cesium": f"{CDN}cesium@1.145.0/Build/Cesium/index.js"}
    names = sorted(p.name for p in tileset.parent.iterdir())
    assert names == [".lodconvert-manifest.json", "tiles", "tileset.json", page.name]
    assert run("validate", tileset).returncode == 0
    result = run(*inputs("multi_lod"), "-o", tileset, *RD_NAP, *TILES_FAST)
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in tileset.parent.iterdir()) == [
        ".lodconvert-manifest.json",
        "tiles",
        "tileset.json",
    ]


def test_view_command_writes_a_tilesets_page_and_refuses_other_json(tmp_path: Path) -> None:
    from .test_tiles import convert

    tileset = convert("multi_lod", tmp_path / "tiles")
    result = run("view", tileset, "--viewer-lib", "/node_modules/cesium")
    assert result.returncode == 0, result.stderr
    page = tileset.parent / "tileset.json.html"
    assert _import_map(page.read_text()) == {"cesium": "/node_modules/cesium/Build/Cesium/index.js"}
    config = _embedded(page.read_text(), "lodconvert-config")
    assert config["library"]["base"] == "/node_modules/cesium/Build/Cesium/"
    assert config["sse"] == 16.0
    other = tmp_path / "other" / "tileset.json"
    other.parent.mkdir()
    other.write_text('{"asset": {"version": "1.1", "generator": "someone else"}, "root": {}}')
    assert_one_line_error(run("view", other), 1, str(other), "not a tileset lodconvert wrote")
    assert list(other.parent.iterdir()) == [other]
