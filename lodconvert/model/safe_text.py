"""Objects' ids and attributes as every output can hold them and every parser read them back.

Input files carry text that an XML document cannot hold or that no parser would read back.
:func:`object_text` bounds an object's id and attributes (its parts' included) before anything
is written or parked on disk: characters XML 1.0 cannot hold and lone surrogates are written as
``\\uXXXX``, strings cut at :data:`MAX_TEXT_CHARS`, lists and mappings nested deeper than
:data:`MAX_DEPTH` written as their JSON text, and an object's attributes kept up to
:data:`MAX_OBJECT_CHARS` characters — far below the 10 MB that libxml2 reads of one X3D
attribute value, even with every character escaped. Each kind of cut is noted in one line (the
report's ``cut``). See *Ids and attributes* in ``docs/cities.md``.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import Any

MAX_TEXT_CHARS = 65_536
"""Longest string kept whole: an id, an attribute's name or value (64 Ki characters)."""
MAX_DEPTH = 32
"""Deepest nesting of lists and mappings in an object's attributes kept as it is."""
MAX_OBJECT_CHARS = 524_288
"""Characters of text kept of one object's attributes (512 Ki): names and values with 2 for
their quotes, 8 for a number or a nesting. Written in X3D, each takes at most 9 bytes."""
NOT_XML_CHARS = r"\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff"
"""Characters that XML 1.0 cannot hold and lone surrogates, as a regular-expression class."""
_NOT_XML = re.compile(f"[{NOT_XML_CHARS}]")
_JSON_CONTROL = re.compile(r"\\u00[01]")
"""How ``json.dumps`` writes a control character other than tab, line feed and return."""
_SCALAR_CHARS = 8
_QUOTES = 2
_SHOWN_PATH_CHARS = 120


def xml_text(text: str) -> str:
    """``text`` with each character XML cannot hold (and each lone surrogate) written as
    ``\\uXXXX``."""
    if _NOT_XML.search(text) is None:
        return text
    return _NOT_XML.sub(lambda m: f"\\u{ord(m.group()):04x}", text)


@dataclass(frozen=True)
class ObjectText:
    """An object's id and attributes as outputs keep them, and what was cut for that."""

    id: str
    attributes: dict[str, Any]
    cut: tuple[str, ...] = ()


@dataclass
class _Cuts:
    """Counts of each kind of cut, with the first place it happened."""

    left: int = MAX_OBJECT_CHARS
    escaped: int = 0
    escaped_at: str = ""
    long: int = 0
    long_at: str = ""
    deep: int = 0
    deep_at: str = ""
    left_out: int = 0
    left_out_at: str = ""
    first_length: int = 0

    def text(self, text: str, path: str) -> str:
        clean = xml_text(text)
        if clean is not text:
            self.escaped += (len(clean) - len(text)) // 5
            self.escaped_at = self.escaped_at or path
        keep = min(MAX_TEXT_CHARS, max(self.left - _QUOTES, 0))
        if len(clean) > keep:
            if not self.long:
                self.long_at, self.first_length = path, len(clean)
            self.long += 1
            clean = clean[:keep]
        self.left -= len(clean) + _QUOTES
        return clean

    def value(self, value: Any, path: str, depth: int) -> Any:
        if isinstance(value, str):
            return self.text(value, path)
        if not isinstance(value, dict | list | tuple):
            self.left -= _SCALAR_CHARS
            return value
        if depth > MAX_DEPTH:
            self.deep += 1
            self.deep_at = self.deep_at or path
            try:
                return self.text(json.dumps(value, ensure_ascii=False, default=str), path)
            except (RecursionError, ValueError):
                return self.text("", path)
        self.left -= _SCALAR_CHARS
        if isinstance(value, dict):
            kept: dict[str, Any] = {}
            for key, item in value.items():
                where = _at(path, f".{key}" if path else str(key))
                if self.left <= 0:
                    self.leave_out(where)
                    continue
                name = self.text(str(key), where)
                kept[name] = self.value(item, where, depth + 1)
            return kept
        items = []
        for index, item in enumerate(value):
            where = _at(path, f"[{index}]")
            if self.left <= 0:
                self.leave_out(where)
                continue
            items.append(self.value(item, where, depth + 1))
        return items

    def leave_out(self, path: str) -> None:
        self.left_out += 1
        self.left_out_at = self.left_out_at or path

    def lines(self) -> list[str]:
        notes = []
        if self.escaped:
            notes.append(
                f"{self.escaped:,} character(s) XML cannot hold written as \\uXXXX (first in "
                f"{_shown(self.escaped_at)})"
            )
        if self.long:
            notes.append(
                f"{self.long:,} string(s) cut (first {_shown(self.long_at)}: "
                f"{self.first_length:,} characters, at most {MAX_TEXT_CHARS:,} kept and "
                f"{MAX_OBJECT_CHARS:,} of the object's attributes)"
            )
        if self.deep:
            notes.append(
                f"{self.deep:,} value(s) nested over {MAX_DEPTH} levels deep written as JSON "
                f"text (first {_shown(self.deep_at)})"
            )
        if self.left_out:
            notes.append(
                f"{self.left_out:,} value(s) left out beyond {MAX_OBJECT_CHARS:,} characters of "
                f"the object's attributes (first {_shown(self.left_out_at)})"
            )
        return notes


def _at(path: str, step: str) -> str:
    """``path`` one step further, kept no longer than a note shows it (a path of long keys
    would otherwise copy them at every level)."""
    return (path + step[: _SHOWN_PATH_CHARS + 1])[: _SHOWN_PATH_CHARS + 1]


def _shown(path: str) -> str:
    """An attribute's path as a note names it: quoted, its characters escaped, cut short."""
    text = xml_text(path)
    return repr(text if len(text) <= _SHOWN_PATH_CHARS else text[:_SHOWN_PATH_CHARS] + "…")


def bounded_id(object_id: str) -> tuple[str, str | None]:
    """``object_id`` as outputs keep it (characters XML cannot hold escaped, cut to
    :data:`MAX_TEXT_CHARS`), and a note of what was done to it (``None``: nothing)."""
    clean = xml_text(object_id)
    done = ["written as \\uXXXX"] if clean is not object_id else []
    if len(clean) > MAX_TEXT_CHARS:
        clean = clean[:MAX_TEXT_CHARS]
        done.append(f"cut to {MAX_TEXT_CHARS:,} characters")
    return clean, "id " + " and ".join(done) if done else None


def _plainly_within(attributes: dict[str, Any]) -> bool:
    """Whether ``attributes`` are within every bound, judged from their compact JSON text at C
    speed (short, few nestings, no character to escape); ``False`` may still be within."""
    try:
        text = json.dumps(attributes, ensure_ascii=False, default=str)
    except (ValueError, RecursionError):
        return False
    return (
        len(text) <= MAX_TEXT_CHARS  # so at most MAX_OBJECT_CHARS // 2 characters counted
        and text.count("{") + text.count("[") <= MAX_DEPTH
        and _NOT_XML.search(text) is None
        and _JSON_CONTROL.search(text) is None
    )


def object_text(object_id: str, attributes: dict[str, Any]) -> ObjectText:
    """``object_id`` and ``attributes`` bounded and cleaned as the module says (text already
    bounded passes unchanged, without notes)."""
    clean_id, id_note = bounded_id(object_id)
    if not attributes or _plainly_within(attributes):
        return ObjectText(clean_id, attributes, (id_note,) if id_note else ())
    cuts = _Cuts()
    kept = cuts.value(attributes, "", 0)
    return ObjectText(clean_id, kept, tuple([id_note] if id_note else []) + tuple(cuts.lines()))
