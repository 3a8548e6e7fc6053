"""3D Tiles 1.1 output: real sample cities pass the official validator with no error and no
warning, tiles sit within 1 mm of pyproj's ECEF of the source, geometricError falls strictly
from parent to child and follows --sse, features carry ids and typed attributes, bad outputs
and cities without a CRS are refused in one line with nothing written, and output is
byte-identical across runs and worker counts."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import itertools
import json
import os
import pickle
import shutil
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
import pytest
from scipy.spatial import cKDTree

from lodconvert.io import read_scene
from lodconvert.io.crs import pyproj_crs
from lodconvert.io.gltf.binary import accessor_values as accessor
from lodconvert.io.tiles import writer as tiles_writer
from lodconvert.io.tiles.check import frame_points, read_glb
from lodconvert.io.tiles.records import TileRecords
from lodconvert.ranges import REFERENCE_VIEW
from lodconvert.validate import validate_file
from tests.conftest import SHARED, require, shared_data
from tests.test_cityjson import city
from tests.test_cli import assert_one_line_error, run
from tests.test_workers import _workers_of

DATA = SHARED / "data"
VALIDATOR = SHARED / "tools" / "3d-tiles-validator" / "validate.sh"
SAMPLES = {
    "multi_lod": ("cityjson/multi_lod_10bldg.city.json", "EPSG:7415"),  # declares none
    "kit": ("citygml/kit_testcases_lod2_100bldg_v3.gml", None),
    "plateau": ("citygml/plateau_53394517_bldg_lod012_v3.gml", None),
    "sig3d": ("citygml/sig3d_house_lod0-4", None),
    "potsdam": ("citygml/potsdam_lod1_v1.gml", None),
    "tum": ("citygml/tum_munich_lod2_v2.zip", None),
    "delft": ("cityjson/delft.city.json", None),
}
RD_NAP = ("--crs", "EPSG:7415")
SLOW = ("potsdam", "tum", "delft", "kit", "plateau", "sig3d")
FAST = ("--levels", "2", "--workers", "1", "-q")


def inputs(name: str) -> list[Path]:
    """The input files of sample ``name`` (a folder: its files, one scene), or skip."""
    path = shared_data(DATA / SAMPLES[name][0])
    return sorted(path.glob("*.gml")) if path.is_dir() else [path]


def convert(name: str, out: Path, *flags: str) -> Path:
    """``out/tileset.json`` converted from sample ``name``; the run must succeed."""
    tileset = out / "tileset.json"
    crs = SAMPLES[name][1]
    result = run(*inputs(name), "-o", tileset, *(("--crs", crs) if crs else ()), *FAST, *flags)
    assert result.returncode == 0, result.stderr
    return tileset


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], Path]:
    """Each sample converted once for the module's tests."""
    done: dict[str, Path] = {}

    def get(name: str) -> Path:
        if name not in done:
            done[name] = convert(name, tmp_path_factory.mktemp(name))
        return done[name]

    return get


def official(tileset: Path, report: Path) -> dict[str, Any]:
    """The official validator's report of ``tileset``."""
    require(VALIDATOR.exists(), f"{VALIDATOR} is absent (shared tools not checked out)")
    require(shutil.which("node") is not None, "node is not on PATH (the 3D Tiles validator)")
    subprocess.run(
        [str(VALIDATOR), str(tileset), str(report)], capture_output=True, text=True, timeout=600
    )
    require(report.exists(), "the 3D Tiles validator could not run (npm install failed?)")
    return json.loads(report.read_text())


def tiles(tile: dict, frame: np.ndarray, base: Path) -> Iterator[tuple[dict, np.ndarray, Path]]:
    """Every tile under ``tile`` with its frame (transforms multiplied down) and the tileset
    file it is in, external tilesets followed."""
    if tile.get("transform") is not None:
        frame = frame @ np.asarray(tile["transform"], dtype=np.float64).reshape(4, 4).T
    yield tile, frame, base
    uri = tile.get("content", {}).get("uri", "")
    if uri.endswith(".json"):
        yield from tiles(json.loads((base.parent / uri).read_text())["root"], frame, base / uri)
    for child in tile.get("children", []):
        yield from tiles(child, frame, base)


def features(document: dict, blob: bytes) -> list[dict[str, Any]]:
    """The rows of a GLB's property table: each feature's id and its INT64, FLOAT64 and
    STRING values (absent ones left out)."""
    metadata = document["extensions"]["EXT_structural_metadata"]
    table = metadata["propertyTables"][0]
    definitions = metadata["schema"]["classes"][table["class"]]["properties"]
    views = document["bufferViews"]

    def view(index: int) -> bytes:
        start = views[index].get("byteOffset", 0)
        return blob[start : start + views[index]["byteLength"]]

    rows: list[dict[str, Any]] = [{} for _ in range(table["count"])]
    for name, column in table["properties"].items():
        definition = definitions[name]
        if definition["type"] == "STRING":
            offsets = np.frombuffer(view(column["stringOffsets"]), dtype=np.uint32)
            data = view(column["values"])
            values: list[Any] = [data[a:b].decode() for a, b in itertools.pairwise(offsets)]
        elif definition.get("componentType") in ("INT64", "FLOAT64"):
            dtype = np.int64 if definition["componentType"] == "INT64" else np.float64
            values = np.frombuffer(view(column["values"]), dtype=dtype).tolist()
        else:
            continue
        for row, value in zip(rows, values, strict=True):
            if value != definition.get("noData"):
                row[definition["name"]] = value
    return rows


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=[pytest.mark.slow] if n in SLOW else []) for n in SAMPLES]
)
def test_sample_cities_pass_the_official_validator_with_no_warning(
    name: str, converted: Callable[[str], Path], tmp_path: Path
) -> None:
    tileset = converted(name)
    report = official(tileset, tmp_path / "report.json")
    problems = [i for i in report["issues"] if i["severity"] in ("ERROR", "WARNING")]
    assert (report["numErrors"], report["numWarnings"]) == (0, 0), problems[:5]
    assert validate_file(tileset) == []


@pytest.mark.parametrize("name", ["multi_lod", "kit"])
def test_content_lies_within_a_millimetre_of_pyprojs_ecef_of_the_source(
    name: str, converted: Callable[[str], Path]
) -> None:
    """1,000 leaf vertices, through their tiles' transforms, against the ECEF pyproj makes of
    the source's own vertices (RD New + NAP: grid convergence −0.8°, so projected offsets taken
    for ENU metres would be metres off)."""
    tileset = converted(name)
    scene = read_scene(inputs(name)[0], crs=SAMPLES[name][1])
    vertical = scene.attributes.get("vertical_crs")
    source = pyproj_crs(scene.crs, vertical)
    points = np.concatenate(
        [
            node.geometry.vertices + node.offset
            for top in scene.nodes
            for node in top.walk()
            if node.geometry is not None
        ]
    )
    to_ecef = pyproj.Transformer.from_crs(source, "EPSG:4978", always_xy=True)
    expected = np.stack(to_ecef.transform(*points.T), axis=1)
    placed = []
    root = json.loads(tileset.read_text())["root"]
    for tile, frame, _ in tiles(root, np.eye(4), tileset):
        if tile.get("content", {}).get("uri", "").endswith("_finest.glb"):
            document, blob = read_glb(tileset.parent / tile["content"]["uri"])
            placed.append(frame_points(frame, _positions(document, blob)))
    ours = np.concatenate(placed)
    chosen = ours[np.random.default_rng(0).choice(len(ours), min(1000, len(ours)), False)]
    distance, _ = cKDTree(expected).query(chosen)
    assert len(chosen) >= min(1000, len(points) // 2)
    assert distance.max() <= 1e-3, distance.max()


def _positions(document: dict, blob: bytes) -> np.ndarray:
    return np.concatenate(
        [
            accessor(document, blob, primitive["attributes"]["POSITION"])
            for mesh in document["meshes"]
            for primitive in mesh["primitives"]
        ]
    ).astype(np.float64)


def test_geometric_error_falls_from_parent_to_child_and_follows_sse(
    converted: Callable[[str], Path], tmp_path: Path
) -> None:
    tileset = converted("kit")
    data = json.loads(tileset.read_text())
    assert data["geometricError"] >= data["root"]["geometricError"] > 0
    every = list(tiles(data["root"], np.eye(4), tileset))
    for tile, _, _ in every:
        assert tile["refine"] == "REPLACE"
        for child in tile.get("children", []):
            assert child["geometricError"] < tile["geometricError"]
        if not tile.get("children"):
            assert tile["geometricError"] == 0.0
    # a cell's tile refines where the cell switches: GE = 16 · cutoff / focal_px
    report = tmp_path / "report.json"
    doubled = convert("kit", tmp_path / "sse32", "--sse", "32", "--report", str(report))
    cells = {cell["id"]: cell for cell in json.loads(report.read_text())["hlod"]["cells"]}
    found = 0
    for tile, _, _ in tiles(json.loads(doubled.read_text())["root"], np.eye(4), doubled):
        cell = cells.get(tile.get("extras", {}).get("cell"))
        if cell is not None:
            wanted = 32 * cell["cutoffs"][0] / REFERENCE_VIEW.focal_px
            assert tile["geometricError"] == pytest.approx(wanted, rel=1e-12)
            found += 1
    assert found == len(cells) > 0


def test_leaves_carry_each_buildings_id_and_typed_attributes(
    converted: Callable[[str], Path],
) -> None:
    tileset = converted("multi_lod")
    scene = read_scene(inputs("multi_lod")[0], crs="EPSG:7415")
    source = {node.id: node.attributes for node in scene.nodes}
    rows = []
    for leaf in sorted((tileset.parent / "tiles").glob("*_finest.glb")):
        document, blob = read_glb(leaf)
        properties = document["extensions"]["EXT_structural_metadata"]["schema"]["classes"]
        types = {p["name"]: p for p in properties["cityObject"]["properties"].values()}
        assert types["oorspronkelijk_bouwjaar"]["componentType"] == "INT64"
        assert types["h_maaiveld"]["componentType"] == "FLOAT64"
        assert types["geconstateerd"]["type"] == "BOOLEAN"
        rows.extend(features(document, blob))
    assert sorted(row["id"] for row in rows) == sorted(source)
    for row in rows:
        attributes = source[row["id"]]
        assert row["type"] == "Building"
        assert row["oorspronkelijk_bouwjaar"] == attributes["oorspronkelijk_bouwjaar"]
        assert row["h_maaiveld"] == attributes["h_maaiveld"]
        assert row["dak_type"] == attributes["dak_type"]


@pytest.mark.slow
def test_a_large_tree_is_split_into_external_tilesets(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(tiles_writer, "EXTERNAL_BYTES", 1000)
    tileset = convert("kit", tmp_path / "out", "--hlod", "50")
    data = json.loads(tileset.read_text())
    references = [c["content"]["uri"] for c in data["root"]["children"]]
    assert references and all(uri.endswith(".json") for uri in references)
    assert validate_file(tileset) == []
    report = official(tileset, tmp_path / "report.json")
    assert (report["numErrors"], report["numWarnings"]) == (0, 0), report["issues"][:5]


@pytest.mark.parametrize(
    "name, flags",
    [
        ("multi_lod", ()),
        pytest.param("kit", ("--hlod", "50"), marks=pytest.mark.slow),
        pytest.param("kit", ("--hlod", "50,200"), marks=pytest.mark.slow),
    ],
)
def test_output_is_byte_identical_across_runs_and_worker_counts(
    tmp_path: Path, name: str, flags: tuple[str, ...]
) -> None:
    """The same files for any worker count, tiles made in worker processes included (KIT in
    50 m cells: 8 tiles, some made while others are in flight)."""

    def files(out: Path) -> dict[str, bytes]:
        return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*"))
                if p.is_file()}  # fmt: skip

    one = convert(name, tmp_path / "one", *flags).parent
    again = convert(name, tmp_path / "again", *flags).parent
    two = convert(name, tmp_path / "two", *flags, "--workers", "2").parent
    assert files(one) == files(again) == files(two)
    assert len(files(one)) > 2


@pytest.mark.slow
def test_a_two_worker_run_makes_its_tiles_in_its_two_workers(tmp_path: Path) -> None:
    """Tiles are made by the worker processes that bake, while they bake: a ``--workers 2``
    tileset run never has more than two of them alive."""
    alive: list[int] = []
    stop = threading.Event()

    def watch() -> None:
        while not stop.is_set():
            with contextlib.suppress(OSError):  # a process ended while it was looked at
                alive.append(len(_workers_of(os.getpid())))
            stop.wait(0.01)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        tileset = convert("multi_lod", tmp_path, "--hlod", "20", "--workers", "2")
    finally:
        stop.set()
        watcher.join()
    assert len(list((tileset.parent / "tiles").glob("*.glb"))) > 2
    assert max(alive) == 2


SENT = """
import sys
from collections import Counter
from lodconvert import tasks
from lodconvert.cli import main
real, sent = tasks.pickled, Counter()
def pickled(message):
    sent[type(message).__name__] += 1
    return real(message)
tasks.pickled = pickled
if __name__ == "__main__":
    code = main(sys.argv[1:])
    print(dict(sent), flush=True)
    sys.exit(code)
"""
"""The command line, printing how many of each kind of message its main process sent."""


@pytest.mark.slow
def test_with_workers_a_coarsest_cells_tiles_are_made_where_it_is_baked(tmp_path: Path) -> None:
    """With workers, the task that bakes a coarsest cell makes its tiles and gives them back
    with it: the main process sends no tile task (the objects' geometry goes out once, to
    their cell), and the tileset is the one a single process writes."""
    tileset = tmp_path / "two" / "tileset.json"
    [source] = inputs("multi_lod")
    flags = ("--crs", "EPSG:7415", "--hlod", "20,80", *FAST)
    command = [sys.executable, "-c", SENT, str(source), "-o", str(tileset), *flags]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    result = subprocess.run(
        [*command, "--workers", "2"], capture_output=True, text=True, env=env, check=False
    )
    assert result.returncode == 0, result.stderr
    sent = json.loads(result.stdout.strip().splitlines()[-1].replace("'", '"'))
    assert sent.get("CellTask", 0) > 0 and "TileTask" not in sent
    one = convert("multi_lod", tmp_path / "one", "--hlod", "20,80")

    def files(out: Path) -> dict[str, bytes]:
        return {str(p.relative_to(out)): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    written = files(tileset.parent)
    assert written == files(one.parent) and sum(n.endswith(".glb") for n in written) > 2


@pytest.mark.slow
def test_a_previous_tileset_of_ours_is_replaced(tmp_path: Path) -> None:
    out = tmp_path / "out"
    convert("multi_lod", out, "--hlod", "50")
    before = {p.name for p in (out / "tiles").iterdir()}
    convert("multi_lod", out, "--hlod", "2000")
    after = {p.name for p in (out / "tiles").iterdir()}
    assert before != after
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def _unchanged(folder: Path) -> Callable[[], None]:
    """A check that nothing under ``folder`` (or beside it) changed since now."""
    before = sorted(str(p) for p in folder.parent.rglob("*"))

    def check() -> None:
        assert sorted(str(p) for p in folder.parent.rglob("*")) == before

    return check


def test_a_folder_that_is_not_ours_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "photos"
    out.mkdir()
    (out / "holiday.jpg").write_bytes(b"\xff\xd8")
    unchanged = _unchanged(out)
    result = run(*inputs("multi_lod"), "-o", out / "tileset.json", *RD_NAP, *FAST)
    assert_one_line_error(result, 1, "photos", "holiday.jpg", "not a tileset lodconvert wrote")
    unchanged()


def test_a_folder_holding_the_input_is_refused(tmp_path: Path) -> None:
    city = tmp_path / "city"
    city.mkdir()
    shutil.copy(inputs("multi_lod")[0], city / "district.city.json")
    unchanged = _unchanged(city)
    result = run(city / "district.city.json", "-o", city / "tileset.json", *RD_NAP, *FAST)
    assert_one_line_error(result, 1, "district.city.json")
    unchanged()


def test_a_tileset_of_ours_holding_the_input_is_not_replaced(tmp_path: Path) -> None:
    out = convert("multi_lod", tmp_path / "out").parent
    tile = sorted((out / "tiles").glob("*.glb"))[0]  # a file of ours, listed in its manifest
    unchanged = _unchanged(out)
    result = run(tile, "-o", out / "tileset.json", *RD_NAP, *FAST)
    assert_one_line_error(result, 1, tile.name, "an input of this run")
    moved = out / "tiles" / "district.city.json"
    shutil.copy(inputs("multi_lod")[0], moved)  # a file of the user's: not ours to replace
    result = run(moved, "-o", out / "tileset.json", *RD_NAP, *FAST)
    assert_one_line_error(result, 1, "district.city.json", "not written by lodconvert")
    moved.unlink()
    unchanged()


def test_a_city_of_one_building_is_one_cell_over_its_blocks_and_leaf(
    converted: Callable[[str], Path],
) -> None:
    tileset = converted("plateau")  # one building, in geographic coordinates (JGD2011)
    root = json.loads(tileset.read_text())["root"]
    uris = [tile.get("content", {}).get("uri") for tile, _, _ in tiles(root, np.eye(4), tileset)]
    assert uris[0] is None and uris[1].endswith(".glb") and uris[-1].endswith("_finest.glb")
    document, blob = read_glb(tileset.parent / uris[-1])
    assert len(features(document, blob)) == 1


def test_an_unwritable_folder_is_refused(tmp_path: Path) -> None:
    if os.geteuid() == 0:
        pytest.skip("root writes into any folder")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        result = run(*inputs("multi_lod"), "-o", locked / "out" / "tileset.json", *RD_NAP)
        assert_one_line_error(result, 1, "not writable")
    finally:
        locked.chmod(0o755)


def test_other_json_names_are_a_usage_error(tmp_path: Path) -> None:
    result = run(*inputs("multi_lod"), "-o", tmp_path / "city.json", *RD_NAP, *FAST)
    assert_one_line_error(result, 2, "tileset.json")
    assert list(tmp_path.iterdir()) == []


def test_a_missing_input_is_one_line_with_nothing_written(tmp_path: Path) -> None:
    result = run(tmp_path / "none.city.json", "-o", tmp_path / "out" / "tileset.json")
    assert_one_line_error(result, 1, "none.city.json", "no such file")
    assert list(tmp_path.iterdir()) == []


def test_a_city_without_a_crs_is_refused_with_nothing_written(tmp_path: Path) -> None:
    result = run(*inputs("multi_lod"), "-o", tmp_path / "out" / "tileset.json", *FAST)
    assert result.returncode == 1
    errors = [line for line in result.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and "no CRS" in errors[0] and "multi_lod" in errors[0], errors
    assert "Traceback" not in result.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_crs_that_cannot_be_placed_on_the_globe_is_refused(tmp_path: Path) -> None:
    """A CRS of Mars has no way to the Earth's ECEF."""
    result = run(
        *inputs("multi_lod"), "-o", tmp_path / "out" / "tileset.json", "--crs", "IAU_2015:49910",
        *FAST,
    )  # fmt: skip
    assert result.returncode == 1, result.stderr
    errors = [line for line in result.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and "cannot be placed on the globe" in errors[0], errors
    assert list(tmp_path.iterdir()) == []


def test_the_tileset_folder_is_readable_by_others_as_a_web_server_needs(
    converted: Callable[[str], Path],
) -> None:
    folder = converted("multi_lod").parent
    assert folder.stat().st_mode & 0o777 == 0o755
    assert (folder / "tiles").stat().st_mode & 0o005 == 0o005


def test_the_current_folder_is_not_replaced(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    result = run(*inputs("multi_lod"), "-o", "tileset.json", *RD_NAP, *FAST)
    assert_one_line_error(result, 2, "current folder", "tiles/tileset.json")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("output", "flags", "words"),
    [
        ("model.glb", ("--sse", "8"), ("--sse is for 3D Tiles",)),
        ("out/tileset.json", ("--sse", "0"), ("positive",)),
        ("out/tileset.json", ("--html", "--viewer-lib", "nowhere"), ("nowhere", "not a folder")),
    ],
)
def test_tileset_options_are_checked_before_any_work(
    tmp_path: Path, output: str, flags: tuple[str, ...], words: tuple[str, ...]
) -> None:
    result = run(*inputs("multi_lod"), "-o", tmp_path / output, *RD_NAP, *FAST, *flags)
    assert_one_line_error(result, 2, *words)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("tamper", "code"),
    [
        ("child_error", "GEOMETRIC_ERROR"),
        ("tileset_error", "GEOMETRIC_ERROR"),
        ("shrunk_box", "VOLUME"),
        ("missing_tile", "URI"),
        ("not_json", "JSON"),
    ],
)
def test_validate_finds_what_the_official_validator_does_not(
    converted: Callable[[str], Path], tmp_path: Path, tamper: str, code: str
) -> None:
    out = tmp_path / "copy"
    shutil.copytree(converted("kit").parent, out)
    tileset = out / "tileset.json"
    data = json.loads(tileset.read_text())
    cell = data["root"]["children"][0]
    if tamper == "child_error":
        cell["children"][0]["geometricError"] = cell["geometricError"] * 2
    elif tamper == "tileset_error":
        data["geometricError"] = data["root"]["geometricError"] / 2
    elif tamper == "shrunk_box":
        cell["boundingVolume"]["box"][3:] = [0.5, 0, 0, 0, 0.5, 0, 0, 0, 0.5]
    elif tamper == "missing_tile":
        (out / cell["content"]["uri"]).unlink()
    tileset.write_text("{" if tamper == "not_json" else json.dumps(data))
    result = run("validate", tileset)
    assert result.returncode == 1
    assert f"error {code}" in result.stdout, result.stdout
    assert "Traceback" not in result.stdout + result.stderr


def test_point_far_levels_are_points_tiles_sized_for_cesium(tmp_path: Path) -> None:
    tileset = convert("multi_lod", tmp_path / "out", "--hlod-kind", "points")
    data = json.loads(tileset.read_text())
    cell = data["root"]["children"][0]
    document, _ = read_glb(tileset.parent / cell["content"]["uri"])
    primitive = document["meshes"][0]["primitives"][0]
    assert primitive["mode"] == 0 and set(primitive["attributes"]) == {"POSITION", "COLOR_0"}
    shading = data["asset"]["extras"]["lodconvert"]["point_cloud_shading"]
    assert shading["geometricErrorScale"] == cell["extras"]["point_size_px"] / 16
    report = official(tileset, tmp_path / "report.json")
    assert (report["numErrors"], report["numWarnings"]) == (0, 0), report["issues"][:5]


@pytest.mark.slow
def test_block_far_levels_pass_the_official_validator_and_are_byte_identical(
    tmp_path: Path,
) -> None:
    """TUM Munich with ``--hlod-kind blocks``: every cell's far tile is its block proxy (one
    coloured triangle primitive, as light as the report says), the official validator finds
    no error or warning and ours none, and a second run writes the same bytes."""
    report_path = tmp_path / "report.json"
    tileset = convert("tum", tmp_path / "one", "--hlod-kind", "blocks", "--report", report_path)
    cells = {cell["id"]: cell for cell in json.loads(report_path.read_text())["hlod"]["cells"]}
    assert {cell["kind"] for cell in cells.values()} == {"blocks"}
    found = [t for t, _, _ in tiles(json.loads(tileset.read_text())["root"], np.eye(4), tileset)
             if "cell" in t.get("extras", {})]  # fmt: skip
    assert {t["extras"]["cell"] for t in found} == set(cells)
    for tile in found:
        document, _ = read_glb(tileset.parent / tile["content"]["uri"])
        (primitive,) = document["meshes"][0]["primitives"]
        assert primitive.get("mode", 4) == 4 and "COLOR_0" in primitive["attributes"]
        positions = document["accessors"][primitive["attributes"]["POSITION"]]
        assert positions["count"] == cells[tile["extras"]["cell"]]["counts"]["blocks"]
    report = official(tileset, tmp_path / "validator.json")
    assert (report["numErrors"], report["numWarnings"]) == (0, 0), report["issues"][:5]
    assert validate_file(tileset) == []
    again = convert("tum", tmp_path / "again", "--hlod-kind", "blocks")
    for path in sorted(p for p in tileset.parent.rglob("*") if p.is_file()):
        assert path.read_bytes() == (again.parent / path.relative_to(tileset.parent)).read_bytes()


def test_a_city_of_broken_buildings_only_writes_no_tileset(tmp_path: Path) -> None:
    broken = {"type": "MultiSurface", "lod": "2", "boundaries": [[[0, 1, 2]]]}
    document = city(
        {"a": {"type": "Building", "geometry": [broken]}},
        [[8500.0, 44600.0, 0.0], [8501.0, 44600.0, 0.0], [1e308, 44601.0, 0.0]],
        transform={"scale": [10, 10, 10], "translate": [0, 0, 0]},  # 1e308 · 10: past float64
        metadata={"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/7415"},
    )
    source = tmp_path / "broken.city.json"
    source.write_text(json.dumps(document))
    result = run(source, "-o", tmp_path / "out" / "tileset.json", *FAST)
    assert_one_line_error(result, 1, "broken.city.json", "vertex 2")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.city.json"]


def test_the_tileset_states_the_vertical_datum_of_several_inputs(
    converted: Callable[[str], Path],
) -> None:
    """SIG3D's five files declare EPSG:25832 + EPSG:5783 (DHHN92): one scene keeps both."""
    extras = json.loads(converted("sig3d").read_text())["asset"]["extras"]["lodconvert"]
    assert extras["crs"] == "EPSG:25832 + EPSG:5783"
    assert extras["heights"].startswith("DHHN92 height (EPSG:5783): taken as heights above")


def test_a_district_over_two_utm_zones_is_placed_within_a_millimetre(tmp_path: Path) -> None:
    """Buildings either side of 12° E, in files of UTM 32 and UTM 33 (EPSG:25832/25833): the
    second file is reprojected into the first's zone, past its edge, and every vertex still
    lies within 1 mm of pyproj's ECEF of its own file's coordinates."""
    expected, paths = [], []
    for zone, lon in (("25832", 11.9995), ("25833", 12.0005)):
        to_utm = pyproj.Transformer.from_crs("EPSG:4326", f"EPSG:{zone}", always_xy=True)
        x0, y0 = to_utm.transform(lon, 48.1)
        vertices = []
        objects = {}
        for k in range(3):
            x, y = round(x0) + 30 * k, round(y0)
            base = len(vertices)
            corners = [(x, y), (x + 10, y), (x + 10, y + 8), (x, y + 8)]
            vertices += [[cx, cy, 520] for cx, cy in corners]
            vertices += [[cx, cy, 532] for cx, cy in corners]
            rings = [[[base + i for i in ring]] for ring in (
                (0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)
            )]  # fmt: skip
            objects[f"b{zone}_{k}"] = {"type": "Building", "geometry": [
                {"type": "Solid", "lod": "1", "boundaries": [rings]}
            ]}  # fmt: skip
        metadata = {"referenceSystem": f"https://www.opengis.net/def/crs/EPSG/0/{zone}"}
        path = tmp_path / f"utm{zone}.city.json"
        path.write_text(json.dumps(city(objects, vertices, metadata=metadata)))
        paths.append(path)
        to_ecef = pyproj.Transformer.from_crs(pyproj_crs(f"EPSG:{zone}", None), "EPSG:4978",
                                              always_xy=True)  # fmt: skip
        expected.append(np.stack(to_ecef.transform(*np.array(vertices, float).T), axis=1))
    tileset = tmp_path / "out" / "tileset.json"
    result = run(*paths, "-o", tileset, *FAST)
    assert result.returncode == 0, result.stderr
    placed, ids = [], []
    for tile, frame, _ in tiles(json.loads(tileset.read_text())["root"], np.eye(4), tileset):
        if tile.get("content", {}).get("uri", "").endswith("_finest.glb"):
            document, blob = read_glb(tileset.parent / tile["content"]["uri"])
            placed.append(frame_points(frame, _positions(document, blob)))
            ids += [row["id"] for row in features(document, blob)]
    assert sorted(ids) == [f"b{zone}_{k}" for zone in ("25832", "25833") for k in range(3)]
    ours, wanted = np.concatenate(placed), np.concatenate(expected)
    assert cKDTree(wanted).query(ours)[0].max() <= 1e-3
    assert cKDTree(ours).query(wanted)[0].max() <= 1e-3


def _drawn(path: Path) -> int:
    """Vertices + points of a GLB (its primitives' POSITION counts)."""
    document, blob = read_glb(path)
    return len(_positions(document, blob))


@pytest.mark.slow
def test_far_tiers_are_lighter_than_their_children_and_buildings_beside_cells_have_one(
    tmp_path: Path,
) -> None:
    """Parents that pay, on TUM Munich in 250 m and 1000 m cells: per tier, the far tiles hold
    at most half (250 m) and three quarters (1000 m: judged from above the horizon too, blocks
    need members' own far meshes mixed in) of the vertices and bytes of the tiles they refine
    into, every cell at silhouette F ≥ 0.95; the buildings no cell admitted hang below a far
    tile of their own, lighter than the LOD1 blocks it refines into; the official validator
    finds no error or warning and ours none."""
    report_path, tileset = tmp_path / "report.json", tmp_path / "tum" / "tileset.json"
    flags = ("--hlod", "250,1000", "--workers", "1", "-q", "--report", report_path)
    result = run(*inputs("tum"), "-o", tileset, *flags)  # all levels, as benchmarks/tiles.py
    assert result.returncode == 0, result.stderr
    cells = {cell["id"]: cell for cell in json.loads(report_path.read_text())["hlod"]["cells"]}
    tiers: dict[str, list[int]] = {}
    beside = []
    for tile, _, _ in tiles(json.loads(tileset.read_text())["root"], np.eye(4), tileset):
        if "cell" not in tile.get("extras", {}):
            continue
        cell = cells[tile["extras"]["cell"]]
        assert cell["silhouette_f"][cell["kind"]] >= 0.95
        far = tileset.parent / tile["content"]["uri"]
        below = [tileset.parent / child["content"]["uri"] for child in tile["children"]]
        counts = [_drawn(far), sum(map(_drawn, below)),
                  far.stat().st_size, sum(p.stat().st_size for p in below)]  # fmt: skip
        if tile["extras"].get("beside"):
            beside.append((tile, cell))
            assert counts[0] < counts[1] and counts[2] < counts[3]
            continue
        sums = tiers.setdefault(str(tile["extras"]["tier"]), [0, 0, 0, 0])
        sums[:] = [a + b for a, b in zip(sums, counts, strict=True)]
    assert set(tiers) == {"1", "2"}
    for tier, (far_vertices, vertices, far_bytes, size) in tiers.items():
        share = {"1": 1 / 2, "2": 3 / 4}[tier]
        assert far_vertices <= vertices * share and far_bytes <= size * share
    assert beside
    for tile, cell in beside:
        assert cell["id"].endswith("_beside") and cell["beside"] and cell["left_out"] == []
        (blocks,) = tile["children"]  # the buildings' LOD1 blocks, then their finest
        assert blocks["content"]["uri"].endswith(f"{cell['id']}_coarsest.glb")
        assert 0 < blocks["geometricError"] < tile["geometricError"]
        assert blocks["children"][0]["content"]["uri"].endswith(f"{cell['id']}_finest.glb")
    report = official(tileset, tmp_path / "validator.json")
    assert (report["numErrors"], report["numWarnings"]) == (0, 0), report["issues"][:5]
    assert validate_file(tileset) == []


def _corner_task(where: Any, corners: np.ndarray, packed: bool) -> Any:
    """The task of a tile of three ``corners``: a building's packed triangle (``packed``), or
    a far level's points."""
    from lodconvert.io.tiles.task import Placed, TileTask
    from lodconvert.model import Level, PointCloud, Surface

    origin = corners[0]
    grey = np.full((3, 4), 200, np.uint8)
    if packed:
        mesh = Surface(corners - origin, np.array([[0, 1, 2]]), grey)
        level = Level("LOD2", "source", mesh=mesh).packed()
        assert level.mesh is None and level.packed_geometry is not None
        return TileTask(
            "t.glb", where, (Placed(level.geometry, origin),), (("b", "Building", {}),), "t"
        )
    points = PointCloud(corners - origin, grey, np.zeros((3, 3), np.float32))
    return TileTask("t.glb", where, (Placed(points, origin),), (), "t")


def test_a_tile_is_made_in_a_worker_without_its_folder_and_written_by_the_main_process(
    tmp_path: Path,
) -> None:
    """A tile task touches no file (a dask worker on another machine has no staged folder):
    it gives back the GLB, which the main process writes with its record, kept when resumed."""
    import pyproj

    from lodconvert.io.tiles.task import Where
    from lodconvert.reproject import Georef
    from lodconvert.sinks import Outputs
    from lodconvert.tasks import pickled

    georef = Georef("EPSG:25832", pyproj.CRS("EPSG:25832"))
    where = Where(georef, "EPSG:25832", "test", "EPSG:25832")
    corners = np.array(
        [[690000.0, 5335000.0, 520.0], [690010, 5335000, 520], [690000, 5335010, 530]]
    )
    task = _corner_task(where, corners, packed=True)
    result = task.run()
    assert result.error is None and result.data is not None and result.data[:4] == b"glTF"
    # as a worker takes it: pickled (its place, origin and packed level), the same tile
    assert pickle.loads(pickled(task)).run().data == result.data
    assert list(tmp_path.iterdir()) == []
    with Outputs() as outputs:
        sink = outputs.directory(tmp_path / "out", resume="k" * 64)
        written = TileRecords(sink).written(task.name, result)
        staged = next(tmp_path.glob(".out.*.tmp"))
        assert (staged / "tiles" / "t.glb").read_bytes() == result.data and written.data is None
        kept = TileRecords(sink).kept(task.name, task.key)
    assert kept is not None and kept.reused and np.array_equal(kept.box, result.box)


def test_tile_records_are_lines_of_one_file_and_a_torn_line_is_no_record(
    tmp_path: Path,
) -> None:
    """A tileset records its tiles in one file, a line each, appended once each file is whole:
    the last line of a tile is its record, and a line a killed run left half-written is none
    (the tile is kept by its whole line, and the next record starts a line of its own)."""
    import pyproj

    from lodconvert.io.tiles.task import Where
    from lodconvert.reproject import Georef
    from lodconvert.sinks import Outputs

    georef = Georef("EPSG:25832", pyproj.CRS("EPSG:25832"))
    where = Where(georef, "EPSG:25832", "test", "EPSG:25832")
    corners = np.array(
        [[690000.0, 5335000.0, 520.0], [690010, 5335000, 520], [690000, 5335010, 530]]
    )
    task = _corner_task(where, corners, packed=False)
    other = _corner_task(where, corners + np.array([5.0, 0.0, 0.0]), packed=False)
    other = dataclasses.replace(other, name="u.glb")
    with Outputs() as outputs:
        sink = outputs.directory(tmp_path / "out", resume="k" * 64)
        records = TileRecords(sink)
        records.written(task.name, task.run())
        records.written(other.name, other.run())
        staged = next(tmp_path.glob(".out.*.tmp"))
        assert sorted(p.name for p in (staged / ".resume").iterdir()) == [
            "run", "tiles.jsonl", "written"
        ]  # fmt: skip
        with (staged / ".resume" / "tiles.jsonl").open("ab") as file:
            file.write(b'{"name": "u.glb", "key": "')  # a killed run's last, torn line
        again = TileRecords(sink)
        assert again.torn and sorted(again.found) == ["t.glb", "u.glb"]
        assert again.kept(task.name, task.key) and again.kept(other.name, other.key)
        (staged / "tiles" / "u.glb").write_bytes(b"glTF half")
        assert again.kept(other.name, other.key) is None  # the file no longer has its recorded hash
        again.written(other.name, other.run())
        lines = (staged / ".resume" / "tiles.jsonl").read_bytes().splitlines()
        assert len(lines) == 4 and json.loads(lines[-1])["name"] == "u.glb"
        last = TileRecords(sink)
        assert not last.torn and last.kept(other.name, other.key) is not None


def test_a_tile_whose_content_leaves_its_box_fails_where_it_is_made(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The task that makes a tile checks its GLB as the tileset's check would (the
    conversion's own check then reads no tile content): content written 5 m off its points
    is refused with the one line of a failed check, naming the tile."""
    import pyproj

    from lodconvert.io.gltf.binary import pack_glb
    from lodconvert.io.tiles import task as task_module
    from lodconvert.io.tiles.check import glb_parts
    from lodconvert.io.tiles.task import Where
    from lodconvert.reproject import Georef

    georef = Georef("EPSG:25832", pyproj.CRS("EPSG:25832"))
    where = Where(georef, "EPSG:25832", "test", "EPSG:25832")
    corners = np.array(
        [[690000.0, 5335000.0, 520.0], [690010, 5335000, 520], [690000, 5335010, 530]]
    )
    task = _corner_task(where, corners, packed=False)
    assert task.run().error is None
    made = task_module.points_glb

    def moved(*args: Any, **kwargs: Any) -> bytes:
        document, blob = glb_parts(made(*args, **kwargs))
        document["nodes"][0]["translation"] = [5.0, 0.0, 0.0]
        out = io.BytesIO()
        pack_glb(out, json.dumps(document).encode(), blob)
        return out.getvalue()

    monkeypatch.setattr(task_module, "points_glb", moved)
    result = task.run()
    failed = "output fails validation: VOLUME: tiles/t.glb: content lies outside its box"
    assert result.error == failed
