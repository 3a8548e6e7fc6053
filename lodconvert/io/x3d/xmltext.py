"""XML text as lxml writes it (two-space indentation, attribute values escaped as libxml2 does),
built from strings without an element tree, so that a document streams with one object's text
in memory (:class:`XmlOut`); texts made apart and inserted at any depth (:func:`piece_text`)."""

from __future__ import annotations

import io
import re
from collections.abc import Callable, Iterable
from typing import BinaryIO

from ...model.safe_text import NOT_XML_CHARS, xml_text

_DECLARATION = "<?xml version='1.0' encoding='UTF-8'?>"
_ENTITIES = (
    ("&", "&amp;"),
    ("<", "&lt;"),
    (">", "&gt;"),
    ('"', "&quot;"),
    ("\t", "&#9;"),
    ("\n", "&#10;"),
    ("\r", "&#13;"),
)
"""What libxml2 escapes in a double-quoted attribute value, ``&`` first."""
_TO_ESCAPE = re.compile(f'[&<>"\\t\\n\\r{NOT_XML_CHARS}]')


def escape(value: str) -> str:
    """``value`` as double-quoted XML attribute text, escaped as libxml2 (lxml) writes it; a
    character XML cannot hold (which lxml refuses) or a lone surrogate is written as
    ``\\uXXXX`` first (:func:`~lodconvert.model.safe_text.xml_text`)."""
    if _TO_ESCAPE.search(value) is None:
        return value
    value = xml_text(value)
    for char, entity in _ENTITIES:
        if char in value:
            value = value.replace(char, entity)
    return value


_VERBATIM_FIELDS = frozenset(
    {
        *("DEF", "USE", "name", "containerField", "solid"),
        *("fromNode", "toNode", "fromField", "toField"),
        *("index", "point", "color", "diffuseColor", "transparency", "level"),
        *("translation", "rotation", "scale", "scaleOrientation", "center", "size", "range"),
        *("whichChoice", "integerKey", "attenuation"),
        *("pointSizeScaleFactor", "pointSizeMinValue", "pointSizeMaxValue"),
    }
)
"""Fields that the X3D writer fills only with number text (:mod:`..numbers`, ``repr``, ``str``),
its own constant names, ``true``/``false`` or the NCName DEFs of :mod:`.names`: nothing in them
needs escaping, so they are written as they are (coordinates are most of the text)."""


class XmlOut:
    """The XML text of a document, as lxml's ``xmlfile`` writes it with two-space indentation:
    each element on a line of its own, indented by its depth, empty ones self-closed, attribute
    values escaped (:func:`escape`; not those of :data:`_VERBATIM_FIELDS`). :meth:`flush`
    writes the text added so far to the binary ``handle`` in UTF-8."""

    def __init__(self, handle: BinaryIO) -> None:
        self.handle = handle
        self.parts: list[str] = [_DECLARATION]
        self.indent = "\n"
        self.open_tags: list[str] = []

    def _start_tag(self, tag: str, attrib: dict[str, str] | None) -> str:
        text = f"{self.indent}<{tag}"
        if attrib:
            for name, value in attrib.items():
                text += f' {name}="{value if name in _VERBATIM_FIELDS else escape(value)}"'
        return text

    def node(self, tag: str, attrib: dict[str, str] | None = None) -> XmlOut:
        """Open an element whose children are written inside the ``with`` block that this
        call starts (``with out.node(tag):``)."""
        self.parts.append(f"{self._start_tag(tag, attrib)}>")
        self.open_tags.append(tag)
        self.indent += "  "
        return self

    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc_info: object) -> None:
        """Close the element :meth:`node` opened last."""
        self.indent = indent = self.indent[:-2]
        self.parts.append(f"{indent}</{self.open_tags.pop()}>")

    def leaf(self, tag: str, attrib: dict[str, str] | None = None) -> None:
        """Write an element without children."""
        self.parts.append(f"{self._start_tag(tag, attrib)}/>")

    def flush(self) -> None:
        """Write the text added since the last flush to the handle."""
        self.handle.write("".join(self.parts).encode("utf-8"))
        self.parts.clear()

    def inserted(self, text: str) -> None:
        """Add ``text`` made by :func:`piece_text` as the children of the element open now."""
        self.parts.append(text.replace("\n", self.indent))


def piece_text(write: Callable[[XmlOut], None]) -> str:
    """The text ``write`` adds to a document as the children of an element at depth 0, each
    line starting with its line break and its depth's indentation, to be moved to any depth by
    :meth:`XmlOut.inserted` (no line break stands elsewhere: attribute values have theirs
    escaped, and the fields written verbatim hold none)."""
    out = XmlOut(io.BytesIO())
    out.parts.clear()
    write(out)
    return "".join(out.parts)


def mfstring(values: Iterable[str]) -> str:
    """X3D MFString text: each value double-quoted, with ``\\`` and ``"`` escaped."""
    return " ".join('"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"' for v in values)
