"""The CityJSON reader on the shared samples (10 multi-LoD buildings; Delft, 570 objects) and on
small hand-written files: LoDs, semantic colours, ids and attributes through to X3D and glTF,
vertex round trip, geographic CRSs, CityJSONSeq, templates, bad indices, types filter, refused
inputs."""

from __future__ import annotations

import copy
import gzip
import json
import re
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from lxml import etree
from scipy.spatial import cKDTree

from lodconvert import convert
from lodconvert.errors import InputError
from lodconvert.io import read_chains, read_scene
from lodconvert.io.geometry_checks import tally_of
from lodconvert.model import Node
from lodconvert.semantics import DEFAULT_CLASS_COLORS
from lodconvert.validate import validate_file

from .conftest import SHARED
from .test_cli import assert_one_line_error, run
from .test_gltf import _assert_valid

CITYJSON = SHARED / "data" / "cityjson"


def sample(name: str) -> Path:
    """Path of a CityJSON sample in ../shared/data/cityjson, or skip the test."""
    path = CITYJSON / name
    if not path.exists():
        pytest.skip(f"{path} is absent (shared test data not checked out)")
    return path


def multi_lod() -> Path:
    return sample("multi_lod_10bldg.city.json")


def delft() -> Path:
    return sample("delft.city.json")


def nodes_of(path: Path, **options) -> list[Node]:
    """Every node of the file read, depth first."""
    return list(read_scene(path, **options).walk())


def write_json(path: Path, data: dict) -> Path:
    path.write_text(json.dumps(data))
    return path


def square(z: float = 0.0) -> list[list[float]]:
    return [[0, 0, z], [10, 0, z], [10, 10, z], [0, 10, z]]


def city(objects: dict, vertices: list, **extra) -> dict:
    """A CityJSON 2.0 document of ``objects`` over ``vertices`` (no transform)."""
    return {
        "type": "CityJSON",
        "version": "2.0",
        "CityObjects": objects,
        "vertices": vertices,
        **extra,
    }


def surface_object(*polygons: list, kind: str = "Building") -> dict:
    """A CityObject with one LoD 1 MultiSurface of ``polygons`` (lists of rings)."""
    geometry = {"type": "MultiSurface", "lod": "1", "boundaries": list(polygons)}
    return {"type": kind, "geometry": [geometry]}


# --- the samples ----------------------------------------------------------------------------------


def test_multi_lod_buildings_have_every_lod_and_semantic_colours() -> None:
    scene = read_scene(multi_lod())
    nodes = list(scene.walk())
    assert scene.crs is None  # the file declares none
    assert [n.type for n in nodes] == ["Building"] * 10
    for node in nodes:
        assert set(node.lods) == {"1.2", "1.3", "2.2"}
        assert node.geometry is node.lods["2.2"]
        assert node.attributes["id"] == node.id and node.attributes["type"] == "Building"
        assert "identificatie" in node.attributes
        colours = {tuple(p.base_color) for p in node.geometry.parts}
        assert colours == {tuple(DEFAULT_CLASS_COLORS[c]) for c in ("roof", "wall", "ground")}
        # coarser LoDs have no semantics: one part in the default colour
        assert len(node.lods["1.2"].parts) == 1
    assert len({tuple(DEFAULT_CLASS_COLORS[c]) for c in ("roof", "wall", "ground")}) == 3


def test_delft_reads_every_object_with_its_crs() -> None:
    scene = read_scene(delft())
    nodes = list(scene.walk())
    counts = Counter(n.type for n in nodes)
    assert counts["Building"] == 160
    assert (counts["Road"], counts["PlantCover"], counts["LandUse"]) == (143, 126, 81)
    assert len(nodes) == 570 == scene.size
    assert scene.crs == "EPSG:7415"
    assert {n.crs for n in nodes} == {"EPSG:7415"}
    assert all(set(n.lods) == {"1"} and n.geometry is n.lods["1"] for n in nodes)
    # geometry in float64 RD New coordinates, inside the file's box
    low = np.min([n.geometry.bounds[0] for n in nodes], axis=0)
    high = np.max([n.geometry.bounds[1] for n in nodes], axis=0)
    assert np.allclose(low, [84616.468, 447422.999, -0.452], atol=1e-6)
    assert np.allclose(high, [85140.839, 447750.636, 16.846], atol=1e-6)


def test_types_keeps_only_those_types(tmp_path: Path) -> None:
    nodes = nodes_of(delft(), types=frozenset({"Building"}))
    assert len(nodes) == 160 and {n.type for n in nodes} == {"Building"}
    types = frozenset({"Building", "Bridge"})
    report = convert(delft(), tmp_path / "b.glb", read_options={"types": types})
    assert report["totals"]["objects"] == 163


def test_types_keeps_no_object_whose_type_is_not_a_string(tmp_path: Path) -> None:
    """A ``type`` that is a JSON list or object (unhashable) matches no type of ``--types``:
    the object is left out, its kept children read, and the run goes on."""
    objects = {
        "a": surface_object([[0, 1, 2, 3]]),
        "b": {**surface_object([[0, 1, 2, 3]]), "type": ["Building"], "children": ["c"]},
        "c": {**surface_object([[0, 1, 2, 3]]), "type": "BuildingPart"},
        "d": {**surface_object([[0, 1, 2, 3]]), "type": {"Building": 1}},
    }
    path = write_json(tmp_path / "types.city.json", city(objects, square()))
    types = frozenset({"Building", "BuildingPart"})
    assert [n.id for n in nodes_of(path, types=types)] == ["a", "c"]
    result = run(path, "-o", tmp_path / "types.glb", "--types", "Building")
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    only = write_json(tmp_path / "only.city.json", city({"b": objects["b"]}, square()))
    result = run(only, "-o", tmp_path / "only.glb", "--types", "Building")
    assert_one_line_error(result, 1, "only.city.json", "no CityObject of type Building")


# --- end to end -----------------------------------------------------------------------------------


def _attributes_in_x3d(path: Path) -> dict[str, dict]:
    """Object id → the ``attributes`` JSON of its chain's MetadataSet."""
    found = {}
    for transform in etree.parse(str(path)).iter("Transform"):
        entries = {m.get("name"): m.get("value") for m in transform.findall("MetadataSet/*")}
        if "attributes" in entries:
            (object_id,) = json.loads(f"[{entries['object_id']}]")
            text = re.sub(r"\\(.)", r"\1", entries["attributes"][1:-1])
            found[object_id] = json.loads(text)
    return found


def _gltf_names(path: Path) -> list[str]:
    data = path.read_bytes()
    length = int.from_bytes(data[12:16], "little")
    doc = json.loads(data[20 : 20 + length])
    roots = doc["scenes"][0]["nodes"]
    if "frame" in doc["asset"]["extras"]["lodconvert"]:  # the objects in the y-up frame node
        (frame,) = roots
        roots = doc["nodes"][frame]["children"]
    return [doc["nodes"][i]["name"] for i in roots]


def _round_trip_error(out: Path, nodes: dict[str, Node]) -> float:
    """The largest distance between a vertex of a chain's finest level, as written to ``out``
    (plus the chain's origin), and the vertices of its source node, both ways; every buffer
    and coordinate list holds small values."""
    worst = 0.0
    for chain in read_chains(out):
        for level in chain.levels:
            local = level.mesh.vertices if level.mesh is not None else level.points.positions
            assert np.abs(local).max() < 1e5, (chain.object_id, level.name)
        written = chain.levels[0].mesh.vertices + chain.origin
        source_vertices = nodes[chain.object_id].geometry.vertices
        worst = max(
            worst,
            cKDTree(source_vertices).query(written)[0].max(),
            cKDTree(written).query(source_vertices)[0].max(),
        )
    return worst


@pytest.mark.parametrize("suffix", [".x3d", ".glb"])
@pytest.mark.parametrize("name", ["multi_lod_10bldg.city.json", "delft.city.json"])
def test_converts_one_object_per_node_with_ids_attributes_and_millimetres(
    name: str, suffix: str, tmp_path: Path, schema: etree.XMLSchema
) -> None:
    source = sample(name)
    out = tmp_path / f"city{suffix}"
    warnings: list[str] = []
    report = convert(source, out, warn=warnings.append)
    nodes = {n.id: n for n in read_scene(source).walk() if n.geometry is not None}
    # every node with geometry is one object (no BuildingParts here: one per building)
    assert [o["id"] for o in report["objects"]] == list(nodes)
    assert [w for w in warnings if "declares no CRS" not in w] == []  # multi_lod has none
    if suffix == ".x3d":
        assert schema.validate(etree.parse(str(out))), schema.error_log
        attributes = _attributes_in_x3d(out)
        assert set(attributes) == set(nodes)
        for object_id, node in nodes.items():
            assert attributes[object_id] == json.loads(json.dumps(node.attributes))
    else:
        assert validate_file(out) == []
        assert _gltf_names(out) == list(nodes)
    assert _round_trip_error(out, nodes) <= 1e-3


# --- CityJSONSeq ----------------------------------------------------------------------------------


def _features(document: dict) -> list[dict]:
    """One CityJSONFeature per object of ``document``, each with its own vertex list."""
    features = []
    for key, obj in document["CityObjects"].items():
        used: dict[int, int] = {}

        def local(value, used=used):
            if isinstance(value, list):
                return [local(v) for v in value]
            return used.setdefault(value, len(used))

        obj = copy.deepcopy(obj)
        for geometry in obj["geometry"]:
            geometry["boundaries"] = local(geometry["boundaries"])
        vertices = [document["vertices"][i] for i in used]
        features.append(
            {"type": "CityJSONFeature", "id": key, "CityObjects": {key: obj}, "vertices": vertices}
        )
    return features


@pytest.mark.parametrize("name", ["seq.city.jsonl", "seq.city.jsonl.gz"])
def test_sequence_reads_the_same_buildings_lazily(name: str, tmp_path: Path) -> None:
    document = json.loads(multi_lod().read_text())
    header = {
        "type": "CityJSON",
        "version": "2.0",
        "transform": document["transform"],
        "metadata": {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/7415"},
        "CityObjects": {},
        "vertices": [],
    }
    lines = [json.dumps(header), *(json.dumps(f) for f in _features(document))]
    path = tmp_path / name
    opener = gzip.open if name.endswith(".gz") else open
    with opener(path, "wt") as handle:
        handle.write("\n".join(lines) + "\n")
    scene = read_scene(path)
    assert not isinstance(scene.nodes, list)  # yielded as the lines are read
    assert scene.crs == "EPSG:7415"
    expected = {n.id: n for n in read_scene(multi_lod()).walk()}
    got = {n.id: n for n in scene.walk()}
    assert list(got) == list(expected)
    for key, node in got.items():
        assert set(node.lods) == set(expected[key].lods)
        for label, mesh in node.lods.items():
            assert np.array_equal(mesh.vertices, expected[key].lods[label].vertices)
            assert np.array_equal(mesh.faces, expected[key].lods[label].faces)


# --- problems: reported and skipped, or refused ---------------------------------------------------


def test_out_of_range_index_skips_that_object_only(tmp_path: Path) -> None:
    document = json.loads(multi_lod().read_text())
    bad = list(document["CityObjects"])[3]
    document["CityObjects"][bad]["geometry"][1]["boundaries"][0][0][0][0] = 10**6
    path = write_json(tmp_path / "bad.city.json", document)
    scene = read_scene(path)
    assert [n.id for n in scene.walk()] == [k for k in document["CityObjects"] if k != bad]
    (skipped,) = tally_of(scene).skipped
    assert skipped["id"] == bad and "index 1000000" in skipped["reason"]
    warnings: list[str] = []
    report = convert(path, tmp_path / "bad.x3d", warn=warnings.append)
    assert report["totals"]["objects"] == 9
    (warning,) = [w for w in warnings if "declares no CRS" not in w]
    assert "\n" not in warning and str(path) in warning and bad in warning


def test_degenerate_and_malformed_objects_are_reported_and_dropped(tmp_path: Path) -> None:
    line = [[4, 5, 6]]  # three points on a line
    vertices = [*square(), [0, 0, 5], [1, 0, 5], [2, 0, 5]]
    malformed = surface_object([["x"]])
    malformed["geometry"][0]["semantics"] = [1]
    objects = {
        "a": {**surface_object([[0, 1, 2, 3]], line), "children": [[1]]},
        "b": surface_object(line),
        "c": malformed,
    }
    scene = read_scene(write_json(tmp_path / "d.json", city(objects, vertices)))
    (node,) = scene.walk()
    assert node.id == "a" and len(node.geometry.faces) == 2
    tally = tally_of(scene)
    assert tally.dropped_faces == 2 and tally.dropped_by_object == {"a": 1}
    assert [s["id"] for s in tally.skipped] == ["b", "c"]
    assert "malformed MultiSurface boundaries" in tally.skipped[1]["reason"]


def test_polygons_with_holes_and_parts_are_merged_into_their_building(tmp_path: Path) -> None:
    """A BuildingPart's LoDs join its building's, as a CityGML building's parts do: one object
    per building, its parts kept as children (attributes, LoDs) without geometry of their own.
    A 1st-level child (a Building below a Building) stays an object of its own."""
    hole = [[2, 2, 0], [2, 8, 0], [8, 8, 0], [8, 2, 0]]
    objects = {
        "house": {
            **surface_object([[0, 1, 2, 3]]),
            "children": ["part", "annex"],
            "attributes": {"measuredHeight": 3.0},
        },
        "part": {
            "parents": ["house"],
            **surface_object([[0, 1, 2, 3], [4, 5, 6, 7]], kind="BuildingPart"),
            "attributes": {"function": "garage"},
        },
        "annex": {"parents": ["house"], **surface_object([[0, 1, 2, 3]])},
    }
    objects["house"]["geometry"][0]["lod"] = "0"
    path = write_json(tmp_path / "h.json", city(objects, square() + hole))
    (root,) = read_scene(path).nodes
    assert [c.id for c in root.children] == ["part", "annex"]
    part, annex = root.children
    assert sorted(root.lods) == ["0", "1"] and root.geometry is root.lods["1"]
    assert part.geometry is None and list(part.lods) == ["1"]
    assert part.attributes["function"] == "garage"
    assert annex.geometry is not None and annex.type == "Building"
    mesh = root.geometry
    edges = mesh.triangles[:, 1:] - mesh.triangles[:, :1]
    area = np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1).sum() / 2
    assert area == pytest.approx(100 - 36)
    out = tmp_path / "h.glb"
    report = convert(path, out)
    assert [o["id"] for o in report["objects"]] == ["house", "annex"]
    data = out.read_bytes()
    document = json.loads(data[20 : 20 + int.from_bytes(data[12:16], "little")])
    (house,) = [n for n in document["nodes"] if n.get("name") == "house"]
    assert house["extras"]["attributes"]["parts"] == [
        {"function": "garage", "id": "part", "type": "BuildingPart"}
    ]


def test_template_instances_share_one_mesh(tmp_path: Path) -> None:
    cube = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    template = {"type": "Solid", "lod": "2", "boundaries": [[[f] for f in faces]]}
    scale = [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1]

    def tree(point: int) -> dict:
        geometry = {
            "type": "GeometryInstance",
            "template": 0,
            "boundaries": [point],
            "transformationMatrix": scale,
        }
        return {"type": "SolitaryVegetationObject", "geometry": [geometry]}

    document = city(
        {"t1": tree(0), "t2": tree(1)},
        [[100, 200, 0], [150, 250, 3]],
        **{"geometry-templates": {"templates": [template], "vertices-templates": cube}},
    )
    path = write_json(tmp_path / "trees.city.json", document)
    t1, t2 = read_scene(path).walk()
    assert t1.geometry is t2.geometry and t1.lods == {"2": t1.geometry}
    assert np.allclose(t1.geometry.bounds, [[0, 0, 0], [1, 1, 1]])
    expected = np.diag([2.0, 2.0, 2.0, 1.0])
    expected[:3, 3] = [150, 250, 3]
    assert np.array_equal(t2.transform, expected)
    report = convert(path, tmp_path / "trees.x3d")
    assert [o["id"] for o in report["objects"]] == ["t1", "t2"]
    assert b"USE=" in (tmp_path / "trees.x3d").read_bytes()


def test_material_colour_wins_over_semantics(tmp_path: Path) -> None:
    obj = surface_object([[0, 1, 2, 3]])
    obj["geometry"][0]["material"] = {"summer": {"values": [0]}, "winter": {"value": 1}}
    obj["geometry"][0]["semantics"] = {"surfaces": [{"type": "RoofSurface"}], "values": [0]}
    materials = [{"name": "m", "diffuseColor": [0.0, 0.5, 1.0], "transparency": 0.5}, {}]
    document = city({"a": obj}, square(), appearance={"materials": materials})
    (node,) = read_scene(write_json(tmp_path / "m.json", document)).walk()
    assert node.geometry.parts[0].base_color.tolist() == [0, 128, 255, 128]


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ('{"type": "FeatureCollection", "features": []}', "is not CityJSON (its type is"),
        ("[1, 2]", "is not CityJSON (a JSON list"),
        ("{not json", "is not CityJSON (not valid JSON"),
        ('{"type": "CityJSON", "version": "3.0"}', "CityJSON 3.0; 1.1 and 2.0 are read"),
    ],
)
def test_other_json_is_refused_in_one_line(text: str, says: str, tmp_path: Path) -> None:
    path = tmp_path / "other.json"
    path.write_text(text)
    with pytest.raises(InputError) as caught:
        read_scene(path)
    assert says in str(caught.value) and "\n" not in str(caught.value)


def _geographic_delft(tmp_path: Path) -> tuple[Path, np.ndarray]:
    """Delft with its RD New vertices turned into EPSG:4979 latitude, longitude (degrees, as
    integers of a 1e-9° ``transform``) and its heights kept; the file and the vertices' float64
    degrees as the file gives them."""
    from pyproj import Transformer

    document = json.loads(delft().read_text())
    rd = np.asarray(document["vertices"], dtype=np.float64) * document["transform"]["scale"]
    rd += document["transform"]["translate"]
    lat, lon = Transformer.from_crs("EPSG:28992", "EPSG:4326").transform(rd[:, 0], rd[:, 1])
    scale = np.array([1e-9, 1e-9, 1e-3])
    translate = np.floor(np.array([lat.min(), lon.min(), 0.0]))
    integers = np.round((np.stack([lat, lon, rd[:, 2]], axis=1) - translate) / scale)
    document["vertices"] = integers.astype(np.int64).tolist()
    document["transform"] = {"scale": scale.tolist(), "translate": translate.tolist()}
    document["metadata"] = {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/4979"}
    path = write_json(tmp_path / "delft_4979.city.json", document)
    return path, integers * scale + translate


def _area(mesh) -> float:
    """Surface area of a mesh."""
    a, b, c = (mesh.vertices[mesh.faces[:, k]] for k in range(3))
    return float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum() / 2)


def _projected(degrees: np.ndarray, proj: str) -> np.ndarray:
    """Latitude, longitude, height onto the local frame ``proj``, by a pipeline of its own."""
    from pyproj import Transformer

    steps = "+proj=pipeline +step +proj=axisswap +order=2,1 +step +proj=unitconvert "
    steps += f"+xy_in=deg +xy_out=rad +step {proj.replace(' +units=m +no_defs', '')}"
    x, y = Transformer.from_pipeline(steps).transform(degrees[:, 0], degrees[:, 1])
    return np.stack([x, y, degrees[:, 2]], axis=1)


def test_geographic_crs_is_projected_to_a_metric_local_frame(
    tmp_path: Path, schema: etree.XMLSchema, gltf_validator
) -> None:
    path, degrees = _geographic_delft(tmp_path)
    scene = read_scene(path)
    frame = scene.attributes["local_frame"]
    assert frame["source_crs"] == "EPSG:4979" and "+proj=tmerc" in frame["proj"]
    assert scene.crs == frame["proj"]
    lat, lon = frame["center"]
    assert 51.99 < lat < 52.03 and 4.34 < lon < 4.40  # Delft
    nodes = {n.id: n for n in scene.walk()}
    assert {n.crs for n in nodes.values()} == {frame["proj"]}
    rd = {n.id: n for n in read_scene(delft()).walk()}
    assert list(nodes) == list(rd)
    expected = _projected(degrees, frame["proj"])
    tree = cKDTree(expected)
    for key, node in nodes.items():
        vertices = node.geometry.vertices
        assert tree.query(vertices)[0].max() <= 1e-3, key  # on the frame's own projection
        assert np.abs(vertices[:, :2]).max() < 1000.0  # metres from the centre of Delft
        # the same shapes, turned by the grids' convergence (≈0.8° here) and RD's scale (≈0.9999)
        assert _area(node.geometry) == pytest.approx(_area(rd[key].geometry), rel=1e-3), key
        assert np.ptp(vertices[:, 2]) == pytest.approx(np.ptp(rd[key].geometry.vertices[:, 2]))
    for suffix in (".x3d", ".glb"):
        out = tmp_path / f"delft{suffix}"
        convert(path, out)
        if suffix == ".x3d":
            assert schema.validate(etree.parse(str(out))), schema.error_log
            assert f'content="{frame["proj"]}"' in out.read_text()
        else:
            assert validate_file(out) == []
            _assert_valid(gltf_validator(out))  # the Khronos glTF-Validator
        assert _round_trip_error(out, nodes) <= 1e-3


def test_geographic_sequence_is_projected_on_its_first_feature(tmp_path: Path) -> None:
    path, degrees = _geographic_delft(tmp_path)
    document = json.loads(path.read_text())
    header = {key: document[key] for key in ("type", "version", "transform", "metadata")}
    lines = [json.dumps({**header, "CityObjects": {}, "vertices": []})]
    lines += [json.dumps(f) for f in _features(document)]
    seq = tmp_path / "delft_4979.city.jsonl"
    seq.write_text("\n".join(lines) + "\n")
    scene = read_scene(seq)
    frame = scene.attributes["local_frame"]
    assert scene.crs == frame["proj"] and frame["source_crs"] == "EPSG:4979"
    nodes = list(scene.walk())
    assert len(nodes) == 570 and {n.crs for n in nodes} == {frame["proj"]}
    first = json.loads(lines[1])
    box = np.asarray(first["vertices"]) * header["transform"]["scale"]
    center = (box.min(axis=0) + box.max(axis=0)) / 2 + header["transform"]["translate"]
    assert np.allclose(frame["center"], center[:2], atol=1e-6)
    tree = cKDTree(_projected(degrees, frame["proj"]))
    assert max(tree.query(n.geometry.vertices)[0].max() for n in nodes) <= 1e-3


def test_colors_option_changes_the_class_colours() -> None:
    from lodconvert.errors import UsageError
    from lodconvert.semantics import DEFAULT_PALETTE

    red = DEFAULT_PALETTE.with_text("roof=#ff0000")
    scene = read_scene(multi_lod(), colors=red)
    node = next(iter(scene.nodes))
    colours = {tuple(part.material_color) for part in node.geometry.parts}
    assert (255, 0, 0, 255) in colours
    assert tuple(DEFAULT_PALETTE.classes["roof"]) not in colours
    for bad in ("roof=red", "chimney=#000000"):
        with pytest.raises(UsageError):
            DEFAULT_PALETTE.with_text(bad)


def test_fuzz_found_a_float_vertex_index_too_large_for_an_integer(tmp_path: Path) -> None:
    """A boundary index of 1e308 (found by the fuzzer: OverflowError) is a malformed object,
    reported and skipped like any other."""
    from .fuzz.seeds import seeds_for

    seed = seeds_for(".json")[0]
    data = json.loads(seed)
    data["CityObjects"]["house"]["geometry"][0]["boundaries"][0][0][0][0] = 1e308
    path = write_json(tmp_path / "big_index.city.json", data)
    assert [n.id for n in read_scene(path).walk()] == []  # the only object is skipped
    result = run(path, "-o", tmp_path / "out.glb")
    assert_one_line_error(result, 1, "big_index.city.json", "house")


def test_no_declared_crs_is_a_warning_and_crs_names_it(tmp_path: Path) -> None:
    out = tmp_path / "city.glb"
    result = run(multi_lod(), "-o", out)
    assert result.returncode == 0
    assert "declares no CRS" in result.stderr and "--crs" in result.stderr
    result = run(multi_lod(), "-o", out, "--crs", "EPSG:7415")
    assert result.returncode == 0 and "declares no CRS" not in result.stderr
    data = out.read_bytes()
    length = int.from_bytes(data[12:16], "little")
    assert json.loads(data[20 : 20 + length])["asset"]["extras"]["lodconvert"]["crs"] == (
        "EPSG:7415"
    )
