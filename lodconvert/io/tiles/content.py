"""One tile's content as a GLB (glTF 2.0, y-up, small float32 coordinates about the tile's
origin): buildings batched into one triangle primitive with vertex colours, ``_FEATURE_ID_0``
per vertex (``EXT_mesh_features``) and their ids, types and attributes in an
``EXT_structural_metadata`` property table; a baked point level as one ``POINTS`` primitive
with ``COLOR_0``."""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from typing import Any

import numpy as np

from ...colors import linear_rgba16
from ...model import Surface
from ..gltf.binary import (
    ARRAY_BUFFER,
    COMPONENT_TYPES,
    ELEMENT_ARRAY_BUFFER,
    POINTS,
    TRIANGLES,
    VECTOR_TYPES,
    pack_glb,
)
from ..gltf.buffers import alpha_mode_of, float32_positions, vertex_normals
from ..gltf.document import UNLIT
from .metadata import Feature, property_table

MESH_FEATURES = "EXT_mesh_features"
STRUCTURAL_METADATA = "EXT_structural_metadata"


class _Builder:
    """A GLB's binary buffer, buffer views and accessors."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []

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


def _document(generator: str, primitive: dict[str, Any], material: dict[str, Any]) -> dict:
    """A glTF document of one node drawing one primitive with one material."""
    return {
        "asset": {"version": "2.0", "generator": generator},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{**primitive, "material": 0}]}],
        "materials": [material],
    }


def _material(alpha: np.ndarray, unlit: bool = False) -> dict[str, Any]:
    """White (vertex colours carry the colour), non-metallic, fully rough."""
    material: dict[str, Any] = {
        "pbrMetallicRoughness": {
            "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": 1.0,
        },
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
) -> bytes:
    """A GLB of one triangle primitive: ``vertices`` (n, 3) glTF coordinates (y-up, about the
    tile's origin), ``faces`` (m, 3), ``colors`` (n, 4) sRGB bytes, ``feature_ids`` (n,) into
    ``features`` (``None``: content without features, a merged far level)."""
    builder = _Builder()
    positions = float32_positions(vertices)
    normals = vertex_normals(Surface(positions.astype(np.float64), faces))
    index_type = np.uint16 if len(vertices) < 65536 else np.uint32
    attributes = {
        "POSITION": builder.accessor(positions),
        "NORMAL": builder.accessor(normals),
        "COLOR_0": builder.accessor(linear_rgba16(colors), normalized=True),
    }
    if feature_ids is not None:
        attributes["_FEATURE_ID_0"] = builder.accessor(feature_ids.astype(np.float32))
    indices = builder.accessor(faces.ravel().astype(index_type), target=ELEMENT_ARRAY_BUFFER)
    primitive: dict[str, Any] = {"attributes": attributes, "indices": indices, "mode": TRIANGLES}
    if feature_ids is not None:
        ids = {"featureCount": len(features), "attribute": 0, "propertyTable": 0}
        primitive["extensions"] = {MESH_FEATURES: {"featureIds": [ids]}}
    document = _document(generator, primitive, _material(colors[:, 3]))
    if feature_ids is not None:
        document["extensionsUsed"] = [MESH_FEATURES, STRUCTURAL_METADATA]
        document["extensions"] = {STRUCTURAL_METADATA: property_table(features, builder.view)}
    return builder.glb(document)


def points_glb(positions: np.ndarray, colors: np.ndarray, generator: str) -> bytes:
    """A GLB of one ``POINTS`` primitive: ``positions`` (n, 3) glTF coordinates, ``colors``
    (n, 4) sRGB bytes."""
    builder = _Builder()
    attributes = {
        "POSITION": builder.accessor(float32_positions(positions)),
        "COLOR_0": builder.accessor(linear_rgba16(colors), normalized=True),
    }
    primitive = {"attributes": attributes, "mode": POINTS}
    document = _document(generator, primitive, _material(colors[:, 3], unlit=True))
    document["extensionsUsed"] = [UNLIT]
    return builder.glb(document)
