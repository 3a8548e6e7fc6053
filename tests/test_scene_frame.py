"""The scene frame of georeferenced output: a city's glTF and X3D are y-up (z-up source →
(x, z, −y)) about one scene origin recorded in float64, with no node offset or buffer value of
1e5 or more; the documented formula puts file coordinates back into the source CRS; the X3D
starts with a Viewpoint that frames the scene obliquely; meshes without a CRS keep their axes."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh
from lxml import etree
from scipy.spatial import cKDTree

import lodconvert
from lodconvert import convert
from lodconvert.bake import get_backend
from lodconvert.bakery import iter_chains
from lodconvert.chain import ChainOptions
from lodconvert.city.hlod import HlodOptions
from lodconvert.context import RunContext
from lodconvert.errors import LodConvertError
from lodconvert.io import own_format, read_chains, read_scene
from lodconvert.io.frame import ROTATION
from lodconvert.io.x3d.viewpoint import PITCH_DEG
from lodconvert.model import Node, Surface
from lodconvert.validate import validate_file
from lodconvert.viewer.config import page_config

from .conftest import SAMPLE, SHARED, shared_data
from .test_cityjson import city, square, surface_object, write_json
from .test_cli import run

TUM = SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip"
FAR = np.array([500000.0, 5400000.0, 100.0])


def _tum() -> Path:
    if not TUM.exists():
        pytest.skip(f"{TUM} is absent (shared test data not checked out)")
    return TUM


@pytest.fixture(scope="module")
def tum(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """TUM Munich (EPSG:31468, root translations ~4.5e6 before) as .glb and .x3d, with reports."""
    source = _tum()
    folder = tmp_path_factory.mktemp("tum")
    out = {}
    for suffix in (".glb", ".x3d"):
        out[suffix] = folder / f"tum{suffix}"
        convert(source, out[suffix], backend="numpy", report_path=folder / f"{suffix[1:]}.json")
    return out


def _glb(path: Path) -> tuple[dict, bytes]:
    """JSON and BIN chunk of a GLB, parsed without lodconvert."""
    data = path.read_bytes()
    (length,) = struct.unpack_from("<I", data, 12)
    return json.loads(data[20 : 20 + length]), data[28 + length :]


def _positions(doc: dict, blob: bytes, accessor: int) -> np.ndarray:
    acc = doc["accessors"][accessor]
    view = doc["bufferViews"][acc["bufferView"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(blob, "<f4", acc["count"] * 3, start).reshape(-1, 3).astype(np.float64)


def _source_vertices() -> dict[str, np.ndarray]:
    return {
        node.id: node.geometry.vertices
        for node in read_scene(_tum()).walk()
        if node.geometry is not None
    }


def test_city_glb_is_y_up_about_one_scene_origin_with_small_values(
    tum: dict[str, Path], gltf_validator
) -> None:
    assert gltf_validator(tum[".glb"])["issues"]["numErrors"] == 0  # the Khronos validator
    doc, _ = _glb(tum[".glb"])
    meta = doc["asset"]["extras"]["lodconvert"]
    frame = meta["frame"]
    assert meta["crs"] == "EPSG:31468"
    assert frame["origin"] == [4467678.0, 5334745.0, 526.0]  # the first building's, whole metres
    assert frame["rotation"] == ROTATION.tolist()
    (root,) = doc["scenes"][0]["nodes"]
    frame_node = doc["nodes"][root]
    assert frame_node["name"] == "scene_frame" and len(frame_node["children"]) == 290
    matrix = np.array(frame_node["matrix"]).reshape(4, 4).T  # column-major
    np.testing.assert_array_equal(matrix[:3, :3], ROTATION)  # up (+z) → +Y, north (+y) → −Z
    assert not matrix[:3, 3].any()
    translations = [n["translation"] for n in doc["nodes"] if "translation" in n]
    assert len(translations) == 290 and np.abs(translations).max() < 1e5  # was 5.3e6
    bounds = [a[k] for a in doc["accessors"] if "max" in a for k in ("min", "max")]
    assert np.abs(bounds).max() < 1e5


def test_the_documented_formula_puts_the_glb_back_in_the_source_crs(tum: dict[str, Path]) -> None:
    """source = origin + Rᵀ · scene, computed from the file alone (no lodconvert reader),
    is within 1 mm of every source vertex of every building."""
    doc, blob = _glb(tum[".glb"])
    frame = doc["asset"]["extras"]["lodconvert"]["frame"]
    origin, rotation = np.array(frame["origin"]), np.array(frame["rotation"])
    nodes = doc["nodes"]
    (root,) = doc["scenes"][0]["nodes"]
    matrix = np.array(nodes[root]["matrix"]).reshape(4, 4).T[:3, :3]
    source = _source_vertices()
    worst = 0.0
    for index in nodes[root]["children"]:
        building = nodes[index]
        finest = nodes[building["children"][0]]
        local = np.concatenate(
            [
                _positions(doc, blob, p["attributes"]["POSITION"])
                for p in doc["meshes"][finest["mesh"]]["primitives"]
            ]
        )
        scene = (local + building["translation"]) @ matrix.T  # what a viewer draws
        back = origin + scene @ rotation  # origin + Rᵀ · scene, row by row
        worst = max(worst, cKDTree(source[building["name"]]).query(back)[0].max())
    assert worst <= 1e-3


def test_city_x3d_is_turned_y_up_in_one_transform_and_reads_back(tum: dict[str, Path]) -> None:
    root = etree.parse(str(tum[".x3d"])).getroot()
    scene = root.find("Scene")
    frame, navigation, viewpoint = list(scene)
    assert frame.get("DEF") == "scene_frame"
    assert frame.get("rotation") == "1 0 0 -1.5707963267948966"
    metadata = frame.find("MetadataSet")
    values = {m.get("name"): m.get("value") for m in metadata}
    assert values["origin"] == "4467678.0 5334745.0 526.0"
    assert [float(v) for v in values["rotation"].split()] == ROTATION.ravel().tolist()
    objects = frame.findall("Transform")
    assert len(objects) == 290
    offsets = [[float(v) for v in t.get("translation").split()] for t in objects]
    assert np.abs(offsets).max() < 1e5
    assert navigation.tag == "NavigationInfo" and "EXAMINE" in navigation.get("type")
    assert viewpoint.tag == "Viewpoint"
    # read back in the source CRS: the same origins as the glb, within 1 mm of the source
    x3d, glb = read_chains(tum[".x3d"]), read_chains(tum[".glb"])
    np.testing.assert_array_equal([c.origin for c in x3d], [c.origin for c in glb])
    source = _source_vertices()
    worst = max(
        cKDTree(source[c.object_id]).query(c.levels[0].mesh.vertices + c.origin)[0].max()
        for c in x3d
    )
    assert worst <= 1e-3


def test_x3d_viewpoint_sees_every_building_obliquely(tum: dict[str, Path]) -> None:
    viewpoint = etree.parse(str(tum[".x3d"])).getroot().find("Scene/Viewpoint")
    position = np.array(viewpoint.get("position").split(), float)
    centre = np.array(viewpoint.get("centerOfRotation").split(), float)
    axis_angle = np.array(viewpoint.get("orientation").split(), float)
    fov = float(viewpoint.get("fieldOfView"))
    np.testing.assert_allclose(axis_angle, [1, 0, 0, -math.radians(PITCH_DEG)])
    look = centre - position  # the orientation's view direction: −z turned about x
    pitch = math.degrees(math.atan2(-look[1], -look[2]))
    assert pitch == pytest.approx(PITCH_DEG) and look[2] < 0  # from the south, looking down
    frame = np.array([4467678.0, 5334745.0, 526.0])
    for chain in read_chains(tum[".x3d"], geometry=False):
        seen = ROTATION @ (chain.origin + chain.center - frame) - position
        angle = math.acos(float(seen @ look) / (np.linalg.norm(seen) * np.linalg.norm(look)))
        assert angle < fov / 2, chain.object_id


def test_report_and_viewer_page_know_the_frame(tum: dict[str, Path]) -> None:
    report = json.loads((tum[".glb"].parent / "glb.json").read_text())
    assert report["frame"]["origin"] == [4467678.0, 5334745.0, 526.0]
    assert report["frame"]["rotation"] == ROTATION.tolist()
    chains = read_chains(tum[".glb"], geometry=False)
    for suffix in (".glb", ".x3d"):
        config = page_config(tum[suffix])
        assert config["rotation"] == ROTATION.tolist()
        assert config["view"]["direction"][1] > 0  # tilted: from above the horizon
        for chain, obj in zip(chains, config["objects"], strict=True):
            scene = ROTATION @ (chain.origin + chain.center - report["frame"]["origin"])
            np.testing.assert_allclose(obj["center"], scene, atol=1e-9)


@pytest.mark.slow
def test_identical_runs_write_identical_city_files(tum: dict[str, Path], tmp_path: Path) -> None:
    for suffix, path in tum.items():
        again = tmp_path / f"again{suffix}"
        convert(_tum(), again, backend="numpy")
        assert again.read_bytes() == path.read_bytes(), suffix


def test_a_mesh_without_a_crs_keeps_its_axes(tmp_path: Path) -> None:
    report = convert(SAMPLE, tmp_path / "knot.glb", backend="numpy")
    doc, _ = _glb(tmp_path / "knot.glb")
    assert "frame" not in doc["asset"]["extras"]["lodconvert"] and report["frame"] is None
    (root,) = doc["scenes"][0]["nodes"]
    assert doc["nodes"][root]["name"] == "torus_knot"
    assert doc["nodes"][root]["translation"] == report["objects"][0]["origin"]
    convert(SAMPLE, tmp_path / "knot.x3d", backend="numpy")
    scene = etree.parse(str(tmp_path / "knot.x3d")).getroot().find("Scene")
    assert [e.tag for e in scene] == ["Transform", "NavigationInfo", "Viewpoint"]
    assert scene[0].get("DEF") == "torus_knot" and scene[0].get("rotation") is None


def _placed_balls(folder: Path) -> Path:
    """A GLB whose one sphere mesh is placed by two nodes at UTM-like coordinates, one turned."""
    turned = trimesh.transformations.rotation_matrix(0.5, [0, 0, 1]) @ np.diag([2, 2, 2, 1.0])
    scene = trimesh.Scene()
    scene.add_geometry(
        trimesh.creation.icosphere(subdivisions=2), node_name="ball0", geom_name="ball"
    )
    for i, placement in enumerate([np.eye(4), turned]):
        matrix = trimesh.transformations.translation_matrix([*FAR[:2], FAR[2] + 10.0 * i])
        scene.graph.update(
            frame_to=f"ball{i}",
            frame_from=scene.graph.base_frame,
            matrix=matrix @ placement,
            geometry="ball",
        )
    path = folder / "balls.glb"
    scene.export(path)
    return path


@pytest.mark.parametrize("suffix", [".glb", ".x3d"])
def test_instances_placed_by_a_matrix_follow_the_frame(tmp_path: Path, suffix: str) -> None:
    scene = read_scene(_placed_balls(tmp_path))
    chains = list(iter_chains(scene, ChainOptions(), RunContext.here(get_backend("numpy"))))
    assert len(chains) == 2 and all(chain.transform is not None for chain in chains)
    assert chains[0].levels is chains[1].levels  # one bake, two placements
    plain, framed = tmp_path / f"plain{suffix}", tmp_path / f"framed{suffix}"
    lodconvert.write(chains, plain)
    lodconvert.write(chains, framed, crs="EPSG:25832")
    for got, expected in zip(read_chains(framed), read_chains(plain), strict=True):
        np.testing.assert_array_equal(got.origin, expected.origin)
        np.testing.assert_array_equal(got.transform, expected.transform)
    if suffix == ".glb":
        doc, _ = _glb(framed)
        (root,) = doc["scenes"][0]["nodes"]
        for index in doc["nodes"][root]["children"]:
            node = doc["nodes"][index]  # moved only (translation), or turned too (matrix)
            matrix = np.array(node.get("matrix", np.eye(4).ravel())).reshape(4, 4).T
            offset = node.get("translation", matrix[:3, 3])
            assert np.abs(offset).max() < 100.0  # from the scene origin, not 5.4e6


def test_an_object_beyond_100_km_of_the_scene_origin_is_an_error(tmp_path: Path) -> None:
    box = trimesh.creation.box()
    chains = []
    for name, shift in (("near", FAR), ("far", np.add(FAR, (150_000.0, 0.0, 0.0)))):
        node = Node(name, geometry=Surface(box.vertices + shift, box.faces))
        chains.append(lodconvert.bake(node))
    out = tmp_path / "region.glb"
    with pytest.raises(LodConvertError, match=r"object 'far' lies 150 km from the scene origin"):
        lodconvert.write(chains, out, crs="EPSG:25832")
    assert list(tmp_path.iterdir()) == []  # nothing left behind


@pytest.mark.slow
def test_lod_parents_far_levels_follow_the_frame(tmp_path: Path) -> None:
    """TUM Munich in 250 m cells: the far nodes are offsets from the scene origin too, and both
    formats read every cell's centre back at the same place in the source CRS."""
    cells = {}
    for suffix in (".glb", ".x3d"):
        out = tmp_path / f"cells{suffix}"
        convert(_tum(), out, backend="numpy", hlod=HlodOptions((250.0,)))
        cells[suffix] = own_format(out).read_cells(out)
    doc, _ = _glb(tmp_path / "cells.glb")
    fars = [doc["nodes"][cell["gltf"]["far"]] for cell in cells[".glb"]]
    assert fars and all(np.abs(far["translation"]).max() < 1e5 for far in fars)
    centres = {s: np.array([cell["center"] for cell in found]) for s, found in cells.items()}
    assert np.abs(centres[".glb"]).max() > 1e6  # in the source CRS
    np.testing.assert_allclose(centres[".x3d"], centres[".glb"], rtol=0, atol=1e-6)


def test_a_framed_gltf_is_laid_out_as_json_dumps_lays_it_out(tmp_path: Path) -> None:
    """The frame node is written after the streamed nodes, its children streamed too: the
    .gltf text is still exactly json.dumps(indent=1) of its document."""
    box = trimesh.creation.box()
    chains = [
        lodconvert.bake(Node(f"box{i}", geometry=Surface(box.vertices + FAR + i, box.faces)))
        for i in range(3)
    ]
    out = tmp_path / "boxes.gltf"
    lodconvert.write(chains, out, crs="EPSG:25832")
    text = out.read_text()
    doc = json.loads(text)
    assert text == json.dumps(doc, indent=1) + "\n"
    (root,) = doc["scenes"][0]["nodes"]
    assert root == len(doc["nodes"]) - 1 and doc["nodes"][root]["children"] == [0, 2, 4]


@pytest.mark.parametrize("tamper", ["matrix", "origin"])
def test_validate_reports_a_broken_scene_frame(tmp_path: Path, tamper: str) -> None:
    box = trimesh.creation.box()
    chain = lodconvert.bake(Node("box", geometry=Surface(box.vertices + FAR, box.faces)))
    out = tmp_path / "box.gltf"
    lodconvert.write([chain], out, crs="EPSG:25832")
    assert validate_file(out) == []
    doc = json.loads(out.read_text())
    if tamper == "matrix":  # turned the other way: roofs down
        (root,) = doc["scenes"][0]["nodes"]
        doc["nodes"][root]["matrix"][6], doc["nodes"][root]["matrix"][9] = 1.0, -1.0
    else:
        doc["asset"]["extras"]["lodconvert"]["frame"]["origin"] = [1.0, 2.0]
    out.write_text(json.dumps(doc, indent=1))
    findings = validate_file(out)
    assert [f.code for f in findings] == ["SCENE_FRAME"], findings


def test_a_city_without_a_crs_is_upright_too(tmp_path: Path) -> None:
    """multi_lod_10bldg.city.json declares no CRS; its buildings are z-up all the same, so a
    plain glTF or X3D viewer shows them standing and the viewer page from above the horizon."""
    source = shared_data(SHARED / "data" / "cityjson" / "multi_lod_10bldg.city.json")
    for suffix in (".glb", ".x3d"):
        out = tmp_path / f"city{suffix}"
        report = convert(source, out, backend="numpy")
        assert report["crs"]["name"] is None and report["frame"]["rotation"] == ROTATION.tolist()
        origin = np.array(report["frame"]["origin"])
        assert np.abs(np.array(report["objects"][0]["origin"]) - origin).max() < 1
        assert page_config(out)["view"]["direction"][1] > 0  # tilted: from above the horizon
        for chain, record in zip(read_chains(out), report["objects"], strict=True):
            np.testing.assert_allclose(chain.origin, record["origin"], atol=1e-6)
    doc, _ = _glb(tmp_path / "city.glb")
    (root,) = doc["scenes"][0]["nodes"]
    assert doc["nodes"][root]["name"] == "scene_frame"
    scene = etree.parse(str(tmp_path / "city.x3d")).getroot().find("Scene")
    assert scene[0].get("DEF") == "scene_frame"


def _street(tmp_path: Path) -> Path:
    """Four flat buildings 10 m square (CityJSON, z-up), the first 900 m north-east of the
    others: in 250 m cells it lies in the last cell of the grid, not the first."""
    corners = []
    for x, y in ((900.0, 900.0), (0.0, 0.0), (300.0, 0.0), (600.0, 600.0)):
        corners += [[x + dx, y + dy, dz] for z in (0.0, 6.0) for dx, dy, dz in square(z)]
    objects = {
        f"b{k}": surface_object(
            [[8 * k, 8 * k + 1, 8 * k + 2, 8 * k + 3]],
            [[8 * k + 7, 8 * k + 6, 8 * k + 5, 8 * k + 4]],
        )
        for k in range(4)
    }
    return write_json(tmp_path / "street.city.json", city(objects, corners))


def _origins(source: Path, folder: Path, flags: dict[str, tuple[str, ...]]) -> dict[str, list]:
    """The scene origin each run of ``source`` (``flags`` by name; a name's suffix is the
    output's) records in its file and its report."""
    origins = {}
    for name, extra in flags.items():
        out, report = folder / name, folder / f"{name}.json"
        result = run(source, "-o", out, "--report", report, "--levels", "2", *extra, "-q")
        assert result.returncode == 0, result.stderr
        frame = own_format(out).read_frame(out)
        origins[name] = frame.origin.tolist()
        assert json.loads(report.read_text())["frame"]["origin"] == origins[name]
    return origins


def test_the_scene_origin_depends_on_the_input_not_on_lod_parents(tmp_path: Path) -> None:
    """Two outputs of one city overlay with one offset: the scene origin is where the input's
    first building lies, with LOD parents (whose first cell holds other buildings) or without."""
    flags = {
        "plain.x3d": (),
        "cells.glb": ("--hlod", "250"),
        "tiers.x3d": ("--hlod", "250,1000"),
    }
    origins = _origins(_street(tmp_path), tmp_path, flags)
    assert origins == {name: [905.0, 905.0, 3.0] for name in flags}, origins


@pytest.mark.slow
def test_a_real_citys_scene_origin_is_the_same_with_and_without_lod_parents(
    tmp_path: Path,
) -> None:
    """TUM Munich (290 buildings): the origin was (4467678, 5334745, 526) plain, (4467674,
    5334671, 527) with --hlod 250 and (4467817, 5334750, 529) with --hlod 250,1000."""
    flags = {
        "plain.glb": (),
        "cells.x3d": ("--hlod", "250"),
        "tiers.glb": ("--hlod", "250,1000"),
    }
    origins = _origins(_tum(), tmp_path, flags)
    assert origins == {name: [4467678.0, 5334745.0, 526.0] for name in flags}, origins
