"""The vertices of CityJSON: parsed from the JSON text a chunk at a time (a whole file's never
held as Python numbers), checked row by row, scaled and translated by the file's ``transform``.

A document's (or a CityJSONSeq line's) top-level object is parsed key by key
(:func:`top_level`): its ``vertices``, when they are rows of three JSON numbers, are parsed a
chunk of text at a time into an (n, 3) float64 array (24 bytes a vertex, where a list of
lists of Python numbers takes some 200); any other value, and vertices of any other shape,
are parsed by ``json`` whole. Vertex lists so parsed are read row by row
(:func:`vertex_rows`): a row that is not three numbers (a string, a boolean, two numbers) or
whose numbers overflow float64 becomes a row of NaN, which makes every object using it
skipped with the vertex named (:func:`check_used`), as a non-finite coordinate does.
"""

from __future__ import annotations

import json
import re
from itertools import chain
from typing import Any

import numpy as np

from ...errors import InputError
from ..crs import Crs
from ..geometry_checks import MAX_MAGNITUDE, InputTally, check_magnitude
from .jsonkind import json_kind

_SPACE = re.compile(r"[ \t\n\r]*")
_EMPTY = re.compile(r"\[[ \t\n\r]*\]")
_CLOSE = re.compile(r"\][ \t\n\r]*\]")
_COMMA = re.compile(r"[ \t\n\r]*,")
_NOT_NUMBERS = re.compile(r"[^-+.0-9eE\[\], \t\n\r]")
_TEXT_CHUNK = 1 << 20
"""Characters of vertex text parsed at once (bounds the Python objects parsing makes)."""
_DECODER = json.JSONDecoder()
_NUMBERS = {int, float}


def top_level(text: str, tally: InputTally | None = None) -> Any:
    """``text`` parsed as JSON (``ValueError`` when it is not), a top-level object's
    ``vertices`` of rows of three numbers as an (n, 3) float64 array: their rows are counted
    against ``tally``'s ``vertices`` limit before it is allocated."""
    at = _SPACE.match(text).end()
    if not text.startswith("{", at):
        return json.loads(text)
    data: dict[str, Any] = {}
    at = _SPACE.match(text, at + 1).end()
    if text.startswith("}", at):
        at += 1
    else:
        while True:
            if not text.startswith('"', at):
                raise json.JSONDecodeError("Expecting property name in double quotes", text, at)
            key, at = json.decoder.scanstring(text, at + 1)
            at = _SPACE.match(text, at).end()
            if not text.startswith(":", at):
                raise json.JSONDecodeError("Expecting ':' delimiter", text, at)
            at = _SPACE.match(text, at + 1).end()
            rows = _vertex_array(text, at, tally) if key == "vertices" else None
            if rows is not None:
                data[key], at = rows
            else:
                data[key], at = _DECODER.raw_decode(text, at)
            at = _SPACE.match(text, at).end()
            if text.startswith("}", at):
                at += 1
                break
            if not text.startswith(",", at):
                raise json.JSONDecodeError("Expecting ',' delimiter", text, at)
            at = _SPACE.match(text, at + 1).end()
    at = _SPACE.match(text, at).end()
    if at != len(text):
        raise json.JSONDecodeError("Extra data", text, at)
    return data


def _vertex_array(text: str, start: int, tally: InputTally | None) -> tuple[np.ndarray, int] | None:
    """The JSON array at ``text[start]`` as an (n, 3) float64 array and the index past it,
    parsed :data:`_TEXT_CHUNK` characters of rows at a time (a row that is not three numbers
    within float64 a row of NaN, see :func:`vertex_rows`); None unless it is an array of
    arrays that are no deeper (then ``json`` parses it whole)."""
    if empty := _EMPTY.match(text, start):
        return np.zeros((0, 3)), empty.end()
    close = _CLOSE.search(text, start)
    if close is None:
        return None
    last = close.start() + 1  # past the last row: the first "]]" ends rows of numbers
    rows = text.count("[", start, last) - 1
    if tally is not None:
        tally.count(rows, 0, declared=True)
    out = np.empty((rows, 3), dtype=np.float64)
    filled, at = 0, start + 1
    while at < last:
        cut = text.find("]", at + _TEXT_CHUNK) + 1 if at + _TEXT_CHUNK < last else last
        if filled:
            comma = _COMMA.match(text, at, cut)
            if comma is None:
                return None
            at = comma.end()
        piece = text[at:cut]
        try:
            parsed = json.loads(f"[{piece}]")
        except ValueError:
            return None
        values = None if _NOT_NUMBERS.search(piece) else _numbers(parsed)
        if values is None:
            values = vertex_rows(parsed, "")  # a row that is not three numbers is NaN
        count = len(values)
        if filled + count > rows:
            return None
        out[filled : filled + count] = values
        filled, at = filled + count, cut
    return (out, close.end()) if filled == rows else None


def _numbers(rows: list[Any]) -> np.ndarray | None:
    """``rows`` as an (n, 3) float64 array when each is three JSON numbers within float64."""
    try:
        values = np.array(rows)
    except ValueError:  # rows of different lengths
        return None
    if values.ndim != 2 or values.shape[1:] != (3,) or values.dtype.kind not in "if":
        return None
    return values.astype(np.float64, copy=False)


def vertex_rows(values: Any, where: str) -> np.ndarray:
    """A JSON vertex list (or an array :func:`top_level` read) as an (n, 3) float64 array; a
    row that is not three numbers, or whose numbers overflow float64, is a row of NaN.
    :class:`InputError` when ``values`` is not a list."""
    if isinstance(values, np.ndarray):
        return values
    if values is None:
        values = []
    if not isinstance(values, list):
        raise InputError(f"has vertices that are not a list (JSON {json_kind(values)})", where)
    rows = set(map(type, values)) <= {list} and set(map(len, values)) <= {3}
    if rows and set(map(type, chain.from_iterable(values))) <= _NUMBERS:
        try:
            return np.array(values, dtype=np.float64).reshape(-1, 3)
        except OverflowError:
            pass  # an integer beyond float64: that row alone is unreadable
    return np.array([_row(value) for value in values], dtype=np.float64).reshape(-1, 3)


def _row(value: Any) -> tuple[float, ...]:
    """A vertex row as three floats; NaN for one that is not three numbers within float64."""
    if isinstance(value, list) and len(value) == 3 and set(map(type, value)) <= _NUMBERS:
        try:
            return tuple(map(float, value))
        except OverflowError:
            pass
    return (np.nan,) * 3


def _triple(value: Any, name: str, where: str) -> np.ndarray:
    """``transform``'s ``scale`` or ``translate``: three finite numbers."""
    if isinstance(value, list) and len(value) == 3 and set(map(type, value)) <= _NUMBERS:
        try:
            triple = np.array(value, dtype=np.float64)
        except OverflowError:
            triple = np.full(3, np.inf)
        if np.isfinite(triple).all():
            return triple
    raise InputError(f"has a malformed transform (its {name} is not three finite numbers)", where)


def vertices_of(values: Any, transform: Any, where: str, crs: Crs | None = None) -> np.ndarray:
    """A vertex list in float64 metres: scaled and translated by ``transform`` where given,
    then, for a geographic ``crs``, projected onto its local frame (which the first vertices
    projected centre). Unreadable rows and coordinates that are not finite, or that the
    scaling makes overflow, are NaN, for :func:`check_used` to refuse the objects using them."""
    v = vertex_rows(values, where)
    if transform is not None:
        if not isinstance(transform, dict):
            raise InputError(f"has a malformed transform (JSON {json_kind(transform)})", where)
        scale = _triple(transform.get("scale"), "scale", where)
        translate = _triple(transform.get("translate"), "translate", where)
        with np.errstate(over="ignore", invalid="ignore"):
            v = v * scale + translate
    if crs is None or not crs.geographic:
        return v
    good = np.isfinite(v).all(axis=1) & (np.abs(v) <= MAX_MAGNITUDE).all(axis=1)
    if good.all():
        return crs.to_metric(v)
    projected = np.full_like(v, np.nan)
    with np.errstate(all="ignore"):
        projected[good] = crs.to_metric(v[good])
    return projected


def check_used(vertices: np.ndarray, index: np.ndarray, where: str) -> None:
    """:class:`InputError` naming ``where`` and the first vertex at fault unless the vertices
    ``index`` uses are finite and within :data:`MAX_MAGNITUDE`."""
    used = vertices[index]
    finite = np.isfinite(used).all(axis=1)
    if not finite.all():
        vertex = int(index[np.flatnonzero(~finite)[0]])
        raise InputError(
            f"uses vertex {vertex}, whose coordinates are unreadable or not finite", where
        )
    check_magnitude(float(np.abs(used).max(initial=0.0)), where)
