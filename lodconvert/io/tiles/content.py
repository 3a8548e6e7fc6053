"""One tile's content as a GLB (glTF 2.0, y-up, small float32 coordinates about the tile's
origin): buildings batched into one triangle primitive with vertex colours (and one more per
atlas page of their textures), ``_FEATURE_ID_0`` per vertex (``EXT_mesh_features``) and their
ids, types and attributes in an ``EXT_structural_metadata`` property table; a baked point level
as one ``POINTS`` primitive with ``COLOR_0``."""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...colors import linear_rgba16
from ...model import Surface
from ...textures import ATLAS_SIZE, Atlas, packed
from ..gltf.binary import (
    ARRAY_BUFFER,
    CLAMP_TO_EDGE,
    COMPONENT_TYPES,
    ELEMENT_ARRAY_BUFFER,
    LINEAR,
    LINEAR_MIPMAP_LINEAR,
    POINTS,
    TRIANGLES,
    VECTOR_TYPES,
    pack_glb,
)
from ..gltf.buffers import alpha_mode_of, float32_positions, vertex_normals
from ..gltf.compression import (
    NONE,
    POSITION_TOLERANCE,
    Filtered,
    Quantizer,
    StoredView,
    fallback_buffer,
    required,
    stored_attribute,
    stored_positions,
    stored_view,
)
from ..gltf.document import UNLIT
from ..gltf.texture_copies import COPIES, texture_copy
from ..images import encoded
from .metadata import Feature, property_table

MESH_FEATURES = "EXT_mesh_features"
STRUCTURAL_METADATA = "EXT_structural_metadata"


class _Builder:
    """A GLB's binary buffer, buffer views and accessors; with ``compress`` (a
    :data:`~..gltf.compression.COMPRESSIONS`) other than ``none``, its vertex attributes and
    indices compressed so (meshopt positions within ``tolerance`` metres, or float32's step
    where that is finer); its textures with a ``copy`` where asked
    (:func:`~..gltf.texture_copies.check_texture_format`)."""

    def __init__(self, compress: str = NONE, copy: str = "", tolerance: float = 0.0) -> None:
        self.compress, self.copy, self.tolerance = compress, copy, tolerance
        self.blob = bytearray()
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []
        self.images: list[dict[str, Any]] = []
        self.textures_made: list[dict[str, Any]] = []
        self.fallback = 0
        """Bytes of the meshopt fallback buffer (the compressed views' uncompressed layout)."""
        self.quantized = False
        """Whether an attribute is stored as ``KHR_mesh_quantization`` allows."""
        self.position_error = 0.0
        """How far (metres) a stored position lies from its float32 position, at most."""

    def texture(self, rgba: np.ndarray, photographic: bool) -> int:
        """A texture of the image ``rgba`` (:func:`~..images.encoded`; preferring its copy where
        the builder makes one), sampled with mipmaps and clamped at its edges (an atlas
        page: nothing repeats)."""
        data, mime = encoded(rgba, photographic)
        self.images.append({"bufferView": self.view(data), "mimeType": mime})
        texture: dict[str, Any] = {"sampler": 0, "source": len(self.images) - 1}
        copy = texture_copy(rgba, photographic, self.copy)
        if copy is not None:
            self.images.append({"bufferView": self.view(copy.data), "mimeType": copy.mime})
            texture["extensions"] = {copy.extension: {"source": len(self.images) - 1}}
        self.textures_made.append(texture)
        return len(self.textures_made) - 1

    def textures(self) -> dict[str, Any]:
        """The document's ``images``, ``samplers`` and ``textures`` (one per image)."""
        if not self.images:
            return {}
        sampler = {"magFilter": LINEAR, "minFilter": LINEAR_MIPMAP_LINEAR,
                   "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE}  # fmt: skip
        return {"images": self.images, "samplers": [sampler], "textures": self.textures_made}

    def view(self, data: bytes, target: int | None = None) -> int:
        """A buffer view of ``data`` at an 8-byte boundary (as property tables need)."""
        return self._add(StoredView(data, len(data)), target)

    def _add(self, stored: StoredView, target: int | None) -> int:
        """A buffer view of ``stored`` (its data at an 8-byte boundary)."""
        self.blob.extend(b"\0" * (-len(self.blob) % 8))
        self.views.append(stored.json(target, len(self.blob), self.fallback))
        self.blob.extend(stored.data)
        if stored.packed is not None:
            self.fallback += -(-stored.length // 4) * 4
        return len(self.views) - 1

    def accessor(
        self,
        array: np.ndarray,
        target: int = ARRAY_BUFFER,
        normalized: bool = False,
        bounds: bool = False,
        filtered: Filtered | None = None,
    ) -> int:
        """An accessor of ``array`` ((n,) or (n, k)), with its ``bounds`` (positions), its
        view as the builder compresses (:func:`~..gltf.compression.stored_view`)."""
        array = np.ascontiguousarray(array)
        view = self._add(stored_view(array, target, self.compress, filtered), target)
        width = 1 if array.ndim == 1 else array.shape[1]
        accessor: dict[str, Any] = {
            "bufferView": view,
            "componentType": COMPONENT_TYPES[array.dtype],
            "count": len(array),
            "type": VECTOR_TYPES[width],
        }
        if normalized:
            accessor["normalized"] = True
        if bounds:
            accessor["min"] = array.min(axis=0).tolist()
            accessor["max"] = array.max(axis=0).tolist()
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def positions(self, positions: np.ndarray) -> tuple[int, Quantizer | None]:
        """The ``POSITION`` accessor of float32 ``positions`` as the builder stores them
        (:func:`~..gltf.compression.stored_positions`; the node transform of quantized ones
        returned), their error kept in :attr:`position_error`."""
        stored = stored_positions(positions, self.compress, tolerance=self.tolerance)
        self.quantized |= stored.quantizer is not None
        self.position_error = stored.error
        accessor = self.accessor(stored.values, bounds=True, filtered=stored.filtered)
        return accessor, stored.quantizer

    def attribute(self, name: str, values: np.ndarray) -> int:
        """The ``NORMAL`` or ``TEXCOORD_0`` accessor of float32 ``values`` as the builder
        stores them (:func:`~..gltf.compression.stored_attribute`)."""
        stored = stored_attribute(name, values, self.compress)
        self.quantized |= stored.normalized
        return self.accessor(stored.values, normalized=stored.normalized, filtered=stored.filtered)

    def feature_ids(self, ids: np.ndarray, count: int) -> int:
        """The ``_FEATURE_ID_0`` accessor of ``ids`` (below ``count``): unsigned shorts where
        the builder compresses and they fit, else float32."""
        small = self.compress != NONE and count <= 65536
        return self.accessor(ids.astype(np.uint16 if small else np.float32))

    def glb(self, document: dict[str, Any]) -> bytes:
        """The GLB of ``document`` with this buffer (and the fallback buffer of compressed
        views, the extensions they take named used and required, and a texture copy's used)."""
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        buffers: list[dict[str, Any]] = [{"byteLength": len(self.blob)}]
        if self.fallback:
            buffers.append(fallback_buffer(self.fallback))
        needed = required(self.quantized, self.fallback > 0)
        copies = [COPIES[self.copy][0]] if self.copy and self.images else []
        used = document.get("extensionsUsed", []) + copies
        document = {
            **document,
            "accessors": self.accessors,
            "bufferViews": self.views,
            "buffers": buffers,
        }
        if used + needed:
            document["extensionsUsed"] = used + needed
        if needed:
            document["extensionsRequired"] = needed
        if self.compress != NONE:
            extras = {"compress": self.compress, "position_error": self.position_error}
            document["asset"] = {**document["asset"], "extras": {"lodconvert": extras}}
        text = json.dumps(document, separators=(",", ":"), ensure_ascii=False).encode()
        out = io.BytesIO()
        pack_glb(out, text, bytes(self.blob))
        return out.getvalue()


@dataclass(frozen=True)
class TileTextures:
    """The textures of a tile's vertices: per vertex, its image (an index into ``images``;
    -1: none) and texture coordinates ((n, 2), origin at the image's bottom left); whether
    every image is a photograph (then opaque pages are written as JPEG)."""

    image_of: np.ndarray
    uv: np.ndarray
    images: tuple[np.ndarray, ...]
    photographic: bool = False


def _document(
    generator: str,
    drawn: list[tuple[dict[str, Any], dict[str, Any]]],
    quantized: Quantizer | None = None,
) -> dict:
    """A glTF document of one node drawing one mesh of ``drawn`` primitives, each with its
    material (the node's transform turns ``quantized`` positions back)."""
    node = {"mesh": 0, **(quantized.node() if quantized is not None else {})}
    return {
        "asset": {"version": "2.0", "generator": generator},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [node],
        "meshes": [{"primitives": [{**p, "material": k} for k, (p, _) in enumerate(drawn)]}],
        "materials": [material for _, material in drawn],
    }


def _material(alpha: np.ndarray, unlit: bool = False, texture: int | None = None) -> dict[str, Any]:
    """White (vertex colours, or the ``texture``, carry the colour), non-metallic, fully
    rough."""
    pbr: dict[str, Any] = {
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
        "metallicFactor": 0.0,
        "roughnessFactor": 1.0,
    }
    if texture is not None:
        pbr["baseColorTexture"] = {"index": texture}
    material: dict[str, Any] = {
        "pbrMetallicRoughness": pbr,
        "alphaMode": alpha_mode_of(alpha),
        "doubleSided": not unlit,
    }
    if unlit:
        material["extensions"] = {UNLIT: {}}
    return material


def mesh_glb(
    vertices: np.ndarray,
    faces: np.ndarray,
    colors: np.ndarray,
    feature_ids: np.ndarray | None,
    features: Sequence[Feature],
    generator: str,
    textures: TileTextures | None = None,
    atlas_size: int = ATLAS_SIZE,
    compress: str = NONE,
    copy: str = "",
    tolerance: float = POSITION_TOLERANCE[0],
) -> bytes:
    """A GLB of a triangle primitive: ``vertices`` (n, 3) glTF coordinates (y-up, about the
    tile's origin), ``faces`` (m, 3), ``colors`` (n, 4) sRGB bytes, ``feature_ids`` (n,) into
    ``features`` (``None``: content without features, a merged far level); the faces of
    textured vertices (``textures``) are drawn by a primitive per atlas page (at most
    ``atlas_size`` texels a side) instead, on the same vertices (their colours multiply the
    texture: white shows it as it is); its geometry compressed as ``compress`` says (meshopt
    positions within ``tolerance`` metres), its pages with a ``copy`` where asked."""
    if compress != NONE:
        vertices, faces, colors, feature_ids, textures = _in_fetch_order(
            vertices, faces, colors, feature_ids, textures
        )
    builder = _Builder(compress, copy, tolerance)
    positions = float32_positions(vertices)
    normals = vertex_normals(Surface(positions.astype(np.float64), faces))
    index_type = np.uint16 if len(vertices) < 65536 else np.uint32
    paged = _pages(textures, atlas_size) if textures is not None else None
    position, quantized = builder.positions(positions)
    attributes = {
        "POSITION": position,
        "NORMAL": builder.attribute("NORMAL", normals),
        "COLOR_0": builder.accessor(linear_rgba16(colors), normalized=True),
    }
    if feature_ids is not None:
        attributes["_FEATURE_ID_0"] = builder.feature_ids(feature_ids, len(features))
    extensions: dict[str, Any] = {}
    if feature_ids is not None:
        ids = {"featureCount": len(features), "attribute": 0, "propertyTable": 0}
        extensions = {"extensions": {MESH_FEATURES: {"featureIds": [ids]}}}

    def primitive(chosen: np.ndarray, more: dict[str, int]) -> dict[str, Any]:
        indices = builder.accessor(chosen.ravel().astype(index_type), ELEMENT_ARRAY_BUFFER)
        return {"attributes": {**attributes, **more}, "indices": indices, "mode": TRIANGLES,
                **extensions}  # fmt: skip

    drawn = []
    face_page = np.full(len(faces), -1) if paged is None else paged[0][faces[:, 0]]
    plain = faces[face_page < 0]
    if len(plain):
        drawn.append((primitive(plain, {}), _material(colors[:, 3])))
    if paged is not None:
        _, atlas_uv, atlas = paged
        coordinates = {"TEXCOORD_0": builder.attribute("TEXCOORD_0", atlas_uv)}
        for page, image in enumerate(atlas.pages):
            texture = builder.texture(image, textures.photographic)  # type: ignore[union-attr]
            material = _material(image[..., 3].ravel(), texture=texture)
            drawn.append((primitive(faces[face_page == page], coordinates), material))
    document = _document(generator, drawn, quantized)
    document.update(builder.textures())
    if feature_ids is not None:
        document["extensionsUsed"] = [MESH_FEATURES, STRUCTURAL_METADATA]
        document["extensions"] = {STRUCTURAL_METADATA: property_table(features, builder.view)}
    return builder.glb(document)


def _in_fetch_order(
    vertices: np.ndarray,
    faces: np.ndarray,
    colors: np.ndarray,
    feature_ids: np.ndarray | None,
    textures: TileTextures | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, TileTextures | None]:
    """The vertices (and what each carries) in the order the faces first use them, unused
    ones last, and the faces on them: consecutive vertices then lie close and the triangle
    codec finds most indices as the next new vertex."""
    used, first = np.unique(faces.ravel(), return_index=True)
    rest = np.setdiff1d(np.arange(len(vertices)), used)
    order = np.concatenate([used[np.argsort(first, kind="stable")], rest])
    index_of = np.empty(len(vertices), dtype=np.int64)
    index_of[order] = np.arange(len(vertices))
    if textures is not None:
        textures = replace(textures, image_of=textures.image_of[order], uv=textures.uv[order])
    ids = feature_ids[order] if feature_ids is not None else None
    return vertices[order], index_of[faces], colors[order], ids, textures


def _pages(textures: TileTextures, size: int) -> tuple[np.ndarray, np.ndarray, Atlas] | None:
    """The tile's images packed into atlas pages of at most ``size`` texels a side: per
    vertex, its page (-1: untextured) and its glTF texture coordinates (float32, origin at the
    page's top left), and the atlas; None where no vertex is textured."""
    textured = textures.image_of >= 0
    if not textured.any():
        return None
    atlas = packed(textures.images, size)
    image = textures.image_of[textured]
    uv = np.zeros((len(textures.uv), 2))
    uv[textured] = atlas.coordinates(image, textures.uv[textured])
    uv[:, 1] = 1.0 - uv[:, 1]
    pages = np.full(len(textures.uv), -1, dtype=np.int64)
    pages[textured] = np.asarray(atlas.page_of, dtype=np.int64)[image]
    return pages, uv.astype(np.float32), atlas


def points_glb(
    positions: np.ndarray,
    colors: np.ndarray,
    generator: str,
    compress: str = NONE,
    tolerance: float = POSITION_TOLERANCE[0],
) -> bytes:
    """A GLB of one ``POINTS`` primitive: ``positions`` (n, 3) glTF coordinates, ``colors``
    (n, 4) sRGB bytes; compressed as ``compress`` says (meshopt positions within
    ``tolerance`` metres)."""
    builder = _Builder(compress, tolerance=tolerance)
    position, quantized = builder.positions(float32_positions(positions))
    attributes = {
        "POSITION": position,
        "COLOR_0": builder.accessor(linear_rgba16(colors), normalized=True),
    }
    primitive = {"attributes": attributes, "mode": POINTS}
    drawn = [(primitive, _material(colors[:, 3], unlit=True))]
    document = _document(generator, drawn, quantized)
    document["extensionsUsed"] = [UNLIT]
    return builder.glb(document)
