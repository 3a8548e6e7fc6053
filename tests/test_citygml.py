"""CityGML reader: the real samples in ../shared/data/citygml (1.0, 2.0, 3.0; projected and
geographic), end to end into X3D and glTF, and hostile documents."""

from __future__ import annotations

import gzip
import json
import re
import struct
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from lodconvert import convert
from lodconvert.io import read_chains, read_scene
from lodconvert.io.geometry_checks import tally_of
from lodconvert.limits import Limits
from lodconvert.model import Mesh, Node, Surface
from lodconvert.semantics import DEFAULT_CLASS_COLORS, TYPE_COLORS
from lodconvert.validate import errors_of, validate_file

from .conftest import SHARED
from .test_cli import assert_one_line_error, run
from .test_gltf import _assert_valid

CITYGML = SHARED / "data" / "citygml"
ROOF_COLOR, WALL_COLOR, GROUND_COLOR, OTHER_COLOR = (
    DEFAULT_CLASS_COLORS[c] for c in ("roof", "wall", "ground", "other")
)
SIG3D = "sig3d_house_lod0-4/Building_LOD{}-EPSG25832.gml"
SAMPLES = {
    "tum_munich_lod2_v2.zip": 290,
    "potsdam_lod1_v1.gml": 97,
    "kit_testcases_lod2_100bldg_v3.gml": 100,
    "plateau_53394517_bldg_lod012_v2.gml": 1,
    "plateau_53394517_bldg_lod012_v3.gml": 1,
    **{SIG3D.format(lod): 1 for lod in range(5)},
}
"""Each sample and its count of top-level buildings (../shared/data/README.md)."""
PLATEAU = ("plateau_53394517_bldg_lod012_v2.gml", "plateau_53394517_bldg_lod012_v3.gml")


def sample(name: str) -> Path:
    """Path of a CityGML sample in ../shared/data/citygml, or skip the test."""
    path = CITYGML / name
    if not path.exists():
        pytest.skip(f"{path} is absent (shared test data not checked out)")
    return path


def nodes_of(path: Path, **options: object) -> list[Node]:
    return list(read_scene(path, **options).nodes)


def buildings_of(path: Path) -> list[Node]:
    """The ``Building`` nodes of a sample (the SIG3D files also hold their terrain)."""
    return [node for node in nodes_of(path) if node.type == "Building"]


def colors(mesh: Mesh) -> set[tuple[int, ...]]:
    return {tuple(int(c) for c in part.material_color) for part in mesh.parts}


def as_tuple(color: np.ndarray) -> tuple[int, ...]:
    return tuple(int(c) for c in color)


# --- the samples ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(SAMPLES))
def test_every_sample_reads_with_its_building_count(name: str) -> None:
    nodes = nodes_of(sample(name))
    assert sum(node.type == "Building" for node in nodes) == SAMPLES[name]
    for node in nodes:
        assert node.geometry is not None and len(node.geometry.faces) > 0
        assert node.attributes["type"] == node.type and node.attributes["id"]
        assert any(node.geometry is mesh for mesh in node.lods.values())


def test_projected_samples_keep_their_crs_and_coordinates() -> None:
    scene = read_scene(sample(SIG3D.format(2)))
    node, _terrain = scene.nodes
    assert scene.crs == node.crs == "EPSG:25832"
    assert scene.attributes["vertical_crs"] == "EPSG:5783"
    bounds = node.geometry.bounds
    assert np.all(bounds[0] >= [458868, 5438343, 112]) and np.all(
        bounds[1] <= [458892, 5438362, 117]
    )
    assert read_scene(sample("tum_munich_lod2_v2.zip")).crs == "EPSG:31468"


def test_lod2_house_has_roof_wall_and_ground_parts() -> None:
    (node,) = buildings_of(sample(SIG3D.format(2)))
    assert list(node.lods) == ["lod2"]
    found = colors(node.geometry)
    assert {as_tuple(ROOF_COLOR), as_tuple(WALL_COLOR), as_tuple(GROUND_COLOR)} <= found
    # the lod2Solid refers to the thematic surfaces' polygons: each is read once
    assert len(node.geometry.faces) == 16


def test_lod0_lod3_and_lod4_houses_carry_their_lods() -> None:
    (lod0,) = buildings_of(sample(SIG3D.format(0)))
    assert list(lod0.lods) == ["lod0"]
    assert colors(lod0.geometry) == {as_tuple(ROOF_COLOR), as_tuple(GROUND_COLOR)}
    (lod3,) = buildings_of(sample(SIG3D.format(3)))
    assert "lod3" in lod3.lods and lod3.geometry is lod3.lods["lod3"]
    assert as_tuple(OTHER_COLOR) in colors(lod3.geometry)  # windows and the door
    (lod4,) = buildings_of(sample(SIG3D.format(4)))
    assert list(lod4.lods) == ["lod4"]


def test_lod4_interior_is_read_as_parts_of_the_building() -> None:
    """The SIG3D LoD4 house's room (its own walls, floor and ceiling; its links to the house's
    ground surface are read once, by the house) and the furniture in it are parts of the
    house: children with their own LoD4 and attributes, inside the house, in its LoD4."""
    scene = read_scene(sample(SIG3D.format(4)))
    house = next(node for node in scene.nodes if node.type == "Building")
    (room,) = house.children
    (furniture,) = room.children
    assert (room.type, furniture.type) == ("Room", "BuildingFurniture")
    assert list(room.lods) == list(furniture.lods) == ["lod4"]
    assert furniture.attributes["function"] == "1340"
    assert WALL_COLOR.tolist() in [p.material_color.tolist() for p in room.lods["lod4"].parts]
    assert scene.attributes["citygml"]["unresolved_links"] == {}
    own = house.lods["lod4"]
    for part in (room, furniture):
        box = part.lods["lod4"].bounds
        assert (box[0] >= own.bounds[0] - 1e-6).all() and (box[1] <= own.bounds[1] + 1e-6).all()
    faces = [len(n.lods["lod4"].faces) for n in (room, furniture)]
    assert len(own.faces) > sum(faces) > 2000


def test_plateau_is_projected_to_a_metric_local_frame_and_both_versions_agree() -> None:
    meshes = []
    for name in PLATEAU:
        scene = read_scene(sample(name))
        (node,) = scene.nodes
        frame = scene.attributes["local_frame"]
        assert scene.crs == frame["proj"] == node.crs and "+proj=tmerc" in scene.crs
        assert frame["source_crs"] == "EPSG:6697"
        assert sorted(node.lods) == ["lod0", "lod1", "lod2"] and node.geometry is node.lods["lod2"]
        extent = np.ptp(node.geometry.vertices, axis=0)
        assert 31.0 <= extent[2] <= 33.0  # measuredHeight 31.7 m
        assert 10.0 < extent[0] < 200.0 and 10.0 < extent[1] < 200.0
        assert np.all(np.abs(node.geometry.bounds[:, :2]) < 200.0)  # centred on the data
        assert node.attributes["measuredHeight"] == pytest.approx(31.7)
        meshes.append(node.geometry)
    assert np.array_equal(meshes[0].faces, meshes[1].faces)
    assert np.abs(meshes[0].vertices - meshes[1].vertices).max() <= 1e-3


def test_attributes_are_read() -> None:
    (house,) = buildings_of(sample(SIG3D.format(1)))
    attributes = house.attributes
    assert attributes["id"] == "GML_7b1a5a6f-ddad-4c3d-a507-3eb9ee0a8e68"
    assert attributes["name"] == "Example Building LOD1"
    assert attributes["yearOfConstruction"] == 1985 and attributes["measuredHeight"] == 5.0
    assert attributes["address"].startswith("Hermann-von-Helmholtz-Platz 1, 76344")
    tum = nodes_of(sample("tum_munich_lod2_v2.zip"))[0].attributes
    assert tum["generic"]["HoeheDach"] == pytest.approx(53.8)
    assert tum["generic"]["Gemeindeschluessel"] == "09162000"
    assert tum["storeysAboveGround"] == 5 and tum["function"] == "1001"
    plateau = nodes_of(sample(PLATEAU[1]))[0].attributes
    assert plateau["generic"]["建物ID"] == "13104-bldg-53"
    json.dumps([attributes, tum, plateau])


@pytest.mark.parametrize("lod", range(5))
def test_terrain_is_read_as_its_own_object(lod: int) -> None:
    """Each SIG3D file's ``ReliefFeature`` (a ``TINRelief`` of 9 triangles, its ``dem:lod``
    the file's LoD; the LoD4 file's is LoD3) is an object of its own, under the house,
    coloured as terrain."""
    house, terrain = nodes_of(sample(SIG3D.format(lod)))
    assert (house.type, terrain.type) == ("Building", "ReliefFeature")
    assert terrain.id == "GML_6bb30328-7599-4500-90ef-766fde6aa67b"
    assert list(terrain.lods) == [f"lod{min(lod, 3)}"]
    assert len(terrain.geometry.faces) == 9
    assert colors(terrain.geometry) == {as_tuple(TYPE_COLORS["ReliefFeature"])}
    low, high = terrain.geometry.bounds, house.geometry.bounds
    assert (low[0, :2] <= high[0, :2]).all() and (low[1, :2] >= high[1, :2]).all()
    assert low[0, 2] <= high[0, 2] + 0.5  # the ground, not floating above the house's base


def relief(tin: str) -> str:
    """A 2.0 ``ReliefFeature`` whose LoD2 ``TINRelief`` holds ``tin`` (a ``gml:Tin``)."""
    return (
        '<cityObjectMember><dem:ReliefFeature gml:id="ground"><dem:lod>2</dem:lod>'
        "<dem:reliefComponent><dem:TINRelief><dem:lod>2</dem:lod>"
        f"<dem:tin>{tin}</dem:tin></dem:TINRelief></dem:reliefComponent></dem:ReliefFeature>"
        "</cityObjectMember>"
    )


@pytest.mark.parametrize(
    ("max_length", "triangles"), [("", 4), ("<gml:maxLength>10.05</gml:maxLength>", 2)]
)
def test_a_tin_of_control_points_is_triangulated_in_plan(
    tmp_path: Path, max_length: str, triangles: int
) -> None:
    """A ``gml:Tin`` that lists control points and no triangles (a square's corners and a
    raised point off its centre) is triangulated in plan, every triangle facing up, and
    triangles with a side over ``maxLength`` are left out."""
    points = "0 0 0 10 0 0 10 10 0 0 10 0 3 3 2"
    tin = (
        f"<gml:Tin><gml:trianglePatches/>{max_length}"
        f'<gml:controlPoint><gml:posList srsDimension="3">{points}</gml:posList>'
        "</gml:controlPoint></gml:Tin>"
    )
    path = tmp_path / "terrain.gml"
    head = HEAD.replace(">", ' xmlns:dem="http://www.opengis.net/citygml/relief/2.0">', 1)
    path.write_text(document(relief(tin)).replace(HEAD, head))
    (node,) = nodes_of(path)
    assert node.type == "ReliefFeature" and list(node.lods) == ["lod2"]
    mesh = node.geometry
    assert len(mesh.faces) == triangles
    corners = mesh.triangles
    up = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, 2]
    assert (up > 0).all()
    if triangles == 4:  # the whole square is covered
        assert np.abs(up).sum() / 2 == pytest.approx(100.0)


def test_terrain_and_ground_covers_get_no_prism(tmp_path: Path) -> None:
    """A house's LoD2 file gives the house a prism to weigh for LOD1 (its steep gable roof
    makes the block miss silhouette F 0.95 where it would switch in: the LoD2 stays on), its
    terrain none (a block from its lowest to its highest point would hide the house); the
    terrain is no neighbour of the house, which stands alone on its plot (γ 10 m, not the 2 m
    of half the distance between their centres)."""
    report = convert([sample(SIG3D.format(2))], tmp_path / "house.x3d")
    house, terrain = report["objects"]
    assert house["gamma"] == terrain["gamma"] == 10.0
    assert [lv["kind"] for lv in house["levels"]] == ["source"]
    assert (
        house["dropped"]["LOD1"].startswith("silhouette F 0.9")
        and "below 0.95" in house["dropped"]["LOD1"]
    )
    assert [lv["kind"] for lv in terrain["levels"]] == ["source"]
    assert "covers the ground: no prism" in terrain["dropped"]["LOD1"]
    assert errors_of(validate_file(tmp_path / "house.x3d")) == []


@pytest.mark.parametrize("suffix", [".x3d", ".glb"])
def test_a_lod0_only_building_is_its_prism(tmp_path: Path, suffix: str) -> None:
    """The SIG3D LoD0 house (footprint and roof edge, measuredHeight 5 m) is one LOD1 prism
    5 m high over its LoD0 outline; its terrain, a ground cover, stays as it is."""
    (house,) = buildings_of(sample(SIG3D.format(0)))
    out = tmp_path / f"house{suffix}"
    report = convert([sample(SIG3D.format(0))], out)
    obj, terrain = report["objects"]
    assert [(lv["name"], lv["kind"]) for lv in obj["levels"]] == [("LOD1", "prism")]
    assert obj["cutoffs"] == [] and set(obj["dropped"]) == {"LOD4", "LOD3", "LOD2"}
    assert [lv["kind"] for lv in terrain["levels"]] == ["mesh"]
    (chain, _) = read_chains(out)
    prism = chain.levels[0].mesh.vertices + chain.origin
    assert np.ptp(prism[:, 2]) == pytest.approx(5.0, abs=1e-3)
    outline = house.lods["lod0"].bounds
    assert np.allclose(prism[:, :2].min(axis=0), outline[0, :2], atol=1e-3)
    assert np.allclose(prism[:, :2].max(axis=0), outline[1, :2], atol=1e-3)
    assert errors_of(validate_file(out)) == []


def test_objects_without_semantic_surfaces_take_their_type_colour(tmp_path: Path) -> None:
    """A ``PlantCover`` whose geometry is its own (no thematic surface) is vegetation green."""
    cover = building("cover", box()).replace("bldg:Building", "veg:PlantCover")
    cover = cover.replace("bldg:lod2MultiSurface", "veg:lod2MultiSurface")
    head = HEAD.replace(">", ' xmlns:veg="http://www.opengis.net/citygml/vegetation/2.0">', 1)
    path = tmp_path / "cover.gml"
    path.write_text(document(cover).replace(HEAD, head))
    (node,) = nodes_of(path)
    assert node.type == "PlantCover"
    assert colors(node.geometry) == {as_tuple(TYPE_COLORS["PlantCover"])}


def veg_document(*objects: str) -> str:
    """:func:`document` with the vegetation namespace declared."""
    head = HEAD.replace(">", ' xmlns:veg="http://www.opengis.net/citygml/vegetation/2.0">', 1)
    return document(*objects).replace(HEAD, head)


CROWN = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [0, 0, 3]], dtype=float)
"""A pyramid: the template of the trees below (its base and four sides)."""
CROWN_FACES = [[0, 3, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]


def tree_matrix(k: int) -> np.ndarray:
    """Tree ``k``'s transformation: turned k × 90° about z, scaled 1–3×, raised 0.5 m."""
    turn = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)
    matrix = np.eye(4)
    matrix[:3, :3] = np.linalg.matrix_power(turn, k % 4) * (1 + k % 3)
    matrix[2, 3] = 0.5
    return matrix


def tree(k: int, reference: tuple[float, ...], crown: str = "#crown", matrix: str = "") -> str:
    """Tree ``k``: a lod2 implicit representation of the crown (inline for ``crown=""``)."""
    if crown:
        geometry = f'<relativeGMLGeometry xlink:href="{crown}"/>'
    else:
        members = "".join(
            "<gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing><gml:posList>"
            + " ".join(f"{v:g}" for i in [*face, face[0]] for v in CROWN[i])
            + "</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>"
            for face in CROWN_FACES
        )
        geometry = (
            f'<relativeGMLGeometry><gml:MultiSurface gml:id="crown">{members}'
            "</gml:MultiSurface></relativeGMLGeometry>"
        )
    matrix = matrix or " ".join(f"{v:g}" for v in tree_matrix(k).ravel())
    point = " ".join(f"{v!r}" for v in reference)
    return (
        f'<cityObjectMember><veg:SolitaryVegetationObject gml:id="tree{k}">'
        "<veg:lod2ImplicitRepresentation><ImplicitGeometry>"
        f"<transformationMatrix>{matrix}</transformationMatrix>{geometry}"
        f"<referencePoint><gml:Point><gml:pos>{point}</gml:pos></gml:Point></referencePoint>"
        "</ImplicitGeometry></veg:lod2ImplicitRepresentation>"
        "</veg:SolitaryVegetationObject></cityObjectMember>"
    )


def test_implicit_geometry_is_placed_and_shared_across_batches(
    tmp_path: Path, schema: etree.XMLSchema, gltf_validator
) -> None:
    """70 trees (more than one batch of objects): the first defines the crown, the others link
    to it; each is the crown turned and scaled by its matrix at its reference point. A link to
    a crown defined nowhere and a matrix of 15 values are reported; the rest convert."""
    references = [(690000.0 + 10 * k, 5336000.0 + 3 * k, 500.0 + k) for k in range(70)]
    trees = [tree(k, ref, crown="" if k == 0 else "#crown") for k, ref in enumerate(references)]
    trees.append(tree(70, references[1], crown="#nowhere"))
    trees.append(tree(71, references[2], matrix=" ".join(["1"] * 15)))
    path = tmp_path / "trees.gml"
    path.write_text(veg_document(*trees))
    scene = read_scene(path)
    nodes = list(scene.nodes)
    assert [n.id for n in nodes] == [f"tree{k}" for k in range(70)]
    for k, node in enumerate(nodes):
        assert list(node.lods) == ["lod2"] and len(node.geometry.faces) == 6
        matrix = tree_matrix(k)
        expected = CROWN @ matrix[:3, :3].T + matrix[:3, 3] + references[k]
        assert _max_distance(node.geometry.vertices, expected) <= 1e-9
        assert _max_distance(expected, node.geometry.vertices) <= 1e-9
        assert colors(node.geometry) == {as_tuple(TYPE_COLORS["SolitaryVegetationObject"])}
    assert scene.attributes["citygml"]["unresolved_links"] == {"tree70": 1}
    skipped = {s["id"]: s["reason"] for s in tally_of(scene).skipped}
    assert "transformationMatrix of 15 values, not 16" in skipped["tree71"]
    for suffix in (".x3d", ".glb"):
        out = tmp_path / f"trees{suffix}"
        report = convert(path, out, backend="numpy")
        assert report["totals"]["objects"] == 70
        if suffix == ".x3d":
            schema.assertValid(etree.parse(str(out)))
        else:
            _assert_valid(gltf_validator(out))  # the Khronos glTF-Validator


def test_implicit_geometry_in_a_geographic_crs_is_placed_in_metres(tmp_path: Path) -> None:
    """With EPSG:4979 the reference point (latitude, longitude, height) is projected onto the
    local frame and the crown is placed there in metres."""
    from pyproj import Transformer

    envelope = '<gml:Envelope srsName="http://www.opengis.net/def/crs/EPSG/0/4979"/>'
    references = [(35.68 + 1e-4 * k, 139.76, 40.0) for k in range(3)]
    trees = [tree(k, ref, crown="" if k == 0 else "#crown") for k, ref in enumerate(references)]
    path = tmp_path / "trees.gml"
    text = veg_document(*trees)
    at = text.index("<cityObjectMember>")
    path.write_text(f"{text[:at]}<gml:boundedBy>{envelope}</gml:boundedBy>{text[at:]}")
    scene = read_scene(path)
    frame = scene.attributes["local_frame"]
    to_frame = Transformer.from_pipeline(
        "+proj=pipeline +step +proj=axisswap +order=2,1 +step +proj=unitconvert +xy_in=deg "
        f"+xy_out=rad +step {frame['proj'].replace(' +units=m +no_defs', '')}"
    )
    for k, node in enumerate(scene.nodes):
        x, y = to_frame.transform(references[k][0], references[k][1])
        matrix = tree_matrix(k)
        expected = CROWN @ matrix[:3, :3].T + matrix[:3, 3] + [x, y, references[k][2]]
        assert _max_distance(node.geometry.vertices, expected) <= 1e-6
        assert np.ptp(node.geometry.vertices[:, 2]) == pytest.approx(3 * (1 + k % 3))
    assert abs(frame["center"][0] - 35.6801) < 1e-3  # centred on the reference points


def test_types_option_filters_objects() -> None:
    path = sample(SIG3D.format(2))
    assert len(nodes_of(path, types=frozenset({"Building"}))) == 1
    with pytest.raises(Exception, match="no city objects of type Road"):
        read_scene(path, types=frozenset({"Road"}))


# --- end to end -----------------------------------------------------------------------------------


def _max_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance from a point of ``a`` to the nearest point of ``b`` and back."""
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return float(max(d.min(axis=1).max(), d.min(axis=0).max()))


def written_attributes(path: Path) -> dict[str, dict]:
    """The attributes each object carries in an output: X3D ``MetadataString attributes``
    (JSON in an MFString) beside its ``object_id``; glTF root-node ``extras.attributes``."""
    if path.suffix == ".x3d":
        found = {}
        for entries in etree.parse(str(path)).iter("MetadataSet"):
            values = {e.get("name"): e.get("value") for e in entries if e.tag == "MetadataString"}
            if "attributes" in values:
                object_id, text = (
                    re.sub(r"\\(.)", r"\1", values[k][1:-1]) for k in ("object_id", "attributes")
                )
                found[object_id] = json.loads(text)
        return found
    data = path.read_bytes()
    document = json.loads(data[20 : 20 + struct.unpack("<I", data[12:16])[0]])
    nodes = document["nodes"]
    return {
        n["name"]: n["extras"]["attributes"] for n in nodes if "attributes" in n.get("extras", {})
    }


@pytest.mark.parametrize("suffix", [".x3d", ".glb"])
def test_parts_attributes_are_written_with_their_building(suffix: str, tmp_path: Path) -> None:
    """The room and the furniture merged into the SIG3D LoD4 house's levels keep their
    attributes in the output, under the house's ``parts``, in document order."""
    out = tmp_path / f"house{suffix}"
    convert(sample(SIG3D.format(4)), out, backend="numpy")
    house = next(v for v in written_attributes(out).values() if v["type"] == "Building")
    assert house["id"] == "GML_7b1a5a6f-ddad-4c3d-a507-3eb9ee0a8e68"
    assert house["parts"] == [
        {"id": "", "type": "Room"},
        {"id": "", "type": "BuildingFurniture", "name": "Rocking Chair", "function": "1340"},
    ]


@pytest.mark.parametrize("name", ["tum_munich_lod2_v2.zip", "kit_testcases_lod2_100bldg_v3.gml"])
@pytest.mark.parametrize("suffix", [".x3d", ".glb"])
def test_districts_convert_one_object_per_building(
    name: str, suffix: str, tmp_path: Path, schema: etree.XMLSchema
) -> None:
    path = sample(name)
    out = tmp_path / f"city{suffix}"
    report = convert(path, out, backend="numpy")
    source = {node.id: node for node in nodes_of(path)}
    assert report["totals"]["objects"] == len(source) == SAMPLES[name]
    if suffix == ".x3d":
        schema.assertValid(etree.parse(str(out)))
    else:
        assert run("validate", out).returncode == 0
    chains = read_chains(out)
    assert sorted(c.object_id for c in chains) == sorted(source)
    attributes = written_attributes(out)
    worst = 0.0
    for chain in chains:
        node = source[chain.object_id]
        assert attributes[chain.object_id] == json.loads(json.dumps(node.attributes))
        for level in chain.levels:  # what the buffers and coordinate lists hold: small
            written = level.mesh.vertices if level.mesh is not None else level.points.positions
            assert np.abs(written).max() < 1e5, (chain.object_id, level.name)
        finest = chain.levels[0].mesh
        worst = max(worst, _max_distance(finest.vertices + chain.origin, node.geometry.vertices))
    assert worst <= 1e-3


# --- hostile and broken documents -----------------------------------------------------------------

HEAD = (
    '<CityModel xmlns="http://www.opengis.net/citygml/2.0" xmlns:gml="http://www.opengis.net/gml" '
    'xmlns:bldg="http://www.opengis.net/citygml/building/2.0" '
    'xmlns:xlink="http://www.w3.org/1999/xlink">'
)


def building(gml_id: str, rings: list[str], extra: str = "") -> str:
    """A 2.0 building whose lod2MultiSurface holds one polygon per posList in ``rings``."""
    members = "".join(
        f'<gml:surfaceMember><gml:Polygon gml:id="{gml_id}_{i}"><gml:exterior><gml:LinearRing>'
        f"<gml:posList>{ring}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon>"
        "</gml:surfaceMember>"
        for i, ring in enumerate(rings)
    )
    return (
        f'<cityObjectMember><bldg:Building gml:id="{gml_id}"><bldg:lod2MultiSurface>'
        f"<gml:MultiSurface>{members}{extra}</gml:MultiSurface></bldg:lod2MultiSurface>"
        "</bldg:Building></cityObjectMember>"
    )


def box(x: float = 0.0, size: float = 10.0) -> list[str]:
    """The six faces of a cube at ``x`` as posLists (outward counter-clockwise)."""
    corners = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
    corners = corners * size + [x, 0, 0]
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return [" ".join(f"{v:g}" for i in q[::-1] + q[-1:] for v in corners[i]) for q in quads]


def document(*objects: str, prolog: str = "") -> str:
    return f'<?xml version="1.0" encoding="UTF-8"?>{prolog}{HEAD}{"".join(objects)}</CityModel>'


@pytest.fixture
def out_dir(tmp_path: Path) -> Path:
    folder = tmp_path / "out"
    folder.mkdir()
    return folder


def refused(path: Path, out_dir: Path, *words: str) -> None:
    """The command line refuses ``path`` with one line holding ``words``, writing nothing."""
    result = run(path, "-o", out_dir / "city.x3d", "-q")
    assert_one_line_error(result, 1, *words)
    assert list(out_dir.iterdir()) == []


def test_doctype_with_an_external_entity_is_refused_unread(tmp_path: Path, out_dir: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET-42")
    prolog = f'<!DOCTYPE CityModel [<!ENTITY leak SYSTEM "file://{secret}">]>'
    text = document(building("B&leak;", box()), prolog=prolog)
    path = tmp_path / "xxe.gml"
    path.write_text(text.replace("<bldg:Building", "<gml:name>&leak;</gml:name><bldg:Building"))
    result = run(path, "-o", out_dir / "city.x3d", "-q")
    assert_one_line_error(result, 1, "DOCTYPE", "security")
    assert "TOP-SECRET" not in result.stderr + result.stdout
    assert list(out_dir.iterdir()) == []


def test_billion_laughs_is_refused_fast(tmp_path: Path, out_dir: Path) -> None:
    entities = '<!ENTITY a0 "ha">' + "".join(
        f'<!ENTITY a{i} "{f"&a{i - 1};" * 10}">' for i in range(1, 10)
    )
    path = tmp_path / "laughs.gml"
    path.write_text(document("<gml:name>&a9;</gml:name>", prolog=f"<!DOCTYPE x [{entities}]>"))
    start = time.process_time()  # CPU, not wall: a loaded machine slows the clock, not the work
    refused(path, out_dir, "DOCTYPE")
    assert time.process_time() - start < 5.0


def test_zip_with_a_parent_path_is_refused(tmp_path: Path, out_dir: Path) -> None:
    path = tmp_path / "evil.zip"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("../evil.gml", document(building("B1", box())))
    refused(path, out_dir, "unsafe member name", "../evil.gml")
    assert not (tmp_path.parent / "evil.gml").exists()


@pytest.mark.parametrize(
    ("flag", "method", "words"),
    [
        (0x1, zipfile.ZIP_STORED, ("encrypted", "city.gml")),
        (0, 99, ("compression method 99", "city.gml")),
    ],
)
def test_zip_member_that_zipfile_cannot_open_is_one_line_error(
    tmp_path: Path, out_dir: Path, flag: int, method: int, words: tuple[str, ...]
) -> None:
    """An encrypted member, or one packed by a method zipfile lacks (found by the fuzzer: a
    traceback), is refused in one line."""
    path = tmp_path / "packed.zip"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("city.gml", document(building("B1", box())))
    data = bytearray(path.read_bytes())
    for header, at in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):  # local, central
        start = data.index(header)
        data[start + at : start + at + 4] = struct.pack("<HH", flag, method)
    path.write_bytes(bytes(data))
    refused(path, out_dir, *words)


def test_zip_member_over_the_inflation_limit_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "big.zip"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("city.gml", document(building("B1", box())) + " " * 100_000)
    with pytest.raises(Exception, match="inflates past the limit of 10,000"):
        read_scene(path, limits=Limits(decompressed_bytes=10_000))


def test_gz_and_zip_read_like_the_plain_file(tmp_path: Path) -> None:
    text = document(building("B1", box()), building("B2", box(20.0)))
    plain = tmp_path / "city.gml"
    plain.write_text(text)
    packed = tmp_path / "city.gml.gz"
    packed.write_bytes(gzip.compress(text.encode()))
    zipped = tmp_path / "city.zip"
    with zipfile.ZipFile(zipped, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("folder/city.gml", text)
    expected = [n.geometry.vertices for n in nodes_of(plain)]
    for path in (packed, zipped):
        got = [n.geometry.vertices for n in nodes_of(path)]
        assert all(np.array_equal(a, b) for a, b in zip(expected, got, strict=True))


def test_xml_that_is_not_citygml_is_refused_naming_its_root(tmp_path: Path, out_dir: Path) -> None:
    path = tmp_path / "notes.xml"
    path.write_text('<?xml version="1.0"?><notes xmlns="urn:example"><note>hi</note></notes>')
    refused(path, out_dir, "is not CityGML", "<notes>", "urn:example")
    broken = tmp_path / "broken.gml"
    broken.write_text(document(building("B1", box()))[:-20])
    refused(broken, out_dir, "not well-formed XML")


def test_document_without_city_objects_is_refused(tmp_path: Path, out_dir: Path) -> None:
    path = tmp_path / "empty.gml"
    path.write_text(document())
    refused(path, out_dir, "has no city objects")


def test_surface_bounds_from_the_batch_are_those_of_their_faces(tmp_path: Path) -> None:
    """The reader sets each surface's bounds for a whole batch at once: they must be what
    :attr:`Surface.bounds` computes (the vertices its faces use), also next to an object
    whose coordinates were unreadable and a face without area that reaches farther out."""
    sliver = "0 0 0 10 0 0 40 0 0 0 0 0"  # three points on a line, beyond the box
    path = tmp_path / "city.gml"
    bad = building("bad", ["0 0 0 1 0 0 1 x 0 0 0 0"])
    path.write_text(document(building("a", box()), bad, building("b", [*box(20.0), sliver])))
    nodes = nodes_of(path) + nodes_of(sample("tum_munich_lod2_v2.zip"))
    assert [node.id for node in nodes[:2]] == ["a", "b"]
    assert nodes[1].geometry.bounds[1, 0] == 30.0  # the sliver is left out
    for node in nodes:
        for part in node.geometry.parts:
            fresh = Surface(part.vertices, part.faces).bounds
            assert np.array_equal(part.bounds, fresh)


def test_degenerate_ring_object_is_reported_and_the_rest_convert(
    tmp_path: Path, out_dir: Path
) -> None:
    line = "0 0 0 5 5 5 0 0 0"  # a ring of 2 points
    path = tmp_path / "city.gml"
    path.write_text(document(building("good", box()), building("flat", [line])))
    result = run(path, "-o", out_dir / "city.x3d", "--report", out_dir / "r.json")
    assert result.returncode == 0, result.stderr
    assert "flat" in result.stderr and "skipped" in result.stderr
    report = json.loads((out_dir / "r.json").read_text())
    assert [o["id"] for o in report["objects"]] == ["good"]
    assert [s["id"] for s in report["skipped"]] == ["flat"]
    alone = tmp_path / "alone.gml"
    alone.write_text(document(building("flat", [line])))
    (out_dir / "city.x3d").unlink()
    (out_dir / "r.json").unlink()
    refused(alone, out_dir, "flat", "no area")


@pytest.mark.parametrize(
    ("ring", "reason"),
    [
        ("0 0 0 10 0 0 10 ten 0 0 0 0", "not a number"),
        ("0 0 0 10 0 0 10 10 0 0 0", "not whole points"),
        ("0 0 0 2e15 0 0 2e15 2e15 0 0 0 0", "magnitude"),
    ],
)
def test_unreadable_coordinates_skip_their_building_only(
    tmp_path: Path, ring: str, reason: str
) -> None:
    """One building with coordinates that cannot be read is skipped with the reason; the
    buildings before and after it in the same batch convert."""
    good = [building(f"good{i}", box(20.0 * i)) for i in range(3)]
    path = tmp_path / "city.gml"
    path.write_text(document(good[0], building("bad", [*box(100.0), ring]), *good[1:]))
    scene = read_scene(path)
    assert [node.id for node in scene.nodes] == ["good0", "good1", "good2"]
    (skipped,) = scene.attributes["input_checks"].skipped
    assert skipped["id"] == "bad" and reason in skipped["reason"]


def test_depth_and_text_limits_are_one_line_errors(tmp_path: Path) -> None:
    path = tmp_path / "city.gml"
    path.write_text(document(building("B1", box())))
    with pytest.raises(Exception, match="deeper than the limit of 5"):
        read_scene(path, limits=Limits(xml_depth=5))
    with pytest.raises(Exception, match="over the limit of 20"):
        read_scene(path, limits=Limits(xml_text_bytes=20))


def test_orientable_surface_flips_and_links_resolve_within_the_object(tmp_path: Path) -> None:
    faces = box()
    flipped = (
        '<gml:surfaceMember><gml:OrientableSurface orientation="-"><gml:baseSurface>'
        f'<gml:Polygon gml:id="P"><gml:exterior><gml:LinearRing><gml:posList>{faces[0]}'
        "</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:baseSurface>"
        "</gml:OrientableSurface></gml:surfaceMember>"
    )
    linked = '<gml:surfaceMember xlink:href="#B_1"/><gml:surfaceMember xlink:href="#elsewhere"/>'
    path = tmp_path / "city.gml"
    path.write_text(document(building("B", faces[1:], flipped + linked)))
    scene = read_scene(path)
    (node,) = scene.nodes
    mesh = node.geometry
    assert len(mesh.faces) == 12  # six quads; the linked polygon is read once
    normals = np.cross(*(mesh.triangles[:, 1:] - mesh.triangles[:, :1]).transpose(1, 0, 2))
    centre = mesh.vertices.mean(axis=0)
    outward = np.einsum("ij,ij->i", normals, mesh.triangles.mean(axis=1) - centre)
    assert (outward > 0).sum() == 10 and (outward < 0).sum() == 2  # the reversed bottom
    assert scene.attributes["citygml"]["unresolved_links"] == {"B": 1}


def test_memory_does_not_grow_with_the_file(tmp_path: Path) -> None:
    """Peak memory reading 2,000 buildings of 50 kB is close to reading 200: each object's
    elements are freed once it is converted."""
    blob = "<gml:description>" + "x" * 50_000 + "</gml:description><bldg:lod2"

    def peak_mb(count: int) -> float:
        path = tmp_path / f"city{count}.gml"
        with path.open("w") as handle:
            handle.write(f'<?xml version="1.0"?>{HEAD}')
            for i in range(count):
                handle.write(building(f"B{i}", box()[:1]).replace("<bldg:lod2", blob, 1))
            handle.write("</CityModel>")
        code = (
            "import resource,sys; from lodconvert.io import read_scene; "
            "n=sum(1 for _ in read_scene(sys.argv[1]).nodes); "
            "print(n, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)"
        )
        done = subprocess.run(
            [sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True
        )
        n, peak_kb = done.stdout.split()
        assert int(n) == count
        return int(peak_kb) / 1024

    small, large = peak_mb(200), peak_mb(2000)
    assert (tmp_path / "city2000.gml").stat().st_size > 100e6
    assert large - small < 10, (small, large)


@pytest.mark.parametrize("suffix", [".x3d", ".glb"])
def test_the_five_sig3d_files_are_one_building_with_four_levels(
    tmp_path: Path, suffix: str
) -> None:
    """``lodconvert Building_LOD0.gml … Building_LOD4.gml -o house.x3d``: one building whose
    levels are its own LoD4, LoD3, LoD2 and LoD1 geometry in their slots (LoD0 fills none)."""
    inputs = [sample(SIG3D.format(lod)) for lod in range(5)]
    out = tmp_path / f"house{suffix}"
    report = convert(inputs, out)
    obj, terrain = report["objects"]
    assert terrain["id"] == "GML_6bb30328-7599-4500-90ef-766fde6aa67b"
    assert [(lv["name"], lv["kind"]) for lv in terrain["levels"]] == [
        ("LOD3", "source"),
        ("LOD2", "source"),
        ("LOD1", "source"),
    ]
    assert [(lv["name"], lv["kind"]) for lv in obj["levels"]] == [
        ("LOD4", "source"),
        ("LOD3", "source"),
        ("LOD2", "source"),
        ("LOD1", "source"),
    ]
    assert obj["xs"] == [0.33, 0.66, 1.0] and obj["dropped"] == {}
    assert errors_of(validate_file(out)) == []


def test_fuzz_found_a_zip_whose_member_header_is_broken(tmp_path: Path) -> None:
    """A zip whose central directory is sound but whose member's local header is not (found
    by the fuzzer: zipfile raised BadZipFile on opening the member)."""
    from .fuzz.seeds import seeds_for

    (seed,) = seeds_for(".zip")
    broken = tmp_path / "broken.zip"
    broken.write_bytes(b"Q" + seed[1:])  # "PK\\x03\\x04" → "QK\\x03\\x04"
    assert_one_line_error(run(broken, "-o", tmp_path / "out.x3d"), 1, "broken.zip", "zip")


def test_crs_option_replaces_the_declared_crs() -> None:
    """The KIT test cases declare EPSG:3068 for local coordinates; --crs says what they are."""
    path = sample("kit_testcases_lod2_100bldg_v3.gml")
    assert read_scene(path).crs == "EPSG:3068"
    assert read_scene(path, crs="EPSG:25832").crs == "EPSG:25832"
