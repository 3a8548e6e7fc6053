"""Hypothesis strategies that damage a seed file: byte edits, token edits (numbers replaced by
hostile values, tokens dropped or repeated) and structure edits (lines and JSON values)."""

from __future__ import annotations

import json
import re
from typing import Any

from hypothesis import strategies as st

HOSTILE_NUMBERS = (
    b"-1",
    b"0",
    b"1",
    b"2",
    b"3",
    b"4",
    b"255",
    b"-2147483648",
    b"2147483647",
    b"4294967295",
    b"999999999",
    b"1000000000000",
    b"1e20",
    b"-1e308",
    b"1e308",
    b"1e-320",
    b"nan",
    b"inf",
    b"-inf",
    b"1.5",
    b"0x10",
    b"",
    b"abc",
)
"""Values a token is replaced with: index edges, huge and tiny magnitudes, non-numbers."""
_TOKEN = re.compile(rb"[^\s]+")


def _bytes_edit(data: bytes, draw: Any) -> bytes:
    """One byte-level edit: flip, overwrite, insert, delete a range, or truncate."""
    if not data:
        return draw(st.binary(max_size=64))
    at = draw(st.integers(0, len(data) - 1))
    kind = draw(st.sampled_from(("flip", "set", "insert", "delete", "truncate")))
    if kind == "flip":
        return data[:at] + bytes([data[at] ^ (1 << draw(st.integers(0, 7)))]) + data[at + 1 :]
    if kind == "set":
        value = draw(st.sampled_from((0, 0xFF, 0x7F, 0x80, ord("\n"), ord(" "), ord("-"))))
        return data[:at] + bytes([value]) + data[at + 1 :]
    if kind == "insert":
        return data[:at] + draw(st.binary(min_size=1, max_size=16)) + data[at:]
    if kind == "delete":
        return data[:at] + data[at + draw(st.integers(1, 64)) :]
    return data[:at]


def _token_edit(data: bytes, draw: Any) -> bytes:
    """One whitespace-token edit: replace with a hostile number, drop, or repeat it."""
    tokens = list(_TOKEN.finditer(data))
    if not tokens:
        return _bytes_edit(data, draw)
    token = tokens[draw(st.integers(0, len(tokens) - 1))]
    kind = draw(st.sampled_from(("number", "number", "drop", "repeat")))
    new = {
        "number": draw(st.sampled_from(HOSTILE_NUMBERS)),
        "drop": b"",
        "repeat": token.group() + b" " + token.group(),
    }[kind]
    return data[: token.start()] + new + data[token.end() :]


def _line_edit(data: bytes, draw: Any) -> bytes:
    """One line edit: delete, duplicate (up to many times) or swap lines."""
    lines = data.split(b"\n")
    i = draw(st.integers(0, len(lines) - 1))
    j = draw(st.integers(0, len(lines) - 1))
    kind = draw(st.sampled_from(("delete", "duplicate", "swap")))
    if kind == "delete":
        del lines[i]
    elif kind == "duplicate":
        lines[i:i] = [lines[i]] * draw(st.integers(1, 200))
    else:
        lines[i], lines[j] = lines[j], lines[i]
    return b"\n".join(lines)


def _json_values(doc: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Paths of every scalar in a JSON document."""
    if isinstance(doc, dict):
        return [p for k, v in doc.items() for p in _json_values(v, (*path, k))]
    if isinstance(doc, list):
        return [p for i, v in enumerate(doc) for p in _json_values(v, (*path, i))]
    return [path]


def _json_edit(doc: Any, draw: Any) -> Any:
    """``doc`` with one scalar replaced by a hostile value (an int edge, a float, a string,
    null, a list, or removed)."""
    paths = _json_values(doc)
    if not paths:
        return doc
    path = paths[draw(st.integers(0, len(paths) - 1))]
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    value = draw(
        st.sampled_from((-1, 0, 1, 2, 3, 5120, 5126, 2**31, 2**62, 1e308, -0.5, "x", None, [], {}))
    )
    if isinstance(parent, dict) and draw(st.booleans()):
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return doc


def _glb_json_edit(data: bytes, draw: Any) -> bytes:
    """A GLB with one value of its JSON chunk edited (lengths fixed up), else a byte edit."""
    if len(data) < 20 or data[:4] != b"glTF":
        return _bytes_edit(data, draw)
    length = int.from_bytes(data[12:16], "little")
    try:
        doc = json.loads(data[20 : 20 + length])
    except ValueError:
        return _bytes_edit(data, draw)
    chunk = json.dumps(_json_edit(doc, draw)).encode()
    chunk += b" " * (-len(chunk) % 4)
    rest = data[20 + length :]
    total = 20 + len(chunk) + len(rest)
    header = data[:8] + total.to_bytes(4, "little") + len(chunk).to_bytes(4, "little")
    return header + data[16:20] + chunk + rest


def _structure_edit(data: bytes, draw: Any) -> bytes:
    """A structural edit: JSON values of glTF/GLB, else lines of a text format, else bytes."""
    if data[:4] == b"glTF":
        return _glb_json_edit(data, draw)
    if data.lstrip()[:1] == b"{":
        try:
            return json.dumps(_json_edit(json.loads(data), draw)).encode()
        except ValueError:
            return _bytes_edit(data, draw)
    return _line_edit(data, draw)


EDITS = {"bytes": _bytes_edit, "token": _token_edit, "structure": _structure_edit}


@st.composite
def mutated(draw: Any, seeds: tuple[bytes, ...]) -> bytes:
    """A seed of ``seeds`` with one to four edits of any kind."""
    data = draw(st.sampled_from(seeds))
    for _ in range(draw(st.integers(1, 4))):
        data = EDITS[draw(st.sampled_from(sorted(EDITS)))](data, draw)
    return data
