"""Attributes of CityGML city objects: name, description, thematic attributes, address and
generic attributes (CityGML 1.0/2.0 ``gen:stringAttribute``, 3.0 ``gen:StringAttribute``), as
JSON-able values."""

from __future__ import annotations

from typing import Any

from lxml import etree

from .names import GML_NAMESPACES, local, namespace

_ATTRIBUTES = {
    "function": str,
    "usage": str,
    "class": str,
    "roofType": str,
    "yearOfConstruction": int,
    "dateOfConstruction": str,
    "measuredHeight": float,
    "storeysAboveGround": int,
    "storeysBelowGround": int,
}
"""Thematic attributes kept (by local name), with their JSON type."""
_GENERIC_TYPES = {"int": int, "double": float, "measure": float}
"""JSON type of generic attributes by their kind (``gen:intAttribute`` / ``gen:IntAttribute``);
other kinds are kept as text."""


def _typed(text: str, kind: type) -> Any:
    """``text`` as ``kind`` (int, float or str); as text when it is not one."""
    try:
        return kind(text) if kind is not int else int(float(text))
    except (ValueError, OverflowError):
        return text


def _add(attributes: dict[str, Any], key: str, value: Any) -> None:
    """Set ``key``; a repeated key becomes a list of its values."""
    if key not in attributes:
        attributes[key] = value
    elif isinstance(attributes[key], list):
        attributes[key].append(value)
    else:
        attributes[key] = [attributes[key], value]


def _child_text(element: etree._Element, name: str) -> str | None:
    return next((c.text or "" for c in element if local(c) == name), None)


def _generic(element: etree._Element, generic: dict[str, Any]) -> None:
    """Add a generic attribute (2.0 ``gen:stringAttribute name=…``, 3.0
    ``gen:StringAttribute`` with ``gen:name``; sets flattened as ``set.name``, in document
    order, walked with a stack of its own: sets may nest as deep as a document holds)."""
    stack = [(element, "")]
    while stack:
        element, prefix = stack.pop()
        kind = local(element)
        name = element.get("name") or _child_text(element, "name") or kind
        if kind.lower() == "genericattributeset":
            items = []
            for member in element:
                inner = member if local(member)[:1].isupper() or member.get("name") else None
                items += [inner] if inner is not None else list(member)
            stack += [(item, f"{prefix}{name}.") for item in reversed(items)]
            continue
        text = (_child_text(element, "value") or "").strip()
        generic[prefix + name] = _typed(text, _GENERIC_TYPES.get(kind[:-9].lower(), str))


def _joined(found: dict[str, str], *names: str) -> str:
    return " ".join(found[n] for n in names if n in found)


def _address(element: etree._Element) -> str:
    """A readable address (``street number, postcode town, country``) from an ``address``
    property; its other words in document order when it is not xAL 2.0."""
    leaves = [
        (local(e), e.text.strip())
        for e in element.iter()
        if namespace(e) not in GML_NAMESPACES and len(e) == 0 and e.text and e.text.strip()
    ]
    found = dict(leaves)
    street = " ".join(
        filter(None, (found.get("ThoroughfareName"), found.get("ThoroughfareNumber")))
    )
    town = _joined(found, "PostalCodeNumber", "LocalityName")
    parts = [p for p in (street, town, found.get("CountryName")) if p]
    return ", ".join(parts) if parts else ", ".join(text for _, text in leaves)


def attributes_of(element: etree._Element, kind: str, gml_id: str) -> dict[str, Any]:
    """The object's JSON-able attributes: id, type, name, thematic ones, address, generic."""
    attributes: dict[str, Any] = {"id": gml_id, "type": kind}
    generic: dict[str, Any] = {}
    for prop in element:
        name = local(prop)
        if namespace(prop) in GML_NAMESPACES:
            if name in ("name", "description") and prop.text and prop.text.strip():
                _add(attributes, name, prop.text.strip())
        elif name in _ATTRIBUTES and prop.text and prop.text.strip():
            _add(attributes, name, _typed(prop.text.strip(), _ATTRIBUTES[name]))
        elif name == "address":
            _add(attributes, "address", _address(prop))
        elif name == "height":  # 3.0: con:Height with references, status and value
            for height in prop:
                entry = {local(e): _typed((e.text or "").strip(), str) for e in height}
                entry["value"] = _typed(str(entry.get("value", "")), float)
                _add(attributes, "heights", entry)
                if entry.get("status") == "measured":
                    attributes.setdefault("measuredHeight", entry["value"])
        elif name == "genericAttribute":
            for item in prop:
                _generic(item, generic)
        elif name.endswith("Attribute") or name == "genericAttributeSet":
            _generic(prop, generic)
    if generic:
        attributes["generic"] = generic
    return attributes
