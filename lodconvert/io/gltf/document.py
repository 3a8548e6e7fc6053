"""A glTF document being written (:class:`Document`): buffer views, accessors, textures,
materials (untextured ones shared by colour, one unlit white for point levels) and each level's
mesh (shared by instances of one geometry). Where the nodes go is :mod:`.lod`'s."""

from __future__ import annotations

import contextlib
import tempfile
from typing import IO, Any

from ...model import Level
from .binary import LINEAR, LINEAR_MIPMAP_LINEAR, REPEAT
from .buffers import VIEW_HEAD, AccessorData, PrimitiveData, level_data
from .compression import NONE, WEBP, StoredView, fallback_buffer, required
from .json_text import COMPACT, DataUri, JsonArray, Layout, json_object

UNLIT = "KHR_materials_unlit"
SPOOL_BYTES = 1 << 20
"""How much of each temporary file (the buffer, each JSON array) stays in memory."""
_SHARED_MATERIALS = 4096
"""Distinct untextured mesh materials remembered for sharing (later ones are not shared)."""


def _material(
    base_color: list[float],
    alpha_mode: str,
    double_sided: bool,
    texture: int | None = None,
    extensions: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A non-metallic, fully rough material (``emissiveFactor`` written out, black)."""
    pbr = json_object(
        baseColorFactor=base_color,
        metallicFactor=0.0,
        roughnessFactor=1.0,
        baseColorTexture=None if texture is None else {"index": texture, "texCoord": 0},
    )
    return json_object(
        extensions=extensions,
        pbrMetallicRoughness=pbr,
        emissiveFactor=[0.0, 0.0, 0.0],
        alphaMode=alpha_mode,
        doubleSided=double_sided,
    )


class Document:
    """A glTF document being written: its JSON arrays and binary buffer go to temporary files
    as they are made (:mod:`.json_text`), so memory holds the chain being added, not what was
    added before; :meth:`close` deletes them. Levels made here are compressed as ``compress``
    says (docs/compression.md), their textures with a ``webp`` copy where asked."""

    def __init__(self, layout: Layout, compress: str = NONE, webp: bool = False) -> None:
        self._layout = layout
        self.compress, self.webp = compress, webp
        self._files = contextlib.ExitStack()
        self.blob = self._spool()
        self.blob_length = 0
        self._blob_pending = bytearray()
        self.accessors = self.array()
        self.buffer_views = self.array()
        self.images = self.array()
        self.materials = self.array()
        self.meshes = self.array()
        self.nodes = self.array()
        self.samplers = self.array()
        self.textures = self.array()
        self.extensions_used: list[str] = []
        self.fallback_length = 0
        """Bytes of the meshopt fallback buffer (the packed views' uncompressed layout)."""
        self.quantized = False
        self.position_error = 0.0
        """The largest difference of a stored coordinate from its float32 position."""
        self.mesh_nodes: dict[int, dict[str, Any]] = {}
        """The node fields (quantized positions' transform) of each mesh that needs them."""
        self._point_materials: dict[str, int] = {}
        self._mesh_materials: dict[tuple[float | str, ...], int] = {}
        self._shared: dict[int, tuple[Level, int]] = {}  # level of an instance → its mesh

    def _spool(self) -> IO[bytes]:
        return self._files.enter_context(tempfile.SpooledTemporaryFile(SPOOL_BYTES))

    def array(self, depth: int = 1) -> JsonArray:
        """A JSON array in a temporary file of its own (``depth`` 1: a top-level member)."""
        return JsonArray(self._layout, depth, self._spool())

    def flush_blob(self) -> None:
        """Write what was added to the buffer to its file."""
        self.blob.write(self._blob_pending)
        self._blob_pending.clear()

    def close(self) -> None:
        """Delete the temporary files."""
        self._files.close()

    def use(self, extension: str) -> None:
        """List ``extension`` in ``extensionsUsed``."""
        if extension not in self.extensions_used:
            self.extensions_used.append(extension)

    def _buffer_view(
        self, data: bytes | memoryview, target: int | None = None, stored: StoredView | None = None
    ) -> int:
        """Append ``data`` (a packed view's: ``stored``'s) at the next 4-byte boundary of the
        buffer as a new buffer view."""
        pad = -self.blob_length % 4
        self._blob_pending += b"\x00" * pad
        self._blob_pending += data
        if len(self._blob_pending) >= SPOOL_BYTES:
            self.flush_blob()
        start = self.blob_length + pad
        self.blob_length = start + len(data)
        if stored is not None and (stored.packed is not None or stored.stride is not None):
            view = stored.json(target, start, self.fallback_length)
            if stored.packed is not None:
                self.fallback_length += -(-stored.length // 4) * 4
            return self.buffer_views.append(view)
        if self._layout is COMPACT:  # as Layout.text lays it out, without the walk
            tail = "}" if target is None else f',"target":{target}}}'
            text = f'{{"buffer":0,"byteOffset":{start},"byteLength":{len(data)}{tail}'
            return self.buffer_views.append_text(text)
        view = json_object(buffer=0, byteOffset=start, byteLength=len(data), target=target)
        return self.buffer_views.append(view)

    def _accessor(self, accessor: AccessorData) -> int:
        """Add an accessor (and its buffer view); its index."""
        view = self._buffer_view(accessor.view.data, accessor.target, accessor.view)
        if self._layout is COMPACT:
            return self.accessors.append_text(VIEW_HEAD + str(view) + accessor.compact_tail)
        return self.accessors.append({"bufferView": view, **accessor.fields})

    def _texture(self, data: tuple[bytes, str], webp: bytes | None = None) -> int:
        """A texture of the image ``data`` (bytes, MIME type), preferring its ``webp`` copy
        where there is one (``EXT_texture_webp``: the image stays for clients without it)."""
        image = {"mimeType": data[1], "bufferView": self._buffer_view(data[0])}
        sampler = {
            "magFilter": LINEAR,
            "minFilter": LINEAR_MIPMAP_LINEAR,
            "wrapS": REPEAT,
            "wrapT": REPEAT,
        }
        texture: dict[str, Any] = {
            "sampler": self.samplers.append(sampler),
            "source": self.images.append(image),
        }
        if webp is not None:
            self.use(WEBP)
            copy = {"mimeType": "image/webp", "bufferView": self._buffer_view(webp)}
            texture["extensions"] = {WEBP: {"source": self.images.append(copy)}}
        return self.textures.append(texture)

    def _primitive(self, data: PrimitiveData) -> dict[str, Any]:
        """A primitive's JSON, its accessors (and texture) added."""
        added = {name: self._accessor(accessor) for name, accessor in data.attributes.items()}
        texture = self._texture(data.image, data.webp) if data.image is not None else None
        primitive: dict[str, Any] = {
            "attributes": json_object(
                POSITION=added["POSITION"],
                NORMAL=added.get("NORMAL"),
                TEXCOORD_0=added.get("TEXCOORD_0"),
                COLOR_0=added.get("COLOR_0"),
            )
        }
        if data.indices is not None:
            primitive["indices"] = self._accessor(data.indices)
        primitive["mode"] = data.mode
        if data.base is None:
            primitive["material"] = self._point_material(data.alpha_mode)
        else:
            primitive["material"] = self._mesh_material(data.base, data.alpha_mode, texture)
        return primitive

    def _mesh_material(self, base: list[float], alpha_mode: str, texture: int | None) -> int:
        """The material of a mesh primitive: one for all primitives of the same colour and
        alpha mode (a city's few surface colours), its own for a textured one."""
        key = (*base, alpha_mode)
        if texture is None and key in self._mesh_materials:
            return self._mesh_materials[key]
        index = self.materials.append(_material(base, alpha_mode, True, texture=texture))
        if texture is None and len(self._mesh_materials) < _SHARED_MATERIALS:
            self._mesh_materials[key] = index
        return index

    def _point_material(self, alpha_mode: str) -> int:
        """The shared unlit white material of point levels (one per alpha mode)."""
        if alpha_mode not in self._point_materials:
            self.use(UNLIT)
            material = _material(
                [1.0, 1.0, 1.0, 1.0], alpha_mode, double_sided=False, extensions={UNLIT: {}}
            )
            self._point_materials[alpha_mode] = self.materials.append(material)
        return self._point_materials[alpha_mode]

    def level_mesh(
        self,
        name: str,
        level: Level,
        shared: bool = False,
        made: list[PrimitiveData] | None = None,
    ) -> int | None:
        """The mesh of one level's geometry (``None`` when the level is empty), of its
        primitives as a worker ``made`` them or made here. The levels of instances of one
        geometry (``shared``) share their meshes."""
        if not level.count:
            return None
        if id(level) in self._shared:
            return self._shared[id(level)][1]
        made = made or level_data(level, self.compress, self.webp)
        primitives = [self._primitive(data) for data in made]
        mesh = self.meshes.append({"primitives": primitives, "name": name})
        stored = made[0].stored
        if stored is not None:
            self.quantized |= stored.quantized
            self.position_error = max(self.position_error, stored.error)
            if stored.node:
                self.mesh_nodes[mesh] = stored.node
        if shared:  # kept alive with the level, so its id stays unique
            self._shared[id(level)] = (level, mesh)
        return mesh

    def json_value(
        self, asset: dict[str, Any], scene_roots: JsonArray | list[int], data_uri: bool
    ) -> dict[str, Any]:
        """The glTF JSON object of ``asset`` and one scene of ``scene_roots``; the buffer is
        embedded as a base64 data URI when ``data_uri``, else left for a GLB BIN chunk."""
        buffers = []
        if self.blob_length:
            uri = DataUri(self.blob) if data_uri else None
            buffers.append(json_object(uri=uri, byteLength=self.blob_length))
        if self.fallback_length:
            buffers.append(fallback_buffer(self.fallback_length))
        needed = required(self.quantized, self.fallback_length > 0)
        return json_object(
            accessors=self.accessors,
            asset=asset,
            bufferViews=self.buffer_views,
            buffers=buffers,
            extensionsUsed=self.extensions_used + needed,
            extensionsRequired=needed or None,
            images=self.images,
            materials=self.materials,
            meshes=self.meshes,
            nodes=self.nodes,
            samplers=self.samplers,
            scene=0,
            scenes=[json_object(nodes=scene_roots)],
            textures=self.textures,
        )
