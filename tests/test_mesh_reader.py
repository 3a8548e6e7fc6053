"""The mesh reader: every format (and its .gz), colours, materials, textures, transforms."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions, bake_chain
from lodconvert.errors import InputError
from lodconvert.pipeline import read_scene

FORMATS = ("obj", "ply", "stl", "off", "glb", "gltf")


def torus() -> trimesh.Trimesh:
    return trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=32)


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
    mesh = torus()
    mesh.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(baseColorFactor=[200, 40, 10, 255])
    )
    path = tmp_path / "m.glb"
    mesh.export(path)
    (obj,) = list(read_scene(path).with_geometry())
    assert list(obj.geometry.parts[0].material_color) == [200, 40, 10, 255]
    chain = bake_chain(obj, ChainOptions(resolutions=(24, 12, 6)), NumpyBackend())
    assert np.all(chain.levels[1].points.colors == [200, 40, 10, 255])


def test_texture_colours_are_sampled(tmp_path: Path) -> None:
    """A box textured half red (u < 0.5), half blue: points take the texel under them."""
    box = trimesh.creation.box(extents=(2, 1, 1))
    uv = np.stack([(box.vertices[:, 0] + 1) / 2, (box.vertices[:, 1] + 0.5)], axis=1)
    image = np.zeros((8, 8, 3), dtype=np.uint8)
    image[:, :4] = (255, 0, 0)
    image[:, 4:] = (0, 0, 255)
    box.visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(image))
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
