"""glTF JSON text written as it is made: each array of the document (accessors, nodes, …) goes
element by element to a temporary file of its own (:class:`JsonArray`), and the document is then
written from them in blocks (:func:`write_json`), laid out exactly as ``json.dumps`` lays out the
whole document (:class:`Layout`); a ``.gltf`` buffer is base64-encoded block by block into its
data URI (:class:`DataUri`)."""

from __future__ import annotations

import base64
import json
import math
import shutil
from typing import IO, Any, BinaryIO

DATA_URI = "data:application/octet-stream;base64,"
_PENDING = 256
"""Elements of a JSON array kept as text before they are written to its file."""
_BLOCK = 3 << 18
"""Bytes copied at a time (768 KiB, a multiple of 3: base64 blocks join without padding)."""


class Layout:
    """How JSON text is laid out: exactly as ``json.dumps`` with ``indent`` (``None``: compact,
    for GLB; 1: one space per depth, for ``.gltf``) and no NaN or infinity."""

    def __init__(self, indent: int | None) -> None:
        self.indent = indent
        separators = (",", ":") if indent is None else (",", ": ")
        self.colon = separators[1]
        self.encode = json.JSONEncoder(indent=indent, separators=separators, allow_nan=False).encode

    def newline(self, depth: int) -> str:
        """What comes before a member at ``depth``: a line break and its indentation (nothing
        when compact)."""
        return "" if self.indent is None else "\n" + " " * (self.indent * depth)

    def text(self, value: Any, depth: int) -> str:
        """``value`` as JSON text that starts at ``depth`` (compact text has no line breaks)."""
        if type(value) is dict:
            flat = self._flat(value, depth)
            if flat is not None:
                return flat
        text = self.encode(value)
        return text if self.indent is None else text.replace("\n", self.newline(depth))

    def object_text(self, members: list[tuple[str, str]], depth: int) -> str:
        """An object that starts at ``depth`` of ``members``: plain keys (letters and digits)
        with the text of their values, each laid out at ``depth`` + 1."""
        items = self.newline(depth + 1)
        body = ",".join(f'{items}"{key}"{self.colon}{text}' for key, text in members)
        return "{" + body + self.newline(depth) + "}" if members else "{}"

    def array_text(self, texts: list[str], depth: int) -> str:
        """An array that starts at ``depth`` of elements' ``texts``, each laid out at ``depth``
        + 1."""
        if not texts:
            return "[]"
        inner = self.newline(depth + 1)
        return "[" + ",".join(inner + t for t in texts) + self.newline(depth) + "]"

    def _flat(self, value: dict[str, Any], depth: int) -> str | None:
        """An object of integers, strings, booleans and lists of numbers (an accessor, a
        buffer view) laid out without the encoder; ``None`` for any other object."""
        inner, items = self.newline(depth + 2), self.newline(depth + 1)
        parts = []
        for key, item in value.items():
            kind = type(item)
            if kind is int:
                text = int.__repr__(item)
            elif kind is str and item.isalnum() and item.isascii():
                text = f'"{item}"'
            elif kind is bool:
                text = "true" if item else "false"
            elif kind is list and item and all(type(v) is float and math.isfinite(v) for v in item):
                text = "[" + ",".join(inner + float.__repr__(v) for v in item) + items + "]"
            else:
                return None
            if not (type(key) is str and key.isalnum() and key.isascii()):
                return None
            parts.append(f'{items}"{key}"{self.colon}{text}')
        if not parts:
            return None
        return "{" + ",".join(parts) + self.newline(depth) + "}"


COMPACT = Layout(None)
INDENTED = Layout(1)


class JsonArray:
    """A JSON array at a fixed depth of the document, written item by item to a temporary file
    (one item in memory at a time)."""

    def __init__(self, layout: Layout, depth: int, spool: IO[bytes]) -> None:
        self.layout = layout
        self.depth = depth
        self.spool = spool
        self.count = 0
        self.last: dict[str, Any] | None = None
        """An element written after the others, which may hold :class:`JsonArray` s itself."""
        self._head = "," + layout.newline(depth + 1)
        self._pending: list[str] = []

    def __len__(self) -> int:
        return self.count

    def append(self, item: Any) -> int:
        """Write ``item`` as the next element; its index."""
        return self.append_text(self.layout.text(item, self.depth + 1))

    def append_text(self, text: str) -> int:
        """Write the JSON text of an element laid out at the array's depth; its index."""
        self._pending.append(self._head + text if self.count else self._head[1:] + text)
        if len(self._pending) >= _PENDING:
            self._flush()
        self.count += 1
        return self.count - 1

    def extend_text(self, texts: list[str]) -> None:
        """Write the JSON texts of elements laid out at the array's depth (as
        :meth:`append_text` one by one)."""
        if not texts:
            return
        head = self._head
        self._pending.append((head if self.count else head[1:]) + texts[0])
        self._pending.extend([head + text for text in texts[1:]])
        self.count += len(texts)
        if len(self._pending) >= _PENDING:
            self._flush()

    def _flush(self) -> None:
        self.spool.write("".join(self._pending).encode())
        self._pending.clear()

    def write_json(self, out: BinaryIO) -> None:
        """Write the array's JSON text to ``out``."""
        self._flush()
        out.write(b"[")
        _copy(self.spool, out)
        if self.last is not None:
            out.write((("," if self.count else "") + self.layout.newline(self.depth + 1)).encode())
            write_json(self.last, out, self.layout, self.depth + 1)
        empty = not self.count and self.last is None
        out.write((("" if empty else self.layout.newline(self.depth)) + "]").encode())


class DataUri:
    """The binary buffer as a JSON string: a base64 ``data:`` URI, encoded block by block."""

    def __init__(self, blob: IO[bytes]) -> None:
        self.blob = blob

    def write_json(self, out: BinaryIO) -> None:
        """Write the quoted URI to ``out``."""
        out.write(b'"' + DATA_URI.encode())
        self.blob.seek(0)
        rest = b""
        while block := self.blob.read(_BLOCK):
            block = rest + block
            whole = len(block) - len(block) % 3
            out.write(base64.b64encode(block[:whole]))
            rest = block[whole:]
        out.write(base64.b64encode(rest) + b'"')


def _copy(source: IO[bytes], out: BinaryIO) -> None:
    """Copy ``source`` from its start to ``out``, :data:`_BLOCK` bytes at a time."""
    source.seek(0)
    shutil.copyfileobj(source, out, _BLOCK)


def write_json(value: Any, out: BinaryIO, layout: Layout, depth: int = 0) -> None:
    """Write ``value`` (starting at ``depth``) to ``out`` as ``json.dumps`` lays it out, with
    the :class:`JsonArray` and :class:`DataUri` values it holds streamed from their files."""
    if isinstance(value, JsonArray | DataUri):
        value.write_json(out)
        return
    if not (isinstance(value, dict | list) and value):
        out.write(layout.text(value, depth).encode())
        return
    members = value.items() if isinstance(value, dict) else ((None, item) for item in value)
    brackets = "{}" if isinstance(value, dict) else "[]"
    out.write(brackets[0].encode())
    for i, (key, item) in enumerate(members):
        name = "" if key is None else layout.encode(key) + layout.colon
        out.write((("," if i else "") + layout.newline(depth + 1) + name).encode())
        write_json(item, out, layout, depth + 1)
    out.write((layout.newline(depth) + brackets[1]).encode())


def json_object(**members: Any) -> dict[str, Any]:
    """A JSON object of the ``members`` that are set: no ``None`` and no empty list, object or
    :class:`JsonArray`."""
    return {
        key: value
        for key, value in members.items()
        if value is not None and not (isinstance(value, list | dict | JsonArray) and not value)
    }
