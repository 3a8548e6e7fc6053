"""glTF checks (``.glb``, ``.gltf`` with an embedded buffer) for ``lodconvert validate``: GLB
framing (:mod:`.binary`), buffer views, accessors and primitives, references, the ``MSFT_lod``
rules lodconvert follows and the scene frame; a file without any chain is an error.

This module reads the file (GLB chunks, the JSON, buffer 0) and runs the checks: first the
summary checks (:mod:`.summary`), which decide from compact facts whether the file is clean,
and only where they find something the checks element by element (:mod:`.elements`), which say
what is wrong; :mod:`.rules` holds what both hold a file to. Work is bounded by the bytes
present: declared sizes are compared, never allocated; JSON nesting is limited as it is read.
Every rule: ``docs/gltf.md``.
"""

from __future__ import annotations

import base64
import binascii
import codecs
import contextlib
import json
import mmap
import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

from ..findings import Findings
from ..frame import frame_from_record
from .binary import glb_chunks, is_glb
from .elements import ElementChecks
from .lod import FRAME_MATRIX, FRAME_NODE
from .stream import (
    LazyArray,
    NotStreamed,
    Source,
    TooDeep,
    read_object,
    reject_constant,
    too_deep,
    utf8_error,
)
from .summary import SINKS, clean

if TYPE_CHECKING:
    from .. import CheckOptions

MAX_JSON_DEPTH = 64
"""Deepest nesting of JSON arrays and objects accepted (lodconvert writes fewer than 10)."""
IN_MEMORY = 1 << 26
"""JSON arrays up to this many bytes in all are read into memory for :class:`ElementChecks`
(larger ones it reads element by element, again for each look)."""


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
    try:
        return read_object(source, SINKS, limit=MAX_JSON_DEPTH)
    except TooDeep:
        deep = True
    except NotStreamed:  # not one JSON object: json.loads says why, unless it nests too deep
        deep = too_deep(source, MAX_JSON_DEPTH)
    if deep:
        findings.error(
            "GLTF_JSON_DEPTH", f"{what} nests arrays and objects over {MAX_JSON_DEPTH} deep"
        )
        return None
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


def _first_buffer(doc: dict[str, Any]) -> dict[str, Any] | None:
    """``buffers[0]`` when it is an object (a malformed ``buffers`` is reported later)."""
    buffers = doc.get("buffers")
    if isinstance(buffers, list) and buffers and isinstance(buffers[0], dict):
        return buffers[0]
    return None


Parsed = tuple[dict[str, Any], memoryview | bytes, Source]
"""A glTF's JSON object, buffer 0 (a view of the file, not a copy, or the decoded data URI)
and buffer 0 as a :class:`Source` (read without mapping it)."""


def _read_glb(data: memoryview, findings: Findings, fd: int | None) -> Parsed | None:
    """The JSON object and buffer 0 of a GLB; ``None`` when the JSON cannot be read."""
    chunks = glb_chunks(data, findings.error)
    if chunks is None:
        return None
    (start, length), blob = chunks
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
    if is_glb(data):
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


def check_gltf(path: Path, findings: Findings, _: CheckOptions | None) -> None:
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


def _check_frame(doc: dict[str, Any], findings: Findings) -> None:
    """The scene frame that ``asset.extras.lodconvert.frame`` records, if any: a whole record,
    and the default scene's one root node the frame node, its ``matrix`` z-up → y-up."""
    record = doc["asset"].get("extras", {}).get("lodconvert", {}).get("frame")
    if record is None:
        return
    try:
        frame_from_record(record)
    except (KeyError, TypeError, ValueError) as exc:
        findings.error("SCENE_FRAME", f"asset.extras.lodconvert.frame is malformed ({exc})")
        return
    roots = doc["scenes"][doc.get("scene", 0)].get("nodes", [])
    node = doc["nodes"][roots[0]] if len(roots) == 1 else {}
    if node.get("name") != FRAME_NODE or node.get("matrix") != FRAME_MATRIX:
        findings.error(
            "SCENE_FRAME",
            f"the asset records a scene frame, but the scene's roots {roots} are not its one "
            f"{FRAME_NODE!r} node turning z-up into y-up",
        )


def _check_data(data: memoryview, suffix: str, findings: Findings, fd: int | None = None) -> None:
    """Check the file's bytes ``data`` (``fd``: the open file, read from without mapping
    where that is enough): first the summary checks of :func:`clean`, and only where they
    find something every check of :class:`ElementChecks`, for its findings."""
    binary = suffix == ".glb" if suffix in (".glb", ".gltf") else is_glb(data)
    parsed = _read_glb(data, findings, fd) if binary else _read_gltf(data, findings, fd)
    if parsed is None:
        return
    doc, blob, source = parsed
    with contextlib.suppress(AttributeError, KeyError, IndexError, TypeError, ValueError):
        _check_frame(doc, findings)  # (a malformed document: the checks below say what is wrong)
    try:
        if clean(doc, source):
            return
    except (AttributeError, KeyError, IndexError, TypeError, ValueError):
        pass  # the checks below say what is wrong
    if sum(v.nbytes for v in doc.values() if isinstance(v, LazyArray)) <= IN_MEMORY:
        doc = {k: v.whole() if isinstance(v, LazyArray) else v for k, v in doc.items()}
    try:
        ElementChecks(doc, blob, findings).run()
    except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
        findings.error("GLTF_STRUCTURE", f"malformed glTF JSON ({type(exc).__name__}: {exc})")
