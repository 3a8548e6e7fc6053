"""X3D output: validation against the official X3D 4.0 XSD, LOD structure, levels split over
several Shapes, point sizes, round trip through read_x3d_points, georeferenced origins,
streaming, determinism, number formatting and errors on bad files."""

from __future__ import annotations

import base64
import decimal
import io
import math
import re
from collections.abc import Iterator
from dataclasses import replace
from decimal import ROUND_HALF_EVEN, Decimal
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from lxml import etree
from PIL import Image

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions
from lodconvert.errors import InputError, UsageError
from lodconvert.io import OutputInfo, output_format, own_format, read_scene, x3d
from lodconvert.io.numbers import (
    MAX_DECIMALS,
    decimals_for,
    format_exact,
    format_fixed,
    format_floats,
    format_ints,
    format_unit_bytes,
    geometry_decimals,
)
from lodconvert.io.x3d import point_properties, read_x3d_points, vertex_colors, write_x3d
from lodconvert.model import LodChain, Node, Surface
from lodconvert.model.safe_text import xml_text
from lodconvert.plans import bake_chain

from .conftest import stanford

FAR = np.array([500000.0, 5400000.0, 100.0])
INFO = OutputInfo(generator="lodconvert tests", source="fixture.ply", options={"levels": 4})
OPTIONS = ChainOptions(resolutions=(48, 24, 12))


# --- helpers and fixtures -----------------------------------------------------------------------


def _bake(obj: Node, opts: ChainOptions = OPTIONS) -> LodChain:
    return bake_chain(obj, opts, NumpyBackend())


def _write(chains: list[LodChain], info: OutputInfo = INFO) -> bytes:
    out = io.BytesIO()
    write_x3d(chains, out, info)
    return out.getvalue()


def _assert_valid(schema: etree.XMLSchema, data: bytes) -> None:
    """Valid against the XSD, parsed with libxml2's default limits (no ``huge_tree``)."""
    doc = etree.parse(io.BytesIO(data))
    assert schema.validate(doc), "\n".join(str(e) for e in schema.error_log)


@pytest.fixture
def chain(torus: Node) -> LodChain:
    return _bake(torus)


@pytest.fixture
def culled(torus: Node) -> LodChain:
    return _bake(torus, replace(OPTIONS, cull=1.5))


def _lod(data: bytes) -> etree._Element:
    return etree.fromstring(data).find("Scene/Transform/LOD")


def _floats(text: str) -> np.ndarray:
    return np.array(text.split(), dtype=np.float64)


# --- validation ---------------------------------------------------------------------------------


def test_output_validates_against_official_xsd(
    schema: etree.XMLSchema, chain: LodChain, culled: LodChain
) -> None:
    translucent = replace(chain, object_id="translucent")
    points = translucent.levels[1].points
    faded = points.colors.copy()
    faded[::2, 3] = 100  # ColorRGBA instead of Color
    translucent.levels = [
        translucent.levels[0],
        replace(translucent.levels[1], points=replace(points, colors=faded)),
        *translucent.levels[2:],
    ]
    data = _write([chain, replace(culled, object_id="culled"), translucent])
    assert data.startswith(b"<?xml version='1.0' encoding='UTF-8'?>\n<X3D ")
    assert b"<!DOCTYPE" not in data
    assert b"<ColorRGBA " in data
    _assert_valid(schema, data)


@pytest.mark.parametrize(
    ("pattern", "replacement"),
    [
        (rb"(<PointSet>)", rb'\1<Normal vector="0 0 1"/>'),  # the XSD has no PointSet normal
        (rb'pointSizeScaleFactor="[^"]*"', b'pointSizeScaleFactor="0.5"'),  # must be >= 1
        (rb'range="[^"]*"', b'range="near far"'),
        (rb'(<Transform DEF=")[^"]*(")', rb"\g<1>9 lives\2"),  # DEF must be an NCName
    ],
)
def test_validator_rejects_broken_documents(
    schema: etree.XMLSchema, chain: LodChain, pattern: bytes, replacement: bytes
) -> None:
    data = _write([chain])
    broken, n = re.subn(pattern, replacement, data, count=1)
    assert n == 1
    doc = etree.parse(io.BytesIO(broken))
    assert not schema.validate(doc)


def test_awkward_and_repeated_ids_make_unique_valid_defs(
    schema: etree.XMLSchema, chain: LodChain
) -> None:
    chains = [replace(chain, object_id=i) for i in ("1 a:b", "_1_a_b", "_1_a_b", "é")]
    data = _write(chains)
    _assert_valid(schema, data)  # xs:ID: NCName and unique
    defs = [t.get("DEF") for t in etree.fromstring(data).iter("Transform")]
    assert len(set(defs)) == 4
    ids = [
        m.get("value")
        for m in etree.fromstring(data).iter("MetadataString")
        if m.get("name") == "object_id"
    ]
    assert ids == ['"1 a:b"', '"_1_a_b"', '"_1_a_b"', '"é"']


# --- structure ----------------------------------------------------------------------------------


def _lod_children(lod: etree._Element) -> list[etree._Element]:
    return [c for c in lod if c.get("containerField") != "metadata"]


def test_head_declares_components_and_meta(chain: LodChain) -> None:
    root = etree.fromstring(_write([chain], replace(INFO, crs="EPSG:25832")))
    assert root.get("profile") == "Interchange" and root.get("version") == "4.0"
    assert root.nsmap["xsd"] == "http://www.w3.org/2001/XMLSchema-instance"
    components = {c.get("name"): int(c.get("level")) for c in root.iter("component")}
    assert components["Navigation"] >= 2 and components["Shape"] >= 5
    meta = {m.get("name"): m.get("content") for m in root.iter("meta")}
    assert meta["generator"] == INFO.generator and meta["source"] == INFO.source
    assert meta["crs"] == "EPSG:25832"
    assert "1080" in meta["reference-view"] and "range" in meta["lod-ranges"]


def test_lod_has_one_child_more_than_ranges(chain: LodChain) -> None:
    lod = _lod(_write([chain]))
    ranges = _floats(lod.get("range"))
    children = _lod_children(lod)
    assert len(ranges) == len(children) - 1 == len(chain.levels) - 1
    assert np.all(np.diff(ranges) > 0)
    np.testing.assert_allclose(ranges, chain.cutoffs, rtol=1e-12)
    assert [c.tag for c in children] == ["Group"] * len(chain.levels)
    assert [c.get("DEF") for c in children] == [
        "torus_LOD4",
        "torus_LOD3",
        "torus_LOD2",
        "torus_LOD1",
    ]
    shapes = [c.findall("Shape") for c in children]  # the torus's levels fit one Shape each
    assert [len(s) for s in shapes] == [1] * len(chain.levels)
    assert shapes[0][0].find("IndexedTriangleSet") is not None
    assert all(s[0].find("PointSet") is not None for s in shapes[1:])
    appearances = [s[0].find("Appearance") for s in shapes]
    assert [a.get("DEF") for a in appearances] == [f"{c.get('DEF')}_Appearance" for c in children]


def test_culled_chain_ends_with_an_empty_child(culled: LodChain) -> None:
    assert culled.culled and len(culled.cutoffs) == len(culled.levels)
    lod = _lod(_write([culled]))
    children = _lod_children(lod)
    assert len(_floats(lod.get("range"))) == len(children) - 1 == len(culled.levels)
    assert children[-1].tag == "Group" and len(children[-1]) == 0
    assert children[-1].get("DEF") is None
    assert all(c.tag == "Group" and c.find("Shape") is not None for c in children[:-1])


def test_inconsistent_chain_is_refused(chain: LodChain) -> None:
    with pytest.raises(ValueError, match="cutoffs"):
        _write([replace(chain, cutoffs=chain.cutoffs[:-1])])
    with pytest.raises(ValueError, match="increase"):
        _write([replace(chain, cutoffs=chain.cutoffs[::-1])])
    twin = replace(chain.levels[2], name=chain.levels[1].name)
    with pytest.raises(ValueError, match="unique"):
        _write([replace(chain, levels=[*chain.levels[:2], twin, *chain.levels[3:]])])


def _shape_geometry(group: etree._Element) -> list[etree._Element]:
    """The geometry node of each Shape of a level Group (the one after its Appearance)."""
    return [shape[1] for shape in group.iter("Shape")]


def _point_count(geometry: etree._Element) -> int:
    return len(_floats(geometry.find("Coordinate").get("point"))) // 3


def test_pointsets_have_one_colour_per_point_and_no_normals(chain: LodChain) -> None:
    root = etree.fromstring(_write([chain]))
    assert len(list(root.iter("PointSet"))) == 3
    groups = _lod_children(root.find("Scene/Transform/LOD"))[1:]
    for group, level in zip(groups, chain.levels[1:], strict=True):
        for ps in _shape_geometry(group):
            assert ps.tag == "PointSet" and ps.find("Normal") is None
            assert len(_floats(ps.find("Color").get("color"))) == 3 * _point_count(ps)
        assert sum(map(_point_count, _shape_geometry(group))) == level.count


def test_level_and_chain_metadata(chain: LodChain) -> None:
    lod = _lod(_write([chain]))

    def values(node: etree._Element) -> dict[str, str]:
        meta = node.find("MetadataSet")
        assert meta.get("containerField") == "metadata" and node.index(meta) == 0
        return {m.get("name"): m.get("value") for m in meta}

    assert lod.find("MetadataSet") is None  # X3DOM would take it for a level
    top = values(lod.getparent())
    assert top["object_id"] == '"torus"'
    np.testing.assert_allclose(_floats(top["cutoffs"]), chain.cutoffs)
    assert float(top["beta"]) == chain.beta and float(top["alpha"]) == chain.alpha
    level = chain.levels[2]
    group = _lod_children(lod)[2]
    meta = values(group)
    assert meta["level"] == '"LOD2"' and meta["kind"] == '"pcd"'
    assert int(meta["count"]) == level.count
    assert int(meta["resolution"]) == level.params.resolution
    assert float(meta["point_size_px"]) == level.params.point_size
    assert float(meta["design_distance"]) == level.design_distance
    assert float(meta["switch_in"]) == chain.cutoffs[1]
    assert float(meta["spacing"]) == level.spacing


# --- point sizes --------------------------------------------------------------------------------


def _size_px(fields: dict[str, str], r: float) -> float:
    """Pixel size by the X3D 4.0 PointProperties rule (minimum renderable size 1 px)."""
    a, b, c = _floats(fields.get("attenuation", "1 0 0"))
    size = float(fields["pointSizeScaleFactor"]) / (a + b * r + c * r * r)
    return min(max(size, float(fields["pointSizeMinValue"])), float(fields["pointSizeMaxValue"]))


def test_point_size_is_design_size_at_design_distance_and_falls_with_distance(
    chain: LodChain,
) -> None:
    for i, level in enumerate(chain.levels[1:], start=1):
        fields = point_properties(level, chain.cutoffs[i - 1], chain.alpha)
        d, p = level.design_distance, level.params.point_size
        assert _size_px(fields, d) == pytest.approx(p)
        assert _size_px(fields, 2 * d) == pytest.approx(max(1.0, p / 2))
        assert _size_px(fields, 1000 * d) == 1.0  # clamped to pointSizeMinValue
        # points up to alpha/2 nearer than the centre still get their full size
        near = chain.cutoffs[i - 1] - chain.alpha / 2
        assert _size_px(fields, near) == pytest.approx(p * d / near, rel=1e-3)
        assert float(fields["pointSizeMaxValue"]) <= 4 * p


def test_small_and_finest_point_sizes_stay_valid(chain: LodChain) -> None:
    level = chain.levels[1]
    tiny = replace(level, params=replace(level.params, point_size=0.5))
    fields = point_properties(tiny, chain.cutoffs[0], chain.alpha)
    assert float(fields["pointSizeScaleFactor"]) >= 1  # XSD minimum
    assert _size_px(fields, level.design_distance / 2) == pytest.approx(1.0)
    finest = point_properties(level, 0.0, chain.alpha)  # shows from distance 0
    assert float(finest["pointSizeMaxValue"]) == pytest.approx(4 * level.params.point_size)


# --- round trip and georeferencing --------------------------------------------------------------


def _per_corner(
    coordinates: np.ndarray, colours: np.ndarray | None, index: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Coordinates and colours per point, or per triangle corner when ``index`` is given."""
    if index is None:
        return coordinates, colours
    return coordinates[index], None if colours is None else colours[index]


def _check_round_trip(chain: LodChain, path: Path) -> None:
    """Write ``chain`` to ``path`` and read it back: points in order, and mesh triangles in
    order compared corner by corner (a mesh split over several Shapes comes back with shared
    vertices repeated and unused ones dropped)."""
    with path.open("wb") as f:
        write_x3d([chain], f, INFO)
    levels = read_x3d_points(path)
    assert list(levels) == [f"{chain.object_id}_{lv.name}" for lv in chain.levels]
    for level, read in zip(chain.levels, levels.values(), strict=True):
        np.testing.assert_array_equal(read.translation, chain.origin)
        if level.kind == "mesh":
            mesh = level.mesh
            assert read.geometry == "IndexedTriangleSet" and len(read.index) == len(mesh.faces)
            expected = _per_corner(mesh.vertices, vertex_colors(mesh.parts[0]), mesh.faces)
        else:
            assert read.geometry == "PointSet" and read.index is None
            expected = (level.points.positions, level.points.colors)
        coordinates, colours = _per_corner(read.coordinates, read.colors, read.index)
        world, _ = _per_corner(read.world, None, read.index)
        # 7 significant digits on the largest coordinate: float32-level precision
        scale = np.abs(expected[0]).max()
        np.testing.assert_allclose(coordinates, expected[0], rtol=0, atol=5e-7 * scale)
        np.testing.assert_allclose(world, expected[0] + chain.origin, rtol=0, atol=1e-6 * scale)
        if expected[1] is None:
            assert colours is None
        else:
            np.testing.assert_array_equal(colours, expected[1])


def test_round_trip_gives_back_baked_points(chain: LodChain, tmp_path: Path) -> None:
    path = tmp_path / "torus.x3d"
    _check_round_trip(chain, path)
    # one Shape using every vertex: the mesh comes back exactly as it was indexed
    mesh = read_x3d_points(path)["torus_LOD4"]
    np.testing.assert_array_equal(mesh.index, chain.levels[0].mesh.faces)
    assert len(mesh.coordinates) == len(chain.levels[0].mesh.vertices)


def test_far_object_keeps_exact_origin_and_small_coordinates(torus: Node, tmp_path: Path) -> None:
    surface = torus.geometry.translated(FAR)
    chain = _bake(Node("far", surface))
    path = tmp_path / "far.x3d"
    _check_round_trip(chain, path)
    transform = etree.parse(str(path)).find("Scene/Transform")
    origin = _floats(transform.get("translation"))
    np.testing.assert_array_equal(origin, chain.origin)  # every float64 digit kept
    assert np.abs(origin - FAR).max() < 1.0
    for level in read_x3d_points(path).values():
        assert np.abs(level.coordinates).max() < 2.0  # relative to the origin, not millions


def _textured_box(**fields: np.ndarray) -> Surface:
    """A box with a 6 × 10 random RGBA texture and a distinct UV (inside the image) per vertex."""
    mesh = trimesh.creation.box()
    texture = np.random.default_rng(3).integers(0, 256, size=(6, 10, 4), dtype=np.uint8)
    uv = (mesh.vertices[:, :2] + 0.5) * [0.8, 0.6] + [0.1, 0.2] + mesh.vertices[:, 2:] * 0.05
    return Surface(mesh.vertices, mesh.faces.astype(np.int64), uv=uv, texture=texture, **fields)


def _with_mesh(chain: LodChain, surface: Surface) -> LodChain:
    return replace(chain, levels=[replace(chain.levels[0], mesh=surface), *chain.levels[1:]])


def _texture_pixels(url: str) -> np.ndarray:
    """The image of an ImageTexture url holding one PNG data URI."""
    (uri,) = re.fullmatch(r'"([^"\\]*)"', url).groups()
    assert uri.startswith("data:image/png;base64,")
    with Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1], validate=True))) as png:
        assert png.format == "PNG" and png.mode == "RGBA"
        return np.asarray(png)


def test_textured_mesh_keeps_its_texture(chain: LodChain) -> None:
    red = np.array([255, 0, 0, 255], np.uint8)
    surface = _textured_box(base_color=red)
    shape = etree.fromstring(_write([_with_mesh(chain, surface)])).find(".//Group/Shape")
    appearance = shape.find("Appearance")
    assert [c.tag for c in appearance] == ["Material", "ImageTexture"]
    assert appearance.find("Material").get("diffuseColor") == "1 0 0"  # modulates the texture
    pixels = _texture_pixels(appearance.find("ImageTexture").get("url"))
    np.testing.assert_array_equal(pixels, surface.texture)
    triangles = shape.find("IndexedTriangleSet")
    assert triangles.find("Color") is None  # no colours sampled from the texture
    index = _floats(triangles.get("index")).astype(int)
    st = _floats(triangles.find("TextureCoordinate").get("point")).reshape(-1, 2)
    np.testing.assert_allclose(st[index], surface.uv[surface.faces].reshape(-1, 2), atol=5e-7)
    # X3D's t runs up from the image's bottom row: each corner shows the model's texel
    h, w = pixels.shape[:2]
    texels = pixels[((1 - st[:, 1]) * h).astype(int), (st[:, 0] * w).astype(int)]
    plain = replace(surface, base_color=None)
    expected = plain.colors_at(np.repeat(np.arange(12), 3), surface.vertices[surface.faces.ravel()])
    np.testing.assert_array_equal(texels[index], expected)


def test_textured_mesh_validates_shares_its_appearance_and_is_deterministic(
    schema: etree.XMLSchema, chain: LodChain, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(x3d.shapes, "MAX_SHAPE_TRIANGLES", 5)  # the box's 12 triangles in 3 Shapes
    textured = _with_mesh(chain, _textured_box())
    path = tmp_path / "box.x3d"
    path.write_bytes(_write([textured]))
    data = path.read_bytes()
    _assert_valid(schema, data)
    assert _write([textured]) == data  # same PNG, same bytes
    group = _lod_children(_lod(data))[0]
    appearances = [shape.find("Appearance") for shape in group.iter("Shape")]
    assert len(appearances) == 3 and len(list(group.iter("ImageTexture"))) == 1
    assert appearances[0].get("DEF") == "torus_LOD4_Appearance"
    assert all(a.get("USE") == "torus_LOD4_Appearance" for a in appearances[1:])
    assert all(g.find("TextureCoordinate") is not None for g in _shape_geometry(group))
    mesh = read_x3d_points(path)["torus_LOD4"]  # the reader skips texture nodes
    np.testing.assert_allclose(
        mesh.coordinates[mesh.index], textured.levels[0].mesh.triangles, atol=1e-6
    )
    assert mesh.colors is None


def test_textured_part_with_vertex_colours_keeps_both(chain: LodChain) -> None:
    box = _textured_box(base_color=np.array([255, 128, 0, 255], np.uint8))
    box.vertex_colors = np.random.default_rng(5).integers(0, 256, (8, 4), dtype=np.uint8)
    box.vertex_colors[:, 3] = 255
    triangles = etree.fromstring(_write([_with_mesh(chain, box)])).find(".//IndexedTriangleSet")
    assert triangles.find("TextureCoordinate") is not None
    # X3D multiplies the texture by the Color node: vertex colour × base colour, as glTF does
    colours = _floats(triangles.find("Color").get("color")).reshape(-1, 3)
    index = np.unique(box.faces)
    expected = np.rint(box.vertex_colors[index, :3] * [1, 128 / 255, 0]).astype(int)
    np.testing.assert_array_equal(np.rint(colours * 255).astype(int), expected)
    np.testing.assert_array_equal(vertex_colors(box)[:, :3], expected)


def test_large_texture_is_halved_until_its_url_fits(monkeypatch: pytest.MonkeyPatch) -> None:
    texture = np.random.default_rng(9).integers(0, 256, size=(40, 64, 4), dtype=np.uint8)
    texture[..., 3] = 255  # opaque: plain 2 × 2 averages (Pillow weighs colours by alpha)
    full = x3d.shapes.texture_url(texture)
    monkeypatch.setattr(x3d.shapes, "MAX_TEXTURE_URL", len(full) - 1)
    url = x3d.shapes.texture_url(texture)
    assert len(url) < len(full)
    pixels = _texture_pixels(f'"{url}"')
    assert pixels.shape == (20, 32, 4)  # halved once: a quarter of the pixels fits
    boxes = texture.reshape(20, 2, 32, 2, 4).astype(float).mean(axis=(1, 3))
    np.testing.assert_allclose(pixels, boxes, atol=1)


def test_uncoloured_mesh_uses_material_colour(chain: LodChain) -> None:
    mesh = chain.levels[0].mesh
    plain = Surface(mesh.vertices, mesh.faces, base_color=np.array([255, 0, 0, 128], np.uint8))
    level = replace(chain.levels[0], mesh=plain)
    shape = etree.fromstring(_write([replace(chain, levels=[level, *chain.levels[1:]])]))
    material = shape.find(".//Material")
    assert material.get("diffuseColor") == "1 0 0"
    assert float(material.get("transparency")) == pytest.approx(1 - 128 / 255, abs=1e-4)
    assert shape.find(".//IndexedTriangleSet/Color") is None


def test_bunny_round_trip_and_validation(
    schema: etree.XMLSchema, bunny: Node, tmp_path: Path
) -> None:
    chain = _bake(bunny)
    _check_round_trip(chain, tmp_path / "bunny.x3d")
    _assert_valid(schema, (tmp_path / "bunny.x3d").read_bytes())


# --- levels split over several Shapes -------------------------------------------------------------

SMALL_VERTICES, SMALL_TRIANGLES = 500, 800


def _runs(total: int, size: int) -> list[int]:
    """Lengths of consecutive runs of at most ``size`` covering ``total`` items."""
    return [min(size, total - start) for start in range(0, total, size)]


@pytest.mark.parametrize("soup", [False, True], ids=["shared-vertices", "triangle-soup"])
def test_levels_over_the_shape_limits_are_split(
    schema: etree.XMLSchema,
    torus: Node,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    soup: bool,
) -> None:
    monkeypatch.setattr(x3d.shapes, "MAX_SHAPE_VERTICES", SMALL_VERTICES)
    monkeypatch.setattr(x3d.shapes, "MAX_SHAPE_TRIANGLES", SMALL_TRIANGLES)
    surface = torus.geometry.parts[0]
    if soup:  # each face has its own three vertices: the vertex limit binds first
        faces = surface.faces
        surface = Surface(
            surface.vertices[faces].reshape(-1, 3),
            np.arange(faces.size).reshape(-1, 3),
            vertex_colors=surface.vertex_colors[faces].reshape(-1, 4),
        )
    chain = _bake(Node("big", surface))
    path = tmp_path / "big.x3d"
    _check_round_trip(chain, path)
    data = path.read_bytes()
    _assert_valid(schema, data)
    assert _write([chain]) == data  # deterministic

    groups = _lod_children(_lod(data))
    for group, level in zip(groups, chain.levels, strict=True):
        appearances = [shape.find("Appearance") for shape in group.iter("Shape")]
        defined = appearances[0].get("DEF")
        assert defined == f"{group.get('DEF')}_Appearance" and len(appearances[0]) == 1
        assert all(a.get("USE") == defined and len(a) == 0 for a in appearances[1:])
        geometry = _shape_geometry(group)
        counts = [_point_count(g) for g in geometry]
        if level.kind == "mesh":
            triangles = [len(_floats(g.get("index"))) // 3 for g in geometry]
            per_run = SMALL_VERTICES // 3 if soup else SMALL_TRIANGLES
            assert triangles == _runs(len(surface.faces), per_run)  # each run as long as allowed
            assert max(counts) <= SMALL_VERTICES
        else:
            assert counts == _runs(level.count, SMALL_VERTICES)
    shapes = [len(list(g.iter("Shape"))) for g in groups]
    assert shapes[0] > 1 and shapes[1] > 1 and shapes[-1] == 1  # a level that fits: one Shape


@pytest.mark.slow
def test_dragon_validates_with_default_parser_limits(
    schema: etree.XMLSchema, tmp_path: Path
) -> None:
    """871,414 triangles: without splitting, the index attribute alone would be 17.6 MB, more
    than libxml2 parses or validates without ``huge_tree``."""
    obj = next(read_scene(stanford("dragon_vrip.ply.gz")).with_geometry())
    chain = bake_chain(obj, ChainOptions(), NumpyBackend())
    path = tmp_path / "dragon.x3d"
    _check_round_trip(chain, path)
    doc = etree.parse(str(path))  # default limits: no huge_tree
    assert schema.validate(doc), "\n".join(str(e) for e in schema.error_log)
    assert max(len(v) for node in doc.iter() for v in node.attrib.values()) < 4_000_000
    mesh = doc.find("Scene/Transform/LOD/Group")
    assert len(mesh.findall("Shape")) >= math.ceil(871_414 / x3d.shapes.MAX_SHAPE_TRIANGLES)


# --- streaming and determinism ------------------------------------------------------------------


def test_writing_twice_gives_identical_bytes(chain: LodChain, culled: LodChain) -> None:
    chains = [chain, replace(culled, object_id="culled")]
    assert _write(chains) == _write(chains)


def test_chains_are_streamed_as_they_come(chain: LodChain) -> None:
    out = io.BytesIO()
    seen: list[int] = []

    def chains() -> Iterator[LodChain]:
        for name in ("first", "second"):
            seen.append(len(out.getvalue()))
            if name == "second":  # the first chain is already on the handle, to its end
                assert out.getvalue().rstrip().endswith(b"</Transform>")
            yield replace(chain, object_id=name)

    write_x3d(chains(), out, INFO)
    assert len(seen) == 2 and out.getvalue().endswith(b"</X3D>\n")


def test_one_registry_entry_writes_reads_back_and_checks() -> None:
    assert output_format("a.x3d") is own_format("a.X3D") is x3d.FORMAT
    assert x3d.FORMAT.write and x3d.FORMAT.read_back and x3d.FORMAT.check
    with pytest.raises(UsageError, match=r"unknown output format '\.vrml'"):
        output_format("a.vrml")


# --- reader errors ------------------------------------------------------------------------------


def test_truncated_or_foreign_files_raise_input_error(chain: LodChain, tmp_path: Path) -> None:
    data = _write([chain])
    truncated = tmp_path / "cut.x3d"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=re.escape(str(truncated))):
        read_x3d_points(truncated)
    foreign = tmp_path / "foreign.x3d"
    foreign.write_bytes(b"<?xml version='1.0'?><html><body/></html>")
    with pytest.raises(InputError, match=re.escape(f"{foreign}: is not an X3D")):
        read_x3d_points(foreign)
    garbled = tmp_path / "garbled.x3d"
    garbled.write_bytes(data.replace(b'point="', b'point="x ', 1))
    with pytest.raises(InputError, match=re.escape(str(garbled))):
        read_x3d_points(garbled)
    mixed = tmp_path / "mixed.x3d"
    mixed.write_bytes(
        b"<X3D><Scene><Group DEF='a'>"
        b"<Shape><PointSet><Coordinate point='0 0 0'/></PointSet></Shape>"
        b"<Shape><IndexedTriangleSet index='0 0 0'><Coordinate point='0 0 0'/>"
        b"</IndexedTriangleSet></Shape></Group></Scene></X3D>"
    )
    with pytest.raises(InputError, match=re.escape(f"{mixed}: holds malformed")):
        read_x3d_points(mixed)
    missing = tmp_path / "missing.x3d"
    with pytest.raises(InputError, match=re.escape(str(missing))):
        read_x3d_points(missing)


# --- number formatting --------------------------------------------------------------------------


def test_fixed_formatting_matches_python_and_trims_zeros() -> None:
    rng = np.random.default_rng(7)
    values = rng.normal(size=5000) * 10.0 ** rng.integers(-9, 6, size=5000)
    values[:4] = (0.0, -0.0, -1e-12, 100.0)
    for decimals in (0, 3, 8):
        text = format_fixed(values, decimals).split()
        expected = [f"{v:.{decimals}f}" for v in values]
        expected = [e.rstrip("0").rstrip(".") if "." in e else e for e in expected]
        expected = ["0" if e == "-0" else e for e in expected]
        assert text == expected
    assert format_fixed([0.5, -2.0, 1e-9, 1234.56789], 4) == "0.5 -2 0 1234.5679"
    with pytest.raises(ValueError):
        format_fixed([math.nan], 3)


def test_float_ints_colour_and_exact_formatting() -> None:
    assert decimals_for(0.0781) == 8 and decimals_for(5e9) == 0 and decimals_for(0.0) == 0
    v = np.array([[0.1234567891, -0.001, 12.0]])
    assert format_floats(v, significant=4) == "0.12 0 12"
    assert format_floats(np.zeros((0, 3))) == ""
    assert geometry_decimals(v, significant=4) == 2 and geometry_decimals(np.zeros((0, 3))) == 0
    ints = np.array([0, 7, -12, 10, 999999, -(2**40)])
    assert format_ints(ints) == " ".join(map(str, ints.tolist()))
    bytes_ = np.arange(256, dtype=np.uint8)
    back = np.rint(_floats(format_unit_bytes(bytes_)) * 255).astype(int)
    np.testing.assert_array_equal(back, bytes_)
    assert format_unit_bytes(np.array([0, 128, 255], np.uint8)) == "0 0.502 1"
    origin = [500000.123456789, 5400000.987654321, -0.1]
    assert [float(t) for t in format_exact(origin).split()] == origin


FINITE = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=300, deadline=None)
@given(st.lists(FINITE, min_size=1, max_size=8))
def test_format_floats_round_trips_every_finite_float(values: list[float]) -> None:
    """Parsed back, every number is within half a unit of the last decimal written (plus the
    float64 rounding of scaling, 2⁻⁵¹ of the value), over the whole float64 range."""
    decimals = geometry_decimals(values)
    tokens = format_floats(values).split(" ")
    assert len(tokens) == len(values)
    for token, value in zip(tokens, values, strict=True):
        assert re.fullmatch(r"-?\d+(\.\d*[1-9])?", token), token
        error = abs(float(token) - value)
        assert error <= 0.5 * 10.0**-decimals + 2.0**-51 * abs(value) + 5e-324, (token, value)


@settings(max_examples=200, deadline=None)
@given(FINITE, st.integers(0, MAX_DECIMALS))
def test_format_fixed_round_trips_at_any_decimals(value: float, decimals: int) -> None:
    token = format_fixed([value], decimals)
    error = abs(float(token) - value)
    assert error <= 0.5 * 10.0**-decimals + 2.0**-51 * abs(value) + 5e-324, token


def test_coordinates_beyond_int64_are_written_exactly() -> None:
    assert format_floats([1e20, -2e20, 0.5]) == "100000000000000000000 -200000000000000000000 0"
    assert format_fixed([-1.5e300], 0) == str(int(-1.5e300))
    with pytest.raises(ValueError, match="decimals"):
        format_fixed([1.0], MAX_DECIMALS + 1)


def _fixed_oracle(values: list[float], decimals: int) -> str:
    """:func:`format_fixed`'s rule, value by value in exact decimal arithmetic: each value is
    scaled in float64 and rounded half to even (``rint(v * 10**decimals)``) and printed in those
    units, or, where a scaled magnitude of the list reaches 2^62, every value is rounded from its
    exact binary value; trailing zeros and ``-0`` dropped."""
    with np.errstate(over="ignore"):
        units = [float(np.rint(np.float64(v) * 10.0**decimals)) for v in values]
    with decimal.localcontext(prec=1000):
        if max(map(abs, units), default=0.0) >= 2.0**62:
            place = Decimal(1).scaleb(-decimals)
            numbers = [Decimal(v).quantize(place, ROUND_HALF_EVEN) for v in values]
        else:
            numbers = [Decimal(int(u)).scaleb(-decimals) for u in units]
    tokens = [f"{number:f}" for number in numbers]
    tokens = [t.rstrip("0").rstrip(".") if "." in t else t for t in tokens]
    return " ".join("0" if t == "-0" else t for t in tokens)


EDGE_FLOATS = st.sampled_from(
    [
        *(0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1.7976931348623157e308),
        *(0.5, -2.5, 0.125, 1.005, 2.675, 1e-4, 9.99995e-5, -1.5e-5),
        *(1e15, 2.0**51, 2.0**53, 2.0**62, 1e20),
    ]
)
ON_GRID = st.builds(  # on a decimal grid or halfway between two of its points
    lambda units, decimals, half: (units + 0.5 * half) / 10.0**decimals,
    st.integers(-(10**16), 10**16),
    st.integers(0, 25),
    st.booleans(),
)
FIXED_VALUES = st.lists(st.one_of(FINITE, EDGE_FLOATS, ON_GRID), max_size=12)


@settings(max_examples=500, deadline=None)
@given(FIXED_VALUES, st.one_of(st.integers(0, 25), st.integers(0, MAX_DECIMALS)))
def test_format_fixed_follows_its_rule_value_by_value(values: list[float], decimals: int) -> None:
    assert format_fixed(values, decimals) == _fixed_oracle(values, decimals)


@settings(max_examples=300, deadline=None)
@given(FIXED_VALUES)
def test_format_floats_follows_the_fixed_rule(values: list[float]) -> None:
    assert format_floats(values) == _fixed_oracle(values, geometry_decimals(values))


@settings(max_examples=500, deadline=None)
@given(
    st.one_of(st.text(), st.text(alphabet="&<>\"'\t\n\r\x00\x1f\x7f\x85\ud800\ufffe\uffffaß😀 "))
)
def test_attribute_text_is_escaped_as_lxml_escapes_it(text: str) -> None:
    """lxml refuses characters XML forbids; the writer writes them as \\uXXXX first."""
    expected = etree.tostring(etree.Element("a", v=xml_text(text)), encoding="unicode")
    assert f'<a v="{x3d.xmltext.escape(text)}"/>' == expected


@pytest.mark.parametrize(
    ("text", "word"),
    [
        ('<MetadataSet name="lodconvert"/>', "no lodconvert LOD"),
        (
            "<X3D><Scene><Transform><LOD><Group DEF='a'><Shape><IndexedTriangleSet index='0 1 9'>"
            "<Coordinate point='0 0 0 1 0 0 0 1 0'/></IndexedTriangleSet></Shape></Group></LOD>"
            "</Transform></Scene></X3D>",
            "index",
        ),
        (
            "<X3D><Scene><Group DEF='a'><Shape><PointSet><Coordinate point='0 0 nan'/>"
            "</PointSet></Shape></Group></Scene></X3D>",
            "NaN",
        ),
    ],
)
def test_malformed_x3d_read_back_is_one_input_error(tmp_path: Path, text: str, word: str) -> None:
    path = tmp_path / "bad.x3d"
    path.write_text(text)
    with pytest.raises(InputError) as caught:
        (x3d.read_back if "Metadata" in text else read_x3d_points)(path)
    message = str(caught.value)
    assert message.startswith(str(path)) and word in message and "\n" not in message
