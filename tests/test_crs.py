"""CRS safety: inputs in different CRSs reprojected into the first's (Delft's RD New against
copies of some of its buildings made here in EPSG:4979 and in UTM + NAP height), ``--crs``
checked, a geographic CRS on projected coordinates, the missing-CRS warning of a streamed
CityGML file, and the CRS and vertical reference in the outputs and the report."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh
from pyproj import Transformer

from lodconvert.io import read_scene
from lodconvert.io.crs import CrsError
from lodconvert.model import Node, Scene
from lodconvert.reproject import in_one_crs

from .conftest import ROOT, SAMPLE, surface_of
from .test_citygml import SIG3D
from .test_citygml import sample as citygml_sample
from .test_cityjson import delft, write_json
from .test_cli import assert_one_line_error, run

FAST = ("--resolution", "24,12,6")
BUILDINGS = 12
"""Delft buildings copied into another CRS."""


def _delft_copy(tmp_path: Path, crs: str, referenced: str) -> tuple[Path, dict[str, np.ndarray]]:
    """A file of :data:`BUILDINGS` of Delft's buildings, renamed ``copy-<id>``, whose vertices
    pyproj transformed from RD New + NAP (EPSG:7415) into ``crs`` (float64, in ``crs``'s axis
    order: latitude first for EPSG:4979) and which declares ``referenced``; the file and, per
    copied id, the original's RD vertices."""
    document = json.loads(delft().read_text())
    keys = [k for k, o in document["CityObjects"].items() if o["type"] == "Building"][:BUILDINGS]
    rd = np.asarray(document["vertices"], dtype=np.float64) * document["transform"]["scale"]
    rd += document["transform"]["translate"]
    x, y, z = Transformer.from_crs("EPSG:7415", crs).transform(*rd.T)
    document["vertices"] = np.stack([x, y, z], axis=1).tolist()
    del document["transform"]
    document["metadata"] = {"referenceSystem": referenced}
    document["CityObjects"] = {f"copy-{k}": document["CityObjects"][k] for k in keys}
    originals = {f"copy-{n.id}": n.geometry.vertices for n in read_scene(delft()).walk()}
    path = write_json(tmp_path / "copy.city.json", document)
    return path, {key: originals[key] for key in document["CityObjects"]}


def _in_rd(path: Path, warnings: list[str]) -> dict[str, Node]:
    """The objects of ``path`` after Delft (RD New + NAP) in one run's CRS, by id."""
    one = in_one_crs([read_scene(delft()), read_scene(path)], warnings.append)
    assert [scene.crs for scene in one.scenes] == ["EPSG:7415", "EPSG:7415"]
    return {node.id: node for node in one.scenes[1].walk()}


def test_a_geographic_input_is_reprojected_into_the_first_inputs_crs(tmp_path: Path) -> None:
    path, originals = _delft_copy(tmp_path, "EPSG:4979", "urn:ogc:def:crs:EPSG::4979")
    degrees = np.asarray(json.loads(path.read_text())["vertices"])
    warnings: list[str] = []
    nodes = _in_rd(path, warnings)
    assert list(nodes) == list(originals)
    # pyproj on its own, from the file's latitudes, longitudes and heights
    direct = np.stack(Transformer.from_crs("EPSG:4979", "EPSG:7415").transform(*degrees.T), axis=1)
    for key, node in nodes.items():
        vertices = node.geometry.vertices
        assert node.crs == "EPSG:7415" and node.origin is None
        nearest = np.abs(direct[:, None, :] - vertices[None, :, :]).max(axis=2).min(axis=0)
        assert nearest.max() <= 1e-3, key
        assert np.abs(vertices - originals[key]).max() <= 1e-3, key  # where Delft has them
        assert node.lods[max(node.lods)] is node.geometry
    # offline, PROJ has no NAP grid: the heights come through a ballpark transformation
    (warning,) = warnings
    assert "copy.city.json" in warning and "EPSG:4979" in warning and "EPSG:7415" in warning
    assert "unavailable" in warning and "nl_nsgi" in warning and "tens of metres" in warning


def test_a_utm_input_is_reprojected_without_warning(tmp_path: Path) -> None:
    path, originals = _delft_copy(tmp_path, "EPSG:32631+5709", "EPSG:32631+5709")
    warnings: list[str] = []
    nodes = _in_rd(path, warnings)
    assert warnings == []  # WGS 84 to Amersfoort has no grid; NAP heights stay NAP heights
    for key, node in nodes.items():
        assert np.abs(node.geometry.vertices - originals[key]).max() <= 1e-3, key


def test_a_projected_input_lands_on_a_geographic_first_inputs_frame(tmp_path: Path) -> None:
    path, _ = _delft_copy(tmp_path, "EPSG:4979", "EPSG:4979")
    one = in_one_crs([read_scene(path), read_scene(delft())], print)
    first, second = (list(scene.walk()) for scene in one.scenes)
    frame = one.scenes[0].attributes["local_frame"]["proj"]
    assert one.scenes[1].crs == frame and {n.crs for n in second} == {frame}
    assert one.record["vertical"] == "ellipsoidal (WGS 84)"
    moved = {node.id: node for node in second}
    for node in first:  # each copy in the frame, and its RD original moved onto it
        original = moved[node.id.removeprefix("copy-")].geometry.vertices
        assert np.abs(original - node.geometry.vertices).max() <= 1e-3, node.id


def test_template_instances_keep_their_mesh_and_move_their_placement(tmp_path: Path) -> None:
    cube = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    template = {"type": "Solid", "lod": "2", "boundaries": [[[f] for f in faces]]}
    scale = [20, 0, 0, 0, 0, 20, 0, 0, 0, 0, 20, 0, 0, 0, 0, 1]  # a 20 m cube
    trees = {
        f"t{k}": {
            "type": "SolitaryVegetationObject",
            "geometry": [
                {
                    "type": "GeometryInstance",
                    "template": 0,
                    "boundaries": [k],
                    "transformationMatrix": scale,
                }
            ],
        }
        for k in range(2)
    }
    utm = [[594000.0, 5762000.0, 1.0], [596000.0, 5761000.0, 2.0]]
    document = {
        "type": "CityJSON",
        "version": "2.0",
        "CityObjects": trees,
        "vertices": utm,
        "metadata": {"referenceSystem": "EPSG:32631+5709"},
        "geometry-templates": {"templates": [template], "vertices-templates": cube},
    }
    path = write_json(tmp_path / "trees.city.json", document)
    before = [
        node.geometry.vertices @ node.transform[:3, :3].T + node.transform[:3, 3]
        for node in read_scene(path).walk()
    ]
    one = in_one_crs([read_scene(delft()), read_scene(path)], print)
    t0, t1 = one.scenes[1].walk()
    assert t0.geometry is t1.geometry  # still one shared mesh
    pyproj_alone = Transformer.from_crs("EPSG:32631+5709", "EPSG:7415", always_xy=True)
    for node, world in zip((t0, t1), before, strict=True):
        placed = node.geometry.vertices @ node.transform[:3, :3].T + node.transform[:3, 3]
        expected = np.stack(pyproj_alone.transform(*world.T), axis=1)
        assert np.abs(placed - expected).max() <= 1e-3, node.id


def test_merged_inputs_land_in_one_crs_with_the_cli(tmp_path: Path) -> None:
    path, originals = _delft_copy(tmp_path, "EPSG:4979", "EPSG:4979")
    out, report = tmp_path / "both.glb", tmp_path / "both.json"
    result = run(delft(), path, "-o", out, "--types", "Building", "--report", report, "-q")
    assert result.returncode == 0, result.stderr
    assert "1 input reprojected into EPSG:7415" in result.stderr  # the summary line
    assert "best transformation from EPSG:4979 into EPSG:7415 is unavailable" in result.stderr
    facts = json.loads(report.read_text())
    schema = json.loads((ROOT / "schemas" / "report.schema.json").read_text())
    import jsonschema

    jsonschema.validate(facts, schema)
    assert facts["crs"]["name"] == "EPSG:7415"
    assert facts["crs"]["vertical"] == "NAP height (EPSG:5709)"
    (moved,) = facts["crs"]["reprojected"]
    assert moved["from"] == "EPSG:4979" and moved["to"] == "EPSG:7415"
    assert moved["best_available"] is False and moved["missing_grids"]
    assert moved["ballpark_heights"] is True
    # every copy sits on its original: the same bounding-box centre to the millimetre
    origins = {o["id"]: np.asarray(o["origin"]) for o in facts["objects"]}
    for key, vertices in originals.items():
        centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
        assert np.abs(origins[key] - origins[key.removeprefix("copy-")]).max() <= 1e-3, key
        assert np.abs(origins[key] - centre).max() <= 1e-3, key
    data = out.read_bytes()
    length = int.from_bytes(data[12:16], "little")
    extras = json.loads(data[20 : 20 + length])["asset"]["extras"]["lodconvert"]
    assert extras["crs"] == "EPSG:7415" and extras["vertical_reference"] == "NAP height (EPSG:5709)"


def test_another_vertical_crs_is_reprojected_too(tmp_path: Path) -> None:
    """The SIG3D house in EPSG:25832 with DHHN2016 heights beside it with DHHN92 heights."""
    text = citygml_sample(SIG3D.format(2)).read_text(encoding="utf-8")
    other = tmp_path / "dhhn2016.gml"
    other.write_text(text.replace("EPSG::5783", "EPSG::7837"), encoding="utf-8")
    first = read_scene(citygml_sample(SIG3D.format(1)))
    one = in_one_crs([first, read_scene(other)], print)
    (moved,) = one.record["reprojected"]
    assert moved["from"] == "EPSG:25832 + EPSG:7837" and moved["to"] == "EPSG:25832 + EPSG:5783"
    streamed = one.scenes[1]
    assert not isinstance(streamed.nodes, list)  # transformed as the nodes are taken
    assert {node.crs for node in streamed.walk()} == {"EPSG:25832"}
    again = in_one_crs([read_scene(citygml_sample(SIG3D.format(1))), first], print)
    assert again.record["reprojected"] == []  # the same CRS: nothing to do


def test_no_transformation_is_one_line_naming_both_files_and_crss(tmp_path: Path) -> None:
    text = citygml_sample(SIG3D.format(2)).read_text(encoding="utf-8")
    unknown = re.sub(r'srsName="[^"]*"', 'srsName="urn:adv:crs:ETRS89_UTM32*DE_DHHN92_NH"', text)
    other = tmp_path / "adv.gml"
    other.write_text(unknown, encoding="utf-8")
    out = tmp_path / "house.x3d"
    result = run(citygml_sample(SIG3D.format(1)), other, "-o", out)
    assert_one_line_error(
        result, 1, "adv.gml", "urn:adv:crs:ETRS89_UTM32*DE_DHHN92_NH", "EPSG:25832",
        "Building_LOD1-EPSG25832.gml",
    )  # fmt: skip
    assert not out.exists()
    with pytest.raises(CrsError):
        in_one_crs([read_scene(citygml_sample(SIG3D.format(1))), read_scene(other)], print)


@pytest.mark.parametrize(
    "given",
    ["foo", "EPSG:99999", "EPSG:" + "9" * 5_000, "EPSG:25832+" + "9" * 5_000],
    ids=["foo", "unknown-code", "5000-digit-code", "5000-digit-vertical-code"],
)
def test_crs_option_must_name_a_crs(given: str, tmp_path: Path) -> None:
    """Any code pyproj does not know is a usage error, shown cut to 80 characters (one of
    5,000 digits was a ``ValueError`` and exit 1)."""
    out = tmp_path / "city.glb"
    result = run(delft(), "-o", out, "--crs", given)
    assert_one_line_error(result, 2, "--crs", given[:40])
    assert len(result.stderr) < 300
    assert not out.exists()


def test_a_file_naming_a_code_of_5000_digits_reads_as_one_naming_an_unknown_crs(
    tmp_path: Path,
) -> None:
    """An ``srsName`` whose EPSG code has 5,000 digits is a name like any pyproj does not
    know (it was a ``ValueError``)."""
    text = citygml_sample(SIG3D.format(1)).read_text(encoding="utf-8")
    srs = re.search(r'srsName="([^"]*)"', text)
    assert srs is not None
    name = "EPSG:" + "9" * 5_000
    path = tmp_path / "long.gml"
    path.write_text(text.replace(srs.group(1), name), encoding="utf-8")
    scene = read_scene(path)
    assert scene.crs == name and len(list(scene.walk())) > 0


def test_crs_given_to_a_mesh_is_warned_of_not_dropped_silently(tmp_path: Path) -> None:
    """A mesh records no CRS (its axes are its own): --crs given with one says so."""
    out = tmp_path / "knot.glb"
    result = run(SAMPLE, "-o", out, "--crs", "EPSG:25832", "--backend", "numpy")
    assert result.returncode == 0, result.stderr
    (line,) = [w for w in result.stderr.splitlines() if "--crs" in w]
    assert line == (
        f"lodconvert: warning: {SAMPLE}: not a city model: --crs is not applied "
        "(a mesh keeps its own axes and coordinates)"
    )
    assert _glb_extras(out)["crs"] is None
    result = run(delft(), SAMPLE, "-o", tmp_path / "both.x3d", "--crs", "EPSG:7415")
    assert result.returncode == 0 and result.stderr.count("--crs is not applied") == 1


def _glb_extras(path: Path) -> dict:
    data = path.read_bytes()
    length = int.from_bytes(data[12:16], "little")
    return json.loads(data[20 : 20 + length])["asset"]["extras"]["lodconvert"]


def test_geographic_crs_on_projected_coordinates_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "city.glb"
    for path in (delft(), citygml_sample(SIG3D.format(2))):
        result = run(path, "-o", out, "--crs", "EPSG:4326")
        assert_one_line_error(result, 1, path.name, "not latitude and longitude", "EPSG:4326")
        assert "proj=" not in result.stderr
    assert not out.exists()


def test_a_streamed_citygml_file_without_crs_is_warned_of_alone_and_twice(tmp_path: Path) -> None:
    text = citygml_sample(SIG3D.format(2)).read_text(encoding="utf-8")
    bare = [tmp_path / "a.gml", tmp_path / "b.gml"]
    for path in bare:
        path.write_text(re.sub(r' srsName="[^"]*"', "", text), encoding="utf-8")
    for inputs in (bare[:1], bare):
        out = tmp_path / "house.x3d"
        result = run(*inputs, "-o", out)
        assert result.returncode == 0, result.stderr
        for path in inputs:
            assert f"{path}: declares no CRS" in result.stderr
        text = out.read_text()
        assert '<meta name="vertical-reference" content="as in the source, not declared"/>' in text
    result = run(citygml_sample(SIG3D.format(1)), bare[0], "-o", tmp_path / "house.x3d")
    assert result.returncode == 0, result.stderr
    assert f"{bare[0]}: declares no CRS; its coordinates are taken to be in EPSG:25832" in (
        result.stderr
    )


def test_an_input_without_crs_beside_one_with_is_warned_of_and_refused_for_tiles(
    tmp_path: Path,
) -> None:
    """A mesh, or a city model that declares no CRS, beside a house in EPSG:25832: each warned
    of by name for glTF and X3D (the mesh was placed in EPSG:25832 silently), refused in one
    line naming it for a tileset (3D Tiles place every input on the globe: both were
    written)."""
    house = citygml_sample(SIG3D.format(1))
    bare = tmp_path / "bare.gml"
    bare.write_text(
        re.sub(r' srsName="[^"]*"', "", house.read_text(encoding="utf-8")), encoding="utf-8"
    )
    for other, what in ((SAMPLE, "is a mesh, which declares no CRS"), (bare, "declares no CRS")):
        for name in ("both.glb", "both.x3d"):
            result = run(house, other, "-o", tmp_path / name, "--backend", "numpy", *FAST)
            far = other == SAMPLE and name == "both.glb"  # the knot 5,438 km off the origin
            assert result.returncode == (1 if far else 0), result.stderr
            warned = [line for line in result.stderr.splitlines() if "no CRS" in line]
            assert warned == [
                f"lodconvert: warning: {other}: {what}; its coordinates are taken to be in "
                "EPSG:25832 + EPSG:5783" + (" (--crs EPSG:… names it)" if other == bare else "")
            ]
        tiles = tmp_path / "tiles" / "tileset.json"
        result = run(house, other, "-o", tiles)
        assert_one_line_error(
            result, 1, str(other), what, f"beside {house.name} in EPSG:25832", "3D Tiles"
        )
        assert not tiles.parent.exists()


def test_x3d_and_report_name_the_crs_and_its_vertical_reference(tmp_path: Path) -> None:
    out, report = tmp_path / "house.x3d", tmp_path / "house.json"
    result = run(citygml_sample(SIG3D.format(2)), "-o", out, "--report", report)
    assert result.returncode == 0, result.stderr
    facts = json.loads(report.read_text())["crs"]
    assert facts == {
        "name": "EPSG:25832",
        "vertical": "DHHN92 height (EPSG:5783)",
        "reprojected": [],
    }
    text = out.read_text()
    assert '<meta name="vertical-reference" content="DHHN92 height (EPSG:5783)"/>' in text


def test_nodes_placed_by_an_origin_keep_geometry_relative_to_it() -> None:
    """Geometry relative to a float64 origin, with and without a placement, lands where pyproj
    puts its world coordinates, and stays small numbers about the moved origin."""
    box = surface_of(trimesh.creation.box((30.0, 20.0, 10.0)))
    origin = np.array([594000.0, 5762000.0, 5.0])
    turn = trimesh.transformations.rotation_matrix(0.3, [0, 0, 1])
    turn[:3, 3] = [100.0, -50.0, 0.0]
    nodes = [Node("plain", box, origin=origin), Node("turned", box, origin=origin, transform=turn)]
    worlds = [origin + box.vertices, origin + box.vertices @ turn[:3, :3].T + turn[:3, 3]]
    first = Scene("rd", [], "EPSG:28992")
    one = in_one_crs([first, Scene("utm", nodes, "EPSG:32631")], print)
    alone = Transformer.from_crs("EPSG:32631", "EPSG:28992", always_xy=True)
    for node, world in zip(one.scenes[1].walk(), worlds, strict=True):
        local = node.geometry.vertices
        if node.transform is not None:
            local = local @ node.transform[:3, :3].T + node.transform[:3, 3]
        expected = np.stack(alone.transform(*world.T), axis=1)
        assert np.abs(node.offset + local - expected).max() <= 1e-3, node.id
        assert np.abs(node.geometry.vertices).max() < 100.0 and node.crs == "EPSG:28992"
