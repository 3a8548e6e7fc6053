"""A level's glTF buffers (:func:`level_data`): its geometry as the accessor data of its
primitives (float32 positions, unit normals, linear ``COLOR_0`` shorts, flipped texture
coordinates, PNG textures, indices), with the compact JSON text of each accessor."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...colors import linear_rgba, linear_rgba16
from ...errors import LodConvertError
from ...model import Level, PointCloud, Surface
from ..images import encoded
from .binary import (
    ARRAY_BUFFER,
    COMPONENT_TYPES,
    ELEMENT_ARRAY_BUFFER,
    POINTS,
    TRIANGLES,
    VECTOR_TYPES,
)
from .compression import (
    NONE,
    QUANTIZE,
    Filtered,
    Quantizer,
    StoredView,
    quantizer,
    stored_attribute,
    stored_positions,
    stored_view,
)
from .json_text import COMPACT, json_object
from .texture_copies import TextureCopy, texture_copy


def float32_positions(positions: np.ndarray) -> np.ndarray:
    """``positions`` as float32, or :class:`LodConvertError` where a coordinate is beyond the
    float32 range (it would be written as infinity)."""
    largest = float(np.abs(positions).max(initial=0.0))
    if not largest <= np.finfo(np.float32).max:
        raise LodConvertError(
            f"a level coordinate of magnitude {largest:.3g} is beyond the float32 range of glTF"
        )
    return positions.astype(np.float32)


NORMALS_AT_ONCE = 1 << 16
"""Faces (or rows) whose normals :func:`vertex_normals` (:func:`unit_normals`) finds at a
time."""


def unit_normals(normals: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length as float32; zero or non-finite rows become (0, 0, 1).
    :data:`NORMALS_AT_ONCE` rows at a time."""
    n = np.asarray(normals, dtype=np.float64)
    out = np.empty((len(n), 3), dtype=np.float32)
    for start in range(0, len(n), NORMALS_AT_ONCE):
        rows = n[start : start + NORMALS_AT_ONCE]
        length = np.sqrt(np.add.reduce(rows * rows, axis=1))  # as np.linalg.norm(rows, axis=1)
        ok = np.isfinite(length) & (length > 0)
        unit = np.zeros((len(rows), 3))
        unit[:, 2] = 1.0
        unit[ok] = rows[ok] / length[ok, None]
        out[start : start + len(rows)] = unit
    return out


def vertex_normals(surface: Surface) -> np.ndarray:
    """Area-weighted unit vertex normals (n, 3) float32; unused vertices get (0, 0, 1). The
    faces' normals are found :data:`NORMALS_AT_ONCE` faces at a time (their corners' (m, 3, 3)
    coordinates took five times the output's memory)."""
    faces, vertices = surface.faces, surface.vertices
    crossed = np.empty((len(faces), 3))  # each face's cross product: 2 · area long
    for start in range(0, len(faces), NORMALS_AT_ONCE):
        tri = vertices[faces[start : start + NORMALS_AT_ONCE]]
        a, b = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
            crossed[start : start + len(tri), k] = a[:, i] * b[:, j] - a[:, j] * b[:, i]
    corners = faces.ravel()
    n = len(vertices)
    summed = np.empty((n, 3))
    for k in range(3):
        summed[:, k] = np.bincount(corners, np.repeat(crossed[:, k], 3), minlength=n)
    return unit_normals(summed)


def alpha_mode_of(*alphas: np.ndarray | None) -> str:
    """``BLEND`` when any given alpha byte is below 255, else ``OPAQUE``."""
    blend = any(a is not None and a.size and int(a.min()) < 255 for a in alphas)
    return "BLEND" if blend else "OPAQUE"


def surface_image(surface: Surface) -> tuple[bytes, str]:
    """The bytes and MIME type of a textured surface's image (:func:`~..images.encoded`)."""
    assert surface.texture is not None
    return encoded(surface.texture, surface.photographic)


@dataclass(frozen=True)
class AccessorData:
    """An accessor's buffer view (its bytes, little-endian, as compressed:
    :class:`~.compression.StoredView`), the view's target and the accessor's other fields,
    with their compact JSON text (what follows its ``bufferView`` number in a GLB)."""

    view: StoredView
    target: int
    fields: dict[str, Any]
    compact_tail: str


VIEW_HEAD = '{"bufferView":'


def _accessor_data(
    array: np.ndarray,
    target: int = ARRAY_BUFFER,
    normalized: bool = False,
    bounds: bool = False,
    compress: str = NONE,
    filtered: Filtered | None = None,
) -> AccessorData:
    """An accessor over ``array`` ((k,) scalars or (k, w) vectors, dtype of the buffer), its
    view stored as ``compress`` says (``filtered``: the data packed in its place)."""
    data = np.ascontiguousarray(array)
    stored = np.ascontiguousarray(data, dtype=data.dtype.newbyteorder("<"))
    fields = json_object(
        byteOffset=0,
        componentType=COMPONENT_TYPES[data.dtype],
        normalized=True if normalized else None,
        count=len(data),
        type=VECTOR_TYPES[1 if data.ndim == 1 else data.shape[1]],
        max=[float(v) for v in data.max(axis=0)] if bounds else None,
        min=[float(v) for v in data.min(axis=0)] if bounds else None,
    )
    compact = COMPACT.text({"bufferView": 0, **fields}, 2)
    view = stored_view(stored, target, compress, filtered)
    return AccessorData(view, target, fields, compact[len(VIEW_HEAD) + 1 :])


@dataclass(frozen=True)
class PrimitiveData:
    """What a primitive's JSON needs of its geometry: its accessors' data in the order they
    are added to the buffer (``POSITION``, ``NORMAL``, ``COLOR_0``, ``TEXCOORD_0``), its
    texture (image bytes and MIME type, added next: :func:`surface_image`) and indices (last);
    for a mesh, the linear base colour of its material (``None``: a point level's shared unlit
    one) and the alpha mode; how its positions are stored (:class:`Stored`)."""

    attributes: dict[str, AccessorData]
    mode: int
    alpha_mode: str
    base: list[float] | None = None
    image: tuple[bytes, str] | None = None
    indices: AccessorData | None = None
    stored: Stored | None = None
    copy: TextureCopy | None = None
    """The image's copy (``--texture-format``), which the texture prefers."""


@dataclass(frozen=True)
class Stored:
    """How a level's positions are stored: the node transform of quantized ones (the same
    for all its primitives), the largest difference of a coordinate from its float32
    position (metres) and whether an attribute is quantized."""

    node: dict[str, Any]
    error: float
    quantized: bool


class _Storing:
    """Accessors of one level stored as ``compress`` says (quantized positions as
    ``steps_of`` makes them)."""

    def __init__(self, compress: str, steps_of: Quantizer | None) -> None:
        self.compress, self.steps_of = compress, steps_of
        self.quantized = False
        self.error = 0.0

    def data(self, array: np.ndarray, target: int = ARRAY_BUFFER, **fields: Any) -> AccessorData:
        """An accessor over ``array`` (:func:`_accessor_data`)."""
        return _accessor_data(array, target, compress=self.compress, **fields)

    def positions(self, vertices: np.ndarray) -> AccessorData:
        """The ``POSITION`` accessor of ``vertices`` (:func:`~.compression.stored_positions`)."""
        stored = stored_positions(float32_positions(vertices), self.compress, self.steps_of)
        self.quantized |= stored.quantizer is not None
        self.error = max(self.error, stored.error)
        return self.data(stored.values, bounds=True, filtered=stored.filtered)

    def attribute(self, name: str, values: np.ndarray) -> AccessorData:
        """The ``NORMAL`` or ``TEXCOORD_0`` accessor of float32 ``values``
        (:func:`~.compression.stored_attribute`)."""
        stored = stored_attribute(name, values, self.compress)
        self.quantized |= stored.normalized
        return self.data(stored.values, normalized=stored.normalized, filtered=stored.filtered)

    def colors(self, rgba: np.ndarray) -> AccessorData:
        """COLOR_0 accessor: VEC4 normalised unsigned shorts in linear space."""
        return self.data(linear_rgba16(rgba), normalized=True)

    def stored(self) -> Stored:
        """How the level's positions were stored."""
        node = self.steps_of.node() if self.steps_of is not None else {}
        return Stored(node, self.error, self.quantized)


def _mesh_data(
    surface: Surface, storing: _Storing, normals: bool = True, copy_kind: str = ""
) -> PrimitiveData:
    attributes = {"POSITION": storing.positions(surface.vertices)}
    if normals:
        attributes["NORMAL"] = storing.attribute("NORMAL", vertex_normals(surface))
    if surface.vertex_colors is not None:
        attributes["COLOR_0"] = storing.colors(surface.vertex_colors)
    textured = surface.texture is not None and surface.uv is not None
    image = copy = None
    if textured:
        # Surface.uv has its origin at the image's bottom-left, glTF at the top-left.
        flipped = np.column_stack([surface.uv[:, 0], 1.0 - surface.uv[:, 1]])
        attributes["TEXCOORD_0"] = storing.attribute("TEXCOORD_0", flipped.astype(np.float32))
        image = surface_image(surface)
        assert surface.texture is not None
        copy = texture_copy(surface.texture, surface.photographic, copy_kind)
    index_type = np.uint16 if len(surface.vertices) < 65536 else np.uint32
    indices = storing.data(surface.faces.ravel().astype(index_type), ELEMENT_ARRAY_BUFFER)
    alpha_mode = alpha_mode_of(
        surface.material_color[3:],
        None if surface.vertex_colors is None else surface.vertex_colors[:, 3],
        surface.texture[..., 3] if textured else None,
    )
    base = [float(v) for v in linear_rgba(surface.material_color)]
    return PrimitiveData(attributes, TRIANGLES, alpha_mode, base, image, indices, copy=copy)


def _points_data(points: PointCloud, storing: _Storing) -> PrimitiveData:
    attributes = {
        "POSITION": storing.positions(points.positions),
        "NORMAL": storing.attribute("NORMAL", unit_normals(points.normals)),
        "COLOR_0": storing.colors(points.colors),
    }
    return PrimitiveData(attributes, POINTS, alpha_mode_of(points.colors[:, 3]))


def level_data(level: Level, compress: str = NONE, copy: str = "") -> list[PrimitiveData]:
    """The primitives of one (non-empty) level, compressed as ``compress`` says (quantized
    positions: in steps of the whole level, whose node turns them back), their textures with a
    ``copy`` where asked (:func:`~.texture_copies.texture_copy`). A LOD parent's
    merged far mesh has no normals: its corners are welded
    (:func:`~lodconvert.bake.qem.simplify_within`), where normals per vertex would round every
    building's edges, and glTF clients shade a primitive without normals flat (three.js from
    screen-space derivatives, with no vertex split)."""
    steps_of = None
    if compress == QUANTIZE:
        mesh = level.mesh
        parts = [level.points.positions] if mesh is None else [p.vertices for p in mesh.parts]
        steps_of = quantizer(float32_positions(np.concatenate(parts)).astype(np.float64))
    storing = _Storing(compress, steps_of)
    if level.mesh is None:
        made = [_points_data(level.points, storing)]
    else:
        flat = level.kind == "merged"
        made = [_mesh_data(part, storing, not flat, copy) for part in level.mesh.parts]
    stored = storing.stored()
    return [replace(data, stored=stored) for data in made]
