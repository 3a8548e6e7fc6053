"""A glTF document being written (:class:`Document`): buffer views, accessors, textures,
materials (untextured ones shared by colour, one unlit white for point levels) and each level's
mesh (shared by instances of one geometry). A chain's part of it can be made apart, in the
worker that baked the chain (:class:`PartDocument`), with its indices as marks that
:meth:`Document.merge` fills in. Where the nodes go is :mod:`.lod`'s."""

from __future__ import annotations

import contextlib
import io
import re
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from typing import IO, Any

from ...model import Level
from .binary import LINEAR, LINEAR_MIPMAP_LINEAR, REPEAT
from .buffers import VIEW_HEAD, AccessorData, PrimitiveData, level_data
from .compression import NONE, StoredView, fallback_buffer, required
from .json_text import COMPACT, DataUri, JsonArray, Layout, json_object
from .texture_copies import TextureCopy

UNLIT = "KHR_materials_unlit"
SPOOL_BYTES = 1 << 20
"""How much of each temporary file (the buffer, each JSON array) stays in memory."""
_ATTRIBUTES = ("POSITION", "NORMAL", "TEXCOORD_0", "COLOR_0")
"""The order of a primitive's ``attributes`` in its JSON."""
_PRIMITIVE_DEPTH = 4
"""Where a primitive starts: ``meshes`` (1), a mesh (2), its ``primitives`` (3)."""
_MARK = re.compile(r'"\\u0000([A-Za-z])(\d*)"')
"""A mark in a :class:`PartDocument`'s text: a JSON string of NUL, a kind letter and a local
index. No other text can hold it: the JSON encoder escapes every control character, and ids
and attributes hold none (:mod:`~lodconvert.model.safe_text`)."""
_NEXT = "\x02"
"""What joins a part's elements of one array (raw, it is in no JSON text)."""
TRANSLATION = '"\\u0000T"'
"""The mark of a chain's root translation, which the scene frame decides (:mod:`.lod`)."""
_ARRAYS = {
    "a": "accessors",
    "v": "buffer_views",
    "i": "images",
    "s": "samplers",
    "t": "textures",
    "M": "meshes",
    "n": "nodes",
}
"""Each kind of index a mark stands for, and the array it indexes."""
MaterialKey = tuple[Any, ...] | None
"""What a material is shared by: ``("points", alpha mode)``, an untextured mesh's colour and
alpha mode, or ``None`` (not shared: a textured one)."""
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


@dataclass(frozen=True)
class Marked:
    """JSON text with marks (:data:`_MARK`), split at them: the texts ``between`` them (one
    more than the marks), and each mark's kind (one letter of ``kinds``) and local index."""

    between: tuple[str, ...]
    kinds: str
    indices: tuple[int, ...]

    @classmethod
    def of(cls, text: str) -> Marked:
        """``text`` split at its marks."""
        parts = _MARK.split(text)
        indices = tuple(int(index or 0) for index in parts[2::3])
        return cls(tuple(parts[0::3]), "".join(parts[1::3]), indices)

    def filled(self, values: list[str]) -> str:
        """The text with each mark replaced by its text in ``values``."""
        out = [""] * (2 * len(values) + 1)
        out[0::2] = self.between
        out[1::2] = values
        return "".join(out)


@dataclass(frozen=True)
class DocumentPart:
    """A chain's part of a document, made apart (:meth:`PartDocument.part`): the new elements
    of each array (``counts`` of them, in the order of :data:`_ARRAYS`; their ``texts``
    joined by :data:`_NEXT`), its materials (each with what it is shared by), its buffer bytes
    (from a 4-byte boundary), the bytes it adds to the meshopt fallback buffer, the extensions
    it uses (in order), and how its positions are stored."""

    texts: Marked
    counts: tuple[int, ...]
    materials: tuple[tuple[MaterialKey, str], ...]
    blob: bytes
    fallback_length: int
    extensions: tuple[str, ...]
    quantized: bool
    position_error: float


class Document:
    """A glTF document being written: its JSON arrays and binary buffer go to temporary files
    as they are made (:mod:`.json_text`), so memory holds the chain being added, not what was
    added before; :meth:`close` deletes them. Levels made here are compressed as ``compress``
    says (docs/compression.md), their textures with a ``copy`` where asked
    (:func:`~.texture_copies.check_texture_format`)."""

    def __init__(self, layout: Layout, compress: str = NONE, copy: str = "") -> None:
        self.layout = layout
        self.compress, self.copy = compress, copy
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
        self._materials: dict[MaterialKey, int] = {}
        self._shared: dict[int, tuple[Level, int]] = {}  # level of an instance → its mesh

    def _spool(self) -> IO[bytes]:
        return self._files.enter_context(tempfile.SpooledTemporaryFile(SPOOL_BYTES))

    def array(self, depth: int = 1) -> JsonArray:
        """A JSON array in a temporary file of its own (``depth`` 1: a top-level member)."""
        return JsonArray(self.layout, depth, self._spool())

    def ref(self, kind: str, index: int) -> str:
        """The JSON text of an ``index`` into the array of ``kind`` (:data:`_ARRAYS`), or of a
        byte offset into the buffer (``b``) or the fallback buffer (``f``)."""
        return str(index)

    def value(self, kind: str, index: int) -> Any:
        """What stands for an ``index`` (as :meth:`ref`) in JSON data."""
        return index

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

    def merge(self, part: DocumentPart, translation: str) -> None:
        """Add a chain's ``part`` made apart, its marks filled in with where it lands here
        (and its root's translation with the JSON text ``translation``)."""
        for extension in part.extensions:
            self.use(extension)
        bases = {kind: len(getattr(self, name)) for kind, name in _ARRAYS.items()}
        bases.update(b=self._aligned(part.blob) if part.blob else 0, f=self.fallback_length)
        materials: list[int] = []

        def filled(mark: re.Match[str]) -> str:  # a material's texture
            return str(bases[mark.group(1)] + int(mark.group(2)))

        for key, text in part.materials:
            materials.append(self._material_index(key, lambda text=text: _MARK.sub(filled, text)))
        marked = part.texts
        values = [
            translation if kind == "T" else str(materials[i] if kind == "m" else bases[kind] + i)
            for kind, i in zip(marked.kinds, marked.indices, strict=True)
        ]
        texts = marked.filled(values).split(_NEXT)
        at = 0
        for name, count in zip(_ARRAYS.values(), part.counts, strict=True):
            if count:
                getattr(self, name).extend_text(texts[at : at + count])
                at += count
        self.fallback_length += part.fallback_length
        self.quantized |= part.quantized
        self.position_error = max(self.position_error, part.position_error)

    def _aligned(self, data: bytes | memoryview) -> int:
        """Append ``data`` to the buffer at its next 4-byte boundary; where it starts."""
        pad = -self.blob_length % 4
        self._blob_pending += b"\x00" * pad
        self._blob_pending += data
        if len(self._blob_pending) >= SPOOL_BYTES:
            self.flush_blob()
        start = self.blob_length + pad
        self.blob_length = start + len(data)
        return start

    def _material_index(self, key: MaterialKey, text: Callable[[], str]) -> int:
        """The index of the material whose JSON ``text`` is made on demand: the one made
        before for its ``key`` where there is one (mesh colours up to :data:`_SHARED_MATERIALS`
        of them), else a new one."""
        if key is not None and key in self._materials:
            return self._materials[key]
        index = self.materials.append_text(text())
        if key is not None and (key[0] == "points" or len(self._materials) < _SHARED_MATERIALS):
            self._materials[key] = index
        return index

    def _buffer_view(
        self, data: bytes | memoryview, target: int | None = None, stored: StoredView | None = None
    ) -> int:
        """Append ``data`` (a packed view's: ``stored``'s) at the next 4-byte boundary of the
        buffer as a new buffer view."""
        start = self._aligned(data)
        if stored is not None and (stored.packed is not None or stored.stride is not None):
            fallback = self.value("f", self.fallback_length)
            view = stored.json(target, self.value("b", start), fallback)
            if stored.packed is not None:
                self.fallback_length += -(-stored.length // 4) * 4
            return self.buffer_views.append(view)
        if self.layout is COMPACT:  # as Layout.text lays it out, without the walk
            tail = "}" if target is None else f',"target":{target}}}'
            offset = self.ref("b", start)
            text = f'{{"buffer":0,"byteOffset":{offset},"byteLength":{len(data)}{tail}'
            return self.buffer_views.append_text(text)
        view = json_object(
            buffer=0, byteOffset=self.value("b", start), byteLength=len(data), target=target
        )
        return self.buffer_views.append(view)

    def _accessor(self, accessor: AccessorData) -> int:
        """Add an accessor (and its buffer view); its index."""
        view = self._buffer_view(accessor.view.data, accessor.target, accessor.view)
        if self.layout is COMPACT:
            text = VIEW_HEAD + self.ref("v", view) + accessor.compact_tail
            return self.accessors.append_text(text)
        return self.accessors.append({"bufferView": self.value("v", view), **accessor.fields})

    def _texture(self, data: tuple[bytes, str], copy: TextureCopy | None = None) -> int:
        """A texture of the image ``data`` (bytes, MIME type), preferring its ``copy``
        where there is one (named by its extension: the image stays for clients without it)."""
        image = {"mimeType": data[1], "bufferView": self.value("v", self._buffer_view(data[0]))}
        sampler = {
            "magFilter": LINEAR,
            "minFilter": LINEAR_MIPMAP_LINEAR,
            "wrapS": REPEAT,
            "wrapT": REPEAT,
        }
        texture: dict[str, Any] = {
            "sampler": self.value("s", self.samplers.append(sampler)),
            "source": self.value("i", self.images.append(image)),
        }
        if copy is not None:
            self.use(copy.extension)
            view = self.value("v", self._buffer_view(copy.data))
            index = self.images.append({"mimeType": copy.mime, "bufferView": view})
            texture["extensions"] = {copy.extension: {"source": self.value("i", index)}}
        return self.textures.append(texture)

    def _primitive(self, data: PrimitiveData) -> str:
        """A primitive's JSON text, its accessors (and texture) added."""
        ref = self.ref
        added = {name: self._accessor(accessor) for name, accessor in data.attributes.items()}
        texture = self._texture(data.image, data.copy) if data.image is not None else None
        attributes = [(name, ref("a", added[name])) for name in _ATTRIBUTES if name in added]
        members = [("attributes", self.layout.object_text(attributes, _PRIMITIVE_DEPTH + 1))]
        if data.indices is not None:
            members.append(("indices", ref("a", self._accessor(data.indices))))
        members.append(("mode", str(data.mode)))
        if data.base is None:
            material = self._point_material(data.alpha_mode)
        else:
            material = self._mesh_material(data.base, data.alpha_mode, texture)
        members.append(("material", ref("m", material)))
        return self.layout.object_text(members, _PRIMITIVE_DEPTH)

    def _mesh_material(self, base: list[float], alpha_mode: str, texture: int | None) -> int:
        """The material of a mesh primitive: one for all primitives of the same colour and
        alpha mode (a city's few surface colours), its own for a textured one."""
        key = (*base, alpha_mode) if texture is None else None
        index = None if texture is None else self.value("t", texture)

        def text() -> str:
            return self.layout.text(_material(base, alpha_mode, True, texture=index), 2)

        return self._material_index(key, text)

    def _point_material(self, alpha_mode: str) -> int:
        """The shared unlit white material of point levels (one per alpha mode)."""
        self.use(UNLIT)

        def text() -> str:
            white = [1.0, 1.0, 1.0, 1.0]
            material = _material(white, alpha_mode, double_sided=False, extensions={UNLIT: {}})
            return self.layout.text(material, 2)

        return self._material_index(("points", alpha_mode), text)

    def level_mesh(self, name: str, level: Level, shared: bool = False) -> int | None:
        """The mesh (named by the JSON text ``name``) of one level's geometry (``None`` when
        the level is empty). The levels of instances of one geometry (``shared``) share their
        meshes."""
        if not level.count:
            return None
        if id(level) in self._shared:
            return self._shared[id(level)][1]
        made = level_data(level, self.compress, self.copy)
        primitives = self.layout.array_text([self._primitive(data) for data in made], 3)
        mesh = self.meshes.append_text(
            self.layout.object_text([("primitives", primitives), ("name", name)], 2)
        )
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


class _Texts(JsonArray):
    """An array of a :class:`PartDocument`: its elements' texts, kept in a list."""

    def __init__(self, layout: Layout, depth: int) -> None:
        super().__init__(layout, depth, io.BytesIO())
        self.texts: list[str] = []

    def append_text(self, text: str) -> int:
        self.texts.append(text)
        self.count += 1
        return self.count - 1


class PartDocument(Document):
    """A chain's part of a document, made apart (in the worker that baked the chain): its
    indices and buffer offsets count from 0 and are written as marks (:data:`_MARK`), its
    materials are all its own, and its buffer stays in memory; :meth:`part` is what
    :meth:`Document.merge` takes."""

    def __init__(self, layout: Layout, compress: str = NONE, copy: str = "") -> None:
        self._made_materials: list[tuple[MaterialKey, str]] = []
        super().__init__(layout, compress, copy)

    def _spool(self) -> IO[bytes]:
        return io.BytesIO()

    def array(self, depth: int = 1) -> JsonArray:
        return _Texts(self.layout, depth)

    def ref(self, kind: str, index: int) -> str:
        return f'"\\u0000{kind}{index}"'

    def value(self, kind: str, index: int) -> Any:
        return f"\x00{kind}{index}"

    def flush_blob(self) -> None:
        """Keep the buffer in memory: it is the part's."""

    def _material_index(self, key: MaterialKey, text: Callable[[], str]) -> int:
        self._made_materials.append((key, text()))
        return len(self._made_materials) - 1

    def part(self) -> DocumentPart:
        """What was added, for :meth:`Document.merge`."""
        arrays = [getattr(self, name) for name in _ARRAYS.values()]
        texts = [text for array in arrays for text in array.texts]
        return DocumentPart(
            texts=Marked.of(_NEXT.join(texts)),
            counts=tuple(len(array.texts) for array in arrays),
            materials=tuple(self._made_materials),
            blob=bytes(self._blob_pending),
            fallback_length=self.fallback_length,
            extensions=tuple(self.extensions_used),
            quantized=self.quantized,
            position_error=self.position_error,
        )
