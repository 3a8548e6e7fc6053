"""City appearances read and kept: CityGML ParameterizedTexture (TexCoordList and TexCoordGen)
and X3DMaterial, CityJSON textures and materials, themes, images beside the input or in its
zip, every image or coordinate that cannot be used warned of with the image and the object
(the surface falls back to its material or class colour), and textured outputs that pass the
official validators. docs/textures.md."""

from __future__ import annotations

import importlib
import io
import json
import os
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from lxml import etree
from PIL import Image

from lodconvert.colors import ciede2000, normalized
from lodconvert.io import read_scene
from lodconvert.io.gltf.binary import accessor_values
from lodconvert.io.tiles.check import glb_parts
from lodconvert.model import Mesh, Surface
from lodconvert.semantics import DEFAULT_CLASS_COLORS
from lodconvert.textures import PADDING, packed

from .conftest import ROOT, SHARED, gl_renderer
from .test_cli import assert_one_line_error, run
from .test_gltf import _assert_valid
from .test_tiles import official

PLATEAU = SHARED / "data" / "citygml"
ROTTERDAM = SHARED / "data" / "cityjson" / "rotterdam" / "rotterdam_subset.city.json"
ROOF = np.array(DEFAULT_CLASS_COLORS["roof"])
QUADRANTS = {"top_left": (220, 30, 30), "top_right": (30, 200, 30),
             "bottom_left": (30, 30, 220), "bottom_right": (230, 220, 30)}  # fmt: skip
"""The colours of the test image's quadrants (its top-left quadrant red…)."""

MODEL = """<?xml version="1.0" encoding="UTF-8"?>
<core:CityModel xmlns:core="http://www.opengis.net/citygml/2.0"
 xmlns:bldg="http://www.opengis.net/citygml/building/2.0"
 xmlns:app="http://www.opengis.net/citygml/appearance/2.0"
 xmlns:gml="http://www.opengis.net/gml">
<gml:boundedBy><gml:Envelope srsName="EPSG:25832" srsDimension="3">
 <gml:lowerCorner>690000 5336000 0</gml:lowerCorner>
 <gml:upperCorner>690010 5336010 6</gml:upperCorner></gml:Envelope></gml:boundedBy>
<core:cityObjectMember><bldg:Building gml:id="B1">{local}
{surfaces}
</bldg:Building></core:cityObjectMember>
{appearance}
</core:CityModel>
"""
BOX = {
    "roof": "0 0 6 10 0 6 10 10 6 0 10 6 0 0 6",
    "south": "0 0 0 10 0 0 10 0 6 0 0 6 0 0 0",
    "east": "10 0 0 10 10 0 10 10 6 10 0 6 10 0 0",
    "north": "10 10 0 0 10 0 0 10 6 10 10 6 10 10 0",
    "west": "0 10 0 0 0 0 0 0 6 0 10 6 0 10 0",
}
"""A 10 m box, 6 m high, in local metres (moved to 690000 5336000 when written)."""
ROOF_UV = "0 0 1 0 1 1 0 1 0 0"


def _moved(text: str) -> str:
    values = np.array(text.split(), dtype=float).reshape(-1, 3) + np.array([690000, 5336000, 0])
    return " ".join(f"{v:.3f}" for v in values.ravel())


def _surface(name: str) -> str:
    kind = "RoofSurface" if name == "roof" else "WallSurface"
    return (
        f"<bldg:boundedBy><bldg:{kind} gml:id='S_{name}'><bldg:lod2MultiSurface><gml:MultiSurface>"
        f"<gml:surfaceMember><gml:Polygon gml:id='P_{name}'><gml:exterior>"
        f"<gml:LinearRing gml:id='L_{name}'><gml:posList>{_moved(BOX[name])}</gml:posList>"
        "</gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember></gml:MultiSurface>"
        f"</bldg:lod2MultiSurface></bldg:{kind}></bldg:boundedBy>"
    )


def texture(uri: str, target: str = "roof", coordinates: str = ROOF_UV, theme: str = "rgb") -> str:
    """An ``Appearance`` of ``theme`` texturing polygon ``target`` with the image ``uri``."""
    return (
        f"<app:Appearance><app:theme>{theme}</app:theme><app:surfaceDataMember>"
        f"<app:ParameterizedTexture><app:imageURI>{uri}</app:imageURI>"
        f"<app:target uri='#P_{target}'><app:TexCoordList>"
        f"<app:textureCoordinates ring='#L_{target}'>{coordinates}</app:textureCoordinates>"
        "</app:TexCoordList></app:target></app:ParameterizedTexture></app:surfaceDataMember>"
        "</app:Appearance>"
    )


def material(rgb: str, target: str = "north", theme: str = "rgb") -> str:
    return (
        f"<app:Appearance><app:theme>{theme}</app:theme><app:surfaceDataMember><app:X3DMaterial>"
        f"<app:diffuseColor>{rgb}</app:diffuseColor><app:target>#P_{target}</app:target>"
        "</app:X3DMaterial></app:surfaceDataMember></app:Appearance>"
    )


def quadrants(size: int = 64) -> Image.Image:
    """A square image whose quadrants have the :data:`QUADRANTS` colours."""
    pixels = np.zeros((size, size, 3), dtype=np.uint8)
    half = size // 2
    pixels[:half, :half] = QUADRANTS["top_left"]
    pixels[:half, half:] = QUADRANTS["top_right"]
    pixels[half:, :half] = QUADRANTS["bottom_left"]
    pixels[half:, half:] = QUADRANTS["bottom_right"]
    return Image.fromarray(pixels)


def city(
    folder: Path, *appearances: str, local: str = "", image: str | None = "tex/roof.png"
) -> Path:
    """A one-building CityGML 2.0 file in ``folder`` with ``appearances`` at its root (and
    ``local`` ones in the building), the quadrant image written at ``image``."""
    if image is not None:
        (folder / image).parent.mkdir(parents=True, exist_ok=True)
        quadrants().save(folder / image)
    members = "".join(f"<app:appearanceMember>{a}</app:appearanceMember>" for a in appearances)
    text = MODEL.format(
        local="".join(f"<app:appearance>{a}</app:appearance>" for a in local.split("|") if a),
        surfaces="\n".join(_surface(name) for name in BOX),
        appearance=members,
    )
    path = folder / "city.gml"
    path.write_text(text)
    return path


def finest(path: Path, **options: object) -> Mesh:
    """The finest mesh of the only object of ``path``."""
    [node] = list(read_scene(path, **options).nodes)
    assert node.geometry is not None
    return node.geometry


def textured(mesh: Mesh) -> list[Surface]:
    return [part for part in mesh.parts if part.texture is not None]


def roof_colour_at(mesh: Mesh, x: float, y: float) -> np.ndarray:
    """The colour of the roof of ``mesh`` above local point (x, y)."""
    [roof] = [part for part in mesh.parts if np.allclose(part.vertices[:, 2], 6.0)]
    point = np.array([[x + 690000, y + 5336000, 6.0]])
    faces = np.arange(len(roof.faces))
    inside = [f for f in faces if _inside(roof.vertices[roof.faces[f]], point[0])]
    return roof.colors_at(np.array(inside[:1]), point)[0, :3]


def _inside(triangle: np.ndarray, point: np.ndarray) -> bool:
    a, b, c = triangle[:, :2] - point[:2]
    cross = [p[0] * q[1] - p[1] * q[0] for p, q in ((a, b), (b, c), (c, a))]
    return all(v >= 0 for v in cross) or all(v <= 0 for v in cross)


def warnings_of(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("lodconvert: warning")]


def warned(source: Path, out: Path, *flags: str) -> list[str]:
    """The warnings of converting ``source`` into ``out``, which succeeds."""
    result = run(source, "-o", out, *flags)
    assert result.returncode == 0, result.stderr
    return warnings_of(result.stderr)


# --- CityGML ------------------------------------------------------------------------------


def test_a_parameterized_texture_is_read_with_its_orientation(tmp_path: Path) -> None:
    """Texture coordinates (0, 0) are the image's bottom left: the roof's south-west corner
    shows the bottom-left quadrant, its north-east corner the top-right one."""
    mesh = finest(city(tmp_path, texture("tex/roof.png")))
    [roof] = textured(mesh)
    assert roof.uv is not None and roof.texture is not None
    assert np.array_equal(roof_colour_at(mesh, 1, 1), QUADRANTS["bottom_left"])
    assert np.array_equal(roof_colour_at(mesh, 9, 9), QUADRANTS["top_right"])
    assert np.array_equal(roof_colour_at(mesh, 9, 1), QUADRANTS["bottom_right"])
    walls = [part for part in mesh.parts if part.texture is None]
    assert walls and all(np.array_equal(w.base_color, DEFAULT_CLASS_COLORS["wall"]) for w in walls)


def test_a_texture_is_cut_to_what_its_coordinates_cover(tmp_path: Path) -> None:
    """A roof using the image's top-right quadrant carries that quadrant (and a few texels
    around it), not the whole image, and still shows its colour."""
    mesh = finest(
        city(tmp_path, texture("tex/roof.png", coordinates="0.5 0.5 1 0.5 1 1 0.5 1 0.5 0.5"))
    )
    [roof] = textured(mesh)
    assert roof.texture is not None and roof.texture.shape[0] <= 32 + 2 * 4
    assert np.array_equal(roof_colour_at(mesh, 5, 5), QUADRANTS["top_right"])


def test_local_appearances_texture_coordinate_generation_and_materials(tmp_path: Path) -> None:
    """An appearance inside the building counts as one at the root; TexCoordGen's
    world-to-texture matrix gives the coordinates; an X3DMaterial colours its target."""
    x0, y0 = 690000, 5336000  # s = (x - x0) / 10, t = (y - y0) / 10
    matrix = f"0.1 0 0 {-x0 / 10} 0 0.1 0 {-y0 / 10} 0 0 0 1"
    generated = (
        "<app:Appearance><app:theme>rgb</app:theme><app:surfaceDataMember>"
        "<app:ParameterizedTexture><app:imageURI>tex/roof.png</app:imageURI>"
        "<app:target uri='#P_roof'><app:TexCoordGen><app:worldToTexture>"
        f"{matrix}</app:worldToTexture></app:TexCoordGen></app:target>"
        "</app:ParameterizedTexture></app:surfaceDataMember></app:Appearance>"
    )
    mesh = finest(city(tmp_path, material("0 0.5 1"), local=generated))
    assert np.array_equal(roof_colour_at(mesh, 1, 1), QUADRANTS["bottom_left"])
    assert np.array_equal(roof_colour_at(mesh, 9, 9), QUADRANTS["top_right"])
    colours = {bytes(p.base_color[:3]) for p in mesh.parts if p.texture is None}
    assert bytes([0, 128, 255]) in colours


def test_a_georeferenced_texture_lies_where_its_reference_point_and_orientation_say(
    tmp_path: Path,
) -> None:
    """64 texels over the roof's 10 m, the reference point at the centre of the top-left
    texel (the roof's north-west corner, half a texel in), rows going south."""
    texel = 10 / 64
    georeferenced = (
        "<app:Appearance><app:theme>rgb</app:theme><app:surfaceDataMember>"
        "<app:GeoreferencedTexture><app:imageURI>tex/roof.png</app:imageURI>"
        "<app:referencePoint><gml:Point><gml:pos>"
        f"{690000 + texel / 2} {5336010 - texel / 2}</gml:pos></gml:Point></app:referencePoint>"
        f"<app:orientation>{texel} 0 0 {-texel}</app:orientation>"
        "<app:target>#P_roof</app:target></app:GeoreferencedTexture></app:surfaceDataMember>"
        "</app:Appearance>"
    )
    mesh = finest(city(tmp_path, georeferenced))
    assert len(textured(mesh)) == 1
    for (x, y), quadrant in {
        (1, 1): "bottom_left",
        (9, 9): "top_right",
        (1, 9): "top_left",
    }.items():
        assert np.array_equal(roof_colour_at(mesh, x, y), QUADRANTS[quadrant])


def test_the_theme_asked_for_is_read_and_a_missing_one_is_warned_of(tmp_path: Path) -> None:
    source = city(
        tmp_path, texture("tex/roof.png", theme="summer"), material("1 0 0", "roof", "winter")
    )
    assert textured(finest(source))  # the first theme met: summer
    winter = finest(source, appearance_theme="winter")
    assert not textured(winter)
    assert any(np.array_equal(p.base_color[:3], [255, 0, 0]) for p in winter.parts)
    said = warned(source, tmp_path / "out.x3d", "--appearance-theme", "autumn")
    assert any("has no appearance theme 'autumn' (it has 'summer', 'winter')" in w for w in said)


@pytest.mark.parametrize(
    ("uri", "problem"),
    [
        ("tex/missing.png", "is not found in the input's folder"),
        ("../outside.png", "lies outside the input's folder"),
        ("/etc/passwd", "lies outside the input's folder"),
        ("http://example.com/roof.png", "a URI is not read over a network"),
        ("file:///etc/passwd", "a URI is not read over a network"),
        ("tex/link.png", "is not found in the input's folder (or is a link"),
        ("tex/garbage.png", "is not an image lodconvert can decode"),
        ("tex/huge.png", "over the limit of 4,096 (raise it with --limit image_pixels=N)"),
    ],
)
def test_an_image_that_cannot_be_used_is_warned_of_and_the_roof_keeps_its_colour(
    tmp_path: Path, uri: str, problem: str
) -> None:
    (tmp_path / "outside.png").write_bytes(b"")
    source = city(tmp_path, texture(uri))
    os.symlink(tmp_path / "tex" / "roof.png", tmp_path / "tex" / "link.png")
    (tmp_path / "tex" / "garbage.png").write_bytes(b"\x89PNG not really")
    Image.new("RGB", (65, 65)).save(tmp_path / "tex" / "huge.png")
    out = tmp_path / "out.glb"
    result = run(source, "-o", out, "--limit", "image_pixels=4096", "--report", tmp_path / "r.json")
    assert result.returncode == 0, result.stderr
    [warning] = [w for w in warnings_of(result.stderr) if "texture image" in w]
    assert f"B1: texture image {uri!r} " in warning and problem in warning
    assert "its surfaces take their material or class colour" in warning
    assert str(source) in warning
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["appearance"]["unusable_images"] == [uri]
    mesh = finest(source, limits=_limits(image_pixels=4096))
    assert not textured(mesh)
    assert np.array_equal(roof_colour_at(mesh, 5, 5), ROOF[:3])


def _limits(**values: int) -> object:
    from lodconvert.limits import Limits

    return Limits(**values)


def test_an_image_over_the_byte_limit_is_not_read(tmp_path: Path) -> None:
    source = city(tmp_path, texture("tex/roof.png"))
    said = warned(source, tmp_path / "out.x3d", "--limit", "image_bytes=100")
    assert any("larger than the limit of 100 bytes (raise it with --limit image_bytes=N)" in w
               for w in said)  # fmt: skip


def test_a_decompression_bomb_is_refused_from_its_header(tmp_path: Path) -> None:
    """A 1 KB PNG that claims 20,000² pixels is refused before a pixel is decoded."""
    source = city(tmp_path, texture("tex/roof.png"))
    bomb = io.BytesIO()
    Image.new("1", (20_000, 20_000)).save(bomb, format="PNG", optimize=True)
    assert len(bomb.getvalue()) < 100_000
    (tmp_path / "tex" / "roof.png").write_bytes(bomb.getvalue())
    said = warned(source, tmp_path / "out.x3d")
    assert any("has 20,000 × 20,000 pixels, over the limit of 67,108,864" in w for w in said)


@pytest.mark.parametrize(
    ("coordinates", "problem"),
    [
        ("0 0 1 0 1 1 0 1", "do not match their rings' points"),
        ("0 0 1 0 NaN 1 0 1 0 0", "not finite numbers"),
        ("0.5 0.5 0.5 0.5 0.5 0.5 0.5 0.5 0.5 0.5", "cover no area (a 0×0 footprint)"),
        ("0 0 0.5 0.5 1 1 0.5 0.5 0 0", "cover no area (a 0×0 footprint)"),
        ("0 0 1 0 1 1 0 1 0", "not pairs of numbers"),
    ],
)
def test_texture_coordinates_that_cannot_be_used_are_warned_of(
    tmp_path: Path, coordinates: str, problem: str
) -> None:
    source = city(tmp_path, texture("tex/roof.png", coordinates=coordinates))
    assert any(problem in w for w in warned(source, tmp_path / "out.glb"))
    assert not textured(finest(source))


def test_a_zipped_city_reads_its_images_from_the_zip_and_never_outside_it(tmp_path: Path) -> None:
    source = city(tmp_path, texture("tex/roof.png"), texture("../roof.png", "south"))
    archive = tmp_path / "city.zip"
    with zipfile.ZipFile(archive, "w") as z:
        z.write(source, "data/city.gml")
        z.write(tmp_path / "tex" / "roof.png", "data/tex/roof.png")
        z.write(tmp_path / "tex" / "roof.png", "roof.png")  # beside data/, outside its folder
    mesh = finest(archive)
    assert len(textured(mesh)) == 1
    assert np.array_equal(roof_colour_at(mesh, 9, 9), QUADRANTS["top_right"])
    result = run(archive, "-o", tmp_path / "out.x3d")
    assert any("'../roof.png' lies outside the input's folder" in w
               for w in warnings_of(result.stderr))  # fmt: skip


def test_the_plateau_building_keeps_its_texture_in_x3d_and_glb(
    tmp_path: Path, schema: etree.XMLSchema, gltf_validator: object
) -> None:
    """The real textured PLATEAU building (CityGML 2.0 and 3.0): its LoD2 is written with its
    texture, roofs and walls one surface on one cut of the atlas, and its LoD1 with a small
    texture baked from it (two texels a pixel where it switches in); the
    outputs validate."""
    for version in ("v2", "v3"):
        source = PLATEAU / f"plateau_53394517_bldg_lod012_{version}.gml"
        if not source.exists():
            pytest.skip(f"{source} is absent")
        mesh = finest(source)
        images = textured(mesh)
        [surface] = images  # roofs and walls: one image, one cut of it
        atlas = Image.open(PLATEAU / "53394517_bldg_6697_appearance/stad0158.jpg")
        assert surface.texture is not None
        assert surface.texture.shape[:2] <= atlas.size[::-1]
        glb, x3d = tmp_path / f"{version}.glb", tmp_path / f"{version}.x3d"
        for out in (glb, x3d):
            result = run(source, "-o", out, "--report", tmp_path / f"{version}.json")
            assert result.returncode == 0, result.stderr
        assert schema.validate(etree.parse(str(x3d))), schema.error_log
        assert x3d.read_text().count("<ImageTexture") == 2
        assert x3d.read_text().count("data:image/jpeg;base64,") == 2  # photographs: JPEG
        document, _ = glb_parts(glb.read_bytes())
        assert [image["mimeType"] for image in document["images"]] == ["image/jpeg"] * 2
        sides = sorted(max(image.size) for image in _glb_images(glb))
        assert sides[0] <= 256 and sides[1] >= 1024
        _assert_valid(gltf_validator(glb))  # type: ignore[operator]
        back = read_scene(glb)
        assert sum(len(textured(n.geometry)) for n in back.nodes if n.geometry is not None) == 1
        report = json.loads((tmp_path / f"{version}.json").read_text())
        assert report["appearance"] == {
            "theme": "rgbTexture",
            "themes": ["rgbTexture"],
            "images": ["53394517_bldg_6697_appearance/stad0158.jpg"],
            "unusable_images": [],
        }


def _glb_images(glb: Path) -> list[Image.Image]:
    """The images a ``.glb`` holds, in its order."""
    document, blob = glb_parts(glb.read_bytes())
    views = [document["bufferViews"][image["bufferView"]] for image in document["images"]]
    return [
        Image.open(io.BytesIO(blob[view["byteOffset"] :][: view["byteLength"]])) for view in views
    ]


def test_the_prism_takes_its_roof_colour_from_the_texture(tmp_path: Path) -> None:
    """A roof textured in one colour gives the LOD1 prism's roof that colour."""
    source = city(tmp_path, texture("tex/roof.png", coordinates="0 0 0.4 0 0.4 0.4 0 0.4 0 0"))
    from lodconvert.city.prisms import prism_colors

    roof, _ = prism_colors(finest(source))
    assert np.abs(roof[:3].astype(int) - QUADRANTS["bottom_left"]).max() <= 2


def test_a_textured_city_converts_alike_on_any_number_of_workers(tmp_path: Path) -> None:
    """Same bytes on one worker and two; a PNG texture stays lossless (PNG)."""
    source = city(tmp_path, texture("tex/roof.png"), material("0 0.5 1"))
    outputs = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}.glb"
        assert run(source, "-o", out, "--workers", workers).returncode == 0
        outputs.append(out.read_bytes())
    assert outputs[0] == outputs[1]
    document, _ = glb_parts(outputs[0])
    assert [image["mimeType"] for image in document["images"]] == ["image/png"]


# --- CityJSON ------------------------------------------------------------------------------


def test_rotterdam_keeps_its_one_shipped_texture_and_warns_of_the_73_missing(
    tmp_path: Path, gltf_validator: object
) -> None:
    """The real Rotterdam subset ships one of its 74 images: the building that uses it is
    textured, every missing image is warned of once with the first object using it."""
    if not ROTTERDAM.exists():
        pytest.skip(f"{ROTTERDAM} is absent")
    out = tmp_path / "r.glb"
    result = run(ROTTERDAM, "-o", out, "--report", tmp_path / "r.json")
    assert result.returncode == 0, result.stderr
    missing = [w for w in warnings_of(result.stderr) if "is not found in the input's folder" in w]
    assert len(missing) == 73
    assert all(str(ROTTERDAM) in w and "texture image 'appearances/0320_" in w for w in missing)
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["appearance"]["images"] == ["appearances/0320_4_15.jpg"]
    assert len(report["appearance"]["unusable_images"]) == 73
    nodes = [n for n in read_scene(ROTTERDAM).nodes if n.geometry is not None]
    assert sum(bool(textured(n.geometry)) for n in nodes) == 1
    _assert_valid(gltf_validator(out))  # type: ignore[operator]


def _cityjson(folder: Path, value: list, vertices_texture: list) -> Path:
    """A one-building CityJSON 2.0 file whose roof has the texture ``value``."""
    quadrants().save(folder / "roof.png")
    box = [
        [0, 0, 0],
        [10, 0, 0],
        [10, 10, 0],
        [0, 10, 0],
        [0, 0, 6],
        [10, 0, 6],
        [10, 10, 6],
        [0, 10, 6],
    ]
    surfaces = [[[4, 5, 6, 7]], [[0, 1, 5, 4]], [[1, 2, 6, 5]], [[2, 3, 7, 6]], [[3, 0, 4, 7]]]
    document = {
        "type": "CityJSON",
        "version": "2.0",
        "transform": {"scale": [1, 1, 1], "translate": [85000, 447000, 0]},
        "metadata": {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/7415"},
        "CityObjects": {
            "B1": {
                "type": "Building",
                "geometry": [
                    {
                        "type": "MultiSurface",
                        "lod": "2",
                        "boundaries": surfaces,
                        "semantics": {
                            "surfaces": [{"type": "RoofSurface"}, {"type": "WallSurface"}],
                            "values": [0, 1, 1, 1, 1],
                        },
                        "texture": {
                            "rgb": {"values": [value, [[None]], [[None]], [[None]], [[None]]]}
                        },
                    }
                ],
            }
        },
        "vertices": box,
        "appearance": {
            "textures": [{"type": "PNG", "image": "roof.png"}],
            "vertices-texture": vertices_texture,
        },
    }
    path = folder / "city.json"
    path.write_text(json.dumps(document))
    return path


UV = [[0, 0], [1, 0], [1, 1], [0, 1]]


def test_a_cityjson_texture_is_read_with_its_orientation(tmp_path: Path) -> None:
    mesh = finest(_cityjson(tmp_path, [[0, 0, 1, 2, 3]], UV))
    [roof] = textured(mesh)
    centre = roof.vertices.mean(axis=0)
    inset = np.array([1.0, 1.0, 0.0])
    corner = roof.vertices.min(axis=0) + inset
    corner[2] = centre[2]
    far = roof.vertices.max(axis=0) - inset
    for point, colour in ((corner, "bottom_left"), (far, "top_right")):
        face = next(
            f for f in range(len(roof.faces)) if _inside(roof.vertices[roof.faces[f]], point)
        )
        assert np.array_equal(
            roof.colors_at(np.array([face]), point[None])[0, :3], QUADRANTS[colour]
        )


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        ([[5, 0, 1, 2, 3]], "name texture 5, which does not exist"),
        ([[0, 0, 1, 2, 9]], "refer to texture vertices that do not exist"),
        ([[0, 0, 1, 2]], "have texture values that do not match their rings"),
        ([[0, 0, 0, 0, 0]], "cover no area (a 0×0 footprint)"),
        ([[True, 0, 1, 2, 3]], "a texture index that is not a whole number"),
    ],
)
def test_cityjson_texture_values_that_cannot_be_used_are_warned_of(
    tmp_path: Path, value: list, problem: str
) -> None:
    source = _cityjson(tmp_path, value, UV)
    [warning] = [w for w in warned(source, tmp_path / "out.x3d") if problem in w]
    assert f"{source}: B1: 1 surface(s)" in warning
    assert not textured(finest(source))


# --- 3D Tiles: atlases ----------------------------------------------------------------------


def test_images_pack_into_bounded_pages_and_map_their_coordinates() -> None:
    """Every image lands whole in a page of at most the atlas size (a larger one halved), no
    two overlap, and each image's corners map onto its own texels."""
    rng = np.random.default_rng(7)
    sizes = [(40, 70), (100, 30), (64, 64), (10, 200), (300, 20), (90, 90), (700, 100)]
    images = [rng.integers(0, 255, (h, w, 4), dtype=np.uint8) for h, w in sizes]
    for image in images:
        image[..., 3] = 255
    atlas = packed(images, 256)
    assert len(atlas.pages) >= 2 and all(max(p.shape[:2]) <= 256 for p in atlas.pages)
    again = packed(images, 256)
    assert all(np.array_equal(a, b) for a, b in zip(atlas.pages, again.pages, strict=True))
    for k, image in enumerate(images):
        page = atlas.pages[atlas.page_of[k]]
        h, w = page.shape[:2]
        fitted = image if max(image.shape[:2]) <= 256 - 2 * PADDING else None
        centre = np.array([[0.5, 0.5]])
        for corner in ((0.01, 0.01), (0.99, 0.99), (0.01, 0.99)):
            u, v = atlas.coordinates(k, np.array([corner]))[0]
            x, y = int(u * w), int((1 - v) * h)
            if fitted is not None:
                row = int((1 - corner[1]) * image.shape[0])
                col = int(corner[0] * image.shape[1])
                assert np.array_equal(page[y, x], image[row, col])
        assert 0 < atlas.coordinates(k, centre)[0].min() < 1
    big = atlas.pages[atlas.page_of[6]]  # 700 × 100, halved to 350 × 50, then to 175 × 25
    assert max(big.shape[:2]) <= 256


def test_a_tileset_packs_textures_into_atlases_and_passes_the_official_validator(
    tmp_path: Path,
) -> None:
    """The PLATEAU building to 3D Tiles: its finest tile draws its textured surfaces with the
    texture in an atlas page (at most ``--atlas-size`` a side), its feature ids and metadata
    as before; the coarser tiles carry the texture's colours in their vertices."""
    source = PLATEAU / "plateau_53394517_bldg_lod012_v2.gml"
    if not source.exists():
        pytest.skip(f"{source} is absent")
    for size in (4096, 256):
        out = tmp_path / str(size) / "tileset.json"
        result = run(source, "-o", out, "--atlas-size", str(size), "-q")
        assert result.returncode == 0, result.stderr
        [finest] = (out.parent / "tiles").glob("*_finest.glb")
        document, blob = glb_parts(finest.read_bytes())
        textured = [
            p for p in document["meshes"][0]["primitives"] if "TEXCOORD_0" in p["attributes"]
        ]
        assert len(textured) == 1 and "_FEATURE_ID_0" in textured[0]["attributes"]
        [image] = document["images"]
        view = document["bufferViews"][image["bufferView"]]
        data = blob[view["byteOffset"] : view["byteOffset"] + view["byteLength"]]
        page = Image.open(io.BytesIO(data))
        assert max(page.size) <= size and image["mimeType"] == "image/jpeg"
        assert document["materials"][textured[0]["material"]]["alphaMode"] == "OPAQUE"
    report = official(out, tmp_path / "report.json")
    assert report["numErrors"] == 0 and report["numWarnings"] == 0, report["issues"]


@pytest.mark.parametrize("far", [(), ("--hlod", "250,1000", "--hlod-kind", "blocks")])
def test_a_textured_district_makes_the_same_tileset_on_one_worker_and_on_two(
    tmp_path: Path, far: tuple[str, ...]
) -> None:
    """Copies of the PLATEAU building, each with its own appearance of the one image: the
    image is packed into each tile's atlas once, however many buildings show it and whichever
    process baked them, so that two workers write the tileset one process writes. The LOD1
    tiles, and block proxies' far tiles, carry textures of their own baked from it, a few
    hundred texels a side, not the photograph."""
    if not (PLATEAU / "53394517_bldg_6697_appearance").exists():
        pytest.skip("the PLATEAU texture is absent")
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from textured_district import district

    source = district(9, tmp_path, textured=True)
    folders = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}" / "tileset.json"
        result = run(source, "-o", out, "--workers", workers, "-q", *far)
        assert result.returncode == 0, result.stderr
        folders.append(out.parent)
    files = sorted(p.relative_to(folders[0]) for p in folders[0].rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(folders[1]) for p in folders[1].rglob("*") if p.is_file())
    assert all((folders[0] / f).read_bytes() == (folders[1] / f).read_bytes() for f in files)
    for tile in (folders[1] / "tiles").glob("*_finest.glb"):
        document, _ = glb_parts(tile.read_bytes())
        assert len(document.get("images", [])) <= 1, tile.name
    coarser = [t for t in (folders[1] / "tiles").glob("*.glb") if "_finest" not in t.name]
    if far:
        assert any("_coarsest" not in t.name for t in coarser)  # the cells' far tiles
    for tile in coarser:
        if far or "_coarsest" in tile.name:  # a far mesh of the default kind: vertex colours
            [image] = _glb_images(tile)
            assert max(image.size) <= 512, tile.name


def test_a_textured_roof_shows_its_texture_in_the_tile_and_its_colour_far_away(
    tmp_path: Path,
) -> None:
    """The roof's texels reach the atlas at its coordinates (within JPEG's error); the prism
    of the coarser tile takes the texture's mean colour, not the material's white."""
    source = city(tmp_path, texture("tex/roof.png", coordinates="0 0 0.4 0 0.4 0.4 0 0.4 0 0"))
    out = tmp_path / "out" / "tileset.json"
    result = run(source, "-o", out, "--workers", "1", "-q")
    assert result.returncode == 0, result.stderr
    [finest] = (out.parent / "tiles").glob("*_finest.glb")
    document, blob = glb_parts(finest.read_bytes())
    [image] = document["images"]
    view = document["bufferViews"][image["bufferView"]]
    page = np.asarray(Image.open(io.BytesIO(blob[view["byteOffset"] :][: view["byteLength"]])))
    [primitive] = [
        p for p in document["meshes"][0]["primitives"] if "TEXCOORD_0" in p["attributes"]
    ]
    uv = normalized(accessor_values(document, blob, primitive["attributes"]["TEXCOORD_0"]))
    used = accessor_values(document, blob, primitive["indices"])
    centre = uv[used].mean(axis=0)  # glTF: origin at the top left
    texel = page[int(centre[1] * page.shape[0]), int(centre[0] * page.shape[1]), :3]
    assert np.abs(texel.astype(int) - QUADRANTS["bottom_left"]).max() <= 12
    colours = []
    for tile in (out.parent / "tiles").glob("*.glb"):
        if "finest" not in tile.name:
            for node in read_scene(tile).nodes:
                colours += [
                    n.geometry.baked_colors() for n in node.walk() if n.geometry is not None
                ]
    found = np.concatenate(colours)[:, :3].astype(int)
    assert (np.abs(found - QUADRANTS["bottom_left"]).max(axis=1) <= 3).any()
    assert not (found == 255).all(axis=1).any()


def test_a_cityjsonseq_feature_wears_its_own_textures(tmp_path: Path) -> None:
    """A CityJSONSeq feature's own ``appearance`` (its textures and texture vertices) is read
    against the image beside the file, in one process and on two workers alike."""
    document = json.loads(_cityjson(tmp_path, [[0, 0, 1, 2, 3]], UV).read_text())
    header = {k: document[k] for k in ("type", "version", "transform", "metadata")}
    header |= {"CityObjects": {}, "vertices": []}
    feature = {
        "type": "CityJSONFeature",
        "id": "B1",
        "CityObjects": document["CityObjects"],
        "vertices": document["vertices"],
        "appearance": document["appearance"],
    }
    source = tmp_path / "city.jsonl"
    source.write_text(json.dumps(header) + "\n" + json.dumps(feature) + "\n")
    [roof] = textured(finest(source))
    assert roof.texture is not None
    outputs = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}.glb"
        assert not warned(source, out, "--workers", workers)
        outputs.append(out.read_bytes())
    assert outputs[0] == outputs[1]


@pytest.mark.parametrize(
    ("first", "second", "expected"),
    [  # Sharma, Wu and Dalal's test data, pairs 1, 7, 13, 17 and 25
        ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
        ((50.0, 2.5, 0.0), (50.0, 0.0, -2.5), 4.3065),
        ((50.0, -1.0, 2.0), (50.0, 0.0, 0.0), 2.3669),
        ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
        ((22.7233, 20.0904, -46.6940), (23.0331, 14.9730, -42.5619), 2.0373),
    ],
)
def test_ciede2000_matches_the_published_test_data(
    first: tuple[float, ...], second: tuple[float, ...], expected: float
) -> None:
    assert float(ciede2000(np.array(first), np.array(second))) == pytest.approx(expected, abs=1e-4)


def test_a_far_level_takes_a_texture_baked_from_what_it_stands_for(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A textured roof of four squares, one quadrant of the image each, under a flat top a
    little lower (two triangles) and a wall: the top takes a texture of its own in which each
    quarter shows the quadrant above it, in its colour, not the roof's mean; the wall, which
    no textured face faces the way of, keeps its colour; the texture is a few texels a pixel,
    not the source's, and bounded however near the level is seen; over an untextured source
    the level stays as it is."""
    from lodconvert.bake.far_textures import in_source_textures

    image = np.asarray(quadrants(256).convert("RGBA"))
    corners = [(x, y) for y in (0.0, 5.0) for x in (0.0, 5.0)]
    vertices = np.array(
        [(x + dx, y + dy, 6.0) for x, y in corners for dx, dy in ((0, 0), (5, 0), (5, 5), (0, 5))]
    )
    faces = np.array([(k, k + 1, k + 2) for k in range(0, 16, 4)]
                     + [(k, k + 2, k + 3) for k in range(0, 16, 4)])  # fmt: skip
    uv = np.array(
        [(u + du, v + dv) for v in (0.0, 0.5) for u in (0.0, 0.5)
         for du, dv in ((0, 0), (0.5, 0), (0.5, 0.5), (0, 0.5))]
    )  # fmt: skip
    roof = Mesh([Surface(vertices, faces, uv=uv, texture=image, photographic=True)])
    top = np.array([[0.0, 0.0, 5.5], [10.0, 0.0, 5.5], [10.0, 10.0, 5.5], [0.0, 10.0, 5.5]])
    wall = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 0.0, 5.5]])
    points = np.concatenate([top, wall])
    level = Mesh(
        [
            Surface(
                points,
                np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]]),
                vertex_colors=np.full((7, 4), 77, dtype=np.uint8),
            )
        ]
    )
    baked = in_source_textures(level, roof, pixel=2.5)
    (part,) = baked.parts
    assert part.texture is not None and part.uv is not None and part.photographic
    assert max(part.texture.shape[:2]) <= 64  # 1.25 m texels: 8 a side for the top
    at = {"bottom_left": (2.5, 2.5), "bottom_right": (7.5, 2.5), "top_left": (2.5, 7.5),
          "top_right": (7.5, 7.5)}  # fmt: skip
    for quadrant, (x, y) in at.items():
        point = np.array([[x, y, 5.5]])
        face = np.array([0 if x > y else 1])
        colour = baked.colors_at(face, point)[0, :3].astype(int)
        assert np.abs(colour - QUADRANTS[quadrant]).max() <= 2, quadrant
    wall_face = np.flatnonzero(baked.face_normals(np.arange(3))[:, 1] < -0.5)
    assert (baked.face_colors(wall_face)[0, :3] == 77).all()
    bounds = importlib.import_module("lodconvert.bake.far_textures")
    monkeypatch.setattr(bounds, "MOST_TEXELS", 24 * 24)  # 2,048² in a run
    monkeypatch.setattr(bounds, "MOST_SAMPLES", 24 * 24 * 4)
    near = in_source_textures(level, roof, pixel=0.6)  # 34 texels a side, unbounded
    (part,) = near.parts
    assert part.texture is not None and part.texture.shape[0] * part.texture.shape[1] <= 32 * 64
    for quadrant, (x, y) in at.items():
        face = np.array([0 if x > y else 1])
        colour = near.colors_at(face, np.array([[x, y, 5.5]]))[0, :3].astype(int)
        assert np.abs(colour - QUADRANTS[quadrant]).max() <= 2, quadrant
    plain = Mesh([Surface(vertices, faces, base_color=np.array([9, 9, 9, 255], np.uint8))])
    assert in_source_textures(level, plain, pixel=2.5) is level


def test_colours_at_known_barycentric_coordinates_are_those_found_by_projecting() -> None:
    """A mesh of a textured part and a vertex-coloured one gives, at points given with their
    barycentric coordinates, the colours it finds from the points alone."""
    image = np.asarray(quadrants().convert("RGBA"))
    square = np.array([[0.0, 0.0, 0.0], [8.0, 0.0, 0.0], [8.0, 8.0, 0.0], [0.0, 8.0, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    textured = Surface(square, faces, uv=square[:, :2] / 8.0, texture=image)
    corners = np.array([[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [9, 9, 9, 255]])
    painted = Surface(square + np.array([0.0, 0.0, 1.0]), faces, corners.astype(np.uint8))
    mesh = Mesh([textured, painted])
    rng = np.random.default_rng(3)
    face_ids = rng.integers(0, 4, 200)
    weights = rng.dirichlet((1.0, 1.0, 1.0), 200)
    points = np.einsum("kj,kjd->kd", weights, mesh.triangles[face_ids])
    found = mesh.colors_at(face_ids, points)
    assert len(np.unique(found, axis=0)) > 8  # quadrants and blends, not one colour
    assert np.array_equal(mesh.colors_at(face_ids, points, weights), found)


@pytest.mark.parametrize(("batch", "tested"), [(1 << 16, 1 << 24), (64, 1 << 24), (64, 0)])
def test_the_faces_a_chart_may_see_are_every_box_it_overlaps(
    batch: int, tested: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Pairing source faces with far-level charts finds every pair of boxes that overlap and
    face the same way, and only those, in order, whatever their sizes (a street-long face
    among small ones): tested pair by pair where they are few, through the tree where they
    are many."""
    from lodconvert.bake import far_textures

    monkeypatch.setattr(far_textures, "BOX_BATCH", batch)
    monkeypatch.setattr(far_textures, "TESTED_PAIRS", tested)
    rng = np.random.default_rng(7)
    low = rng.uniform(0, 100, (400, 3))
    high = low + rng.uniform(0, 5, (400, 3))
    high[0] = low[0] + (90.0, 0.5, 10.0)
    near = rng.uniform(0, 100, (60, 3))
    far = near + rng.uniform(0, 20, (60, 3))
    normal, towards = (rng.normal(size=(n, 3)) for n in (400, 60))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    first = far_textures._Boxes(low, high, normal)
    i, j = far_textures._overlapping(first, far_textures._Boxes(near, far, towards))
    every = ((low[:, None] <= far[None]) & (high[:, None] >= near[None])).all(axis=2)
    facing = np.einsum("ik,jk->ij", normal, towards) > far_textures.FACING
    expected = np.nonzero(every & facing)
    assert len(expected[0]) > 10 and len(np.nonzero(every)[0]) > len(expected[0])
    assert i.tolist() == expected[0].tolist() and j.tolist() == expected[1].tolist()


def test_each_sample_of_a_chart_shows_the_outermost_face_within_reach() -> None:
    """The compiled bake draws each pair of a source face and a chart into the chart's
    samples: at each sample, of the faces over it, the outermost no more than ``front`` in
    front of the chart (a face beyond is left out, the first of two at one height kept), with
    its texel and barycentric coordinates; a sample no face covers is not listed."""
    from lodconvert.bake.texels import outermost

    triangles = np.array(
        [
            [(-1.0, -1.0, 0.5), (10.0, -1.0, 0.5), (-1.0, 10.0, 0.5)],  # the whole chart, low
            [(0.0, 0.0, 1.0), (2.0, 0.0, 1.0), (0.0, 2.0, 1.0)],  # a corner, higher
            [(-1.0, -1.0, 3.0), (10.0, -1.0, 3.0), (-1.0, 10.0, 3.0)],  # beyond reach
            [(0.0, 0.0, 1.0), (2.0, 0.0, 1.0), (0.0, 2.0, 1.0)],  # the corner again
            [(10.0, 10.0, 1.0), (11.0, 10.0, 1.0), (10.0, 11.0, 1.0)],  # beside the chart
        ]
    )
    frame = np.array([[(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]])
    layout = np.array([[0, 0, 2, 2]])  # 2 × 2 texels from texel and sample 0
    faces = np.arange(len(triangles))
    texel, which, weights = outermost(
        triangles, faces, np.zeros_like(faces), frame, np.array([1.0]), layout, 2, 2.0
    )
    centres = [(x + 0.5, y + 0.5) for y in range(4) for x in range(4)]  # sample by sample
    assert which.tolist() == [1 if x + y <= 2.0 else 0 for x, y in centres]
    assert texel.tolist() == [(y // 2) * 2 + x // 2 for y in range(4) for x in range(4)]
    corner = which == 1
    points = np.array(centres)[corner]
    assert np.allclose(weights[corner], points / 2.0)  # corners 2 and 3 lie at x = 2, y = 2
    low = np.array(centres)[~corner] + 1.0
    assert np.allclose(weights[~corner], low / 11.0)
    nothing = outermost(triangles[4:], faces[:1], faces[:1] * 0, frame, np.ones(1), layout, 2, 2.0)
    assert all(len(part) == 0 for part in nothing)


def test_a_coarser_source_lod_takes_the_textures_colours(tmp_path: Path) -> None:
    """A source LoD1 without an appearance of its own (PLATEAU's lod1Solid) is drawn in a
    texture baked from the finest LoD's, roofs and walls apart, not in class colours (here
    the roof's one textured face stands for the whole of it, in one quadrant's colour)."""
    from lodconvert.city.prisms import in_texture_colours, prism_colors

    source = city(tmp_path, texture("tex/roof.png", coordinates="0 0 0.4 0 0.4 0.4 0 0.4 0 0"))
    finest_mesh = finest(source)
    plain = Mesh([Surface(p.vertices, p.faces, base_color=p.base_color) for p in finest_mesh.parts])
    coloured = in_texture_colours(plain, finest_mesh, pixel=1.0)
    _, wall = prism_colors(finest_mesh)
    [part] = coloured.parts
    assert part.texture is not None
    faces = np.arange(coloured.face_count)
    up = coloured.face_normals(faces)[:, 2] > 0.5
    colours = coloured.face_colors(faces)[:, :3].astype(int)
    assert np.abs(colours[up] - QUADRANTS["bottom_left"]).max() <= 2
    assert np.abs(colours[~up] - wall[:3]).max() <= 1
    assert in_texture_colours(plain, plain, pixel=1.0) is plain


@pytest.fixture(scope="module")
def albedo() -> Iterator[object]:
    from lodconvert.analysis.albedo import AlbedoRenderer

    yield from gl_renderer(AlbedoRenderer)


@pytest.mark.gl
def test_the_colour_renderer_draws_a_roof_in_its_texture_and_a_flat_one_apart(
    tmp_path: Path, albedo: object
) -> None:
    """The roof drawn from above shows the quadrants where they lie (from near) and their
    mean (from afar, mipmapped); a roof in one flat colour is that colour's ΔE away, and the
    quadrants lie their spread from their mean."""
    from lodconvert.analysis.albedo import ROOF as ROOF_KIND
    from lodconvert.analysis.albedo import class_delta_e_rendered
    from lodconvert.views import towards_camera

    mesh = finest(city(tmp_path, texture("tex/roof.png")))
    centre = (mesh.bounds[0] + mesh.bounds[1]) / 2
    [near] = albedo.pictures(mesh, centre, 50.0, towards_camera(0, 89.9)[None], 256)  # type: ignore[attr-defined]
    roof = near.kind == ROOF_KIND
    assert roof.sum() > 1000
    colours = {tuple(c) for c in near.rgb[roof].reshape(-1, 3)[::50]}
    assert {tuple(QUADRANTS[q]) for q in QUADRANTS} <= colours
    [far] = albedo.pictures(mesh, centre, 2_000.0, towards_camera(0, 89.9)[None], 16)  # type: ignore[attr-defined]
    mean = np.mean([QUADRANTS[q] for q in QUADRANTS], axis=0)
    assert np.abs(far.rgb[far.kind == ROOF_KIND].mean(axis=0) - mean).max() < 12
    flat = Mesh(
        [
            Surface(
                p.vertices,
                p.faces,
                base_color=ROOF.copy() if p.texture is not None else p.base_color,
            )
            for p in mesh.parts
        ]
    )  # the roof in its class colour, the walls as they are
    oblique = towards_camera(45, 30)[None]
    for supersample in (1, 8):
        errors = class_delta_e_rendered(albedo, mesh, flat, 50.0, oblique, supersample)  # type: ignore[arg-type]
        assert errors["roof"] > 20 and errors["wall"] == pytest.approx(0.0, abs=0.5)
        # one geometry: every pixel shows the same kind in both
        assert errors["roof_same"] == errors["roof"] and errors["wall_same"] == errors["wall"]
        # four quadrants lie far from their mean, though nearer than from the class colour;
        # walls in one colour lie at it
        assert 10 < errors["roof_spread"] < errors["roof"]
        assert errors["wall_spread"] == pytest.approx(0.0, abs=0.5)


def test_a_supersampled_pixel_is_the_mean_of_the_pixels_drawn_under_it() -> None:
    """Each compared pixel of a supersampled picture is the mean, in linear light, of the
    drawn pixels under it that show something (the background adds no black) and of their
    most frequent kind; one under which nothing shows shows nothing."""
    from lodconvert.analysis.albedo import ROOF as ROOF_KIND
    from lodconvert.analysis.albedo import WALL, _downsampled
    from lodconvert.colors import linear_rgba, srgb_rgba

    drawn = np.zeros((4, 4, 4), dtype=np.uint8)  # alpha: the face kind, 0 where nothing
    drawn[0, 0], drawn[0, 1], drawn[1, 0] = (255, 0, 0, ROOF_KIND), (0, 0, 255, ROOF_KIND), (
        0, 0, 255, WALL)  # fmt: skip
    drawn[2:, 2:] = (40, 80, 120, WALL)
    picture = _downsampled(drawn, 2)
    under = np.array([[255, 0, 0, 255], [0, 0, 255, 255], [0, 0, 255, 255]], dtype=np.uint8)
    expected = srgb_rgba(linear_rgba(under).mean(axis=0))[:3]
    assert (picture.rgb[0, 0] == expected).all() and picture.kind[0, 0] == ROOF_KIND
    assert (picture.rgb[1, 1] == (40, 80, 120)).all() and picture.kind[1, 1] == WALL
    assert picture.kind[0, 1] == 0 and picture.kind[1, 0] == 0


def test_appearances_are_found_across_the_chunks_a_document_is_read_in(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The scan for appearances reads a document a chunk at a time (a memory map would make
    every page of a 12 GB city resident) and finds an ``appearanceMember`` whose tags straddle
    two chunks, wherever the boundary falls."""
    from lodconvert.io.citygml import appearance
    from lodconvert.limits import DEFAULT_LIMITS

    monkeypatch.setattr(appearance, "_SCAN_BYTES", 64)
    path = tmp_path / "city.gml"
    for pad in range(70):
        path.write_bytes(b"x" * pad + b"<app:appearanceMember>" + b" " * 30 + b"<app:Appearance>")
        assert appearance._marks(path, DEFAULT_LIMITS) == {b"Appearance", b"appearanceMember"}
    path.write_bytes(b"x" * 60 + b"<app:Appearance>" + b"x" * 200)
    assert appearance._marks(path, DEFAULT_LIMITS) == {b"Appearance"}
    path.write_bytes(b"x" * 500)
    assert appearance._marks(path, DEFAULT_LIMITS) == set()


TRICKY_DOCUMENT = (
    b'<?xml version="1.0" encoding="UTF-8"?>\n<?style href="a?b"?>'
    b'<core:CityModel xmlns:core="urn:core" xmlns:app="urn:app" xmlns="urn:plain">'
    b"<!-- <app:appearanceMember><app:Appearance><app:theme>comment</app:theme>"
    b"</app:Appearance></app:appearanceMember> -->"
    b'<core:cityObjectMember><b note="appearanceMember">appearanceMember <![CDATA['
    b"<app:appearanceMember><app:Appearance><app:theme>cdata</app:theme></app:Appearance>"
    b"</app:appearanceMember>]]></b><appearanceMembers/></core:cityObjectMember>"
    b'<app:appearanceMember  a=">"><app:Appearance><app:theme>one</app:theme>'
    b"<!-- </app:appearanceMember> --></app:Appearance></app:appearanceMember >"
    b'<app:appearanceMember xlink:href="#x" xmlns:xlink="urn:xlink"/>'
    b"<core:cityObjectMember><x/></core:cityObjectMember>"
    b"<appearanceMember><app:Appearance><app:theme>two</app:theme></app:Appearance>"
    b"</appearanceMember>"
    b"<core:appearanceMember><app:Appearance><app:theme>three</app:theme></app:Appearance>"
    b"</core:appearanceMember></core:CityModel>"
)
"""A city whose appearances at the root hide among look-alikes: the name in a comment, in a
CDATA section, in text, in an attribute and in a longer name; a ``>`` in an attribute; an end
tag in a comment; a member by reference; members in the default namespace and another prefix."""


@pytest.mark.parametrize("chunk", [7, 64, 1 << 16])
def test_the_appearances_at_the_root_are_picked_from_the_bytes_alone(
    tmp_path: Path, chunk: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Only the root's ``appearanceMember`` elements are parsed for appearances, picked from
    the document's bytes: the same themes, in order, as parsing the whole document finds,
    whatever the chunks it is read in; a document in UTF-16 is parsed whole, to the same."""
    from lodconvert.io.citygml import appearance, member_bytes
    from lodconvert.io.citygml.source import first_look, open_document
    from lodconvert.limits import DEFAULT_LIMITS

    monkeypatch.setattr(member_bytes, "CHUNK", chunk)
    expected = ["one", "two", "three"]
    whole = etree.fromstring(TRICKY_DOCUMENT)
    assert [t.text for t in whole.iterfind("*/{urn:app}Appearance/{urn:app}theme")] == expected
    for name, data, picked in (
        ("utf8.gml", TRICKY_DOCUMENT, True),
        ("utf8-bom.gml", b"\xef\xbb\xbf" + TRICKY_DOCUMENT, True),
        (
            "utf16.gml",
            TRICKY_DOCUMENT.replace(b"UTF-8", b"UTF-16").decode().encode("utf-16"),
            False,
        ),
    ):
        path = tmp_path / name
        path.write_bytes(data)
        stream = open_document(path, DEFAULT_LIMITS)
        replay, root = first_look(stream, DEFAULT_LIMITS, str(path))
        assert (member_bytes.appearance_members(replay, replay.head, root) is not None) == picked
        stream.close()
        found = appearance.Appearances()
        stream = open_document(path, DEFAULT_LIMITS)
        appearance.read_global(stream, found, DEFAULT_LIMITS, str(path))
        stream.close()
        assert found.themes == expected, name


@pytest.mark.parametrize("chunk", [7, 1 << 16])
def test_the_city_objects_are_read_without_the_appearances_at_the_root(
    chunk: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """What the objects are read from once the appearances are: the document without its
    root's ``appearanceMember`` elements (so that they are neither parsed again nor held),
    everything else as it was, its line breaks where they were."""
    from lodconvert.io.citygml import member_bytes

    monkeypatch.setattr(member_bytes, "CHUNK", chunk)
    document = TRICKY_DOCUMENT.replace(b"><", b">\n<")
    stream = member_bytes.without_appearance_members(io.BytesIO(document), document[:64])
    assert stream is not None
    kept = b"".join(iter(lambda: stream.read(), b""))
    assert kept.count(b"\n") == document.count(b"\n")
    root = etree.fromstring(kept)
    names = [etree.QName(child).localname for child in root.iterchildren(etree.Element)]
    assert names == ["cityObjectMember"] * 2
    assert b"<app:theme>cdata</app:theme>" in kept and b"<app:theme>one" not in kept
    assert (
        member_bytes.without_appearance_members(io.BytesIO(b""), "\ufeff<".encode("utf-16")) is None
    )


def test_a_broken_appearance_at_the_root_is_told_at_its_line_in_the_document(
    tmp_path: Path,
) -> None:
    """The members picked from the bytes keep the document's line breaks before them: a
    broken tag in one is reported at its own line."""
    from lodconvert.io.citygml import appearance
    from lodconvert.io.citygml.source import open_document
    from lodconvert.limits import DEFAULT_LIMITS

    broken = TRICKY_DOCUMENT.replace(b"<app:theme>two</app:theme>", b"\n\n<app:theme>two</x>")
    path = tmp_path / "city.gml"
    path.write_bytes(broken.replace(b"<core:cityObjectMember>", b"\n<core:cityObjectMember>"))
    stream = open_document(path, DEFAULT_LIMITS)
    with pytest.raises(etree.XMLSyntaxError) as error:
        appearance.read_global(stream, appearance.Appearances(), DEFAULT_LIMITS, str(path))
    stream.close()
    assert error.value.lineno == 6


@pytest.mark.parametrize(
    ("output", "size", "message"),
    [
        ("out/tileset.json", "100", "--atlas-size must be a power of two from 64 to 16384 texels"),
        ("out/tileset.json", "32768", "--atlas-size must be a power of two from 64 to 16384"),
        ("out.glb", "256", "--atlas-size is for 3D Tiles; write DIR/tileset.json"),
    ],
)
def test_a_wrong_atlas_size_is_a_usage_error_that_writes_nothing(
    tmp_path: Path, output: str, size: str, message: str
) -> None:
    source = city(tmp_path, texture("tex/roof.png"))
    result = run(source, "-o", tmp_path / output, "--atlas-size", size)
    assert result.returncode == 2 and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists() and not (tmp_path / "out.glb").exists()


def _webp_textures(document: dict, blob: bytes) -> list[tuple[Image.Image, Image.Image]]:
    """Each texture's fallback image and its ``EXT_texture_webp`` copy, decoded."""
    views = document["bufferViews"]

    def image(index: int) -> Image.Image:
        view = views[document["images"][index]["bufferView"]]
        data = blob[view["byteOffset"] :][: view["byteLength"]]
        return Image.open(io.BytesIO(data))

    return [
        (image(t["source"]), image(t["extensions"]["EXT_texture_webp"]["source"]))
        for t in document["textures"]
    ]


def test_webp_copies_of_textures_pass_the_validators_and_hold_the_same_texels(
    tmp_path: Path, gltf_validator
) -> None:
    """``--texture-format webp``: every texture of a ``.glb`` and of a tileset's atlas pages
    also comes as WebP (``EXT_texture_webp``, used, not required: the PNG stays), lossless for
    a PNG source (the same texels), as both validators accept; the same run twice writes the
    same bytes."""
    source = city(tmp_path, texture("tex/roof.png"))
    glb, again = tmp_path / "roof.glb", tmp_path / "again.glb"
    tileset = tmp_path / "tiles" / "tileset.json"
    for out in (glb, again, tileset):
        result = run(source, "-o", out, "--texture-format", "webp", "-q")
        assert result.returncode == 0, result.stderr
    assert glb.read_bytes() == again.read_bytes()
    _assert_valid(gltf_validator(glb))
    report = official(tileset, tmp_path / "report.json")
    assert report["numErrors"] == 0 and report["numWarnings"] == 0, report["issues"]
    pages = [glb, *(tileset.parent / "tiles").glob("*_finest.glb")]
    for path in pages:
        document, blob = glb_parts(path.read_bytes())
        assert "EXT_texture_webp" in document["extensionsUsed"]
        assert "EXT_texture_webp" not in document.get("extensionsRequired", [])
        pairs = _webp_textures(document, blob)
        assert pairs, path.name
        for fallback, webp in pairs:
            assert fallback.format == "PNG" and webp.format == "WEBP"
            texels = (np.asarray(image.convert("RGBA")) for image in (fallback, webp))
            assert np.array_equal(*texels)


KTX2_WARNINGS = {"VALUE_NOT_IN_LIST", "IMAGE_UNRECOGNIZED_FORMAT"}
"""What glTF-Validator (2.0.0-dev.3.10, also inside the 3D Tiles validator) says of each KTX2
image: it does not know ``KHR_texture_basisu`` (KhronosGroup/glTF-Validator#177), so it
lists ``image/ktx2`` as a MIME type not in the core list and the bytes as no format it reads."""


def _ktx2_header(data: bytes) -> dict[str, int]:
    """The fields of a KTX2 file's header and of its data format descriptor that
    ``KHR_texture_basisu`` constrains."""
    assert data[:12] == b"\xabKTX 20\xbb\r\n\x1a\n"
    names = ("vk_format", "type_size", "width", "height", "depth", "layers", "faces", "levels")
    fields = dict(zip(names, np.frombuffer(data, "<u4", 8, 12).tolist(), strict=True))
    fields["scheme"] = int(np.frombuffer(data, "<u4", 1, 44)[0])
    dfd = int(np.frombuffer(data, "<u4", 1, 48)[0])
    model, primaries, transfer, flags = data[dfd + 12 : dfd + 16]
    return {**fields, "model": model, "primaries": primaries, "transfer": transfer, "flags": flags}


def _assert_ktx2_copies(path: Path) -> int:
    """Every texture of the GLB at ``path`` has a ``KHR_texture_basisu`` copy (used, not
    required: its PNG or JPEG stays) as the extension asks for a base colour: ETC1S with
    BasisLZ, sRGB and BT.709, not premultiplied, 2D, sides of multiples of 4 within a block of
    its fallback's, every mipmap level; how many."""
    document, blob = glb_parts(path.read_bytes())
    assert "KHR_texture_basisu" in document["extensionsUsed"]
    assert "KHR_texture_basisu" not in document.get("extensionsRequired", [])
    views = document["bufferViews"]

    def data(index: int) -> bytes:
        view = views[document["images"][index]["bufferView"]]
        return blob[view.get("byteOffset", 0) :][: view["byteLength"]]

    for texture in document["textures"]:
        fallback = Image.open(io.BytesIO(data(texture["source"])))
        assert fallback.format in ("PNG", "JPEG")
        copy = texture["extensions"]["KHR_texture_basisu"]["source"]
        assert document["images"][copy]["mimeType"] == "image/ktx2"
        header = _ktx2_header(data(copy))
        assert (header["vk_format"], header["scheme"], header["model"]) == (0, 1, 163), header
        assert (header["primaries"], header["transfer"], header["flags"] & 1) == (1, 2, 0)
        assert (header["depth"], header["layers"], header["faces"]) == (0, 0, 1), header
        width, height = header["width"], header["height"]
        assert width % 4 == 0 and height % 4 == 0, header
        assert abs(width - fallback.width) <= 2 and abs(height - fallback.height) <= 2, header
        assert header["levels"] == max(width, height).bit_length(), header
    return len(document["textures"])


def _ktx2_only_warnings(report: dict, path: Path) -> None:
    """glTF-Validator's ``report`` on the GLB at ``path``: no error, and no warning but the
    two of :data:`KTX2_WARNINGS` on each of its KTX2 images."""
    messages = report["issues"]["messages"]
    assert report["issues"]["numErrors"] == 0, messages
    images = glb_parts(path.read_bytes())[0]["images"]
    ktx2 = [f"/images/{i}" for i, image in enumerate(images) if image["mimeType"] == "image/ktx2"]
    warned = [m for m in messages if m["severity"] <= 1]
    found = sorted((m["pointer"].removesuffix("/mimeType"), m["code"]) for m in warned)
    assert found == sorted((i, code) for i in ktx2 for code in KTX2_WARNINGS), warned
    unsupported = {m["message"] for m in messages if m["code"] == "UNSUPPORTED_EXTENSION"}
    assert all("MSFT_lod" in m or "KHR_texture_basisu" in m for m in unsupported), unsupported


def _leaves(issues: list[dict]) -> Iterator[dict]:
    """The innermost issues of a 3D Tiles validator report (the content's own messages)."""
    for issue in issues:
        causes = issue.get("causes", [])
        yield from _leaves(causes) if causes else [issue]


def test_ktx2_copies_of_textures_are_basis_universal_as_the_extension_asks(
    tmp_path: Path, gltf_validator, basisu: str
) -> None:
    """``--texture-format ktx2``: every texture of a ``.glb`` and of a tileset's atlas pages
    also comes as KTX2 with Basis Universal (``KHR_texture_basisu``) as the extension asks
    (:func:`_assert_ktx2_copies`); both validators find no error, and no warning but the two
    each KTX2 image takes from a validator that does not know the extension; the same run twice
    writes the same bytes, on one worker or two."""
    source = city(tmp_path, texture("tex/roof.png"))
    glb, again = tmp_path / "roof.glb", tmp_path / "again.glb"
    tileset = tmp_path / "tiles" / "tileset.json"
    for out, workers in ((glb, "1"), (again, "2"), (tileset, "1")):
        flags = ("--texture-format", "ktx2", "--workers", workers, "-q")
        result = run(source, "-o", out, *flags)
        assert result.returncode == 0, result.stderr
    assert glb.read_bytes() == again.read_bytes()
    assert _assert_ktx2_copies(glb) >= 1
    _ktx2_only_warnings(gltf_validator(glb), glb)
    pages = sorted((tileset.parent / "tiles").glob("*.glb"))
    assert sum(_assert_ktx2_copies(p) for p in pages if b"image/ktx2" in p.read_bytes()) >= 1
    report = official(tileset, tmp_path / "report.json")
    assert report["numErrors"] == 0, report["issues"]
    warned = [i for i in _leaves(report["issues"]) if i["severity"] == "WARNING"]
    ktx2 = ("Invalid value 'image/ktx2'", "Image format not recognized")
    assert all(i["message"].startswith(ktx2) for i in warned), warned


@pytest.mark.parametrize("shape", [(1, 1), (3, 7), (1, 4096), (6, 10)])
def test_ktx2_takes_any_image_and_an_encoder_named_relative_to_the_working_folder(
    basisu: str, monkeypatch: pytest.MonkeyPatch, shape: tuple[int, int]
) -> None:
    """A texture of any size (a texel, a sliver) becomes KTX2 with sides of multiples of 4
    and every mipmap level, by an encoder named by a path relative to where the run started
    (the encoder runs in a folder of its own)."""
    from lodconvert.io.ktx2 import ktx2_encoded

    monkeypatch.chdir(Path(basisu).parent)
    monkeypatch.setenv("LODCONVERT_BASISU", "./basisu")
    rgba = np.full((*shape, 4), 200, dtype=np.uint8)
    header = _ktx2_header(ktx2_encoded(rgba))
    width, height = header["width"], header["height"]
    assert width % 4 == 0 and height % 4 == 0 and abs(width - shape[1]) < 4, header
    assert abs(height - shape[0]) < 4 and header["levels"] == max(width, height).bit_length()


def test_ktx2_without_its_encoder_is_a_one_line_usage_error_that_writes_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    source = city(tmp_path, texture("tex/roof.png"))
    monkeypatch.setenv("LODCONVERT_BASISU", str(tmp_path / "no-basisu"))
    for out in (tmp_path / "out.glb", tmp_path / "tiles" / "tileset.json"):
        result = run(source, "-o", out, "--texture-format", "ktx2")
        assert_one_line_error(result, 2, "--texture-format ktx2", "basisu", "LODCONVERT_BASISU")
    assert not (tmp_path / "out.glb").exists() and not (tmp_path / "tiles").exists()


def test_an_encoder_that_fails_is_a_one_line_error_that_writes_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An encoder that fails (here a script that says why and exits 3) stops the run with its
    name and last word, on one worker or in a worker of two; nothing is left."""
    source = city(tmp_path, texture("tex/roof.png"))
    failing = tmp_path / "basisu"
    failing.write_text("#!/bin/sh\necho 'ERROR: out of texels' >&2\nexit 3\n")
    failing.chmod(0o755)
    monkeypatch.setenv("LODCONVERT_BASISU", str(failing))
    for out, workers in ((tmp_path / "out.glb", "1"), (tmp_path / "tiles" / "tileset.json", "2")):
        result = run(source, "-o", out, "--texture-format", "ktx2", "--workers", workers)
        assert_one_line_error(result, 1, str(failing), "failed on a texture", "out of texels")
    assert not (tmp_path / "out.glb").exists() and not (tmp_path / "tiles").exists()


def test_a_wrong_texture_format_is_a_one_line_usage_error(tmp_path: Path) -> None:
    source = city(tmp_path, texture("tex/roof.png"))
    result = run(source, "-o", tmp_path / "out.glb", "--texture-format", "ktx9")
    assert_one_line_error(result, 2, "--texture-format", "ktx9")
    result = run(source, "-o", tmp_path / "out.x3d", "--texture-format", "webp")
    assert_one_line_error(result, 2, "--texture-format", "out.x3d")
    assert not (tmp_path / "out.glb").exists() and not (tmp_path / "out.x3d").exists()


@pytest.mark.parametrize("small", [32, 0])
def test_texture_coordinates_follow_the_points_in_order_or_by_position(
    small: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A polygon's vertices take their rings' texture coordinates: in order where they are
    the rings' points without the closing ones (a square with a hole), by position where
    triangulating left points out or reordered them, and never where a ring has none, where
    one is not a finite number or where they cover no area (checked number by number for a
    small polygon, with numpy for a large one)."""
    from lodconvert import textures
    from lodconvert.textures import polygon_coordinates

    monkeypatch.setattr(textures, "SMALL_POLYGON", small)

    outer = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0], [0, 0, 0]], dtype=float)
    hole = np.array([[1, 1, 0], [1, 3, 0], [3, 3, 0], [3, 1, 0], [1, 1, 0]], dtype=float)
    rings = (outer, hole)
    uv = tuple(ring[:, :2] / 4 for ring in rings)
    vertices = np.concatenate([outer[:-1], hole[:-1]])
    faces = np.array([[0, 1, 4], [1, 2, 6], [2, 3, 6], [3, 0, 4]])
    found, fault = polygon_coordinates(vertices, faces, rings, uv)
    assert fault is None and np.array_equal(found, vertices[:, :2] / 4)
    shuffled = vertices[[5, 0, 3, 1, 2]]
    found, fault = polygon_coordinates(shuffled, faces % 5, rings, uv)
    assert fault is None and np.array_equal(found, shuffled[:, :2] / 4)
    found, fault = polygon_coordinates(vertices, faces, rings, (uv[0], None))
    assert found is None and fault == "have rings without texture coordinates"
    broken = (uv[0].copy(), uv[1])
    broken[0][2, 1] = np.inf
    found, fault = polygon_coordinates(vertices, faces, rings, broken)
    assert found is None and fault == "have texture coordinates that are not finite numbers"
    flat = (np.zeros((5, 2)), np.zeros((5, 2)))
    found, fault = polygon_coordinates(vertices, faces, rings, flat)
    assert (
        found is None and fault == "have texture coordinates that cover no area (a 0×0 footprint)"
    )
