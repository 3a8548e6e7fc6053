"""A tile's features as an ``EXT_structural_metadata`` property table: one class
(:data:`CLASS`) with each feature's ``id`` and ``type`` and its attributes with real types.

An attribute's type follows its values in the tile: all booleans → ``BOOLEAN``, all integers
(within int64) → ``INT64``, all numbers → ``FLOAT64``, else ``STRING`` (numbers and booleans as
their JSON text, nested values as JSON). A feature without the attribute holds the property's
``noData`` value (:data:`NO_DATA`); a boolean attribute that some feature lacks is a
``STRING`` (``BOOLEAN`` takes no ``noData``). Property ids are the attribute names made
identifiers (other characters → ``_``); the name is kept as the property's ``name``.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

CLASS = "cityObject"
INT64 = np.iinfo(np.int64)
NO_DATA = {"STRING": "", "INT64": int(INT64.min), "FLOAT64": -float(np.finfo(np.float64).max)}
"""What a feature without the attribute holds, per type."""
_IDENTIFIER = re.compile(r"[^A-Za-z0-9_]")

Feature = tuple[str, str, dict[str, Any]]
"""One feature: its id, its type and its attributes."""
View = Callable[[bytes], int]
"""Adds bytes as a buffer view (8-byte aligned) and returns its index."""


def _kind(values: list[Any]) -> str:
    """The property type of ``values`` (one per feature; ``None``: no value)."""
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return "BOOLEAN" if len(present) == len(values) else "STRING"
    numbers = present and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in present
    )
    if numbers and all(isinstance(v, int) and INT64.min < v <= INT64.max for v in present):
        return "INT64"
    if numbers and all(np.isfinite(float(v)) for v in present):
        return "FLOAT64"
    return "STRING"


def _text(value: Any) -> str:
    """A STRING property's text of ``value``: strings as they are, others as JSON."""
    if isinstance(value, str):
        return value
    return json.dumps(value, sort_keys=True, ensure_ascii=False, default=str)


def _identifiers(names: Sequence[str]) -> dict[str, str]:
    """Each attribute name's property id: unique, a valid identifier, never ``id``/``type``."""
    taken = {"id", "type"}
    found: dict[str, str] = {}
    for name in names:
        base = _IDENTIFIER.sub("_", name) or "_"
        base = f"_{base}" if base[0].isdigit() else base
        ident, n = base, 2
        while ident in taken:
            ident, n = f"{base}_{n}", n + 1
        taken.add(ident)
        found[name] = ident
    return found


def _column(kind: str, values: list[Any], view: View) -> dict[str, Any] | None:
    """A property table column of ``values`` (``None``: no data); ``None`` for strings that
    are all empty (a column of no bytes: the property is left out of the table)."""
    if kind == "STRING":
        texts = [NO_DATA["STRING"] if v is None else _text(v) for v in values]
        encoded = [t.encode("utf-8") for t in texts]
        if not any(encoded):
            return None
        offsets = np.concatenate([[0], np.cumsum([len(b) for b in encoded])]).astype(np.uint32)
        return {
            "values": view(b"".join(encoded)),
            "stringOffsets": view(offsets.tobytes()),
            "stringOffsetType": "UINT32",
        }
    if kind == "BOOLEAN":
        bits = np.packbits(np.array(values, dtype=bool), bitorder="little")
        return {"values": view(bits.tobytes())}
    dtype = np.int64 if kind == "INT64" else np.float64
    filled = [NO_DATA[kind] if v is None else v for v in values]
    return {"values": view(np.array(filled, dtype=dtype).tobytes())}


def property_table(features: Sequence[Feature], view: View) -> dict[str, Any]:
    """The ``EXT_structural_metadata`` object of a GLB holding ``features`` (feature id i is
    ``features[i]``), its columns added through ``view``."""
    names = sorted({name for _, _, attributes in features for name in attributes})
    properties: dict[str, Any] = {
        "id": {"name": "id", "type": "STRING", "required": True},
        "type": {"name": "type", "type": "STRING", "noData": NO_DATA["STRING"]},
    }
    columns: dict[str, dict[str, Any] | None] = {
        "id": _column("STRING", [f[0] for f in features], view),
        "type": _column("STRING", [f[1] or None for f in features], view),
    }
    for name, ident in _identifiers(names).items():
        values = [attributes.get(name) for _, _, attributes in features]
        kind = _kind(values)
        definition: dict[str, Any] = {"name": name, "type": kind}
        if kind == "INT64":
            definition["componentType"], definition["type"] = "INT64", "SCALAR"
        elif kind == "FLOAT64":
            definition["componentType"], definition["type"] = "FLOAT64", "SCALAR"
        if kind != "BOOLEAN":
            definition["noData"] = NO_DATA[kind]
        properties[ident] = definition
        columns[ident] = _column(kind, values, view)
    columns = {name: column for name, column in columns.items() if column is not None}
    return {
        "schema": {"id": "lodconvert", "classes": {CLASS: {"properties": properties}}},
        "propertyTables": [{"class": CLASS, "count": len(features), "properties": columns}],
    }
