"""Geometry nodes of a level: ``Shape`` s of ``IndexedTriangleSet`` (a mesh part, its
``Material``, vertex ``Color``, ``ImageTexture`` as a PNG ``data:`` URI) or ``PointSet`` (points
sized by ``PointProperties``), each Shape small enough that no attribute nears libxml2's 10 MB
text limit. Numbers with float32-level precision, the same decimals in all of a level's Shapes.
Why each rule holds (texture modulation, point attenuation): ``docs/x3d.md``."""

from __future__ import annotations

import base64
import math
from collections.abc import Iterator, Sequence
from dataclasses import replace

import numpy as np

from ...model import Level, Mesh, Surface
from ..images import encoded
from ..numbers import format_exact, format_fixed, format_ints, format_unit_bytes, geometry_decimals
from .xmltext import XmlOut, mfstring

MAX_POINT_GROWTH = 4.0
"""Cap on how much larger than ``params.point_size`` a point may grow when the viewer comes
closer than the design distance (a baked finest level shows from distance 0)."""

MAX_SHAPE_VERTICES = 100_000
"""Most vertices (mesh) or points (point level) in one ``Shape``. With 7 significant digits a
coordinate takes at most 12 characters and a space while the level's largest coordinate is at
least 0.001 (10 from 0.1 on), so the ``point`` attribute stays under 3.9 MB, and an RGBA
``color`` (at most 7 characters a channel) under 2.8 MB."""

MAX_SHAPE_TRIANGLES = 200_000
"""Most triangles in one ``Shape``: its ``index`` attribute (indices below
:data:`MAX_SHAPE_VERTICES`, at most 6 characters each) stays under 3.6 MB."""

MAX_TEXTURE_URL = 8_000_000
"""Most characters of a texture's ``data:`` URI, so that the ``url`` attribute stays under
libxml2's 10 MB limit like every other: a larger image is halved until it fits."""


def point_properties(level: Level, switch_in: float, alpha: float) -> dict[str, str]:
    """``PointProperties`` fields that draw ``level``'s points ``point_size · d / r`` pixels
    wide (``d`` its design distance, ``r`` the viewer distance; see ``docs/x3d.md``).

    The maximum is the size at the nearest distance the level can be seen from: its switch-in
    distance less half the object diagonal ``alpha`` (points lie up to that far from the
    centre), but never closer than ``d / MAX_POINT_GROWTH``. Without a design distance the
    points keep a constant ``point_size``.
    """
    size = level.params.point_size if level.params is not None else 1.0
    scale = max(1.0, size)
    design = level.design_distance
    if design is None or design <= 0:
        fixed = format_exact([scale])
        return {"pointSizeScaleFactor": fixed, "pointSizeMinValue": "1", "pointSizeMaxValue": fixed}
    nearest = max(switch_in - alpha / 2.0, design / MAX_POINT_GROWTH)
    return {
        "pointSizeScaleFactor": format_exact([scale]),
        "pointSizeMinValue": "1",
        # rounded up, so the clamp never cuts the size the attenuation asks for
        "pointSizeMaxValue": format_fixed(
            [max(1.0, math.ceil(100 * size * design / nearest - 1e-6) / 100)], 2
        ),
        "attenuation": "0 " + format_exact([scale / (size * design)]) + " 0",
    }


def _color_node(out: XmlOut, rgba: np.ndarray) -> None:
    """``Color`` (RGB) when every alpha is 255, else ``ColorRGBA``."""
    if (rgba[:, 3] == 255).all():
        out.leaf("Color", {"color": format_unit_bytes(rgba[:, :3])})
    else:
        out.leaf("ColorRGBA", {"color": format_unit_bytes(rgba)})


def _appearance(
    out: XmlOut, name: str, first: bool, children: Sequence[tuple[str, dict[str, str]]]
) -> None:
    """A level's or part's ``Appearance``: defined (``DEF``, with the ``(tag, fields)``
    ``children``) in its first ``Shape`` and re-used (``USE``) in the others."""
    if first:
        with out.node("Appearance", {"DEF": name}):
            for tag, fields in children:
                out.leaf(tag, fields)
    else:
        out.leaf("Appearance", {"USE": name})


def _face_runs(faces: np.ndarray) -> Iterator[np.ndarray]:
    """Split ``faces`` (m, 3) into consecutive runs of at most :data:`MAX_SHAPE_TRIANGLES`
    faces using at most :data:`MAX_SHAPE_VERTICES` distinct vertices (each run as long as
    both allow; at least one face, and one empty run for a mesh without faces)."""
    if len(faces) <= MAX_SHAPE_TRIANGLES and faces.size <= MAX_SHAPE_VERTICES:
        yield faces  # too few corners to use too many vertices
        return
    start = 0
    while True:
        window = faces[start : start + MAX_SHAPE_TRIANGLES]
        # distinct vertices of each prefix of the window: the corners where a vertex first occurs
        _, first = np.unique(window, return_index=True)
        new_per_face = np.bincount(first // 3, minlength=len(window))
        fitting = int(np.count_nonzero(np.cumsum(new_per_face) <= MAX_SHAPE_VERTICES))
        stop = start + max(1, fitting)
        yield faces[start:stop]
        if stop >= len(faces):
            return
        start = stop


def _run_vertices(run: np.ndarray, vertex_count: int) -> tuple[np.ndarray | slice, np.ndarray]:
    """The vertices (of ``vertex_count``) that the faces ``run`` use, ascending, and ``run``
    re-indexed into them, as ``np.unique(run, return_inverse=True)`` gives them; all vertices
    as a slice when every one is used."""
    used = np.zeros(vertex_count, dtype=bool)
    used[run.ravel()] = True
    if used.all():
        return slice(None), run
    return np.flatnonzero(used), (np.cumsum(used) - 1)[run]


def _point_slices(count: int) -> Iterator[slice]:
    """Consecutive slices of at most :data:`MAX_SHAPE_VERTICES` points (one, empty, for none)."""
    for start in range(0, max(count, 1), MAX_SHAPE_VERTICES):
        yield slice(start, start + MAX_SHAPE_VERTICES)


def _textured(surface: Surface) -> bool:
    return surface.texture is not None and surface.uv is not None


def texture_url(rgba: np.ndarray, photographic: bool = False) -> str:
    """The image ``rgba`` (h, w, 4) uint8, top row first, as a ``data:`` URI for an
    ``ImageTexture`` ``url`` (:func:`~..images.encoded`: JPEG for an opaque photograph, else
    PNG): same pixels, same text.

    An image whose URI would be longer than :data:`MAX_TEXTURE_URL` is halved (2×2 box
    average, odd edges rounded up) until it fits; texture coordinates stay valid as they are
    relative.
    """
    from PIL import Image as PILImage  # only for textures: a worker baking none never loads it

    image = PILImage.fromarray(np.ascontiguousarray(rgba, dtype=np.uint8))
    while True:
        data, mime = encoded(np.asarray(image), photographic)
        url = f"data:{mime};base64," + base64.b64encode(data).decode("ascii")
        if len(url) <= MAX_TEXTURE_URL or max(image.size) == 1:
            return url
        image = image.reduce(2)


def vertex_colors(surface: Surface) -> np.ndarray | None:
    """Per-vertex RGBA (n, 4) uint8 of the ``Color`` node of ``surface``'s Shapes, or ``None``
    when the surface has no vertex colours (its :attr:`~Surface.material_color` then goes to
    the Material, and a texture to an ``ImageTexture``).

    Each vertex takes :meth:`Surface.colors_at` of the surface without its texture at its own
    position on the first face that uses it: the vertex colour modulated by the base colour
    (the texture is written as a texture, which X3D multiplies by these colours). Vertices used
    by no face get the material colour.
    """
    if surface.vertex_colors is None:
        return None
    if _textured(surface):
        surface = replace(surface, uv=None, texture=None)
    colors = np.repeat(surface.material_color[None, :], len(surface.vertices), axis=0)
    corners = surface.faces.ravel()
    order = np.argsort(corners, kind="stable")
    ordered = corners[order]
    first = np.ones(len(ordered), dtype=bool)
    first[1:] = ordered[1:] != ordered[:-1]
    used = ordered[first]
    colors[used] = surface.colors_at(order[first] // 3, surface.vertices[used])
    return colors


def mesh_shapes(out: XmlOut, mesh: Mesh, appearance: str) -> None:
    """Every part of ``mesh`` as Shapes (:func:`_part_shapes`); parts after the first name their
    Appearance ``<appearance>_<part>``."""
    for i, part in enumerate(mesh.parts):
        _part_shapes(out, part, appearance if i == 0 else f"{appearance}_{i}")


def _part_shapes(out: XmlOut, surface: Surface, appearance: str) -> None:
    """One part as ``Shape`` s with an ``IndexedTriangleSet`` each, one per run of faces
    (:func:`_face_runs`), holding the vertices (colours, texture coordinates) that run uses,
    re-indexed. A textured part's ``Appearance`` holds its ``ImageTexture``."""
    base = surface.material_color
    material = {"diffuseColor": format_unit_bytes(base[:3])}
    if base[3] < 255:
        material["transparency"] = format_fixed([1.0 - base[3] / 255.0], 4)
    children = [("Material", material)]
    uv = surface.uv if _textured(surface) else None
    if uv is not None:
        assert surface.texture is not None
        url = texture_url(surface.texture, surface.photographic)
        children.append(("ImageTexture", {"url": mfstring([url])}))
    colors = vertex_colors(surface)
    decimals = geometry_decimals(surface.vertices)
    uv_decimals = geometry_decimals(uv) if uv is not None else 0
    for k, run in enumerate(_face_runs(surface.faces)):
        used, index = _run_vertices(run, len(surface.vertices))
        with out.node("Shape"):
            _appearance(out, appearance, k == 0, children)
            attrib = {"solid": "false", "index": format_ints(index)}
            with out.node("IndexedTriangleSet", attrib):
                out.leaf("Coordinate", {"point": format_fixed(surface.vertices[used], decimals)})
                if colors is not None:
                    _color_node(out, colors[used])
                if uv is not None:
                    out.leaf("TextureCoordinate", {"point": format_fixed(uv[used], uv_decimals)})


def point_shapes(
    out: XmlOut, level: Level, switch_in: float, alpha: float, appearance: str
) -> None:
    """The level's points as ``Shape`` s with a ``PointSet`` each, one per slice of
    :data:`MAX_SHAPE_VERTICES` consecutive points."""
    assert level.points is not None
    positions, colors = level.points.positions, level.points.colors
    fields = point_properties(level, switch_in, alpha)
    decimals = geometry_decimals(positions)
    for k, part in enumerate(_point_slices(len(positions))):
        with out.node("Shape"):
            _appearance(out, appearance, k == 0, [("PointProperties", fields)])
            with out.node("PointSet"):
                _color_node(out, colors[part])
                out.leaf("Coordinate", {"point": format_fixed(positions[part], decimals)})
