"""glTF 2.0 output (``.glb`` and self-contained ``.gltf``) with levels chained by ``MSFT_lod``.

Each chain becomes a root node named after the object, translated to ``chain.origin`` (float64
JSON numbers, so georeferenced coordinates keep their precision while level geometry stays small
in float32 buffers). Its only child is the finest level's node, which carries
``extensions.MSFT_lod.ids`` (the coarser level nodes, finest to coarsest) and
``extras.MSFT_screencoverage``. Coarser nodes belong to no scene and no parent: a client without
``MSFT_lod`` loads the finest level only, one with it substitutes them for the finest node.

No viewer switches levels by distance from ``MSFT_lod``, so the switching data (cutoffs, bake
parameters, point sizes) is also written to ``extras.lodconvert`` on the nodes and the asset.
Colours in buffers are linear, as glTF requires; :func:`read_lod_gltf` converts them back to the
sRGB bytes that were written.
"""

from __future__ import annotations

import base64
import dataclasses
import functools
import io
import json
import math
import struct
from collections.abc import Iterable
from typing import Any, BinaryIO

import numpy as np
import pygltflib as gl
from PIL import Image as PILImage

from ...errors import LodConvertError
from ...model import Level, LodChain, PointCloud, Surface
from ...ranges import ReferenceView, screen_coverage
from .. import OutputInfo

MSFT_LOD = "MSFT_lod"
UNLIT = "KHR_materials_unlit"
COVERAGE_MEANING = "projected bounding-box diagonal / viewport height at the reference view"
GLB_MAGIC = b"glTF"
GLB_JSON = b"JSON"
GLB_BIN = b"BIN\x00"
DATA_URI = "data:application/octet-stream;base64,"
_TYPES = {1: gl.SCALAR, 2: gl.VEC2, 3: gl.VEC3, 4: gl.VEC4}
_COMPONENTS = {
    np.dtype(np.float32): gl.FLOAT,
    np.dtype(np.uint8): gl.UNSIGNED_BYTE,
    np.dtype(np.uint16): gl.UNSIGNED_SHORT,
    np.dtype(np.uint32): gl.UNSIGNED_INT,
}
_DTYPES = {code: dtype for dtype, code in _COMPONENTS.items()}
_WIDTHS = {gl.SCALAR: 1, gl.VEC2: 2, gl.VEC3: 3, gl.VEC4: 4}


def float32_positions(positions: np.ndarray) -> np.ndarray:
    """``positions`` as float32, or :class:`LodConvertError` where a coordinate is beyond the
    float32 range (it would be written as infinity)."""
    largest = float(np.abs(positions).max(initial=0.0))
    if not largest <= np.finfo(np.float32).max:
        raise LodConvertError(
            f"a level coordinate of magnitude {largest:.3g} is beyond the float32 range of glTF"
        )
    return positions.astype(np.float32)


def _srgb_table() -> np.ndarray:
    c = np.arange(256) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


SRGB_TO_LINEAR = _srgb_table()
"""Linear value in [0, 1] of each sRGB byte."""
_SRGB_MIDPOINTS = (SRGB_TO_LINEAR[1:] + SRGB_TO_LINEAR[:-1]) / 2.0


# --- colour and geometry conversions ------------------------------------------------------------


def linear_rgba(rgba: np.ndarray) -> np.ndarray:
    """sRGB RGBA bytes (..., 4) → linear float64 in [0, 1] (alpha is linear already: /255)."""
    out = SRGB_TO_LINEAR[rgba]
    out[..., 3] = rgba[..., 3] / 255.0
    return out


def srgb_rgba(linear: np.ndarray) -> np.ndarray:
    """Linear RGBA floats (..., 4) → sRGB bytes: the nearest byte, so that :func:`linear_rgba`
    followed by any encoding finer than the byte spacing round-trips exactly."""
    out = np.searchsorted(_SRGB_MIDPOINTS, np.clip(linear, 0.0, 1.0)).astype(np.uint8)
    out[..., 3] = np.clip(np.rint(linear[..., 3] * 255.0), 0, 255).astype(np.uint8)
    return out


def _unit16(values: np.ndarray) -> np.ndarray:
    """Floats in [0, 1] as normalised unsigned shorts."""
    return np.rint(np.clip(values, 0.0, 1.0) * 65535.0).astype(np.uint16)


def unit_normals(normals: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length as float32; zero or non-finite rows become (0, 0, 1)."""
    n = np.asarray(normals, dtype=np.float64)
    length = np.linalg.norm(n, axis=1) if len(n) else np.zeros(0)
    ok = np.isfinite(length) & (length > 0)
    out = np.tile([0.0, 0.0, 1.0], (len(n), 1))
    out[ok] = n[ok] / length[ok, None]
    return out.astype(np.float32)


def vertex_normals(surface: Surface) -> np.ndarray:
    """Area-weighted unit vertex normals (n, 3) float32; unused vertices get (0, 0, 1)."""
    tri = surface.vertices[surface.faces]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 · area
    corners = surface.faces.ravel()
    n = len(surface.vertices)
    summed = np.stack(
        [np.bincount(corners, np.repeat(face_n[:, k], 3), minlength=n) for k in range(3)], axis=1
    )
    return unit_normals(summed)


def _alpha_mode(*alphas: np.ndarray | None) -> str:
    """``BLEND`` when any given alpha byte is below 255, else ``OPAQUE``."""
    blend = any(a is not None and a.size and int(a.min()) < 255 for a in alphas)
    return gl.BLEND if blend else gl.OPAQUE


def _png(rgba: np.ndarray) -> bytes:
    """Deterministic PNG bytes of an RGBA uint8 image (no timestamps or text chunks)."""
    out = io.BytesIO()
    PILImage.fromarray(np.ascontiguousarray(rgba, dtype=np.uint8), "RGBA").save(out, format="PNG")
    return out.getvalue()


def _plain(value: Any) -> Any:
    """``value`` as JSON-able Python data: numpy scalars and arrays unpacked, tuples as lists,
    non-finite floats as ``None``, unknown objects as their ``str``."""
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, str | int):
        return value
    return str(value)


# --- extras -------------------------------------------------------------------------------------


def _level_params(level: Level) -> dict[str, Any]:
    """Bake parameters of a point level (empty for a mesh level)."""
    if not level.is_points:
        return {}
    params = level.params
    out: dict[str, Any] = {}
    if params is not None:
        out.update(
            resolution=params.resolution,
            slices=params.slices,
            point_size_px=params.point_size,
            filter=params.filter,
        )
    out.update(spacing=level.spacing, design_distance=level.design_distance)
    return _plain(out)


def _chain_extras(chain: LodChain) -> dict[str, Any]:
    """``extras.lodconvert`` of a chain's finest node: switching data and every level's facts."""
    return _plain(
        {
            "cutoffs": chain.cutoffs,
            "alpha": chain.alpha,
            "beta": chain.beta,
            "gamma": chain.gamma,
            "xs": chain.xs,
            "culled": chain.culled,
            "center": chain.center,
            **(
                {"transform": chain.transform.ravel(), "origin": chain.origin}
                if chain.transform is not None
                else {}
            ),
            "levels": [
                {"name": lv.name, "kind": lv.kind, "count": lv.count, **_level_params(lv)}
                for lv in chain.levels
            ],
        }
    )


def _coverages(chain: LodChain, view: ReferenceView) -> list[float]:
    """``MSFT_screencoverage``: one threshold per cutoff, then 0 unless the chain is culled."""
    values = [screen_coverage(chain.alpha, d, view) for d in chain.cutoffs]
    return [float(v) for v in values] + ([] if chain.culled else [0.0])


def _asset_extras(info: OutputInfo) -> dict[str, Any]:
    """``asset.extras.lodconvert``: provenance and the meaning of the coverage values."""
    return _plain(
        {
            "source": info.source,
            "crs": info.crs,
            "reference_view": {"height_px": info.view.height_px, "fov_y_deg": info.view.fov_y_deg},
            "screencoverage": COVERAGE_MEANING,
            "options": info.options,
        }
    )


# --- document assembly --------------------------------------------------------------------------


class _Document:
    """A glTF document being assembled: pygltflib objects plus one growing binary buffer."""

    def __init__(self, info: OutputInfo) -> None:
        self.reference_view = info.view
        self.gltf = gl.GLTF2(
            asset=gl.Asset(generator=info.generator, extras={"lodconvert": _asset_extras(info)}),
            scene=0,
            scenes=[gl.Scene(nodes=[])],
        )
        self.blob = bytearray()
        self._point_materials: dict[str, int] = {}
        self._shared: dict[int, tuple[Level, int]] = {}  # level of an instance → its mesh

    @staticmethod
    def _append(items: list[Any], item: Any) -> int:
        items.append(item)
        return len(items) - 1

    def _use(self, extension: str) -> None:
        if extension not in self.gltf.extensionsUsed:
            self.gltf.extensionsUsed.append(extension)

    def _buffer_view(self, data: bytes, target: int | None) -> int:
        """Append ``data`` at the next 4-byte boundary of the buffer as a new buffer view."""
        self.blob.extend(b"\x00" * (-len(self.blob) % 4))
        view = gl.BufferView(
            buffer=0, byteOffset=len(self.blob), byteLength=len(data), target=target
        )
        self.blob.extend(data)
        return self._append(self.gltf.bufferViews, view)

    def _accessor(
        self,
        array: np.ndarray,
        target: int = gl.ARRAY_BUFFER,
        normalized: bool = False,
        bounds: bool = False,
    ) -> int:
        """An accessor over ``array`` ((k,) scalars or (k, w) vectors, dtype of the buffer)."""
        data = np.ascontiguousarray(array)
        width = 1 if data.ndim == 1 else data.shape[1]
        accessor = gl.Accessor(
            bufferView=self._buffer_view(
                data.astype(data.dtype.newbyteorder("<")).tobytes(), target
            ),
            componentType=_COMPONENTS[data.dtype],
            normalized=True if normalized else None,
            count=len(data),
            type=_TYPES[width],
        )
        if bounds:
            accessor.min = [float(v) for v in data.min(axis=0)]
            accessor.max = [float(v) for v in data.max(axis=0)]
        return self._append(self.gltf.accessors, accessor)

    def _colors(self, rgba: np.ndarray) -> int:
        """COLOR_0 accessor: VEC4 normalised unsigned shorts in linear space."""
        return self._accessor(_unit16(linear_rgba(rgba)), normalized=True)

    def _texture(self, rgba: np.ndarray) -> int:
        image = gl.Image(bufferView=self._buffer_view(_png(rgba), None), mimeType="image/png")
        sampler = gl.Sampler(
            magFilter=gl.LINEAR,
            minFilter=gl.LINEAR_MIPMAP_LINEAR,
            wrapS=gl.REPEAT,
            wrapT=gl.REPEAT,
        )
        texture = gl.Texture(
            source=self._append(self.gltf.images, image),
            sampler=self._append(self.gltf.samplers, sampler),
        )
        return self._append(self.gltf.textures, texture)

    def _mesh_primitive(self, surface: Surface) -> gl.Primitive:
        attributes = gl.Attributes(
            POSITION=self._accessor(float32_positions(surface.vertices), bounds=True),
            NORMAL=self._accessor(vertex_normals(surface)),
        )
        if surface.vertex_colors is not None:
            attributes.COLOR_0 = self._colors(surface.vertex_colors)
        base = linear_rgba(surface.material_color)
        pbr = gl.PbrMetallicRoughness(
            baseColorFactor=[float(v) for v in base], metallicFactor=0.0, roughnessFactor=1.0
        )
        textured = surface.texture is not None and surface.uv is not None
        if textured:
            # Surface.uv has its origin at the image's bottom-left, glTF at the top-left.
            flipped = np.column_stack([surface.uv[:, 0], 1.0 - surface.uv[:, 1]])
            attributes.TEXCOORD_0 = self._accessor(flipped.astype(np.float32))
            pbr.baseColorTexture = gl.TextureInfo(index=self._texture(surface.texture))
        material = gl.Material(
            pbrMetallicRoughness=pbr,
            doubleSided=True,
            alphaMode=_alpha_mode(
                surface.material_color[3:],
                None if surface.vertex_colors is None else surface.vertex_colors[:, 3],
                surface.texture[..., 3] if textured else None,
            ),
        )
        index_type = np.uint16 if len(surface.vertices) < 65536 else np.uint32
        return gl.Primitive(
            attributes=attributes,
            indices=self._accessor(
                surface.faces.ravel().astype(index_type), target=gl.ELEMENT_ARRAY_BUFFER
            ),
            mode=gl.TRIANGLES,
            material=self._append(self.gltf.materials, material),
        )

    def _point_material(self, alpha_mode: str) -> int:
        """The shared unlit white material of point levels (one per alpha mode)."""
        if alpha_mode not in self._point_materials:
            self._use(UNLIT)
            material = gl.Material(
                pbrMetallicRoughness=gl.PbrMetallicRoughness(
                    baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0, roughnessFactor=1.0
                ),
                alphaMode=alpha_mode,
                extensions={UNLIT: {}},
            )
            self._point_materials[alpha_mode] = self._append(self.gltf.materials, material)
        return self._point_materials[alpha_mode]

    def _point_primitive(self, points: PointCloud) -> gl.Primitive:
        attributes = gl.Attributes(
            POSITION=self._accessor(float32_positions(points.positions), bounds=True),
            NORMAL=self._accessor(unit_normals(points.normals)),
            COLOR_0=self._colors(points.colors),
        )
        return gl.Primitive(
            attributes=attributes,
            mode=gl.POINTS,
            material=self._point_material(_alpha_mode(points.colors[:, 3])),
        )

    def _level_node(self, chain: LodChain, level: Level) -> gl.Node:
        """A node holding one level's geometry (no mesh when the level is empty). The levels
        of instances of one geometry share their meshes."""
        name = f"{chain.object_id}_{level.name}"
        node = gl.Node(name=name)
        if not level.count:
            return node
        if id(level) in self._shared:
            node.mesh = self._shared[id(level)][1]
            return node
        if level.mesh is not None:
            primitives = [self._mesh_primitive(part) for part in level.mesh.parts]
        else:
            primitives = [self._point_primitive(level.points)]
        node.mesh = self._append(self.gltf.meshes, gl.Mesh(name=name, primitives=primitives))
        if chain.transform is not None:  # kept alive with the level, so its id stays unique
            self._shared[id(level)] = (level, node.mesh)
        return node

    def add_chain(self, chain: LodChain) -> None:
        """Add a chain's root node (to the scene), finest node (its child) and coarser nodes.
        The root is translated to the chain's origin, or placed by the instance's matrix."""
        nodes = self.gltf.nodes
        placed = np.eye(4) if chain.transform is None else chain.transform.copy()
        placed[:3, 3] += placed[:3, :3] @ chain.origin
        if np.allclose(placed[:3, :3], np.eye(3), rtol=0, atol=0):
            root = gl.Node(name=chain.object_id, translation=[float(v) for v in placed[:3, 3]])
        else:
            root = gl.Node(name=chain.object_id, matrix=[float(v) for v in placed.T.ravel()])
        if chain.metadata:  # the object's attributes, where a GIS user looks for them
            root.extras = {"attributes": _plain(chain.metadata)}
        root_index = self._append(nodes, root)
        self.gltf.scenes[0].nodes.append(root_index)
        finest = self._level_node(chain, chain.levels[0])
        root.children = [self._append(nodes, finest)]
        ids = []
        for level, switch_in in zip(chain.levels[1:], chain.cutoffs, strict=False):
            node = self._level_node(chain, level)
            node.extras = {
                "lodconvert": {
                    "level": level.name,
                    **_level_params(level),
                    "switch_in": float(switch_in),
                }
            }
            ids.append(self._append(nodes, node))
        extras: dict[str, Any] = {}
        if ids:
            self._use(MSFT_LOD)
            finest.extensions = {MSFT_LOD: {"ids": ids}}
            extras["MSFT_screencoverage"] = _coverages(chain, self.reference_view)
        extras["lodconvert"] = _chain_extras(chain)
        finest.extras = extras

    def finish(self, data_uri: bool) -> tuple[dict[str, Any], bytes]:
        """The glTF JSON object and the buffer bytes; the buffer is embedded in the JSON as a
        base64 data URI when ``data_uri``, else left for a GLB BIN chunk."""
        blob = bytes(self.blob)
        if blob:
            uri = DATA_URI + base64.b64encode(blob).decode("ascii") if data_uri else None
            self.gltf.buffers = [gl.Buffer(byteLength=len(blob), uri=uri)]
        return _json_of(self.gltf), blob


def _json_of(value: Any) -> Any:
    """pygltflib objects as JSON data, without ``None`` and empty values, leaving ``extras``
    and ``extensions`` contents as they are (their ``null``, ``[]`` and ``{}`` mean something).
    One pass, no copies (pygltflib's own ``gltf_asdict`` deep-copies every value)."""
    if isinstance(value, list | tuple):
        return [_json_of(v) for v in value]
    if isinstance(value, dict):
        items: Iterable[tuple[str, Any]] = value.items()
    elif isinstance(value, gl.Attributes):
        items = vars(value).items()
    elif dataclasses.is_dataclass(value):
        items = ((name, getattr(value, name)) for name in _field_names(type(value)))
    else:
        return value
    out = {}
    for key, item in items:
        kept = item if key in ("extras", "extensions") else _json_of(item)
        if kept is not None and not (isinstance(kept, list | dict) and not kept):
            out[key] = kept
    return out


@functools.cache
def _field_names(cls: type) -> tuple[str, ...]:
    return tuple(field.name for field in dataclasses.fields(cls))


def _document(chains: Iterable[LodChain], info: OutputInfo) -> _Document:
    doc = _Document(info)
    for chain in chains:
        doc.add_chain(chain)
    return doc


def _json_bytes(obj: dict[str, Any], indent: int | None = None) -> bytes:
    separators = (",", ":") if indent is None else (",", ": ")
    return json.dumps(obj, indent=indent, separators=separators, allow_nan=False).encode("utf-8")


def _padded(data: bytes, fill: bytes) -> bytes:
    return data + fill * (-len(data) % 4)


def write_glb(chains: Iterable[LodChain], handle: BinaryIO, info: OutputInfo) -> None:
    """Write ``chains`` as binary glTF (one JSON chunk, one BIN chunk) to ``handle``."""
    obj, blob = _document(chains, info).finish(data_uri=False)
    chunks = [(GLB_JSON, _padded(_json_bytes(obj), b" "))]
    if blob:
        chunks.append((GLB_BIN, _padded(blob, b"\x00")))
    total = 12 + sum(8 + len(data) for _, data in chunks)
    handle.write(struct.pack("<4sII", GLB_MAGIC, 2, total))
    for kind, data in chunks:
        handle.write(struct.pack("<I4s", len(data), kind))
        handle.write(data)


def write_gltf(chains: Iterable[LodChain], handle: BinaryIO, info: OutputInfo) -> None:
    """Write ``chains`` as one self-contained glTF JSON file (buffer as a base64 data URI)."""
    obj, _ = _document(chains, info).finish(data_uri=True)
    handle.write(_json_bytes(obj, indent=1))
    handle.write(b"\n")
