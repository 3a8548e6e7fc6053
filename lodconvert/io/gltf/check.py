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
import math
import mmap
import os
import re
import struct
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from lxml import etree

from ...validate.findings import Findings
from .writer import GLB_BIN, GLB_JSON, GLB_MAGIC, MSFT_LOD

_COMPONENT_SIZES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_COMPONENT_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_TRIANGLES = 4
GLB_HEADER_SIZE = 12
GLB_CHUNK_HEADER_SIZE = 8
MAX_JSON_DEPTH = 64
"""Deepest nesting of JSON arrays and objects accepted (lodconvert writes fewer than 10)."""
READ_BUDGET = 4
"""Accessor data the value checks read, in multiples of buffer 0's size: accessors that share
their bytes many times over are not all read."""
_JSON_BRACKETS = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"|([\[{])|[\]}]')
"""A JSON string (skipped whole), an opening bracket (group 1) or a closing one."""


def _finite(values: Iterable[Any]) -> bool:
    """Whether every value is a finite JSON number."""
    return all(isinstance(v, int | float) and math.isfinite(v) for v in values)


def _is_uint(value: Any) -> bool:
    """Whether ``value`` is a JSON integer >= 0 (``true`` is not)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _too_deep(text: str) -> bool:
    """Whether JSON ``text`` nests arrays and objects more than :data:`MAX_JSON_DEPTH` deep
    (brackets inside strings do not count)."""
    depth = 0
    for match in _JSON_BRACKETS.finditer(text):
        if match.lastindex:
            depth += 1
            if depth > MAX_JSON_DEPTH:
                return True
        elif text[match.start()] != '"':
            depth -= 1
    return False


def _reject_constant(name: str) -> None:
    """``json.loads`` hook: ``NaN`` and ``Infinity`` are Python's, not JSON."""
    raise ValueError(f"{name} is not a JSON value")


def _load_json(raw: bytes, what: str, findings: Findings) -> dict[str, Any] | None:
    """The JSON object in ``raw`` (``what``: where it is, for messages); ``None`` with a finding
    when it is not UTF-8, too deeply nested, not JSON or not an object."""
    if raw.startswith(codecs.BOM_UTF8):
        findings.error(
            "GLTF_JSON_ENCODING", f"{what} starts with a UTF-8 byte order mark, which glTF forbids"
        )
        return None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        findings.error(
            "GLTF_JSON_ENCODING",
            f"{what} is not UTF-8 text: byte 0x{raw[exc.start]:02x} at offset {exc.start}",
        )
        return None
    if _too_deep(text):
        findings.error(
            "GLTF_JSON_DEPTH", f"{what} nests arrays and objects over {MAX_JSON_DEPTH} deep"
        )
        return None
    try:
        doc = json.loads(text, parse_constant=_reject_constant)
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


def _glb_chunks(
    data: memoryview, findings: Findings
) -> tuple[memoryview, memoryview | None] | None:
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
    json_chunk: memoryview | None = None
    bin_chunk: memoryview | None = None
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
        body = data[start : start + size]
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


def _read_glb(
    data: memoryview, findings: Findings
) -> tuple[dict[str, Any], memoryview | bytes] | None:
    """The JSON object and buffer 0 (a view of ``data``, not a copy) of a GLB; ``None`` when
    the JSON cannot be read."""
    chunks = _glb_chunks(data, findings)
    if chunks is None:
        return None
    raw, blob = bytes(chunks[0]), chunks[1]
    text = raw.rstrip(b"\x00")
    if len(text) < len(raw):
        findings.error(
            "GLB_JSON_PADDING",
            f"the JSON chunk ends in {len(raw) - len(text)} zero bytes; its padding must be "
            "spaces (0x20)",
        )
    doc = _load_json(text, "the GLB JSON chunk", findings)
    if doc is None:
        return None
    buffer = _first_buffer(doc)
    if blob is not None and buffer is not None and "uri" in buffer:
        findings.error(
            "GLB_BIN_BUFFER", "buffer 0 has a uri, but in a GLB with a BIN chunk it is that chunk"
        )
    return doc, blob or b""


def _read_gltf(data: memoryview, findings: Findings) -> tuple[dict[str, Any], bytes] | None:
    """The JSON object and buffer 0 (a base64 data URI) of a ``.gltf``; ``None`` when the JSON
    cannot be read."""
    if data[:4] == GLB_MAGIC:
        findings.error("GLTF_JSON_SYNTAX", "the file is binary glTF (GLB), not JSON: name it .glb")
        return None
    doc = _load_json(bytes(data), "the glTF file", findings)
    if doc is None:
        return None
    buffer = _first_buffer(doc)
    if buffer is None:
        return doc, b""
    uri = buffer.get("uri")
    if not isinstance(uri, str) or not uri.startswith("data:") or "," not in uri:
        findings.error(
            "GLTF_BUFFER_URI",
            "buffer 0 is not embedded as a data: URI (lodconvert writes self-contained files)",
        )
        return doc, b""
    try:
        return doc, base64.b64decode(uri.split(",", 1)[1], validate=True)
    except binascii.Error as exc:
        findings.error("GLTF_BUFFER_URI", f"buffer 0 data URI is not valid base64 ({exc})")
        return doc, b""


class _Gltf:
    """The checks of one parsed glTF document (``doc``, the JSON; ``blob``, buffer 0)."""

    def __init__(self, doc: dict[str, Any], blob: memoryview | bytes, findings: Findings) -> None:
        self.doc, self.blob, self.findings = doc, blob, findings
        self.bad_views: set[int] = set()
        self.bad_accessors: set[int] = set()
        self.read_budget = READ_BUDGET * len(blob)
        self._arrays: dict[str, list[dict[str, Any]]] = {}

    def array(self, key: str) -> list[dict[str, Any]]:
        """The top-level array ``key`` ([] when absent, or, with an error, when it is not an
        array of objects)."""
        if key not in self._arrays:
            items = self.doc.get(key, [])
            if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
                self.findings.error("GLTF_STRUCTURE", f"{key} is not an array of objects")
                items = []
            self._arrays[key] = items
        return self._arrays[key]

    def ref(self, value: Any, key: str, where: str) -> bool:
        """Whether ``value`` indexes the array ``key``; an error when it does not."""
        size = len(self.array(key))
        if _is_uint(value) and value < size:
            return True
        self.findings.error(
            "REFERENCE", f"{where} refers to {key} {value!r}, outside {key} ({size})"
        )
        return False

    def node_name(self, index: int) -> str:
        name = self.array("nodes")[index].get("name")
        return f"node {index}" + (f" ({name})" if name else "")

    def run(self) -> None:
        version = self.doc.get("asset", {}).get("version")
        if version != "2.0":
            self.findings.error("ASSET_VERSION", f"asset.version is {version!r}, not '2.0'")
        self.check_buffers()
        for i, mesh in enumerate(self.array("meshes")):
            for k, primitive in enumerate(mesh.get("primitives", [])):
                self.check_primitive(primitive, f"mesh {i} primitive {k}")
        self.check_graph()
        self.check_msft_lod()

    # buffers, views, accessors

    def check_buffers(self) -> None:
        lengths = []
        for i, buffer in enumerate(self.array("buffers")):
            length = buffer.get("byteLength")
            lengths.append(length if isinstance(length, int) else 0)
            if i == 0 and isinstance(length, int) and length > len(self.blob):
                self.findings.error(
                    "BUFFER_LENGTH",
                    f"buffer 0 declares {length} bytes but the file holds {len(self.blob)}",
                )
        for i, view in enumerate(self.array("bufferViews")):
            where = f"bufferView {i}"
            if not self.ref(view.get("buffer"), "buffers", where) or not self.check_view(
                where, view, lengths[view["buffer"]]
            ):
                self.bad_views.add(i)
        for i, accessor in enumerate(self.array("accessors")):
            if not self.check_accessor(i, accessor):
                self.bad_accessors.add(i)

    def check_view(self, where: str, view: dict[str, Any], buffer_length: int) -> bool:
        """Whether the view's offset, length and stride are usable (an error when not); one
        past the end of its buffer is an error but stays usable for the accessor checks."""
        offset, length = view.get("byteOffset", 0), view.get("byteLength")
        if not (_is_uint(offset) and _is_uint(length) and length > 0):
            self.findings.error(
                "BUFFER_VIEW", f"{where} needs a byteOffset >= 0 and a byteLength >= 1"
            )
            return False
        stride = view.get("byteStride")
        if stride is not None and not (_is_uint(stride) and 4 <= stride <= 252 and stride % 4 == 0):
            self.findings.error(
                "BUFFER_VIEW_STRIDE",
                f"{where} byteStride is {stride!r}, not a multiple of 4 from 4 to 252",
            )
            return False
        if offset + length > buffer_length:
            self.findings.error(
                "BUFFER_VIEW_BOUNDS",
                f"{where} ends at byte {offset + length}, past buffer {view['buffer']} "
                f"({buffer_length} bytes)",
            )
        return True

    def check_accessor(self, index: int, accessor: dict[str, Any]) -> bool:
        """Whether the accessor's data lies inside its view (and can be read)."""
        where = f"accessor {index}"
        width = _WIDTHS.get(accessor.get("type"))
        size = _COMPONENT_SIZES.get(accessor.get("componentType"))
        count, offset = accessor.get("count"), accessor.get("byteOffset", 0)
        if not (width and size and _is_uint(count) and count > 0 and _is_uint(offset)):
            self.findings.error(
                "ACCESSOR", f"{where} has a bad type, componentType, count or byteOffset"
            )
            return False
        if "bufferView" not in accessor:
            return False  # all zeros by the spec: nothing to read
        if not self.ref(accessor["bufferView"], "bufferViews", where):
            return False
        if accessor["bufferView"] in self.bad_views:
            return False
        view = self.array("bufferViews")[accessor["bufferView"]]
        stride = view.get("byteStride", size * width)
        if stride < size * width:
            self.findings.error(
                "ACCESSOR_STRIDE",
                f"{where} elements have {size * width} bytes, more than the byteStride {stride} "
                f"of bufferView {accessor['bufferView']}",
            )
            return False
        end = offset + stride * (count - 1) + size * width
        if end > view["byteLength"]:
            self.findings.error(
                "ACCESSOR_BOUNDS",
                f"{where} needs {end} bytes of bufferView {accessor['bufferView']}, which has "
                f"{view['byteLength']}",
            )
            return False
        for bound in ("min", "max"):
            if bound in accessor and len(accessor[bound]) != width:
                self.findings.error("ACCESSOR_MIN_MAX", f"{where} {bound} needs {width} values")
                return False
        in_blob = view.get("byteOffset", 0) + view["byteLength"] <= len(self.blob)
        return view.get("buffer") == 0 and in_blob

    def data(self, index: int) -> np.ndarray | None:
        """The accessor's values as (count, width) in their stored type; ``None`` when they
        cannot be read (an error was reported, or they are not in buffer 0) or the data read
        so far has used up :data:`READ_BUDGET` (a warning, once)."""
        if index in self.bad_accessors:
            return None
        accessor = self.array("accessors")[index]
        if "bufferView" not in accessor:
            return None
        view = self.array("bufferViews")[accessor["bufferView"]]
        dtype = np.dtype(_COMPONENT_DTYPES[accessor["componentType"]])
        width = _WIDTHS[accessor["type"]]
        start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
        stride = view.get("byteStride", dtype.itemsize * width)
        left = self.read_budget
        self.read_budget -= stride * accessor["count"]
        if self.read_budget < 0:
            if left >= 0:
                self.findings.warning(
                    "ACCESSOR_DATA_UNCHECKED",
                    f"accessors read buffer 0 more than {READ_BUDGET} times over: the values "
                    f"of accessor {index} and later reads are not checked",
                )
            return None
        return np.ndarray(
            (accessor["count"], width), dtype, self.blob, start, (stride, dtype.itemsize)
        )

    def check_bounds(self, index: int, where: str) -> None:
        """Declared ``min``/``max`` equal the data's (POSITION must declare them)."""
        accessor = self.array("accessors")[index]
        values = self.data(index)
        if values is None:
            return
        for bound, actual in (("min", values.min(axis=0)), ("max", values.max(axis=0))):
            if bound not in accessor:
                self.findings.error(
                    "ACCESSOR_MIN_MAX", f"{where} POSITION accessor {index} has no {bound}"
                )
                continue
            declared = np.array(accessor[bound], dtype=np.float64).astype(values.dtype)
            if not np.array_equal(declared, actual):
                self.findings.error(
                    "ACCESSOR_MIN_MAX",
                    f"{where} accessor {index} declares {bound} {accessor[bound]} but its data "
                    f"has {actual.tolist()}",
                )

    def check_primitive(self, primitive: dict[str, Any], where: str) -> None:
        attributes = primitive.get("attributes", {})
        counts = {}
        for name, index in attributes.items():
            if self.ref(index, "accessors", f"{where} {name}"):
                counts[name] = self.array("accessors")[index].get("count")
        if len(set(counts.values())) > 1:
            listed = ", ".join(f"{name} {count}" for name, count in counts.items())
            self.findings.error("PRIMITIVE_COUNT", f"{where} attributes differ in count: {listed}")
        if "POSITION" in counts:
            self.check_bounds(attributes["POSITION"], where)
        if "indices" in primitive and self.ref(
            primitive["indices"], "accessors", f"{where} indices"
        ):
            self.check_indices(primitive, counts.get("POSITION"), where)

    def check_indices(self, primitive: dict[str, Any], vertices: int | None, where: str) -> None:
        index = primitive["indices"]
        count = self.array("accessors")[index].get("count", 0)
        if primitive.get("mode", _TRIANGLES) == _TRIANGLES and count % 3:
            self.findings.error("INDEX_COUNT", f"{where} has {count} indices, not whole triangles")
        values = self.data(index)
        if (
            values is not None
            and vertices is not None
            and values.size
            and int(values.max()) >= vertices
        ):
            self.findings.error(
                "INDEX_RANGE",
                f"{where} index {int(values.max())} is outside its {vertices} vertices",
            )

    # scene graph and MSFT_lod

    def check_graph(self) -> None:
        nodes = self.array("nodes")
        for i, node in enumerate(nodes):
            for child in node.get("children", []):
                self.ref(child, "nodes", f"{self.node_name(i)} child")
            if "mesh" in node:
                self.ref(node["mesh"], "meshes", self.node_name(i))
        scenes = self.array("scenes")
        if "scene" in self.doc:
            self.ref(self.doc["scene"], "scenes", "scene")
        for i, scene in enumerate(scenes):
            for root in scene.get("nodes", []):
                self.ref(root, "nodes", f"scene {i}")

    def check_msft_lod(self) -> None:
        nodes = self.array("nodes")
        used = self.doc.get("extensionsUsed", [])
        required = self.doc.get("extensionsRequired", [])
        roots = {r for scene in self.array("scenes") for r in scene.get("nodes", [])}
        children = {c for node in nodes for c in node.get("children", [])}
        holders = [i for i, node in enumerate(nodes) if MSFT_LOD in node.get("extensions", {})]
        finest = {i: facts for i, node in enumerate(nodes) if (facts := _chain_facts(node))}
        if not holders and not finest:
            self.findings.error(
                "NO_LOD_CHAIN",
                f"no lodconvert LOD chain: no node has {MSFT_LOD} or extras.lodconvert levels",
            )
        if holders and MSFT_LOD not in used:
            self.findings.error("MSFT_LOD_NOT_USED", f"{MSFT_LOD} is missing from extensionsUsed")
        if MSFT_LOD in required:
            self.findings.warning(
                "MSFT_LOD_REQUIRED",
                f"{MSFT_LOD} is in extensionsRequired: clients without it cannot load the file",
            )
        if not set(required) <= set(used):
            self.findings.error(
                "EXTENSIONS", "extensionsRequired lists extensions not in extensionsUsed"
            )
        for i in holders:
            self.check_lod_node(i, nodes[i], roots, children)
        for i, facts in finest.items():
            if i not in holders:  # a one-level chain: no coarser nodes
                self.check_chain_facts(self.node_name(i), facts, 0)

    def check_lod_node(
        self, index: int, node: dict[str, Any], roots: set[int], children: set[int]
    ) -> None:
        name = self.node_name(index)
        ids = node["extensions"][MSFT_LOD].get("ids", [])
        size = len(self.array("nodes"))
        listed = Counter(lod for lod in ids if _is_uint(lod))
        for lod in ids:
            if not (_is_uint(lod) and lod < size):
                self.findings.error(
                    "MSFT_LOD_ID_RANGE", f"{name} MSFT_lod id {lod!r} is outside nodes ({size})"
                )
            elif lod == index or listed[lod] > 1:
                self.findings.error(
                    "MSFT_LOD_ID_DUPLICATE", f"{name} MSFT_lod lists node {lod} twice"
                )
            elif lod in roots:
                self.findings.error(
                    "MSFT_LOD_SCENE_ROOT",
                    f"{name} MSFT_lod level {self.node_name(lod)} is a scene root",
                )
            elif lod in children:
                self.findings.error(
                    "MSFT_LOD_CHILD",
                    f"{name} MSFT_lod level {self.node_name(lod)} is another node's child",
                )
        extras = node.get("extras", {}) if isinstance(node.get("extras"), dict) else {}
        coverage = extras.get("MSFT_screencoverage")
        if coverage is None:
            self.findings.warning("MSFT_LOD_COVERAGE", f"{name} has no extras.MSFT_screencoverage")
        elif len(coverage) != len(ids) + 1:
            self.findings.error(
                "MSFT_LOD_COVERAGE",
                f"{name} has {len(coverage)} screen coverages for {len(ids)} ids "
                f"(needs {len(ids) + 1})",
            )
        elif not _finite(coverage) or min(coverage) < 0:
            self.findings.error("MSFT_LOD_COVERAGE", f"{name} screen coverages are not all >= 0")
        elif any(b >= a for a, b in itertools.pairwise(coverage)):
            self.findings.error(
                "MSFT_LOD_COVERAGE", f"{name} screen coverages do not fall strictly: {coverage}"
            )
        facts = extras.get("lodconvert")
        if isinstance(facts, dict):
            self.check_chain_facts(name, facts, len(ids))

    def check_chain_facts(self, name: str, facts: dict[str, Any], ids: int) -> None:
        """``extras.lodconvert`` of a finest node: one level per node, cutoffs as the chain
        (a LOD parent's near node: one far node, the near level being its members)."""
        levels, cutoffs = facts.get("levels", []), facts.get("cutoffs", [])
        if "cell_id" in facts:
            if ids != 1:
                self.findings.error(
                    "LODCONVERT_CELL", f"{name} is a LOD parent with {ids} far nodes, not 1"
                )
        elif len(levels) != ids + 1:
            self.findings.error(
                "LODCONVERT_LEVELS", f"{name} extras list {len(levels)} levels for {ids + 1} nodes"
            )
        expected = ids + int(bool(facts.get("culled")))
        if len(cutoffs) != expected or any(b <= a for a, b in itertools.pairwise(cutoffs)):
            self.findings.error(
                "LODCONVERT_CUTOFFS",
                f"{name} extras cutoffs {cutoffs} are not {expected} increasing distances",
            )


def _chain_facts(node: dict[str, Any]) -> dict[str, Any] | None:
    """``extras.lodconvert`` of a chain's finest node (the one that lists the ``levels``)."""
    extras = node.get("extras")
    facts = extras.get("lodconvert") if isinstance(extras, dict) else None
    return facts if isinstance(facts, dict) and "levels" in facts else None


def check_gltf(path: Path, findings: Findings, _: etree.XMLSchema | None) -> None:
    """Read the GLB or ``.gltf`` (with an embedded buffer) and run every check; a malformed file
    gives findings, never an exception.

    A ``.glb`` is read as GLB and a ``.gltf`` as JSON, so that a file of the wrong kind is
    named as such; a file with another suffix is read as GLB when it starts with ``glTF``.
    """
    try:
        with path.open("rb") as handle, _mapped(handle) as data:
            _check_data(data, path.suffix.lower(), findings)
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


def _check_data(data: memoryview, suffix: str, findings: Findings) -> None:
    binary = suffix == ".glb" if suffix in (".glb", ".gltf") else data[:4] == GLB_MAGIC
    parsed = _read_glb(data, findings) if binary else _read_gltf(data, findings)
    if parsed is None:
        return
    try:
        _Gltf(*parsed, findings).run()
    except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
        findings.error("GLTF_STRUCTURE", f"malformed glTF JSON ({type(exc).__name__}: {exc})")
