"""One tile's content as a GLB (glTF 2.0, y-up, small float32 coordinates about the tile's
origin): buildings batched into one triangle primitive with vertex colours (and one more per
atlas page of their textures), ``_FEATURE_ID_0`` per vertex (``EXT_mesh_features``) and their
ids, types and attributes in an ``EXT_structural_metadata`` property table; a baked point level
as one ``POINTS`` primitive with ``COLOR_0``."""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from dataclasses import dataclass
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
from ..gltf.document import UNLIT
from ..images import encoded
from .metadata import Feature, property_table

MESH_FEATURES = "EXT_mesh_features"
STRUCTURAL_METADATA = "EXT_structural_metadata"


class _Builder:
    """A GLB's binary buffer, buffer views and accessors."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []
        self.images: list[dict[str, Any]] = []

    def texture(self, rgba: np.ndarray, photographic: bool) -> int:
        """A texture of the image ``rgba`` (:func:`~..images.encoded`), sampled with mipmaps
        and clamped at its edges (an atlas page: nothing repeats)."""
        data, mime = encoded(rgba, photographic)
        self.images.append({"bufferView": self.view(data), "mimeType": mime})
        return len(self.images) - 1

    def textures(self) -> dict[str, Any]:
        """The document's ``images``, ``samplers`` and ``textures`` (one per image)."""
        if not self.images:
            return {}
        sampler = {"magFilter": LINEAR, "minFilter": LINEAR_MIPMAP_LINEAR,
                   "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE}  # fmt: skip
        return {
            "images": self.images,
            "samplers": [sampler],
            "textures": [{"sampler": 0, "source": k} for k in range(len(self.images))],
        }

    def view(self, data: bytes, target: int | None = None) -> int:
        """A buffer view of ``data`` at an 8-byte boundary (as property tables need)."""
        self.blob.extend(b"\0" * (-len(self.blob) % 8))
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.blob.extend(data)
        self.views.append(view)
        return len(self.views) - 1

    def accessor(
        self, array: np.ndarray, target: int = ARRAY_BUFFER, normalized: bool = False
    ) -> int:
        """An accessor of ``array`` ((n,) or (n, k)); positions get their bounds."""
        array = np.ascontiguousarray(array)
        width = 1 if array.ndim == 1 else array.shape[1]
        accessor: dict[str, Any] = {
            "bufferView": self.view(array.tobytes(), target),
            "componentType": COMPONENT_TYPES[array.dtype],
            "count": len(array),
            "type": VECTOR_TYPES[width],
        }
        if normalized:
            accessor["normalized"] = True
        if width == 3 and array.dtype == np.float32 and target == ARRAY_BUFFER:
            accessor["min"] = [float(v) for v in array.min(axis=0)]
            accessor["max"] = [float(v) for v in array.max(axis=0)]
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def glb(self, document: dict[str, Any]) -> bytes:
        """The GLB of ``document`` with this buffer."""
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        document = {
            **document,
            "accessors": self.accessors,
            "bufferViews": self.views,
            "buffers": [{"byteLength": len(self.blob)}],
        }
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


def _document(generator: str, drawn: list[tuple[dict[str, Any], dict[str, Any]]]) -> dict:
    """A glTF document of one node drawing one mesh of ``drawn`` primitives, each with its
    material."""
    return {
        "asset": {"version": "2.0", "generator": generator},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
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
) -> bytes:
    """A GLB of a triangle primitive: ``vertices`` (n, 3) glTF coordinates (y-up, about the
    tile's origin), ``faces`` (m, 3), ``colors`` (n, 4) sRGB bytes, ``feature_ids`` (n,) into
    ``features`` (``None``: content without features, a merged far level); the faces of
    textured vertices (``textures``) are drawn by a primitive per atlas page (at most
    ``atlas_size`` texels a side) instead, on the same vertices (their colours multiply the
    texture: white shows it as it is)."""
    builder = _Builder()
    positions = float32_positions(vertices)
    normals = vertex_normals(Surface(positions.astype(np.float64), faces))
    index_type = np.uint16 if len(vertices) < 65536 else np.uint32
    paged = _pages(textures, atlas_size) if textures is not None else None
    attributes = {
        "POSITION": builder.accessor(positions),
        "NORMAL": builder.accessor(normals),
        "COLOR_0": builder.accessor(linear_rgba16(colors), normalized=True),
    }
    if feature_ids is not None:
        attributes["_FEATURE_ID_0"] = builder.accessor(feature_ids.astype(np.float32))
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
        coordinates = {"TEXCOORD_0": builder.accessor(atlas_uv)}
        for page, image in enumerate(atlas.pages):
            texture = builder.texture(image, textures.photographic)  # type: ignore[union-attr]
            material = _material(image[..., 3].ravel(), texture=texture)
            drawn.append((primitive(faces[face_page == page], coordinates), material))
    document = _document(generator, drawn)
    document.update(builder.textures())
    if feature_ids is not None:
        document["extensionsUsed"] = [MESH_FEATURES, STRUCTURAL_METADATA]
        document["extensions"] = {STRUCTURAL_METADATA: property_table(features, builder.view)}
    return builder.glb(document)


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


def points_glb(positions: np.ndarray, colors: np.ndarray, generator: str) -> bytes:
    """A GLB of one ``POINTS`` primitive: ``positions`` (n, 3) glTF coordinates, ``colors``
    (n, 4) sRGB bytes."""
    builder = _Builder()
    attributes = {
        "POSITION": builder.accessor(float32_positions(positions)),
        "COLOR_0": builder.accessor(linear_rgba16(colors), normalized=True),
    }
    primitive = {"attributes": attributes, "mode": POINTS}
    document = _document(generator, [(primitive, _material(colors[:, 3], unlit=True))])
    document["extensionsUsed"] = [UNLIT]
    return builder.glb(document)
