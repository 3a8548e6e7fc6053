"""What a parsed JSON value is, in the words of JSON, for messages about values of the
wrong type."""

from __future__ import annotations

import json
from typing import Any

_NAMES = {dict: "object", list: "array", str: "string", bool: "boolean", type(None): "null"}


def json_kind(value: Any) -> str:
    """The JSON type of ``value`` (``object``, ``array``, ``string``, ``number``…)."""
    return _NAMES.get(type(value), "number")


def json_shown(value: Any) -> str:
    """``value``'s JSON type and (up to 40 characters of) its JSON text: ``string "16"``
    (``null`` alone)."""
    if value is None:
        return "null"
    return f"{json_kind(value)} {json.dumps(value, default=str)[:40]}"
