"""glTF checks (``.glb``, ``.gltf`` with an embedded buffer): GLB framing; buffer views inside
their buffer and accessors inside their view; a primitive's attributes with equal counts, its
indices inside them, declared ``min``/``max`` equal to the data; every reference inside its
array; and the ``MSFT_lod`` rules lodconvert follows (DESIGN.md): ``ids`` inside ``nodes`` and
distinct, coarser nodes neither scene roots nor children, ``extras.MSFT_screencoverage``
strictly falling with one value more than ``ids``, the extension in ``extensionsUsed`` but not
required, and ``extras.lodconvert`` levels and cutoffs consistent with the chain. A file without
any chain is an error: ``lodconvert validate`` checks lodconvert's outputs.

Work is bounded by the bytes present: sizes a file declares are compared, never allocated or
iterated; JSON nesting is limited before parsing; and the accessor data that the value checks
read is limited to a few times the buffer's size.
"""

from __future__ import annotations

import base64
import binascii
import codecs
import contextlib
import itertools
import json
import mmap
import os
import struct
from array import array
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from lxml import etree

from ...validate.findings import Findings
from .elements import ElementChecks
from .rules import (
    COMPONENT_DTYPES,
    COMPONENT_SIZES,
    READ_BUDGET,
    TRIANGLES,
    WIDTHS,
    chain_facts,
    chain_facts_findings,
    lod_extras_findings,
)
from .stream import (
    LazyArray,
    NotStreamed,
    Source,
    read_object,
    reject_constant,
    too_deep,
    utf8_error,
)
from .writer import GLB_BIN, GLB_JSON, GLB_MAGIC, MSFT_LOD

GLB_HEADER_SIZE = 12
GLB_CHUNK_HEADER_SIZE = 8
MAX_JSON_DEPTH = 64
"""Deepest nesting of JSON arrays and objects accepted (lodconvert writes fewer than 10)."""


def _load_json(source: Source, what: str, findings: Findings) -> dict[str, Any] | None:
    """The JSON object in ``source`` (``what``: where it is, for messages), its big arrays read
    element by element into :class:`LazyArray` facts; ``None`` with a finding when it is not
    UTF-8, too deeply nested, not JSON or not an object."""
    if bytes(source.read(0, len(codecs.BOM_UTF8))) == codecs.BOM_UTF8:
        findings.error(
            "GLTF_JSON_ENCODING", f"{what} starts with a UTF-8 byte order mark, which glTF forbids"
        )
        return None
    bad = utf8_error(source)
    if bad is not None:
        findings.error(
            "GLTF_JSON_ENCODING",
            f"{what} is not UTF-8 text: byte 0x{bad[1]:02x} at offset {bad[0]}",
        )
        return None
    if too_deep(source, MAX_JSON_DEPTH):
        findings.error(
            "GLTF_JSON_DEPTH", f"{what} nests arrays and objects over {MAX_JSON_DEPTH} deep"
        )
        return None
    try:
        return read_object(source, _SINKS)
    except NotStreamed:  # not one JSON object: json.loads says why
        pass
    text = bytes(source.read(0, len(source))).decode("utf-8")
    try:
        doc = json.loads(text, parse_constant=reject_constant)
    except json.JSONDecodeError as exc:
        findings.error(
            "GLTF_JSON_SYNTAX",
            f"{what} is not JSON: {exc.msg} at line {exc.lineno} column {exc.colno}",
        )
        return None
    except ValueError as exc:  # NaN or Infinity; an integer too long to convert
        findings.error("GLTF_JSON_SYNTAX", f"{what} is not JSON: {exc}")
        return None
    if not isinstance(doc, dict):
        findings.error("GLTF_STRUCTURE", f"{what} holds a JSON {type(doc).__name__}, not an object")
        return None
    return doc


def _chunk_name(kind: bytes) -> str:
    return {GLB_JSON: "JSON", GLB_BIN: "BIN"}.get(kind, repr(kind))


Span = tuple[int, int]
"""Where a chunk's data is in the file: (offset, length)."""


def _glb_chunks(data: memoryview, findings: Findings) -> tuple[Span, Span | None] | None:
    """The JSON chunk and BIN chunk (``None`` when absent) of GLB ``data``, checked against the
    framing of glTF 2.0 (section 4.4); ``None`` when no JSON chunk can be read. Each broken rule
    is its own finding."""
    if data[:4] != GLB_MAGIC:
        start = bytes(data[:64]).lstrip()[:1]
        hint = " (it looks like glTF JSON: name it .gltf)" if start == b"{" else ""
        findings.error(
            "GLB_MAGIC",
            f"not a GLB file: the first 4 bytes are {bytes(data[:4])!r}, not 'glTF'{hint}",
        )
        return None
    if len(data) < GLB_HEADER_SIZE:
        findings.error(
            "GLB_HEADER", f"truncated GLB: {len(data)} bytes, less than the 12-byte header"
        )
        return None
    _, version, length = struct.unpack_from("<4sII", data)
    if version != 2:
        findings.error("GLB_VERSION", f"GLB version {version}; glTF 2.0 files are version 2")
        return None
    if length > len(data):
        findings.error(
            "GLB_LENGTH",
            f"truncated GLB: declared length {length} but the file has {len(data)} bytes",
        )
        return None
    if length < len(data):
        findings.error(
            "GLB_LENGTH",
            f"declared length {length} but the file has {len(data)} bytes "
            f"({len(data) - length} after the declared end)",
        )
    if length <= GLB_HEADER_SIZE:
        findings.error("GLB_JSON_CHUNK", "the GLB has no chunks; its first must be JSON")
        return None
    json_chunk: Span | None = None
    bin_chunk: Span | None = None
    offset, index = GLB_HEADER_SIZE, 0
    while offset < length:
        where = f"chunk {index} at byte {offset}"
        if length - offset < GLB_CHUNK_HEADER_SIZE:
            findings.error(
                "GLB_CHUNK_HEADER",
                f"{where}: {length - offset} bytes left, less than a chunk header (8)",
            )
            break
        size, kind = struct.unpack_from("<I4s", data, offset)
        start = offset + GLB_CHUNK_HEADER_SIZE
        where = f"chunk {index} ({_chunk_name(kind)}) at byte {offset}"
        if size > length - start:
            findings.error(
                "GLB_CHUNK_LENGTH",
                f"{where} declares {size} bytes but {length - start} are left",
            )
            break
        if size % 4:
            findings.error("GLB_CHUNK_ALIGNMENT", f"{where} has {size} bytes, not a multiple of 4")
        body = (start, size)
        if index == 0 and kind != GLB_JSON:
            findings.error("GLB_JSON_CHUNK", f"the first chunk is {_chunk_name(kind)}, not JSON")
        elif index == 0:
            json_chunk = body
        elif kind == GLB_JSON:
            findings.error("GLB_CHUNK_ORDER", f"{where}: only the first chunk may be JSON")
        elif kind == GLB_BIN and index == 1:
            bin_chunk = body
        elif kind == GLB_BIN:
            findings.error("GLB_CHUNK_ORDER", f"{where}: only the second chunk may be BIN")
        offset, index = start + size, index + 1
    return None if json_chunk is None else (json_chunk, bin_chunk)


def _first_buffer(doc: dict[str, Any]) -> dict[str, Any] | None:
    """``buffers[0]`` when it is an object (a malformed ``buffers`` is reported later)."""
    buffers = doc.get("buffers")
    if isinstance(buffers, list) and buffers and isinstance(buffers[0], dict):
        return buffers[0]
    return None


def _stripped_length(data: memoryview, start: int, size: int) -> int:
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


Parsed = tuple[dict[str, Any], memoryview | bytes, Source]
"""A glTF's JSON object, buffer 0 (a view of the file, not a copy, or the decoded data URI)
and buffer 0 as a :class:`Source` (read without mapping it)."""


def _read_glb(data: memoryview, findings: Findings, fd: int | None) -> Parsed | None:
    """The JSON object and buffer 0 of a GLB; ``None`` when the JSON cannot be read."""
    chunks = _glb_chunks(data, findings)
    if chunks is None:
        return None
    (start, size), blob = chunks
    length = _stripped_length(data, start, size)
    if length < size:
        findings.error(
            "GLB_JSON_PADDING",
            f"the JSON chunk ends in {size - length} zero bytes; its padding must be spaces (0x20)",
        )
    doc = _load_json(Source(data, start, length, fd), "the GLB JSON chunk", findings)
    if doc is None:
        return None
    buffer = _first_buffer(doc)
    if blob is not None and buffer is not None and "uri" in buffer:
        findings.error(
            "GLB_BIN_BUFFER", "buffer 0 has a uri, but in a GLB with a BIN chunk it is that chunk"
        )
    if blob is None or not blob[1]:
        return doc, b"", Source(b"", 0, 0, None)
    return doc, data[blob[0] : blob[0] + blob[1]], Source(data, *blob, fd)


def _read_gltf(data: memoryview, findings: Findings, fd: int | None) -> Parsed | None:
    """The JSON object and buffer 0 (a base64 data URI) of a ``.gltf``; ``None`` when the JSON
    cannot be read."""
    if data[:4] == GLB_MAGIC:
        findings.error("GLTF_JSON_SYNTAX", "the file is binary glTF (GLB), not JSON: name it .glb")
        return None
    doc = _load_json(Source(data, 0, len(data), fd), "the glTF file", findings)
    if doc is None:
        return None
    blob = _data_uri(doc, findings)
    return doc, blob, Source(blob, 0, len(blob), None)


def _data_uri(doc: dict[str, Any], findings: Findings) -> bytes:
    """Buffer 0 of a ``.gltf``, decoded from its data URI (empty, with an error, when it is
    not one)."""
    buffer = _first_buffer(doc)
    if buffer is None:
        return b""
    uri = buffer.get("uri")
    if not isinstance(uri, str) or not uri.startswith("data:") or "," not in uri:
        findings.error(
            "GLTF_BUFFER_URI",
            "buffer 0 is not embedded as a data: URI (lodconvert writes self-contained files)",
        )
        return b""
    try:
        return base64.b64decode(uri.split(",", 1)[1], validate=True)
    except binascii.Error as exc:
        findings.error("GLTF_BUFFER_URI", f"buffer 0 data URI is not valid base64 ({exc})")
        return b""


def check_gltf(path: Path, findings: Findings, _: etree.XMLSchema | None) -> None:
    """Read the GLB or ``.gltf`` (with an embedded buffer) and run every check; a malformed file
    gives findings, never an exception.

    A ``.glb`` is read as GLB and a ``.gltf`` as JSON, so that a file of the wrong kind is
    named as such; a file with another suffix is read as GLB when it starts with ``glTF``.
    """
    try:
        with path.open("rb") as handle, _mapped(handle) as data:
            _check_data(data, path.suffix.lower(), findings, handle.fileno())
    except OSError as exc:
        findings.error("READ", f"cannot read: {exc.strerror or exc}")


@contextlib.contextmanager
def _mapped(handle: BinaryIO) -> Iterator[memoryview]:
    """The file's bytes, memory-mapped (so a large buffer is read as it is checked, never
    copied); an empty file is an empty view."""
    size = os.fstat(handle.fileno()).st_size
    if size == 0:
        yield memoryview(b"")
        return
    with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as mapped:
        view = memoryview(mapped)
        try:
            yield view
        finally:
            view.release()


def _check_data(data: memoryview, suffix: str, findings: Findings, fd: int | None = None) -> None:
    """Check the file's bytes ``data`` (``fd``: the open file, read from without mapping
    where that is enough): first the summary checks of :func:`_clean`, and only where they
    find something every check of :class:`ElementChecks`, for its findings."""
    binary = suffix == ".glb" if suffix in (".glb", ".gltf") else data[:4] == GLB_MAGIC
    parsed = _read_glb(data, findings, fd) if binary else _read_gltf(data, findings, fd)
    if parsed is None:
        return
    doc, blob, source = parsed
    try:
        if _clean(doc, source):
            return
    except (AttributeError, KeyError, IndexError, TypeError, ValueError):
        pass  # the checks below say what is wrong
    if sum(v.nbytes for v in doc.values() if isinstance(v, LazyArray)) <= IN_MEMORY:
        doc = {k: v.whole() if isinstance(v, LazyArray) else v for k, v in doc.items()}
    try:
        ElementChecks(doc, blob, findings).run()
    except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
        findings.error("GLTF_STRUCTURE", f"malformed glTF JSON ({type(exc).__name__}: {exc})")


# --- summary checks: what a file of any size reduces to, checked with numpy ----------------------

IN_MEMORY = 1 << 26
"""JSON arrays up to this many bytes in all are read into memory for :class:`ElementChecks`
(larger ones it reads element by element, again for each look)."""
_BIG = 1 << 40
"""Numbers from here on are left to :class:`ElementChecks` (so that no sum of them overflows
int64)."""
_BLOCK = 1 << 21
"""Bytes of buffer read at a time for the value checks."""


def _uint(value: Any) -> bool:
    """A JSON integer in [0, :data:`_BIG`) (``true`` is not)."""
    return type(value) is int and 0 <= value < _BIG


def _all_uint(values: list[Any]) -> bool:
    """Whether every value is a JSON integer in [0, :data:`_BIG`)."""
    if not all(type(v) is int for v in values):
        return False
    return not values or (min(values) >= 0 and max(values) < _BIG)


def _numbers(value: Any, width: int) -> bool:
    """A list of ``width`` JSON numbers, each exactly a float64."""
    return (
        type(value) is list
        and len(value) == width
        and all(type(v) is float or (type(v) is int and -(2**53) <= v <= 2**53) for v in value)
    )


class _Facts:
    """What the summary checks need of one top-level array, in int64 columns, gathered as its
    elements are read; ``regular`` stays true while every element has the types lodconvert
    writes (else :class:`ElementChecks` checks the file)."""

    columns: tuple[str, ...] = ()

    def __init__(self) -> None:
        self.regular = True
        self.size = 0
        for name in self.columns:
            setattr(self, name, array("q"))

    def add(self, first: int, items: list[Any]) -> None:
        """The sink of :func:`read_object`: take the facts of elements ``first`` on."""
        self.size += len(items)
        if self.regular and not all(type(item) is dict for item in items):
            self.regular = False
        if self.regular:
            self.regular = self.take_all(first, items)

    def take_all(self, first: int, items: list[dict[str, Any]]) -> bool:
        """Take the facts of elements ``first`` on (objects); whether they are regular."""
        return all(self.take(index, item) for index, item in enumerate(items, first))

    def take(self, index: int, item: dict[str, Any]) -> bool:
        raise NotImplementedError

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.frombuffer(getattr(self, name), np.int64) for name in self.columns}


class _Accessors(_Facts):
    columns = ("view", "offset", "ctype", "count", "width", "bounds")

    def __init__(self) -> None:
        super().__init__()
        self.declared = array("d")  # min then max of the accessors that declare them

    def take_all(self, first: int, items: list[dict[str, Any]]) -> bool:
        view = [item.get("bufferView") for item in items]
        offset = [item.get("byteOffset", 0) for item in items]
        ctype = [item.get("componentType") for item in items]
        count = [item.get("count") for item in items]
        width = [WIDTHS.get(k, 0) if type(k) is str else 0 for k in (i.get("type") for i in items)]
        if not (_all_uint(view) and _all_uint(offset) and _all_uint(count) and all(width)):
            return False
        if min(count, default=1) <= 0:
            return False
        if not all(type(c) is int and c in COMPONENT_SIZES for c in ctype):
            return False
        bounds = [-1] * len(items)
        for k, item in enumerate(items):
            if "min" in item or "max" in item:
                low, high = item.get("min"), item.get("max")
                if not (_numbers(low, width[k]) and _numbers(high, width[k])):
                    return False
                bounds[k] = len(self.declared)
                self.declared.extend(low)
                self.declared.extend(high)
        self.view.extend(view)
        self.offset.extend(offset)
        self.ctype.extend(ctype)
        self.count.extend(count)
        self.width.extend(width)
        self.bounds.extend(bounds)
        return True

    def take(self, index: int, item: dict[str, Any]) -> bool:
        view, offset = item.get("bufferView"), item.get("byteOffset", 0)
        ctype, count, kind = item.get("componentType"), item.get("count"), item.get("type")
        width = WIDTHS.get(kind, 0) if type(kind) is str else 0
        if not (
            width
            and _uint(view)
            and _uint(offset)
            and type(ctype) is int
            and ctype in COMPONENT_SIZES
            and _uint(count)
            and count > 0
        ):
            return False
        bounds = -1
        if "min" in item or "max" in item:
            low, high = item.get("min"), item.get("max")
            if not (_numbers(low, width) and _numbers(high, width)):
                return False
            bounds = len(self.declared)
            self.declared.extend(low)
            self.declared.extend(high)
        self.view.append(view)
        self.offset.append(offset)
        self.ctype.append(ctype)
        self.count.append(count)
        self.width.append(width)
        self.bounds.append(bounds)
        return True


class _Views(_Facts):
    columns = ("buffer", "offset", "length", "stride")

    def take_all(self, first: int, items: list[dict[str, Any]]) -> bool:
        if any("byteStride" in item for item in items):
            return super().take_all(first, items)  # not all as lodconvert writes them
        buffer = [item.get("buffer") for item in items]
        offset = [item.get("byteOffset", 0) for item in items]
        length = [item.get("byteLength") for item in items]
        if not (_all_uint(buffer) and _all_uint(offset) and _all_uint(length)):
            return False
        if min(length, default=1) <= 0:
            return False
        self.buffer.extend(buffer)
        self.offset.extend(offset)
        self.length.extend(length)
        self.stride.frombytes(bytes(8 * len(items)))
        return True

    def take(self, index: int, item: dict[str, Any]) -> bool:
        buffer, offset = item.get("buffer"), item.get("byteOffset", 0)
        length, stride = item.get("byteLength"), item.get("byteStride", 0)
        if "byteStride" in item and not (type(stride) is int and 4 <= stride <= 252):
            return False
        if not (
            _uint(buffer) and _uint(offset) and _uint(length) and length > 0 and stride % 4 == 0
        ):
            return False
        self.buffer.append(buffer)
        self.offset.append(offset)
        self.length.append(length)
        self.stride.append(stride)
        return True


class _Meshes(_Facts):
    """Per primitive: its POSITION and indices accessors (-1: none) and whether it is made of
    triangles; per attribute: its primitive and accessor."""

    columns = ("position", "indices", "triangles", "attribute_of", "attribute")

    def take(self, index: int, item: dict[str, Any]) -> bool:
        primitives = item.get("primitives", [])
        if type(primitives) is not list:
            return False
        for primitive in primitives:
            if type(primitive) is not dict:
                return False
            attributes = primitive.get("attributes", {})
            indices, mode = primitive.get("indices", -1), primitive.get("mode", TRIANGLES)
            if type(attributes) is not dict or type(mode) is not int:
                return False
            if "indices" in primitive and not _uint(indices):
                return False
            if not all(_uint(a) for a in attributes.values()):
                return False
            at = len(self.position)
            for accessor in attributes.values():
                self.attribute_of.append(at)
                self.attribute.append(accessor)
            self.position.append(attributes.get("POSITION", -1))
            self.indices.append(indices)
            self.triangles.append(mode == TRIANGLES)
        return True


class _Nodes(_Facts):
    """Per node its mesh (-1: none); all nodes' children and MSFT_lod ids; how many hold
    MSFT_lod and how many are one-level chains. A node whose own MSFT_lod rules (ids, extras)
    give a finding is not regular."""

    columns = ("mesh", "children", "ids")

    def __init__(self) -> None:
        super().__init__()
        self.holders = self.chains = 0

    def take(self, index: int, item: dict[str, Any]) -> bool:
        children, mesh = item.get("children", []), item.get("mesh", -1)
        extensions = item.get("extensions", {})
        if type(children) is not list or not all(_uint(c) for c in children):
            return False
        if ("mesh" in item and not _uint(mesh)) or type(extensions) is not dict:
            return False
        try:
            if MSFT_LOD in extensions:
                lod = extensions[MSFT_LOD]
                ids = lod.get("ids", []) if type(lod) is dict else None
                if type(ids) is not list or not all(_uint(i) for i in ids):
                    return False
                if index in ids or len(set(ids)) < len(ids):
                    return False
                extras = item.get("extras", {}) if isinstance(item.get("extras"), dict) else {}
                if any(True for _ in lod_extras_findings("", extras, len(ids))):
                    return False
                self.ids.extend(ids)
                self.holders += 1
            elif (facts := chain_facts(item)) is not None:
                if any(True for _ in chain_facts_findings("", facts, 0)):
                    return False
                self.chains += 1
        except (AttributeError, KeyError, IndexError, TypeError, ValueError):
            return False
        self.mesh.append(mesh)
        self.children.extend(children)
        return True


def _sink(kind: type[_Facts]) -> Any:
    def make() -> tuple[_Facts, Any]:
        facts = kind()
        return facts, facts.add

    return make


_SINKS = {
    "accessors": _sink(_Accessors),
    "bufferViews": _sink(_Views),
    "meshes": _sink(_Meshes),
    "nodes": _sink(_Nodes),
}


def _facts(doc: dict[str, Any], key: str, kind: type[_Facts]) -> _Facts | None:
    """The facts of top-level array ``key`` (empty when absent); ``None`` when it is not a
    regular array of objects."""
    if key not in doc:
        return kind()
    items = doc[key]
    if not (isinstance(items, LazyArray) and items.all_objects and isinstance(items.facts, kind)):
        return None
    return items.facts if items.facts.regular else None


def _ints(value: Any) -> bool:
    return type(value) is list and all(_uint(v) for v in value)


def _strings(value: Any) -> bool:
    return type(value) is list and all(type(v) is str for v in value)


def _clean(doc: dict[str, Any], blob: Source) -> bool:
    """Whether :class:`ElementChecks` would find nothing in ``doc`` and ``blob``, decided from
    the facts gathered as the JSON was read (and the accessor values, read a block at a time);
    false also wherever the file is not as lodconvert writes it (:class:`ElementChecks` then
    decides)."""
    parts = [
        _facts(doc, key, kind)
        for key, kind in (
            ("accessors", _Accessors),
            ("bufferViews", _Views),
            ("meshes", _Meshes),
            ("nodes", _Nodes),
        )
    ]
    if any(part is None for part in parts):
        return False
    accessor_facts, view_facts, mesh_facts, node_facts = parts
    assert isinstance(accessor_facts, _Accessors) and isinstance(node_facts, _Nodes)
    asset = doc.get("asset", {})
    if not (type(asset) is dict and asset.get("version") == "2.0"):
        return False
    buffers = doc.get("buffers", [])
    if type(buffers) is not list or not all(type(b) is dict for b in buffers):
        return False
    lengths = [b.get("byteLength") for b in buffers]
    if not all(_uint(n) for n in lengths) or (lengths and lengths[0] > len(blob)):
        return False
    # buffer views and accessors
    views = view_facts.arrays()
    if len(views["buffer"]) and int(views["buffer"].max()) >= len(buffers):
        return False
    view_end = views["offset"] + views["length"]
    if (view_end > np.array(lengths, np.int64)[views["buffer"]]).any():
        return False
    acc = accessor_facts.arrays()
    if len(acc["view"]) and int(acc["view"].max()) >= len(view_end):
        return False
    element = _SIZE_TABLE[acc["ctype"]] * acc["width"]
    stride = views["stride"][acc["view"]]
    stride = np.where(stride > 0, stride, element)
    if (stride < element).any():
        return False
    if (acc["offset"] + stride * (acc["count"] - 1) + element > views["length"][acc["view"]]).any():
        return False
    usable = (views["buffer"][acc["view"]] == 0) & (view_end[acc["view"]] <= len(blob))
    start = views["offset"][acc["view"]] + acc["offset"]
    # primitives
    mesh = mesh_facts.arrays()
    count = acc["count"]
    if len(mesh["attribute"]) and int(mesh["attribute"].max()) >= len(count):
        return False
    if len(mesh["indices"]) and int(mesh["indices"].max()) >= len(count):
        return False
    primitives = len(mesh["position"])
    counts = count[mesh["attribute"]]
    most = np.full(primitives, -1, np.int64)
    least = np.full(primitives, _BIG, np.int64)
    np.maximum.at(most, mesh["attribute_of"], counts)
    np.minimum.at(least, mesh["attribute_of"], counts)
    if ((most >= 0) & (most != least)).any():
        return False
    indexed = mesh["indices"] >= 0
    if (indexed & (mesh["triangles"] == 1) & (count[mesh["indices"]] % 3 != 0)).any():
        return False
    placed = mesh["position"] >= 0
    read_position = placed & usable[mesh["position"]]
    read_indices = indexed & usable[mesh["indices"]]
    cost = stride * count
    spent = int(cost[mesh["position"][read_position]].sum())
    spent += int(cost[mesh["indices"][read_indices]].sum())
    if spent > READ_BUDGET * len(blob):
        return False
    positions = np.unique(mesh["position"][read_position])
    index_accessors = np.unique(mesh["indices"][read_indices])
    if (acc["bounds"][positions] < 0).any() or (acc["ctype"][index_accessors] == 5126).any():
        return False
    declared = np.frombuffer(accessor_facts.declared, np.float64)
    largest = np.zeros(len(count), np.int64)
    wanted = np.union1d(positions, index_accessors)
    for (ctype, width), members in _groups(wanted, acc["ctype"], acc["width"]):
        dtype = np.dtype(COMPONENT_DTYPES[ctype])
        low, high = _extrema(members, start, count, stride, dtype, width, blob)
        bounded = np.isin(members, positions)
        at = acc["bounds"][members[bounded]][:, None] + np.arange(width)
        if not (
            np.array_equal(declared[at].astype(dtype), low[bounded])
            and np.array_equal(declared[at + width].astype(dtype), high[bounded])
        ):
            return False
        indexing = np.isin(members, index_accessors)
        largest[members[indexing]] = high[indexing].max(axis=1)
    checked = read_indices & placed
    if (largest[mesh["indices"][checked]] >= count[mesh["position"][checked]]).any():
        return False
    # scene graph and MSFT_lod
    nodes = node_facts.arrays()
    size = node_facts.size
    for key, limit in (("children", size), ("ids", size), ("mesh", mesh_facts.size)):
        if len(nodes[key]) and int(nodes[key].max()) >= limit:
            return False
    scenes = doc.get("scenes", [])
    if type(scenes) is not list or not all(type(scene) is dict for scene in scenes):
        return False
    if "scene" in doc and not (_uint(doc["scene"]) and doc["scene"] < len(scenes)):
        return False
    roots = [scene.get("nodes", []) for scene in scenes]
    if not all(_ints(r) for r in roots) or any(r >= size for r in itertools.chain(*roots)):
        return False
    taken = np.zeros(size, bool)  # scene roots and children: no MSFT_lod level may be one
    taken[list(itertools.chain(*roots))] = True
    taken[nodes["children"]] = True
    if taken[nodes["ids"]].any():
        return False
    used, required = doc.get("extensionsUsed", []), doc.get("extensionsRequired", [])
    if not (_strings(used) and _strings(required)) or not set(required) <= set(used):
        return False
    if not (node_facts.holders or node_facts.chains) or MSFT_LOD in required:
        return False
    return not node_facts.holders or MSFT_LOD in used


_SIZE_TABLE = np.zeros(max(COMPONENT_SIZES) + 1, np.int64)
_SIZE_TABLE[list(COMPONENT_SIZES)] = list(COMPONENT_SIZES.values())


def _groups(
    members: np.ndarray, ctype: np.ndarray, width: np.ndarray
) -> Iterator[tuple[tuple[int, int], np.ndarray]]:
    """``members`` (accessor indices) grouped by component type and width."""
    keys = ctype[members] * 32 + width[members]
    for key in np.unique(keys):
        yield (int(key) // 32, int(key) % 32), members[keys == key]


def _extrema(
    members: np.ndarray,
    start: np.ndarray,
    count: np.ndarray,
    stride: np.ndarray,
    dtype: np.dtype,
    width: int,
    blob: Source,
) -> tuple[np.ndarray, np.ndarray]:
    """Per accessor of ``members`` (all of ``dtype`` and ``width``) the least and greatest value
    of each component, as (len(members), width) arrays of ``dtype``: tightly packed accessors
    read together a block at a time, others (and long ones) on their own."""
    low = np.empty((len(members), width), dtype)
    high = np.empty((len(members), width), dtype)
    element = dtype.itemsize * width
    first = start[members]
    span = count[members] * element
    together = (stride[members] == element) & (first % dtype.itemsize == 0) & (span <= _BLOCK)
    for k in np.flatnonzero(~together):
        low[k], high[k] = _accessor_extrema(
            int(first[k]), int(count[members[k]]), int(stride[members[k]]), dtype, width, blob
        )
    rest = np.flatnonzero(together)
    rest = rest[np.argsort(first[rest], kind="stable")]
    at = 0
    while at < len(rest):
        begin = int(first[rest[at]])
        stop = at + int(np.searchsorted(first[rest[at:]], begin + _BLOCK, "left"))
        stop = max(stop, at + 1)
        block = rest[at:stop]
        end = int((first[block] + span[block]).max())
        values = np.frombuffer(blob.read(begin, end), dtype)
        lengths = span[block] // dtype.itemsize
        offsets = np.cumsum(lengths) - lengths
        gather = np.repeat((first[block] - begin) // dtype.itemsize - offsets, lengths)
        gather += np.arange(int(lengths.sum()))
        rows = values[gather].reshape(-1, width)
        low[block] = np.minimum.reduceat(rows, offsets // width, axis=0)
        high[block] = np.maximum.reduceat(rows, offsets // width, axis=0)
        at = stop
    return low, high


def _accessor_extrema(
    first: int, count: int, stride: int, dtype: np.dtype, width: int, blob: Source
) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest value of each component of one accessor, read :data:`_BLOCK` bytes
    at a time."""
    low = high = None
    rows = max(1, _BLOCK // stride)
    for row in range(0, count, rows):
        take = min(rows, count - row)
        at = first + row * stride
        data = blob.read(at, at + stride * (take - 1) + dtype.itemsize * width)
        values = np.ndarray((take, width), dtype, data, 0, (stride, dtype.itemsize))
        part_low, part_high = values.min(axis=0), values.max(axis=0)
        low = part_low if low is None else np.minimum(low, part_low)
        high = part_high if high is None else np.maximum(high, part_high)
    assert low is not None and high is not None
    return low, high
