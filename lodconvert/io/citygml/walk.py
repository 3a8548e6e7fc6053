"""The walk that finds the polygons of a CityGML city object and of its parts (:func:`gather`).

A polygon belongs to the nearest object or part above it and is read when it lies under a
geometry property (``lod2Solid``, ``lod0FootPrint``…, a terrain component's ``tin``) of that
object or of a thematic surface, opening or installation of it, not in a property that holds
no geometry read (appearances, addresses). Its semantic type is the feature holding the
property (``WallSurface``; none for the object itself; ``FootPrint``/``RoofEdge`` for LoD 0),
and ``OrientableSurface``s with ``orientation="-"`` above it reverse it. Links
(``xlink:href``) within the object are followed, a polygon met twice is read once, and a
solid's interior shells are left out. In full: ``docs/readers.md`` (CityGML).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

from lxml import etree

from ...heap import return_freed_heap
from .coordinates import Rings, read_coordinates, read_holder, read_object
from .holders import BrokenObject, Holder, Place, Polygon, Read
from .implicit import Templates
from .names import (
    GML_IDS,
    GML_NAMESPACES,
    HOLDING_PROPERTIES,
    LOD_PROPERTY,
    NOT_SURFACES,
    POLYGONS,
    RELIEF_NAMESPACE,
    UNREAD_PROPERTIES,
    XLINK_HREF,
    is_feature,
    local,
    namespace,
)

OBJECT_DEPTH = 3
"""Nesting depth of a top-level city object (the root ``CityModel``, a member, the object)."""
PARSER_DEPTH = 2048
"""Nesting depth libxml2 parses at most (with ``huge_tree``)."""
TRIM_RINGS = 1 << 16
"""Rings of one object read between two hand-backs of the heap its freed elements leave
(:func:`~lodconvert.heap.return_freed_heap`)."""
_ITEMS = {
    gml: etree.XPath(
        " | ".join(
            [f"descendant::gml:{name}" for name in sorted(POLYGONS)]
            + ["descendant::gml:Tin[not(.//gml:Triangle)]", "descendant::*/@xlink:href/.."]
        ),
        namespaces={"gml": gml, "xlink": XLINK_HREF[1:].partition("}")[0]},
    )
    for gml in GML_NAMESPACES
}
"""By GML namespace: the polygons, the TINs given by their control points alone (no
triangles) and the elements with an ``xlink:href`` below an element, in document order."""
_LINKED = etree.XPath(
    "boolean(descendant-or-self::*/@xlink:href)",
    namespaces={"xlink": XLINK_HREF[1:].partition("}")[0]},
)
"""Whether an element or one below it links (``xlink:href``) to another."""


@dataclass
class _Walker:
    """Finds where elements lie below a holder (:meth:`place`; a top-level object, or a part
    collected alone), remembering what lies above each geometry property met."""

    top: Holder
    holders: dict[Any, Holder]
    root: etree._Element
    """The top-level object's element (a terrain component's LoD may be its relief's)."""
    places: dict[Any, Place | None] = field(default_factory=dict)

    def place(self, element: etree._Element) -> Place | None:
        """Where ``element`` lies, or None when it is not read (not under a geometry property,
        or in a solid's interior shell, a curve or a property not read). Remembered for
        ``element`` and for the ancestors with several child elements (those that other
        elements share), so that shared ancestors are walked up once and each polygon's
        single-child wrappers (``surfaceMember``…) cost nothing kept (in a loop: elements may
        nest as deep as a document holds)."""
        unplaced = []
        ancestor: etree._Element | None = element
        while ancestor is not None and ancestor not in self.places:
            name, parent = local(ancestor), ancestor.getparent()
            unplaced.append((ancestor, name, parent))
            ancestor = None if self._settled(ancestor, name, parent) else parent
        found: dict[Any, Place | None] = {}
        for each, name, parent in reversed(unplaced):
            found[each] = place = self._found(each, name, parent, found)
            if each is element or len(each) > 1:
                self.places[each] = place
        return found[element] if element in found else self.places[element]

    def _settled(self, element: etree._Element, name: str, parent: etree._Element | None) -> bool:
        """Whether where ``element`` (its local ``name``, its ``parent``) lies is known without
        its parent's place."""
        if parent is None or element is self.top.element:
            return True
        return not _plain(name) and (
            name in NOT_SURFACES
            or LOD_PROPERTY.fullmatch(name) is not None
            or (name == "tin" and RELIEF_NAMESPACE.fullmatch(namespace(element)) is not None)
            or (name == "interior" and local(parent) == "Solid")
        )

    def _found(
        self,
        element: etree._Element,
        name: str,
        parent: etree._Element | None,
        found: dict[Any, Place | None],
    ) -> Place | None:
        """Where ``element`` (its local ``name``, its ``parent``) lies, its parent's place known
        (remembered, or just ``found``) unless :meth:`_settled`."""
        if parent is None or element is self.top.element:
            return None
        if not _plain(name):
            if name in NOT_SURFACES:
                return None
            if (match := LOD_PROPERTY.fullmatch(name)) is not None:
                above = self._above(element)
                if above is None:
                    return None
                holder, semantic = above
                if match.group(2) in ("FootPrint", "RoofEdge"):
                    semantic = name[4:]
                return Place(holder, f"lod{match.group(1)}", semantic, False)
            if name == "tin" and RELIEF_NAMESPACE.fullmatch(namespace(element)):
                above = self._above(element)
                lod = _relief_lod(parent, self.root)
                return None if above is None or lod is None else Place(above[0], lod, "", False)
            if name == "interior" and local(parent) == "Solid":
                return None
        outer = found[parent] if parent in found else self.places[parent]
        if outer is None:
            return None
        if name == "OrientableSurface":
            return outer._replace(flip=outer.flip ^ (element.get("orientation") == "-"))
        if name == "ImplicitGeometry":
            return outer._replace(implicit=element)
        return outer

    def _above(self, prop: etree._Element) -> tuple[Holder, str] | None:
        """For a geometry property: the holder it belongs to and the semantic type of the
        feature holding it ("" for the holder itself); None when the features and properties
        above it are not read."""
        semantic = ""
        holder = None
        feature_next = True
        element = prop
        while element is not self.top.element:
            element = element.getparent()
            if element is None:
                return None
            if holder is not None or element is self.top.element:
                continue
            name = local(element)
            if feature_next:
                if not is_feature(name):
                    return None
                holder = self.holders.get(element)
                if holder is None and not semantic:
                    semantic = name
            elif (
                name in UNREAD_PROPERTIES
                or name in HOLDING_PROPERTIES
                or namespace(element) in GML_NAMESPACES
            ):
                return None
            feature_next = not feature_next
        if holder is None and not feature_next:
            return None
        return holder or self.top, semantic


@functools.lru_cache(maxsize=4096)
def _plain(name: str) -> bool:
    """Whether an element of local name ``name`` lies where its parent does, whatever its
    parent (not a geometry property, curve, TIN property or interior shell)."""
    return not (
        name in NOT_SURFACES
        or LOD_PROPERTY.fullmatch(name) is not None
        or name in ("tin", "interior")
    )


def _relief_lod(component: etree._Element, top: etree._Element) -> str | None:
    """The LoD label (``"lod2"``) of a terrain component: its ``lod``, else its relief
    feature's; None when neither gives one from 0 to 4."""
    for feature in (component, top):
        for child in feature:
            if local(child) == "lod":
                text = (child.text or "").strip()
                return f"lod{text}" if text in ("0", "1", "2", "3", "4") else None
    return None


def check_depth(element: etree._Element, depth_limit: int) -> None:
    """:class:`BrokenObject` when an element of the top-level object ``element`` lies deeper
    in its document than ``depth_limit`` (checked before any of it is walked; the parser
    refuses a document nesting deeper than :data:`PARSER_DEPTH` itself)."""
    if depth_limit >= PARSER_DEPTH:
        return
    below = depth_limit - OBJECT_DEPTH
    if below < 0 or _deeper_than(below)(element):
        raise BrokenObject(
            f"nests XML elements deeper than the limit of {depth_limit} "
            "(raise it with --limit xml_depth=N)"
        )


@functools.lru_cache(maxsize=4)
def _deeper_than(levels: int) -> etree.XPath:
    """Whether an element has a descendant more than ``levels`` levels below it (libxml2
    walks the tree, level by level)."""
    return etree.XPath(f"boolean({'/'.join(['*'] * (levels + 1))})")


def gather(top: Holder, gml: str, templates: Templates | None = None) -> None:
    """Find the polygons of ``top`` (a top-level object of a document whose GML namespace is
    ``gml``) and of its parts, each put in the holder it belongs to in document order,
    following links (an implicit geometry's also to the relative geometries of ``templates``,
    where this object's are added), and read their coordinates
    (:func:`~.coordinates.read_coordinates`). An object without links (``xlink:href``) is
    gathered a part at a time, innermost parts first, each part's elements freed before the
    next: its polygons then lie in its own elements and nothing else refers to them, so only
    one part's elements are walked at a time."""
    if templates is not None:
        templates.register(top.element)
    if _LINKED(top.element):
        _collect(top, top.element, gml, templates)
        read_coordinates(top)
        return
    read_object(top, functools.partial(_gathered, top, top.element, gml))


def _gathered(holder: Holder, root: etree._Element, gml: str, rings: Rings, read: Read) -> None:
    """Collect and read ``holder``'s parts (each freed: :meth:`Holder.release`), then
    ``holder`` itself (an object without links; ``root``: its element); the heap the parts
    took is handed back every :data:`TRIM_RINGS` rings."""
    for part in holder.parts:
        _gathered(part, root, gml, rings, read)
        part.release()
    _collect(holder, root, gml, None)
    holder.forget_walk()
    read_holder(holder, rings, read)
    if len(rings.counts) >= rings.trimmed + TRIM_RINGS:
        return_freed_heap()
        rings.trimmed = len(rings.counts)


def _collect(top: Holder, root: etree._Element, gml: str, templates: Templates | None) -> None:
    """Find the polygons below holder ``top`` (``root``: its top-level object's element), as
    :func:`gather` says."""
    holders = {holder.element: holder for holder in top.walk() if holder.element is not None}
    walker = _Walker(top, holders, root)
    items = _ITEMS[gml](top.element)
    polygon_ids: dict[str, etree._Element] | None = None  # found when a link needs them
    for item in items:
        href = item.get(XLINK_HREF)
        place = walker.place(item)
        if place is None:
            continue
        holder = place.holder
        if href is None:
            if holder.reach(item, place):
                polygon = Polygon(place.lod, place.semantic, place.flip, item, place.implicit)
                holder.polygons.append(polygon)
            continue
        if polygon_ids is None:
            polygon_ids = _polygon_ids(items)
        target = polygon_ids.get(href.removeprefix("#"))
        direct = walker.place(target) if target is not None else None
        if direct is not None and (
            direct.holder is not holder
            or (not place.semantic and direct.lod == place.lod and direct.semantic)
        ):
            continue  # read where it lies: by its own part, or here with its semantics
        holder.add_linked(item, place, templates)


def _polygon_ids(items: list[etree._Element]) -> dict[str, etree._Element]:
    """The ``items`` that link nowhere (polygons), by their ``gml:id``s."""
    ids = {}
    for item in items:
        for key in GML_IDS:
            if (value := item.get(key)) is not None and item.get(XLINK_HREF) is None:
                ids[value] = item
    return ids
