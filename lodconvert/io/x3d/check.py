"""X3D checks: well-formed XML with an ``X3D`` root and a ``Scene``; the components that ``LOD``
(Navigation 2), ``PointProperties`` (Shape 5) and the nodes of prism switching
(``ProximitySensor``: EnvironmentalSensor 1; ``BooleanFilter``, ``IntegerTrigger``:
EventUtilities 1) need; every ``LOD`` with strictly increasing, non-negative ranges and one child
more than ranges; ``PointSet`` s with one colour per point and no ``Normal``;
``IndexedTriangleSet`` s of whole triangles indexing existing vertices; every ``ROUTE`` after the
nodes it connects; at least one lodconvert chain (an ``LOD`` in a ``Transform`` holding
``MetadataSet name='lodconvert'``, directly or, with prism switching, through the ``Switch``
that hides it); and, when a schema is given, the XSD (the official X3D 4.0 XSD is a test-time
reference, not shipped).

The document is streamed with libxml2's default limits and without resolving entities; each
``Shape`` is cleared once checked, so memory stays small for large files.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np
from lxml import etree

from ...errors import LodConvertError
from ..findings import Findings
from .metadata import METADATA_SET

if TYPE_CHECKING:
    from .. import CheckOptions

MAX_SCHEMA_FINDINGS = 20
"""Schema errors listed one by one; any more are summed up in one finding."""
_SENSING_PROFILES = ("Interactive", "Immersive", "Full")
_NEEDED_COMPONENTS: dict[str, tuple[str, int, tuple[str, ...]]] = {
    "LOD": ("Navigation", 2, ("Immersive", "Full")),
    "PointProperties": ("Shape", 5, ("Full",)),
    "ProximitySensor": ("EnvironmentalSensor", 1, _SENSING_PROFILES),
    "BooleanFilter": ("EventUtilities", 1, _SENSING_PROFILES),
    "IntegerTrigger": ("EventUtilities", 1, _SENSING_PROFILES),
}
"""Node type → the component and level it needs beyond the Interchange profile, and the
profiles that include that level without a component statement."""


class _Catalog(etree.Resolver):
    """Resolves a schema's imports to the local files an OASIS ``catalog.xml`` lists."""

    def __init__(self, catalog: Path) -> None:
        super().__init__()
        entries = etree.parse(str(catalog)).getroot()
        self.local = {
            e.get("name") or e.get("systemId"): str(catalog.parent / e.get("uri"))
            for e in entries
            if e.get("uri")
        }

    def resolve(self, url: str, pubid: str | None, context: object) -> Any:
        local = self.local.get(url)
        return self.resolve_filename(local, context) if local else None


@functools.lru_cache(maxsize=4)
def _schema_at(path: Path) -> etree.XMLSchema:
    parser = etree.XMLParser()
    catalog = path.parent / "catalog.xml"
    if catalog.is_file():
        parser.resolvers.add(_Catalog(catalog))
    return etree.XMLSchema(etree.parse(str(path), parser))


def load_x3d_schema(path: str | Path) -> etree.XMLSchema:
    """The XSD at ``path`` (or ``path/x3d-4.0.xsd`` for a folder), loaded once and cached;
    :class:`LodConvertError` when it cannot be read or is not a schema."""
    path = Path(path)
    if path.is_dir():
        path = path / "x3d-4.0.xsd"
    try:
        return _schema_at(path.resolve())
    except (OSError, etree.XMLSyntaxError, etree.XMLSchemaParseError) as exc:
        raise LodConvertError(f"cannot load the schema: {exc}", str(path)) from None


def _label(element: etree._Element) -> str:
    """``LOD 'bunny_LOD' (line 12)``: the node type, its DEF if any, and its line."""
    name = f" {element.get('DEF')!r}" if element.get("DEF") else ""
    return f"{element.tag}{name} (line {element.sourceline})"


def _numbers(
    element: etree._Element, attribute: str, width: int, findings: Findings, dtype: type = float
) -> np.ndarray | None:
    """The attribute's numbers as (k, width) rows; ``None`` (with a finding) when they are not
    finite numbers or do not fill whole rows."""
    text = (element.get(attribute) or "").replace(",", " ")
    values = _integers(text) if dtype is np.int64 else None
    try:
        if values is None:
            values = np.array(text.split(), dtype=dtype)
    except (ValueError, OverflowError):
        findings.error("NUMBERS", f"{_label(element)} {attribute} holds something not a number")
        return None
    if dtype is float and not np.isfinite(values).all():
        findings.error("NUMBERS", f"{_label(element)} {attribute} holds non-finite numbers")
        return None
    if len(values) % width:
        findings.error(
            "NUMBERS",
            f"{_label(element)} {attribute} has {len(values)} values, not rows of {width}",
        )
        return None
    return values.reshape(-1, width)


_INT64 = np.iinfo(np.int64)


def _integers(text: str) -> np.ndarray | None:
    """The whole numbers of ``text`` parsed in C, or None where that parser would not take
    them all or could have clamped one (then :func:`_numbers` parses them word by word)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            values = np.fromstring(text, sep=" ", dtype=np.int64)
        except (ValueError, DeprecationWarning):
            return None
    if values.size and (values.max() == _INT64.max or values.min() == _INT64.min):
        return None
    return values


def _child_count(
    geometry: etree._Element, tags: dict[str, int], attribute: str, findings: Findings
) -> int | None:
    """Rows of the first child whose tag is in ``tags`` (tag → row width); ``None`` when there
    is none, it is a ``USE``, or its numbers are malformed."""
    for child in geometry:
        if child.tag in tags and not child.get("USE"):
            rows = _numbers(child, attribute, tags[child.tag], findings)
            return None if rows is None else len(rows)
    return None


_COORDINATES = {"Coordinate": 3, "CoordinateDouble": 3}
_COLORS = {"Color": 3, "ColorRGBA": 4}


def _check_point_set(element: etree._Element, findings: Findings) -> None:
    if element.find("Normal") is not None:
        findings.error("POINTSET_NORMAL", f"{_label(element)} has a Normal (X3D 4.0 allows none)")
    points = _child_count(element, _COORDINATES, "point", findings)
    if points is None:
        if not any(c.tag in _COORDINATES for c in element):
            findings.error("POINTSET_COORDINATE", f"{_label(element)} has no Coordinate")
        return
    colors = _child_count(element, _COLORS, "color", findings)
    if colors is not None and colors != points:
        findings.error(
            "POINTSET_COLOR_COUNT", f"{_label(element)} has {colors} colours for {points} points"
        )


def _check_triangle_set(element: etree._Element, findings: Findings) -> None:
    vertices = _child_count(element, _COORDINATES, "point", findings)
    index = _numbers(element, "index", 3, findings, dtype=np.int64)
    if vertices is not None and index is not None and index.size:
        low, high = int(index.min()), int(index.max())
        if low < 0 or high >= vertices:
            findings.error(
                "INDEX_RANGE",
                f"{_label(element)} index {low if low < 0 else high} is outside its "
                f"{vertices} vertices",
            )
    colors = _child_count(element, _COLORS, "color", findings)
    if vertices is not None and colors is not None and colors != vertices:
        findings.error(
            "COLOR_COUNT", f"{_label(element)} has {colors} colours for {vertices} vertices"
        )


def _check_lod(element: etree._Element, findings: Findings) -> None:
    if element.get("USE"):
        return
    ranges = _numbers(element, "range", 1, findings)
    if ranges is None:
        return
    ranges = ranges.ravel()
    children = [c for c in element if isinstance(c.tag, str) and not c.tag.startswith("Metadata")]
    if not len(ranges):
        if len(children) > 1:
            findings.warning(
                "LOD_NO_RANGE", f"{_label(element)} has no range: the browser picks levels freely"
            )
        return
    if len(children) != len(ranges) + 1:
        findings.error(
            "LOD_CHILDREN",
            f"{_label(element)} has {len(ranges)} ranges but {len(children)} children "
            f"(needs {len(ranges) + 1})",
        )
    if (ranges < 0).any():
        findings.error("LOD_RANGE", f"{_label(element)} has negative ranges")
    if (np.diff(ranges) <= 0).any():
        findings.error("LOD_RANGE", f"{_label(element)} ranges do not increase strictly")


def _is_chain(lod: etree._Element) -> bool:
    """Whether ``lod`` is a lodconvert chain: its parent ``Transform`` (with prism switching, the
    parent of the ``Switch`` holding it) holds the chain's ``MetadataSet name='lodconvert'``."""
    parent = lod.getparent()
    if parent is not None and parent.tag == "Switch":
        parent = parent.getparent()
    return (
        parent is not None
        and parent.tag == "Transform"
        and any(c.tag == "MetadataSet" and c.get("name") == METADATA_SET for c in parent)
    )


_X3D_CHECKS: dict[str, Callable[[etree._Element, Findings], None]] = {
    "LOD": _check_lod,
    "PointSet": _check_point_set,
    "IndexedTriangleSet": _check_triangle_set,
}


def _check_components(root: etree._Element, used: set[str], findings: Findings) -> None:
    """The components that the nodes used need beyond the profile (:data:`_NEEDED_COMPONENTS`)."""
    profile = root.get("profile", "")
    levels = {c.get("name"): c.get("level", "1") for c in root.iterfind("head/component")}

    def level(name: str) -> int:
        try:
            return int(levels.get(name, "0"))
        except ValueError:
            return 0

    for node, (component, needed, profiles) in _NEEDED_COMPONENTS.items():
        if node in used and profile not in profiles and level(component) < needed:
            findings.error(
                "X3D_COMPONENT",
                f"{node} needs component {component} level {needed}, which profile "
                f"{profile!r} lacks",
            )


def _check_route(route: etree._Element, defined: set[str], findings: Findings) -> None:
    """A ``ROUTE`` connects nodes DEF'd before it (a browser cannot resolve later ones)."""
    for end in ("fromNode", "toNode"):
        name = route.get(end)
        if name not in defined:
            findings.error(
                "ROUTE_NODE", f"{_label(route)} {end} {name!r} names no node DEF'd before it"
            )


def check_x3d(path: Path | BinaryIO, findings: Findings, options: CheckOptions | None) -> None:
    """Stream the document (a file, or a binary stream read once: then without the schema of
    ``options``; :class:`LodConvertError` where that schema cannot be loaded),
    checking nodes as they close; ``Shape`` s are cleared once checked and each object's
    top-level ``Transform`` once it closes, so that memory stays small for large files and
    many objects."""
    root: etree._Element | None = None
    used: set[str] = set()
    defined: set[str] = set()  # DEF names seen so far
    chains = 0
    try:
        source = str(path) if isinstance(path, Path) else path
        events = etree.iterparse(source, events=("start", "end"), resolve_entities=False)
        for event, element in events:
            if event == "start":
                if root is None:
                    root = element
                    if element.tag != "X3D":
                        findings.error("X3D_ROOT", f"root element is <{element.tag}>, not <X3D>")
                        return
                if element.get("DEF"):
                    defined.add(element.get("DEF"))
                continue
            used.add(element.tag)
            check = _X3D_CHECKS.get(element.tag)
            if check is not None:
                check(element, findings)
            if element.tag == "ROUTE":
                _check_route(element, defined, findings)
            if element.tag == "LOD" and _is_chain(element):
                chains += 1
            if element.tag == "Shape":
                element.clear()
            elif element.tag == "Transform" and _top_level(element):
                _forget(element)
    except etree.XMLSyntaxError as exc:
        findings.error("XML_SYNTAX", f"not well-formed XML: {exc.msg}")
        return
    except OSError as exc:
        findings.error("READ", f"cannot read: {exc.strerror or exc}")
        return
    assert root is not None  # iterparse raises on an empty document
    if root.get("version") != "4.0":
        findings.warning("X3D_VERSION", f"version {root.get('version')!r}, lodconvert writes 4.0")
    if root.find("Scene") is None:
        findings.error("X3D_SCENE", "the X3D element has no Scene")
    elif not chains:
        findings.error(
            "NO_LOD_CHAIN",
            "no lodconvert LOD chain: no LOD inside a Transform holding "
            f"MetadataSet name='{METADATA_SET}'",
        )
    _check_components(root, used, findings)
    if options is not None and options.x3d_schema is not None and isinstance(path, Path):
        _check_schema(path, load_x3d_schema(options.x3d_schema), findings)


def _top_level(element: etree._Element) -> bool:
    """Whether ``element`` is an object's node: a child of the ``Scene``, or of a ``Transform``
    that is one (the scene frame of a georeferenced file, which holds every object)."""
    parent = element.getparent()
    if parent is None:
        return False
    if parent.tag == "Scene":
        return True
    holder = parent.getparent()
    return parent.tag == "Transform" and holder is not None and holder.tag == "Scene"


def _forget(element: etree._Element) -> None:
    """Free a checked top-level node and the checked siblings before it."""
    element.clear(keep_tail=True)
    parent = element.getparent()
    while element.getprevious() is not None:
        del parent[0]


def _check_schema(path: Path, schema: etree.XMLSchema, findings: Findings) -> None:
    if schema.validate(etree.parse(str(path), etree.XMLParser(resolve_entities=False))):
        return
    errors = list(schema.error_log)
    for error in errors[:MAX_SCHEMA_FINDINGS]:
        findings.error("XSD", f"line {error.line}: {error.message}")
    if len(errors) > MAX_SCHEMA_FINDINGS:
        findings.error("XSD", f"{len(errors) - MAX_SCHEMA_FINDINGS} more schema errors")
