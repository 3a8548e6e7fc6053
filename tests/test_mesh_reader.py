"""The mesh reader: every format (and its .gz), OBJ objects and groups, shared instances,
colours (linear glTF, sRGB elsewhere), materials, textures, transforms, mislabelled files."""

from __future__ import annotations

import gzip
import io
import time
from pathlib import Path

import numpy as np
import pygltflib as gl
import pytest
import trimesh
from PIL import Image

from lodconvert import convert
from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions
from lodconvert.errors import InputError
from lodconvert.io import read_scene
from lodconvert.io.gltf import read_lod_gltf
from lodconvert.plans import bake_chain

FORMATS = ("obj", "ply", "stl", "off", "glb", "gltf")


def torus() -> trimesh.Trimesh:
    """A torus of 32 × 32 sections."""
    return trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=32)


# --- helpers --------------------------------------------------------------------------------------


def box(extents=(1.0, 1.0, 1.0), at=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    """A box of ``extents`` centred at ``at``."""
    return trimesh.creation.box(extents=extents).apply_translation(at)


def primitive(mesh: trimesh.Trimesh, **extra) -> dict:
    """A primitive for :func:`write_glb`: ``mesh``'s triangles plus ``colors``/``material``."""
    return {"positions": mesh.vertices, "faces": mesh.faces, **extra}


def write_glb(
    path: Path,
    meshes: list[list[dict]],
    nodes: list[gl.Node],
    materials: list[gl.Material] | None = None,
) -> Path:
    """A GLB of ``meshes`` (each a list of primitives: ``positions``, ``faces``, optional
    ``colors`` as stored, uint8/uint16 normalised or float32, and ``material``) with every
    node of ``nodes`` a root of the scene."""
    doc = gl.GLTF2(scene=0, scenes=[gl.Scene(nodes=list(range(len(nodes))))], nodes=nodes)
    doc.materials = materials or []
    blob = bytearray()
    types = {1: gl.SCALAR, 3: gl.VEC3, 4: gl.VEC4}
    components = {
        np.dtype(np.float32): gl.FLOAT,
        np.dtype(np.uint8): gl.UNSIGNED_BYTE,
        np.dtype(np.uint16): gl.UNSIGNED_SHORT,
        np.dtype(np.uint32): gl.UNSIGNED_INT,
    }

    def accessor(array: np.ndarray, **options) -> int:
        data = np.ascontiguousarray(array)
        blob.extend(b"\0" * (-len(blob) % 4))
        view = gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=data.nbytes)
        doc.bufferViews.append(view)
        blob.extend(data.tobytes())
        doc.accessors.append(
            gl.Accessor(
                bufferView=len(doc.bufferViews) - 1,
                componentType=components[data.dtype],
                count=len(data),
                type=types[1 if data.ndim == 1 else data.shape[1]],
                **options,
            )
        )
        return len(doc.accessors) - 1

    for parts in meshes:
        primitives = []
        for part in parts:
            positions = np.asarray(part["positions"], dtype=np.float32)
            attributes = gl.Attributes(
                POSITION=accessor(
                    positions, min=positions.min(0).tolist(), max=positions.max(0).tolist()
                )
            )
            if "colors" in part:
                colors = part["colors"]
                attributes.COLOR_0 = accessor(colors, normalized=colors.dtype.kind == "u" or None)
            faces = np.asarray(part["faces"], dtype=np.uint32).ravel()
            primitives.append(
                gl.Primitive(
                    attributes=attributes, indices=accessor(faces), material=part.get("material")
                )
            )
        doc.meshes.append(gl.Mesh(primitives=primitives))
    doc.buffers = [gl.Buffer(byteLength=len(blob))]
    doc.set_binary_blob(bytes(blob))
    doc.save_binary(str(path))
    return path


def material(factor: list[float]) -> gl.Material:
    """A glTF material of base colour factor ``factor`` (linear RGBA)."""
    return gl.Material(pbrMetallicRoughness=gl.PbrMetallicRoughness(baseColorFactor=factor))


def output_accessor(doc: gl.GLTF2, index: int) -> np.ndarray:
    """Accessor values of a GLB lodconvert wrote (tightly packed), normalised to [0, 1] for
    normalised integers."""
    acc = doc.accessors[index]
    view = doc.bufferViews[acc.bufferView]
    dtype = {gl.FLOAT: "<f4", gl.UNSIGNED_SHORT: "<u2", gl.UNSIGNED_BYTE: "u1"}[acc.componentType]
    width = {gl.SCALAR: 1, gl.VEC2: 2, gl.VEC3: 3, gl.VEC4: 4}[acc.type]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    values = np.frombuffer(doc.binary_blob(), dtype=dtype, count=acc.count * width, offset=start)
    values = values.reshape(acc.count, width)
    return values / float(np.iinfo(values.dtype).max) if acc.normalized else values


def mesh_primitives(path: Path) -> tuple[gl.GLTF2, list[gl.Primitive]]:
    """A GLB and its triangle primitives (the mesh levels; point levels are left out)."""
    doc = gl.GLTF2.load_binary(str(path))
    primitives = [p for m in doc.meshes for p in m.primitives if p.mode in (None, gl.TRIANGLES)]
    return doc, primitives


def srgb_byte(linear: float) -> int:
    """The sRGB byte of a linear value (IEC 61966-2-1)."""
    s = 12.92 * linear if linear <= 0.0031308 else 1.055 * linear ** (1 / 2.4) - 0.055
    return round(s * 255)


# --- formats, colours, textures, placement --------------------------------------------------------


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("gz", [False, True], ids=["plain", "gz"])
def test_every_format_reads_with_its_geometry(tmp_path: Path, fmt: str, gz: bool) -> None:
    mesh = torus()
    path = tmp_path / f"torus.{fmt}"
    mesh.export(path)
    if gz:
        packed = tmp_path / f"torus.{fmt}.gz"
        packed.write_bytes(gzip.compress(path.read_bytes(), mtime=0))
        path.unlink()
        path = packed
    (obj,) = list(read_scene(path).with_geometry())
    assert obj.id == "torus"
    assert len(obj.geometry.faces) == len(mesh.faces)
    assert np.allclose(obj.geometry.bounds, mesh.bounds, atol=1e-6)


def test_ply_vertex_colours_are_kept(tmp_path: Path) -> None:
    mesh = torus()
    colors = np.zeros((len(mesh.vertices), 4), dtype=np.uint8)
    colors[:, 0] = np.arange(len(mesh.vertices)) % 256
    colors[:, 3] = 255
    mesh.visual.vertex_colors = colors
    path = tmp_path / "c.ply"
    mesh.export(path)
    (obj,) = list(read_scene(path).with_geometry())
    assert np.array_equal(obj.geometry.vertex_colors, colors)


def test_glb_material_base_colour_reaches_the_points(tmp_path: Path) -> None:
    """The factor is linear (200/255 and so on in the file); points get its sRGB bytes."""
    mesh = torus()
    mesh.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(baseColorFactor=[200, 40, 10, 255])
    )
    path = tmp_path / "m.glb"
    mesh.export(path)
    (obj,) = list(read_scene(path).with_geometry())
    srgb = [srgb_byte(v / 255) for v in (200, 40, 10)] + [255]
    assert srgb == [229, 110, 56, 255]
    assert list(obj.geometry.parts[0].material_color) == srgb
    chain = bake_chain(obj, ChainOptions(resolutions=(24, 12, 6)), NumpyBackend())
    assert np.all(chain.levels[1].points.colors == srgb)


def test_texture_colours_are_sampled(tmp_path: Path) -> None:
    """A box textured half red (u < 0.5), half blue: points take the texel under them."""
    box = trimesh.creation.box(extents=(2, 1, 1))
    uv = np.stack([(box.vertices[:, 0] + 1) / 2, (box.vertices[:, 1] + 0.5)], axis=1)
    image = np.zeros((8, 8, 3), dtype=np.uint8)
    image[:, :4] = (255, 0, 0)
    image[:, 4:] = (0, 0, 255)
    # with an image only, trimesh writes a baseColorFactor of 0.4, which darkens the texels
    white = trimesh.visual.material.PBRMaterial(
        baseColorTexture=Image.fromarray(image), baseColorFactor=[255, 255, 255, 255]
    )
    box.visual = trimesh.visual.TextureVisuals(uv=uv, material=white)
    path = tmp_path / "box.glb"
    box.export(path)
    (obj,) = list(read_scene(path).with_geometry())
    assert obj.geometry.parts[0].texture is not None and obj.geometry.parts[0].uv is not None
    chain = bake_chain(obj, ChainOptions(resolutions=(32, 16, 8)), NumpyBackend())
    points = chain.levels[1].points
    left = points.positions[:, 0] < -0.2
    right = points.positions[:, 0] > 0.2
    assert np.all(points.colors[left, 0] > 200) and np.all(points.colors[left, 2] < 50)
    assert np.all(points.colors[right, 2] > 200) and np.all(points.colors[right, 0] < 50)


def test_scene_nodes_stay_objects_with_their_transforms(tmp_path: Path) -> None:
    scene = trimesh.Scene()
    for i in range(3):
        place = np.eye(4)
        place[:3, 3] = (10.0 * i, 0.0, 0.0)
        scene.add_geometry(torus(), node_name=f"ring {i}", geom_name="ring", transform=place)
    path = tmp_path / "rings.glb"
    scene.export(path)
    objects = list(read_scene(path).with_geometry())
    assert [o.id for o in objects] == ["ring_0", "ring_1", "ring_2"]
    centres = [o.geometry.bounds.mean(axis=0)[0] for o in objects]
    assert centres == pytest.approx([0.0, 10.0, 20.0], abs=1e-6)


def test_a_garbage_file_is_an_input_error(tmp_path: Path) -> None:
    path = tmp_path / "junk.glb"
    path.write_bytes(b"glTF" + bytes(range(200)))
    with pytest.raises(InputError, match=r"junk\.glb"):
        read_scene(path)


# --- OBJ objects and groups -----------------------------------------------------------------------


def test_each_obj_object_is_a_node_at_its_own_place(tmp_path: Path) -> None:
    scene = trimesh.Scene()
    for i in range(3):
        scene.add_geometry(box(at=(10.0 * i, 0.0, 0.0)), geom_name=f"building {i}")
    path = tmp_path / "city.obj"
    scene.export(path)
    objects = list(read_scene(path).with_geometry())
    assert [o.id for o in objects] == ["building_0", "building_1", "building_2"]
    assert [o.geometry.face_count for o in objects] == [12, 12, 12]
    centres = [o.geometry.bounds.mean(axis=0) for o in objects]
    assert np.allclose(centres, [[0, 0, 0], [10, 0, 0], [20, 0, 0]])
    assert all(o.transform is None for o in objects)

    (merged,) = read_scene(path, merge_groups=True).nodes
    assert merged.id == "city"
    assert merged.geometry.face_count == 36
    assert np.allclose(merged.geometry.bounds, [[-0.5, -0.5, -0.5], [20.5, 0.5, 0.5]])


OBJ_HOUSES = """mtllib houses.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 5 0 0
v 6 0 0
v 6 1 0
v 5 1 0
v 9 9 9
v 9 8 9
v 8 9 9
g house 1
usemtl roof
f 1 2 3
usemtl wall
f 1 3 4
g house_1
usemtl wall
f 5 6 7
g house 1
f 9 10 11
g
f 5 7 8
"""
MTL_HOUSES = "newmtl roof\nKd 0.8 0.1 0.1\nnewmtl wall\nKd 0.5 0.5 0.5\n"


def test_obj_groups_are_nodes_with_their_materials(tmp_path: Path) -> None:
    """Without ``o`` lines the ``g`` groups are the objects: a group named again gathers its
    faces, each keeps its materials as parts, and names are made unique ids."""
    (tmp_path / "houses.mtl").write_text(MTL_HOUSES)
    path = tmp_path / "houses.obj"
    path.write_text(OBJ_HOUSES)
    first, second, unnamed = read_scene(path).nodes
    assert [first.id, second.id, unnamed.id] == ["house_1", "house_1_2", "object"]
    assert first.attributes["source_node"] == "house 1"
    assert first.geometry.face_count == 3
    assert np.allclose(first.geometry.bounds, [[0, 0, 0], [9, 9, 9]])
    colours = sorted(tuple(p.material_color) for p in first.geometry.parts)
    assert colours == [(128, 128, 128, 255), (204, 26, 26, 255)]
    assert second.geometry.face_count == unnamed.geometry.face_count == 1
    assert np.allclose(second.geometry.bounds[:, 0], [5, 6])


def test_faces_before_the_first_obj_object_are_a_node_of_their_own(tmp_path: Path) -> None:
    path = tmp_path / "site.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\no tower\nf 3 2 1\nf 1 3 2\n")
    loose, tower = read_scene(path).nodes
    assert (loose.id, loose.geometry.face_count) == ("site", 1)
    assert (tower.id, tower.geometry.face_count) == ("tower", 2)


def test_ten_thousand_obj_groups_become_ten_thousand_nodes(tmp_path: Path) -> None:
    count = 10_000
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    lines = []
    for i in range(count):
        lines.append(f"g block {i}")
        lines.extend(f"v {x + 2 * i:g} {y:g} {z:g}" for x, y, z in corners)
        lines.append(f"f {4 * i + 1} {4 * i + 2} {4 * i + 3} {4 * i + 4}")
    path = tmp_path / "blocks.obj"
    path.write_text("\n".join(lines) + "\n")
    start = time.perf_counter()
    scene = read_scene(path)
    assert scene.size == count
    nodes = list(scene.nodes)
    print(f"{count:,} OBJ groups read in {time.perf_counter() - start:.2f} s")
    assert len(nodes) == count
    assert nodes[-1].id == f"block_{count - 1}"
    assert nodes[-1].geometry.bounds[0, 0] == 2 * (count - 1)


# --- instances ------------------------------------------------------------------------------------


def test_a_mesh_placed_by_several_nodes_is_read_once_and_shared(tmp_path: Path) -> None:
    s = np.sqrt(0.5)
    rotated = np.array([[0, -2, 0, 0], [2, 0, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]], dtype=float)
    matrix = np.eye(4)
    matrix[:3, 3] = (1.5, -2.0, 1e6)
    nodes = [
        gl.Node(name="a", mesh=0, translation=[10.0, 0.0, 0.0]),
        gl.Node(name="b", mesh=0, rotation=[0.0, 0.0, s, s], scale=[2.0, 2.0, 2.0]),
        gl.Node(name="c", mesh=0, matrix=matrix.T.ravel().tolist()),  # column-major
        gl.Node(name="d", mesh=1, translation=[0.0, 50.0, 0.0]),
    ]
    shape = box(extents=(1.0, 2.0, 3.0), at=(0.5, 0.0, 0.0))
    path = write_glb(tmp_path / "street.glb", [[primitive(shape)], [primitive(box())]], nodes)
    a, b, c, d = read_scene(path).nodes
    assert [a.id, b.id, c.id, d.id] == ["a", "b", "c", "d"]
    assert a.geometry is b.geometry is c.geometry
    assert np.allclose(a.geometry.bounds, shape.bounds)  # in the mesh's own frame
    expected = [np.eye(4), rotated, matrix]
    expected[0][:3, 3] = (10.0, 0.0, 0.0)
    for node, transform in zip((a, b, c), expected, strict=True):
        assert node.transform.dtype == np.float64
        assert np.allclose(node.transform, transform, rtol=0, atol=1e-9)
    # a mesh placed once is moved into place
    assert d.transform is None
    assert np.allclose(d.geometry.bounds, [[-0.5, 49.5, -0.5], [0.5, 50.5, 0.5]])


def test_a_multi_primitive_glb_mesh_is_one_node_with_a_part_per_primitive(
    tmp_path: Path,
) -> None:
    parts = [
        primitive(box(), material=0),
        primitive(box(at=(0.0, 0.0, 1.0)), material=1),
    ]
    nodes = [gl.Node(name="car", mesh=0), gl.Node(name="twin", mesh=0, translation=[5, 0, 0])]
    materials = [material([1.0, 0.0, 0.0, 1.0]), material([0.0, 0.0, 1.0, 1.0])]
    car, twin = read_scene(write_glb(tmp_path / "cars.glb", [parts], nodes, materials)).nodes
    assert (car.id, twin.id) == ("car", "twin")
    assert car.geometry is twin.geometry
    assert [tuple(p.material_color) for p in car.geometry.parts] == [
        (255, 0, 0, 255),
        (0, 0, 255, 255),
    ]
    assert twin.transform[0, 3] == 5.0


# --- colours --------------------------------------------------------------------------------------


def test_glb_base_colour_factor_survives_glb_to_glb(tmp_path: Path) -> None:
    """glTF factors are linear: 0.502 comes out as 0.502 (not linearised a second time)."""
    factor = [0.502, 0.2, 0.8, 1.0]
    source = write_glb(
        tmp_path / "in.glb", [[primitive(box(), material=0)]], [gl.Node(mesh=0)], [material(factor)]
    )
    (obj,) = read_scene(source).nodes
    assert list(obj.geometry.parts[0].base_color) == [srgb_byte(v) for v in factor[:3]] + [255]
    out = tmp_path / "out.glb"
    convert(source, out)
    doc, (mesh,) = mesh_primitives(out)
    written = doc.materials[mesh.material].pbrMetallicRoughness.baseColorFactor
    assert np.allclose(written, factor, rtol=0, atol=1 / 255)


@pytest.mark.parametrize(
    ("dtype", "with_material"),
    [(np.float32, True), (np.uint16, True), (np.uint8, False)],
    ids=["float-material", "ushort-material", "ubyte-no-material"],
)
def test_glb_vertex_colours_survive_glb_to_glb(
    tmp_path: Path, dtype: type, with_material: bool
) -> None:
    """COLOR_0 is linear; linear values up to 0.8 round-trip within 1/255 (sRGB bytes are
    coarser than that above it)."""
    sphere = trimesh.creation.icosphere(subdivisions=1)
    n = len(sphere.vertices)
    steps = np.linspace(0, 204, 3 * n).round().reshape(n, 3)  # k/255: exact in every dtype
    linear = np.column_stack([steps / 255.0, np.ones(n)])
    stored = {
        np.float32: linear.astype(np.float32),
        np.uint16: np.rint(linear * 65535).astype(np.uint16),
        np.uint8: np.rint(linear * 255).astype(np.uint8),
    }[dtype]
    part = primitive(sphere, colors=stored, **({"material": 0} if with_material else {}))
    materials = [material([1.0, 1.0, 1.0, 1.0])] if with_material else None
    source = write_glb(tmp_path / "in.glb", [[part]], [gl.Node(mesh=0)], materials)
    out = tmp_path / "out.glb"
    convert(source, out)
    doc, (mesh,) = mesh_primitives(out)
    written = output_accessor(doc, mesh.attributes.COLOR_0)
    assert np.abs(written - linear).max() <= 1 / 255


def test_ply_srgb_colours_come_back_from_glb_unchanged(tmp_path: Path) -> None:
    mesh = torus()
    rng = np.random.default_rng(7)
    colors = rng.integers(0, 256, size=(len(mesh.vertices), 4), dtype=np.uint8)
    colors[:, 3] = 255
    mesh.visual.vertex_colors = colors
    source = tmp_path / "c.ply"
    mesh.export(source)
    out = tmp_path / "c.glb"
    convert(source, out)
    (obj,) = read_lod_gltf(out)
    assert np.array_equal(obj.levels[0].colors, colors)


def test_glb_texture_pixels_survive_glb_to_glb(tmp_path: Path) -> None:
    cube = box()
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, size=(8, 8, 3), dtype=np.uint8)
    uv = rng.random((len(cube.vertices), 2))
    cube.visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(image))
    source = tmp_path / "in.glb"
    cube.export(source)
    out = tmp_path / "out.glb"
    convert(source, out)
    doc, (mesh,) = mesh_primitives(out)
    texture = doc.textures[doc.materials[mesh.material].pbrMetallicRoughness.baseColorTexture.index]
    view = doc.bufferViews[doc.images[texture.source].bufferView]
    png = doc.binary_blob()[view.byteOffset : view.byteOffset + view.byteLength]
    pixels = np.asarray(Image.open(io.BytesIO(png)).convert("RGBA"))
    assert np.array_equal(pixels[..., :3], image) and np.all(pixels[..., 3] == 255)


# --- content that is not of the suffix's format ---------------------------------------------------


@pytest.mark.parametrize(
    ("written", "named"),
    [("obj", "stl"), ("ply", "obj"), ("stl", "ply"), ("glb", "gltf"), ("off", "glb")],
)
def test_content_of_another_format_is_reported_as_unreadable(
    tmp_path: Path, written: str, named: str
) -> None:
    source = tmp_path / f"model.{written}"
    torus().export(source)
    path = tmp_path / f"model.{named}"
    path.write_bytes(source.read_bytes())
    with pytest.raises(InputError) as caught:
        read_scene(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: cannot be read as {named.upper()}: ")
    assert message.endswith(f"it looks like {written.upper()}")
    assert "\n" not in message


def test_text_without_geometry_is_not_obj_but_vertices_only_have_no_faces(
    tmp_path: Path,
) -> None:
    notes = tmp_path / "notes.obj"
    notes.write_text("these are notes\nnot a mesh\n")
    with pytest.raises(InputError, match=r"cannot be read as OBJ: no vertex \('v'\) or face"):
        read_scene(notes)
    points = tmp_path / "points.obj"
    points.write_text("o scan\nv 0 0 0\nv 1 0 0\n")
    with pytest.raises(InputError, match="has no faces"):
        read_scene(points)


def test_a_gltf_whose_buffer_file_is_missing_says_so(tmp_path: Path) -> None:
    doc = gl.GLTF2.load_binary(
        str(write_glb(tmp_path / "a.glb", [[primitive(box())]], [gl.Node(mesh=0)]))
    )
    doc.convert_buffers(gl.BufferFormat.BINFILE)
    path = tmp_path / "a.gltf"
    doc.save_json(str(path))
    (tmp_path / doc.buffers[0].uri).unlink()
    with pytest.raises(
        InputError, match=rf"a\.gltf: refers to a missing file: {doc.buffers[0].uri}$"
    ):
        read_scene(path)
