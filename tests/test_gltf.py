"""glTF output: Khronos validation, MSFT_lod structure, round trip through read_lod_gltf,
determinism, colours and textures, and errors on bad input."""

from __future__ import annotations

import base64
import io
import itertools
import json
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions
from lodconvert.colors import SRGB_TO_LINEAR
from lodconvert.errors import InputError
from lodconvert.io import OutputInfo, gltf, output_format, own_format
from lodconvert.io.gltf import FORMAT, read_lod_gltf, write_glb, write_gltf
from lodconvert.model import LodChain, Node, PointCloud, Surface
from lodconvert.model.safe_text import xml_text
from lodconvert.pipeline import RunOptions, convert
from lodconvert.plans import bake_chain
from lodconvert.ranges import screen_coverage

ROOT = Path(__file__).resolve().parents[1]
FAR = np.array([500000.0, 5400000.0, 100.0])
# The validator knows neither MSFT_lod (unsupported extension) nor that coarser level nodes,
# outside the scene, are used (unused object). Nothing else may be a warning or worse.
EXPECTED_ISSUES = {"UNSUPPORTED_EXTENSION", "UNUSED_OBJECT"}
INFO = OutputInfo(
    generator="lodconvert tests",
    source="fixture.ply",
    options={"levels": 4, "resolutions": (32, 16, 8)},
)
WRITE = {".glb": write_glb, ".gltf": write_gltf}


# --- fixtures -----------------------------------------------------------------------------------


def _bake(surface: Surface, object_id: str, **options) -> LodChain:
    opts = ChainOptions(**{"resolutions": (32, 16, 8), **options})
    return bake_chain(Node(object_id, surface), opts, NumpyBackend())


def _coloured_sphere() -> Surface:
    mesh = trimesh.creation.icosphere(subdivisions=3)
    v = mesh.vertices
    colors = np.column_stack(
        [(v + 1.0) * 127.5, np.full(len(v), 255.0)]  # RGB from position, opaque
    ).astype(np.uint8)
    return Surface(vertices=v, faces=mesh.faces.astype(np.int64), vertex_colors=colors)


@pytest.fixture(scope="module")
def sphere_chain() -> LodChain:
    """A 4-level chain of an icosphere with vertex colours."""
    return _bake(_coloured_sphere(), "sphere")


@pytest.fixture(scope="module")
def far_chain() -> LodChain:
    """A torus placed at UTM-like coordinates (millions of metres)."""
    mesh = trimesh.creation.torus(major_radius=2.0, minor_radius=0.5)
    # The fraction makes the origin unrepresentable in float32 (spacing 0.5 m at 5.4e6).
    shift = FAR + np.array([0.123, 0.456, 0.789])
    surface = Surface(vertices=mesh.vertices + shift, faces=mesh.faces.astype(np.int64))
    return _bake(surface, "far")


@pytest.fixture(scope="module")
def culled_chain() -> LodChain:
    """A textured, subdivided box whose chain ends in a cull distance."""
    box = trimesh.creation.box().subdivide().subdivide()
    texture = np.zeros((8, 16, 4), dtype=np.uint8)
    texture[..., 0] = np.arange(16)[None, :] * 16
    texture[..., 1] = np.arange(8)[:, None] * 32
    texture[..., 3] = 255
    surface = Surface(
        vertices=box.vertices,
        faces=box.faces.astype(np.int64),
        uv=box.vertices[:, :2] + 0.5,
        texture=texture,
    )
    return _bake(surface, "box", cull=1.5, resolutions=(12, 8, 4))


def _write(tmp_path: Path, chains, suffix: str = ".glb", name: str = "out") -> Path:
    path = tmp_path / f"{name}{suffix}"
    with path.open("wb") as handle:
        WRITE[suffix](iter(chains), handle, INFO)
    return path


def _load(path: Path) -> tuple[dict, bytes]:
    """JSON and buffer of a written file, parsed independently of lodconvert's reader."""
    data = path.read_bytes()
    if path.suffix == ".gltf":
        doc = json.loads(data)
        uri = doc["buffers"][0]["uri"]
        assert uri.startswith("data:application/octet-stream;base64,")
        return doc, base64.b64decode(uri.split(",", 1)[1])
    magic, version, total = struct.unpack_from("<4sII", data)
    assert (magic, version, total) == (b"glTF", 2, len(data))
    json_len, json_kind = struct.unpack_from("<I4s", data, 12)
    assert json_kind == b"JSON" and json_len % 4 == 0
    bin_len, bin_kind = struct.unpack_from("<I4s", data, 20 + json_len)
    assert bin_kind == b"BIN\x00" and bin_len % 4 == 0
    start = 28 + json_len
    return json.loads(data[20 : 20 + json_len]), data[start : start + bin_len]


def _accessor(doc: dict, blob: bytes, index: int) -> np.ndarray:
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = {5126: "<f4", 5123: "<u2", 5125: "<u4", 5121: "u1"}[acc["componentType"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    assert start % 4 == 0
    values = np.frombuffer(blob, dtype=dtype, count=acc["count"] * width, offset=start)
    return values.reshape(acc["count"], width) if width > 1 else values


def _assert_valid(report: dict) -> set[str]:
    """No errors, and nothing at warning level or worse beyond the expected MSFT_lod codes."""
    issues = report["issues"]
    messages = issues["messages"]
    assert issues["numErrors"] == 0, messages
    assert not issues["truncated"]
    serious = [m for m in messages if m["severity"] <= 1 and m["code"] not in EXPECTED_ISSUES]
    assert not serious, serious
    unsupported = {m["message"] for m in messages if m["code"] == "UNSUPPORTED_EXTENSION"}
    assert all("MSFT_lod" in m for m in unsupported), unsupported
    return {m["code"] for m in messages}


# --- validation ---------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_khronos_validator_passes(
    tmp_path, gltf_validator, suffix, sphere_chain, far_chain, culled_chain
):
    path = _write(tmp_path, [sphere_chain, far_chain, culled_chain], suffix)
    codes = _assert_valid(gltf_validator(path))
    assert "UNUSED_OBJECT" in codes  # the coarser nodes really are outside the scene graph


def test_bunny_round_trips_and_validates(tmp_path, request, bunny):
    chain = _bake(bunny.geometry, "bunny", resolutions=(48, 24, 12))
    path = _write(tmp_path, [chain], ".glb", "bunny")
    (obj,) = read_lod_gltf(path)
    assert [len(lv.positions) for lv in obj.levels] == [lv.count for lv in chain.levels]
    np.testing.assert_array_equal(obj.levels[0].faces, chain.levels[0].mesh.faces)
    np.testing.assert_array_equal(obj.levels[-1].colors, chain.levels[-1].points.colors)
    _assert_valid(request.getfixturevalue("gltf_validator")(path))


def test_large_mesh_uses_uint32_indices(tmp_path, request, sphere_chain):
    big = trimesh.creation.icosphere(subdivisions=7)  # 163,842 vertices
    assert len(big.vertices) >= 65536
    surface = Surface(vertices=big.vertices, faces=big.faces.astype(np.int64))
    finest = replace(sphere_chain.levels[0], mesh=surface)
    chain = replace(sphere_chain, levels=[finest, *sphere_chain.levels[1:]])
    path = _write(tmp_path, [chain])
    doc, _ = _load(path)
    primitive = doc["meshes"][0]["primitives"][0]
    assert doc["accessors"][primitive["indices"]]["componentType"] == 5125
    (obj,) = read_lod_gltf(path)
    np.testing.assert_array_equal(obj.levels[0].faces, big.faces)
    _assert_valid(request.getfixturevalue("gltf_validator")(path))


def test_small_mesh_uses_uint16_indices(tmp_path, sphere_chain):
    doc, blob = _load(_write(tmp_path, [sphere_chain]))
    primitive = doc["meshes"][0]["primitives"][0]
    assert doc["accessors"][primitive["indices"]]["componentType"] == 5123
    faces = _accessor(doc, blob, primitive["indices"]).reshape(-1, 3)
    np.testing.assert_array_equal(faces, sphere_chain.levels[0].mesh.faces)


# --- MSFT_lod structure -------------------------------------------------------------------------


def _lod_nodes(doc: dict) -> list[tuple[dict, dict, list[int]]]:
    """(root, finest, ids) per scene root."""
    out = []
    for root_index in doc["scenes"][doc["scene"]]["nodes"]:
        root = doc["nodes"][root_index]
        assert len(root["children"]) == 1
        finest = doc["nodes"][root["children"][0]]
        ids = finest.get("extensions", {}).get("MSFT_lod", {}).get("ids", [])
        out.append((root, finest, ids))
    return out


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_msft_lod_structure(tmp_path, suffix, sphere_chain, far_chain, culled_chain):
    chains = [sphere_chain, far_chain, culled_chain]
    doc, _ = _load(_write(tmp_path, chains, suffix))
    assert "MSFT_lod" in doc["extensionsUsed"]
    assert "MSFT_lod" not in doc.get("extensionsRequired", [])
    scene_nodes = set(doc["scenes"][doc["scene"]]["nodes"])
    children = {c for node in doc["nodes"] for c in node.get("children", [])}
    lods = _lod_nodes(doc)
    assert [root["name"] for root, _, _ in lods] == [c.object_id for c in chains]
    for (_, finest, ids), chain in zip(lods, chains, strict=True):
        assert finest["name"] == f"{chain.object_id}_{chain.levels[0].name}"
        assert len(ids) == len(chain.levels) - 1 > 0
        assert len(set(ids)) == len(ids)
        assert all(0 <= i < len(doc["nodes"]) for i in ids)
        assert not set(ids) & (scene_nodes | children)
        assert [doc["nodes"][i]["name"] for i in ids] == [
            f"{chain.object_id}_{lv.name}" for lv in chain.levels[1:]
        ]
        coverage = finest["extras"]["MSFT_screencoverage"]
        assert len(coverage) == len(ids) + 1
        assert all(a > b for a, b in itertools.pairwise(coverage))
        expected = [screen_coverage(chain.alpha, d, INFO.view) for d in chain.cutoffs]
        assert coverage[: len(expected)] == pytest.approx(expected)
        if chain.culled:
            assert coverage[-1] > 0
        else:
            assert coverage[-1] == 0.0
        switch_in = [doc["nodes"][i]["extras"]["lodconvert"]["switch_in"] for i in ids]
        assert switch_in == chain.cutoffs[: len(ids)]
    assert culled_chain.culled and not sphere_chain.culled


def test_single_level_chain_has_no_msft_lod(tmp_path, request, sphere_chain):
    single = replace(sphere_chain, levels=sphere_chain.levels[:1], cutoffs=[], xs=[])
    path = _write(tmp_path, [single])
    doc, _ = _load(path)
    ((_, finest, ids),) = _lod_nodes(doc)
    assert ids == [] and "extensions" not in finest
    assert "MSFT_lod" not in doc.get("extensionsUsed", [])
    assert len(doc["nodes"]) == 2
    (obj,) = read_lod_gltf(path)
    assert [lv.name for lv in obj.levels] == ["LOD4"]
    codes = _assert_valid(request.getfixturevalue("gltf_validator")(path))
    assert not codes & EXPECTED_ISSUES  # nothing unused, no unknown extension


def test_position_bounds_and_buffer_layout(tmp_path, sphere_chain, culled_chain):
    doc, blob = _load(_write(tmp_path, [sphere_chain, culled_chain]))
    for view in doc["bufferViews"]:
        assert view["byteOffset"] % 4 == 0
        assert view.get("target") in (34962, 34963, None)
    for mesh in doc["meshes"]:
        (primitive,) = mesh["primitives"]
        acc = doc["accessors"][primitive["attributes"]["POSITION"]]
        data = _accessor(doc, blob, primitive["attributes"]["POSITION"])
        assert acc["min"] == data.min(axis=0).tolist()
        assert acc["max"] == data.max(axis=0).tolist()
        normals = _accessor(doc, blob, primitive["attributes"]["NORMAL"])
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
        view = doc["bufferViews"][acc["bufferView"]]
        assert view["target"] == 34962
        if "indices" in primitive:
            index_view = doc["bufferViews"][doc["accessors"][primitive["indices"]]["bufferView"]]
            assert index_view["target"] == 34963
    modes = [m["primitives"][0]["mode"] for m in doc["meshes"]]
    assert modes == [4, 0, 0, 0, 4] + [0] * (len(culled_chain.levels) - 1)


def test_point_material_is_unlit(tmp_path, sphere_chain):
    doc, _ = _load(_write(tmp_path, [sphere_chain]))
    assert "KHR_materials_unlit" in doc["extensionsUsed"]
    point_material = doc["materials"][doc["meshes"][1]["primitives"][0]["material"]]
    assert "KHR_materials_unlit" in point_material["extensions"]
    assert point_material["pbrMetallicRoughness"]["baseColorFactor"] == [1.0, 1.0, 1.0, 1.0]

    red = np.array([255, 128, 0, 64], dtype=np.uint8)
    mesh = replace(sphere_chain.levels[0].mesh.parts[0], vertex_colors=None, base_color=red)
    chain = replace(sphere_chain, levels=[replace(sphere_chain.levels[0], mesh=mesh)], cutoffs=[])
    doc, _ = _load(_write(tmp_path, [chain], name="red"))
    mesh_material = doc["materials"][doc["meshes"][0]["primitives"][0]["material"]]
    assert mesh_material["doubleSided"] is True
    assert mesh_material["alphaMode"] == "BLEND"
    pbr = mesh_material["pbrMetallicRoughness"]
    assert (pbr["metallicFactor"], pbr["roughnessFactor"]) == (0.0, 1.0)
    assert pbr["baseColorFactor"] == pytest.approx([1.0, SRGB_TO_LINEAR[128], 0.0, 64 / 255])


# --- extras -------------------------------------------------------------------------------------


def test_switching_extras(tmp_path, sphere_chain):
    doc, _ = _load(_write(tmp_path, [sphere_chain], ".gltf"))
    asset = doc["asset"]
    assert asset["generator"] == INFO.generator
    meta = asset["extras"]["lodconvert"]
    assert meta["source"] == "fixture.ply" and meta["crs"] is None
    assert "frame" not in meta  # a mesh without a CRS keeps its axes
    assert meta["reference_view"] == {"height_px": 1080, "fov_y_deg": 45.0}
    assert meta["options"] == {"levels": 4, "resolutions": [32, 16, 8]}
    ((_, finest, ids),) = _lod_nodes(doc)
    facts = finest["extras"]["lodconvert"]
    assert facts["cutoffs"] == sphere_chain.cutoffs
    assert facts["alpha"] == sphere_chain.alpha and facts["culled"] is False
    assert [lv["count"] for lv in facts["levels"]] == [lv.count for lv in sphere_chain.levels]
    for node_index, level in zip(ids, sphere_chain.levels[1:], strict=True):
        node_facts = doc["nodes"][node_index]["extras"]["lodconvert"]
        assert node_facts["level"] == level.name
        assert node_facts["point_size_px"] == level.params.point_size
        assert node_facts["spacing"] == level.spacing
        assert node_facts["design_distance"] == level.design_distance


# --- round trip ---------------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_round_trip_keeps_points_colours_and_origin(tmp_path, suffix, far_chain, sphere_chain):
    path = _write(tmp_path, [far_chain, sphere_chain], suffix)
    objects = read_lod_gltf(path)
    assert [o.object_id for o in objects] == ["far", "sphere"]
    for obj, chain in zip(objects, [far_chain, sphere_chain], strict=True):
        assert obj.origin.dtype == np.float64
        np.testing.assert_array_equal(obj.origin, chain.origin)
        assert [lv.name for lv in obj.levels] == [lv.name for lv in chain.levels]
        assert [len(lv.positions) for lv in obj.levels] == [lv.count for lv in chain.levels]
        for got, level in zip(obj.levels[1:], chain.levels[1:], strict=True):
            assert got.kind == "pcd"
            expected = level.points.positions.astype(np.float32).astype(np.float64)
            np.testing.assert_array_equal(got.positions, expected)
            np.testing.assert_array_equal(got.colors, level.points.colors)
            np.testing.assert_allclose(got.normals, level.points.normals, atol=1e-6)
        mesh = chain.levels[0].mesh
        np.testing.assert_array_equal(obj.levels[0].faces, mesh.faces)
        np.testing.assert_array_equal(
            obj.levels[0].positions, mesh.vertices.astype(np.float32).astype(np.float64)
        )
    # Georeferenced data: the origin holds the millions, the buffers stay small.
    far = objects[0]
    np.testing.assert_allclose(far.origin, FAR, atol=1.0)
    assert not np.array_equal(far.origin.astype(np.float32), far.origin)
    assert max(np.abs(lv.positions).max() for lv in far.levels) < 3.0
    doc, _ = _load(path)
    assert doc["nodes"][0]["translation"] == far_chain.origin.tolist()


def test_every_srgb_byte_round_trips(tmp_path, sphere_chain):
    level = sphere_chain.levels[1]
    k = len(level.points)
    values = np.arange(k * 4) % 256
    colors = values.reshape(k, 4).astype(np.uint8)
    colors[:256, :3] = np.arange(256)[:, None]  # every byte in every channel
    colors[:256, 3] = np.arange(256)
    assert k >= 256
    points = PointCloud(level.points.positions, colors, level.points.normals)
    chain = replace(
        sphere_chain,
        levels=[sphere_chain.levels[0], replace(level, points=points)],
        cutoffs=sphere_chain.cutoffs[:1],
        xs=sphere_chain.xs[:1],
    )
    path = _write(tmp_path, [chain])
    (obj,) = read_lod_gltf(path)
    np.testing.assert_array_equal(obj.levels[1].colors, colors)
    doc, _ = _load(path)
    material = doc["materials"][doc["meshes"][1]["primitives"][0]["material"]]
    assert material["alphaMode"] == "BLEND"  # some points are translucent


def test_vertex_colours_survive(tmp_path, sphere_chain):
    path = _write(tmp_path, [sphere_chain])
    doc, blob = _load(path)
    attributes = doc["meshes"][0]["primitives"][0]["attributes"]
    assert "COLOR_0" in attributes
    color_acc = doc["accessors"][attributes["COLOR_0"]]
    assert (color_acc["type"], color_acc["componentType"], color_acc["normalized"]) == (
        "VEC4",
        5123,
        True,
    )
    mesh = sphere_chain.levels[0].mesh
    linear = _accessor(doc, blob, attributes["COLOR_0"]) / 65535.0
    np.testing.assert_allclose(linear[:, :3], SRGB_TO_LINEAR[mesh.vertex_colors[:, :3]], atol=1e-5)
    material = doc["materials"][doc["meshes"][0]["primitives"][0]["material"]]
    assert material["pbrMetallicRoughness"]["baseColorFactor"] == [1.0, 1.0, 1.0, 1.0]
    (obj,) = read_lod_gltf(path)
    np.testing.assert_array_equal(obj.levels[0].colors, mesh.vertex_colors)
    for level in obj.levels[1:]:
        rgb = level.colors[:, :3].astype(int)
        assert np.ptp(rgb, axis=0).min() > 100  # coloured, not the default grey


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_buffers_made_where_a_chain_is_baked_write_the_same_bytes(
    tmp_path, culled_chain, far_chain, suffix
):
    """Worker processes make each chain's buffers and accessor text (the format's formatter);
    the document written from them is the one written from the chains alone: textures,
    accessor bounds and both layouts included."""
    chains = [culled_chain, far_chain]
    pieces = FORMAT.pieces(INFO, {}, suffix)
    assert pieces is not None and pieces.formatter is not None
    for chain in chains:
        pieces.add(chain, pieces.formatter(chain))
    made = tmp_path / f"made{suffix}"
    with made.open("wb") as handle:
        WRITE[suffix](iter(chains), handle, INFO, pieces=pieces)
    assert made.read_bytes() == _write(tmp_path, chains, suffix).read_bytes()
    assert pieces.take(culled_chain) is None  # each piece is written once


def test_texture_is_embedded_with_flipped_v(tmp_path, culled_chain):
    doc, blob = _load(_write(tmp_path, [culled_chain]))
    primitive = doc["meshes"][0]["primitives"][0]
    material = doc["materials"][primitive["material"]]
    texture = doc["textures"][material["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
    assert "sampler" in texture
    image = doc["images"][texture["source"]]
    assert image["mimeType"] == "image/png"
    view = doc["bufferViews"][image["bufferView"]]
    png = blob[view["byteOffset"] : view["byteOffset"] + view["byteLength"]]
    mesh = culled_chain.levels[0].mesh.parts[0]
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(png))), mesh.texture)
    uv = _accessor(doc, blob, primitive["attributes"]["TEXCOORD_0"])
    np.testing.assert_allclose(uv[:, 0], mesh.uv[:, 0], atol=1e-6)
    np.testing.assert_allclose(uv[:, 1], 1.0 - mesh.uv[:, 1], atol=1e-6)


# --- determinism and registry -------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_output_is_deterministic(tmp_path, suffix, sphere_chain, culled_chain):
    first = _write(tmp_path, [sphere_chain, culled_chain], suffix, "first")
    second = _write(tmp_path, [sphere_chain, culled_chain], suffix, "second")
    assert first.read_bytes() == second.read_bytes()


def test_one_registry_entry_writes_reads_back_and_checks_both_suffixes():
    entry = gltf.FORMAT
    assert output_format("a.glb") is output_format("a.GLTF") is own_format("a.glb") is entry
    assert entry.write and entry.read_back and entry.check and entry.read is None


# --- bad input ----------------------------------------------------------------------------------


def test_truncated_glb_raises_input_error(tmp_path, sphere_chain):
    data = _write(tmp_path, [sphere_chain]).read_bytes()
    cut = tmp_path / "cut.glb"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"cut\.glb") as err:
        read_lod_gltf(cut)
    assert "\n" not in str(err.value) and "truncated" in str(err.value)


@pytest.mark.parametrize(
    ("name", "content"),
    [
        ("garbage.gltf", b"{not json"),
        ("tiny.glb", b"glTF\x02\x00"),
        ("foreign.gltf", json.dumps({"asset": {"version": "2.0"}}).encode()),
    ],
)
def test_bad_files_raise_input_error(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(InputError, match=name) as err:
        read_lod_gltf(path)
    assert "\n" not in str(err.value)


def test_foreign_glb_is_rejected(tmp_path):
    path = tmp_path / "trimesh.glb"
    trimesh.creation.box().export(path)
    with pytest.raises(InputError, match="not a glTF written by lodconvert"):
        read_lod_gltf(path)


def test_object_attributes_are_on_its_root_node(tmp_path, sphere_chain):
    """A city object's attributes (id, type, measured height…) travel with its root node, where
    a GIS user finds the object by name."""
    attributes = {"id": "DEB_LOD2_1", "type": "Building", "measuredHeight": 31.7}
    chain = replace(sphere_chain, object_id="DEB_LOD2_1", metadata=attributes)
    doc, _ = _load(_write(tmp_path, [chain]))
    (root,) = [doc["nodes"][i] for i in doc["scenes"][0]["nodes"]]
    assert root["name"] == "DEB_LOD2_1" and root["extras"]["attributes"] == attributes


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_text_shaped_like_a_part_mark_is_kept_with_workers(tmp_path, suffix):
    """A worker's part of the document writes indices as marks (a JSON string of NUL, a kind
    letter and a number) that the main process fills in; ids and attributes holding NUL or
    the marks' very text come through as the reader keeps them, and two workers write the
    bytes one process writes."""
    marks = ["\x00a0", '"\\u0000n1"', "\\u0000M0", "\x00T", "\x02"]
    objects = {}
    for i, text in enumerate(marks):
        ring = [4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3]
        objects[f"b{i}{text}"] = {
            "type": "Building",
            "attributes": {"note": text, text: i},
            "geometry": [{"type": "MultiSurface", "lod": "1", "boundaries": [[ring]]}],
        }
    corners = ((0, 0), (10, 0), (10, 10), (0, 10))
    vertices = [[20 * i + x, y, 0] for i in range(len(marks)) for x, y in corners]
    source = tmp_path / "marks.city.json"
    document = {"type": "CityJSON", "version": "2.0", "CityObjects": objects}
    source.write_text(json.dumps({**document, "vertices": vertices}))
    written = {}
    for workers in (1, 2):
        out = tmp_path / f"w{workers}{suffix}"
        convert(source, out, RunOptions(workers=workers))
        written[workers] = out.read_bytes()
    assert written[1] == written[2]
    read = {o.object_id: o for o in read_lod_gltf(tmp_path / f"w2{suffix}", geometry=False)}
    assert len(read) == len(marks)
    for i, text in enumerate(marks):
        kept = xml_text(text)
        assert read[f"b{i}{kept}"].attributes["note"] == kept
        assert read[f"b{i}{kept}"].attributes[kept] == i
