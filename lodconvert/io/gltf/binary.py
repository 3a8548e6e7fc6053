"""glTF's binary side, in one place: GLB framing (glTF 2.0 §4.4: a 12-byte header, a JSON chunk
padded with spaces, an optional BIN chunk padded with zeros) read with its every rule checked
(:func:`glb_chunks`, :func:`split_glb`) and written (:func:`pack_glb`), the table of accessor
component types and widths, and accessor values read from a buffer."""

from __future__ import annotations

import io
import json
import os
import shutil
import struct
from collections.abc import Callable
from typing import IO, Any, BinaryIO, NamedTuple

import numpy as np

MAGIC = b"glTF"
VERSION = 2
JSON_CHUNK = b"JSON"
BIN_CHUNK = b"BIN\x00"
HEADER_SIZE = 12
CHUNK_HEADER_SIZE = 8
_HEADER = struct.Struct("<4sII")
"""magic, version, length of the whole file."""
_CHUNK_HEADER = struct.Struct("<I4s")
"""length of the chunk's data, its type."""
_COPY_BLOCK = 1 << 20
"""Bytes copied at a time from a chunk's file."""

FLOAT = 5126
"""The componentType of 32-bit floats."""
COMPONENT_DTYPES = {
    5120: np.dtype("<i1"),
    5121: np.dtype("<u1"),
    5122: np.dtype("<i2"),
    5123: np.dtype("<u2"),
    5125: np.dtype("<u4"),
    FLOAT: np.dtype("<f4"),
}
"""numpy dtype (little-endian) of each accessor componentType."""
COMPONENT_SIZES = {code: dtype.itemsize for code, dtype in COMPONENT_DTYPES.items()}
"""Bytes of each accessor componentType."""
COMPONENT_TYPES = {dtype: code for code, dtype in COMPONENT_DTYPES.items()}
"""The accessor componentType of each dtype."""
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
"""Components of each accessor type."""
VECTOR_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}
"""The accessor type of scalars (1) and of vectors of each width."""
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
"""Buffer view targets: vertex attributes, indices."""
POINTS, TRIANGLES = 0, 4
"""Primitive modes (triangles the default)."""
LINEAR, LINEAR_MIPMAP_LINEAR, REPEAT, CLAMP_TO_EDGE = 9729, 9987, 10497, 33071
"""Sampler filters and wrap modes."""
MESHOPT = "EXT_meshopt_compression"
"""The extension whose buffer views :func:`accessor_values` decodes."""
MESHOPT_EXPANSION = 64
"""The most meshopt data can grow by decoding (a block's 256 zero deltas of a byte take a
4-byte header): a view claiming more is refused before anything is allocated."""


class GlbError(ValueError):
    """GLB framing, or accessor data, that cannot be read."""


Span = tuple[int, int]
"""Where a chunk's data is in the file: (offset, length)."""


class GlbChunks(NamedTuple):
    """Where the JSON text (without zero padding) and the BIN chunk (``None``: none) are."""

    json: Span
    bin: Span | None


Report = Callable[[str, str], None]
"""Called with (code, message) for each broken rule."""


def is_glb(data: bytes | memoryview) -> bool:
    """Whether ``data`` starts as a GLB file does."""
    return bytes(data[:4]) == MAGIC


def _chunk_name(kind: bytes) -> str:
    return {JSON_CHUNK: "JSON", BIN_CHUNK: "BIN"}.get(kind, repr(kind))


def _header(data: bytes | memoryview, report: Report) -> int | None:
    """The file length that GLB ``data``'s header declares, its rules checked; ``None`` when
    no chunk can be read."""
    if not is_glb(data):
        start = bytes(data[:64]).lstrip()[:1]
        hint = " (it looks like glTF JSON: name it .gltf)" if start == b"{" else ""
        report(
            "GLB_MAGIC",
            f"not a GLB file: the first 4 bytes are {bytes(data[:4])!r}, not 'glTF'{hint}",
        )
        return None
    if len(data) < HEADER_SIZE:
        report("GLB_HEADER", f"truncated GLB: {len(data)} bytes, less than the 12-byte header")
        return None
    _, version, length = _HEADER.unpack_from(data)
    if version != VERSION:
        report("GLB_VERSION", f"GLB version {version}; glTF 2.0 files are version 2")
        return None
    if length > len(data):
        report(
            "GLB_LENGTH",
            f"truncated GLB: declared length {length} but the file has {len(data)} bytes",
        )
        return None
    if length < len(data):
        report(
            "GLB_LENGTH",
            f"declared length {length} but the file has {len(data)} bytes "
            f"({len(data) - length} after the declared end)",
        )
    if length <= HEADER_SIZE:
        report("GLB_JSON_CHUNK", "the GLB has no chunks; its first must be JSON")
        return None
    return length


def glb_chunks(data: bytes | memoryview, report: Report) -> GlbChunks | None:
    """The JSON text and BIN chunk of GLB ``data``, checked against the framing of glTF 2.0
    (section 4.4), each broken rule reported; ``None`` when no JSON chunk can be read."""
    length = _header(data, report)
    if length is None:
        return None
    json_chunk: Span | None = None
    bin_chunk: Span | None = None
    offset, index = HEADER_SIZE, 0
    while offset < length:
        where = f"chunk {index} at byte {offset}"
        if length - offset < CHUNK_HEADER_SIZE:
            report(
                "GLB_CHUNK_HEADER",
                f"{where}: {length - offset} bytes left, less than a chunk header (8)",
            )
            break
        size, kind = _CHUNK_HEADER.unpack_from(data, offset)
        start = offset + CHUNK_HEADER_SIZE
        where = f"chunk {index} ({_chunk_name(kind)}) at byte {offset}"
        if size > length - start:
            report(
                "GLB_CHUNK_LENGTH", f"{where} declares {size} bytes but {length - start} are left"
            )
            break
        if size % 4:
            report("GLB_CHUNK_ALIGNMENT", f"{where} has {size} bytes, not a multiple of 4")
        body = (start, size)
        if index == 0 and kind != JSON_CHUNK:
            report("GLB_JSON_CHUNK", f"the first chunk is {_chunk_name(kind)}, not JSON")
        elif index == 0:
            json_chunk = body
        elif kind == JSON_CHUNK:
            report("GLB_CHUNK_ORDER", f"{where}: only the first chunk may be JSON")
        elif kind == BIN_CHUNK and index == 1:
            bin_chunk = body
        elif kind == BIN_CHUNK:
            report("GLB_CHUNK_ORDER", f"{where}: only the second chunk may be BIN")
        offset, index = start + size, index + 1
    if json_chunk is None:
        return None
    start, size = json_chunk
    text = _stripped_length(data, start, size)
    if text < size:
        report(
            "GLB_JSON_PADDING",
            f"the JSON chunk ends in {size - text} zero bytes; its padding must be spaces (0x20)",
        )
    return GlbChunks((start, text), bin_chunk)


def _stripped_length(data: bytes | memoryview, start: int, size: int) -> int:
    """Length of ``data[start : start + size]`` without its trailing zero bytes (read from
    the end, a block at a time)."""
    end = start + size
    while end > start:
        block = bytes(data[max(start, end - 4096) : end])
        kept = len(block.rstrip(b"\x00"))
        if kept:
            return end - len(block) + kept - start
        end -= len(block)
    return 0


def split_glb(data: bytes | memoryview) -> tuple[memoryview, memoryview]:
    """The JSON text and BIN chunk data (empty when there is none) of GLB ``data``, as views
    of it; :class:`GlbError` with the first broken rule of :func:`glb_chunks`."""
    problems: list[str] = []
    chunks = glb_chunks(data, lambda _, message: problems.append(message))
    if problems or chunks is None:
        raise GlbError(problems[0])
    view = memoryview(data)
    (start, size), blob = chunks
    bin_start, bin_size = blob or (start, 0)
    return view[start : start + size], view[bin_start : bin_start + bin_size]


def unpacked_view(blob: bytes | memoryview, packed: dict[str, Any]) -> bytes:
    """The bytes of a buffer view packed with ``EXT_meshopt_compression`` (its extension
    object ``packed``, its data in ``blob``): :class:`GlbError` for data elsewhere, the
    quaternion filter (not decoded here) or data that cannot be decoded."""
    # loads numba: only here
    from .meshopt import (
        MeshoptError,
        decode_indices,
        decode_vertices,
        from_exponential,
        from_octahedral,
    )

    filter_ = packed.get("filter", "NONE")
    octahedral = filter_ == "OCTAHEDRAL" and packed.get("byteStride") in (4, 8)
    if packed.get("buffer", 0) != 0 or not (octahedral or filter_ in ("NONE", "EXPONENTIAL")):
        raise GlbError(
            f"meshopt data outside the binary chunk, or under the {filter_} filter "
            f"with a stride of {packed.get('byteStride')!r}"
        )
    try:
        data = memoryview(blob)[packed.get("byteOffset", 0) :][: packed["byteLength"]]
        stride, count = int(packed["byteStride"]), int(packed["count"])
    except (KeyError, TypeError, ValueError) as exc:
        raise GlbError(f"a meshopt view's fields cannot be read ({exc})") from None
    if not 0 <= stride * count <= MESHOPT_EXPANSION * len(data) + 1024:
        raise GlbError(f"a meshopt view claims {count} × {stride} bytes from {len(data)} bytes")
    try:
        if packed["mode"] == "ATTRIBUTES":
            decoded = decode_vertices(data, count, stride).ravel()
            if filter_ == "EXPONENTIAL":
                decoded = from_exponential(decoded.view("<u4")).view(np.uint8)
            elif octahedral:
                kind = "<i1" if stride == 4 else "<i2"
                decoded = from_octahedral(decoded.view(kind).reshape(-1, 4)).view(np.uint8)
            return decoded.tobytes()
        return decode_indices(data, count, packed["mode"]).astype(f"<u{stride}").tobytes()
    except (MeshoptError, KeyError, TypeError) as exc:
        raise GlbError(f"meshopt data cannot be read ({exc})") from None


def accessor_values(document: dict[str, Any], blob: bytes | memoryview, index: int) -> np.ndarray:
    """The values of accessor ``index`` of ``document`` in buffer ``blob``, (count,) or
    (count, width) of its stored type; a view under ``EXT_meshopt_compression`` (its data in
    ``blob``) decoded; :class:`GlbError` for views interleaving several accessors or data
    that cannot be read."""
    accessor = document["accessors"][index]
    view = document["bufferViews"][accessor["bufferView"]]
    dtype = COMPONENT_DTYPES[accessor["componentType"]]
    width = WIDTHS[accessor["type"]]
    size = dtype.itemsize * width
    stride = view.get("byteStride", size)
    count = accessor["count"]
    start = accessor.get("byteOffset", 0)
    packed = view.get("extensions", {}).get(MESHOPT)
    if packed is not None:
        blob = unpacked_view(blob, packed)
    else:
        start += view.get("byteOffset", 0)
    if stride < size or (stride > size and accessor.get("byteOffset", 0) + size > stride):
        raise GlbError("interleaved buffer views are not supported")
    if stride == size:
        values = np.frombuffer(blob, dtype=dtype, count=count * width, offset=start)
    else:
        rows_of = np.frombuffer(blob, dtype=np.uint8, count=count * stride, offset=start)
        values = rows_of.reshape(count, stride)[:, :size].copy().view(dtype).ravel()
    return values.reshape(count, width) if width > 1 else values


def unpacked_glb(data: bytes, limit: int) -> bytes:
    """GLB ``data`` with the buffer views packed by ``EXT_meshopt_compression`` decoded into
    its binary chunk and the extension (and its fallback buffers) gone, for a reader that
    does not know it; ``data`` itself when nothing is packed. :class:`GlbError` where a view
    cannot be decoded (:func:`unpacked_view`) or they would decode to over ``limit`` bytes."""
    text, blob = split_glb(data)
    if MESHOPT.encode() not in bytes(text):
        return data
    document = json.loads(bytes(text))
    views = document.get("bufferViews", [])
    if not any(MESHOPT in (view.get("extensions") or {}) for view in views):
        return data
    out = bytearray(blob)
    for view in views:
        packed = (view.get("extensions") or {}).pop(MESHOPT, None)
        if packed is None:
            continue
        claimed = int(packed.get("byteStride", 0)) * int(packed.get("count", 0))
        if len(out) - len(blob) + claimed > limit:
            raise GlbError(f"its meshopt views decode to over {limit:,} bytes (the limit)")
        decoded = unpacked_view(blob, packed)
        out.extend(b"\0" * (-len(out) % 4))
        view.update(buffer=0, byteOffset=len(out), byteLength=len(decoded))
        out.extend(decoded)
        if not view["extensions"]:
            del view["extensions"]
    buffers = document["buffers"]
    kept = [k for k, b in enumerate(buffers) if MESHOPT not in (b.get("extensions") or {})]
    renumbered = {old: new for new, old in enumerate(kept)}
    if any(view.get("buffer", 0) not in renumbered for view in views):
        raise GlbError("a buffer view reads a meshopt fallback buffer without being packed")
    for view in views:
        view["buffer"] = renumbered[view.get("buffer", 0)]
    document["buffers"] = [buffers[k] for k in kept]
    document["buffers"][0]["byteLength"] = len(out)
    for key in ("extensionsUsed", "extensionsRequired"):
        if key in document:
            document[key] = [name for name in document[key] if name != MESHOPT] or None
            if document[key] is None:
                del document[key]
    handle = io.BytesIO()
    pack_glb(handle, json.dumps(document, separators=(",", ":")).encode(), bytes(out))
    return handle.getvalue()


ChunkData = bytes | IO[bytes]
"""A chunk's data: bytes, or a file whose whole content it is."""


def _length(data: ChunkData) -> int:
    if isinstance(data, bytes):
        return len(data)
    return data.seek(0, os.SEEK_END)


def _padded(length: int) -> int:
    return length + -length % 4


def pack_glb(out: BinaryIO, text: ChunkData, blob: ChunkData) -> None:
    """Write a GLB to ``out``: the header, a JSON chunk of ``text`` padded with spaces and,
    unless ``blob`` is empty, a BIN chunk of it padded with zeros."""
    chunks = [(JSON_CHUNK, text, b" ")]
    if _length(blob):
        chunks.append((BIN_CHUNK, blob, b"\x00"))
    lengths = [_length(data) for _, data, _ in chunks]
    total = HEADER_SIZE + sum(CHUNK_HEADER_SIZE + _padded(length) for length in lengths)
    out.write(_HEADER.pack(MAGIC, VERSION, total))
    for (kind, data, fill), length in zip(chunks, lengths, strict=True):
        out.write(_CHUNK_HEADER.pack(_padded(length), kind))
        if isinstance(data, bytes):
            out.write(data)
        else:
            data.seek(0)
            shutil.copyfileobj(data, out, _COPY_BLOCK)
        out.write(fill * (_padded(length) - length))
