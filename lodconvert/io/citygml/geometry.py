"""The geometry of CityGML city objects: which polygons an object and each of its parts hold
(with LoD, semantic type and orientation), and, for a batch of objects at once, their
coordinates in metres and their triangles as one checked :class:`Surface` per LoD and semantic
type.

A polygon belongs to the nearest object or part above it and is read when it lies under a
geometry property (``lod2Solid``, ``lod0FootPrint``…, a terrain component's ``tin``) of that
object, of a thematic surface, opening or installation of it, and not in a property that holds
no geometry read (appearances, addresses). Parts and interiors (rooms, furniture) are holders
of their own. Its semantic type is the feature holding the geometry property (``WallSurface``;
none for the object itself; ``FootPrint``/``RoofEdge`` for LoD 0), and ``OrientableSurface``s
with ``orientation="-"`` above it reverse it. ``xlink:href`` links to polygons (or to
geometries holding them) within the object are followed; a polygon that a solid refers to and a
thematic surface holds is read once, with its semantics, and so is a polygon whose exterior
ring repeats another's of the same LoD. A solid's interior shells are left out. Implicit
geometry (a tree's relative geometry, inline or linked from another object) is placed by its
``ImplicitGeometry`` (:mod:`.implicit`).

Triangulating a batch of objects together (:func:`triangulate_batch`) lets the per-polygon work
run as array operations over thousands of polygons instead of a few dozen.
"""

from __future__ import annotations

import functools
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from lxml import etree

from ...errors import InputError
from ...heap import return_freed_heap
from ...model import Surface
from ...polygons import Triangles, points_surface, triangulate_many
from ...semantics import Palette
from ..crs import Crs
from ..geometry_checks import (
    InputTally,
    check_magnitude,
    faces_with_area,
)
from ..numbers import parse_floats
from .implicit import Templates, placed, placement
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
MAX_PART_DEPTH = 32
"""Parts nested in parts below a top-level object (a building's parts' parts…) read; an object
whose parts nest deeper is skipped."""
TRIM_RINGS = 1 << 16
"""Rings of one object read between two hand-backs of the heap its freed elements leave
(:func:`~lodconvert.heap.return_freed_heap`)."""
TRIANGULATED = 4096
"""Polygons triangulated together at most, but for one holder's (a batch's per-polygon
arrays cost some 1 KB a polygon; thousands together already run as array operations)."""
_DEDUP_DECIMALS = 6
"""A polygon whose exterior ring repeats another's of the same LoD to this many decimals is
read once (a solid's copy of a thematic surface's polygon)."""
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
_EXTERIOR = frozenset({"exterior", "outerBoundaryIs"})
_INTERIOR = frozenset({"interior", "innerBoundaryIs"})


class BrokenObject(ValueError):
    """An object whose geometry cannot be read (the message says why)."""


@dataclass(eq=False, slots=True)
class Polygon:
    """One polygon met in an object: its LoD, semantic type (``""``: none), whether an
    ``OrientableSurface`` reversed it, its element and what places it (until its coordinates
    are read, :func:`read_coordinates`), and its rings (exterior first; (k, 3) float64 in
    metres) once the batch's coordinates are in metres."""

    lod: str
    semantic: str
    flip: bool
    element: etree._Element | None
    implicit: etree._Element | None = None
    """The ``ImplicitGeometry`` that places it (its rings are read in its frame), or None."""
    rings: list[np.ndarray] = field(default_factory=list)
    serial: int = 0
    """Its element's number in its holder (a polygon met twice has one), once read."""
    placed_by: int | None = None
    """Its placement's key in :attr:`_Read.placements` (implicit geometry), once read."""
    tin: bool = False
    """Whether it is a ``Tin`` given by its control points (triangulated in plan)."""
    max_length: float | None = None
    """Such a ``Tin``'s ``maxLength`` (longer triangles are left out), when one is given."""


@dataclass(eq=False)
class Holder:
    """A city object or one of its parts: its element and id, its parts, the polygons found in
    it, what was wrong with them, and (after :func:`triangulate_batch`) its surfaces by LoD."""

    element: etree._Element | None
    """Its element, until a part read lets go of it (:meth:`release`)."""
    kind: str
    gml_id: str
    parts: list[Holder]
    where: str = ""
    polygons: list[Polygon] = field(default_factory=list)
    unresolved: int = 0
    degenerate: int = 0
    dropped: int = 0
    surfaces: dict[str, list[Surface]] = field(default_factory=dict)
    attributes: dict[str, Any] = field(default_factory=dict)
    """Its attributes, taken before its elements are freed."""
    read: _Read | None = None
    """A top-level object's coordinates, once read (:func:`read_coordinates`)."""
    broken: str = ""
    """Why a top-level object's coordinates cannot be read, if they cannot."""
    _ids: dict[str, etree._Element] | None = None
    _reached: set[tuple[str, bool, etree._Element]] = field(default_factory=set)
    """Elements walked, by LoD and whether a semantic type was given (see :meth:`reach`)."""

    def walk(self) -> Iterator[Holder]:
        """This holder, then its parts' holders depth first, in document order."""
        yield self
        for part in self.parts:
            yield from part.walk()

    def release(self) -> None:
        """Free a part's elements once it is read: emptied, then taken out of the tree (with
        the property holding it, once that holds nothing else) and let go of, so that none of
        it stays (an emptied part kept, with its property, pins the heap pages around them)."""
        element, self.element = self.element, None
        if element is None:
            return
        element.clear(keep_tail=False)
        prop = element.getparent()
        if prop is None:
            return
        prop.remove(element)
        feature = prop.getparent()
        if feature is not None and not len(prop):
            feature.remove(prop)

    def forget_walk(self) -> None:
        """Let go of what :func:`gather` remembered of the elements walked."""
        self._ids = None
        self._reached = set()

    def target(self, href: str) -> etree._Element | None:
        """The element of this holder that ``href`` (``#id``) refers to, or None."""
        if self._ids is None:
            self._ids = {
                value: e
                for e in self.element.iter()
                for key, value in e.attrib.items()
                if key.endswith("}id")
            }
        return self._ids.get(href.removeprefix("#"))

    def reach(self, element: etree._Element, place: _Place) -> bool:
        """Whether ``element`` is met for the first time at ``place``'s LoD, with or without a
        semantic type as ``place`` has one (noted): a polygon met again is not read again
        (:func:`_kept` keeps each polygon's first with semantics, else its first), nor is a
        geometry walked again, so that links cost what the object holds."""
        key = (place.lod, bool(place.semantic), element)
        if key in self._reached:
            return False
        self._reached.add(key)
        return True

    def add_linked(
        self, element: etree._Element, place: _Place, templates: Templates | None = None
    ) -> None:
        """Add every polygon under ``element`` (a geometry, or an element linking to one) as
        ``place`` says, following ``xlink:href`` within this holder (and, for an implicit
        geometry, to the relative geometries of ``templates``); a solid's interior shells are
        left out. The walk keeps a stack of its own (links may chain as deep as a document
        holds)."""
        stack = [(element, place)]
        while stack:
            element, place = stack.pop()
            href = element.get(XLINK_HREF)
            if href is not None:
                target = self.target(href)
                if target is None and place.implicit is not None and templates is not None:
                    target = templates.get(href)
                if target is None:
                    self.unresolved += 1
                    continue
                element = target
            if not self.reach(element, place):
                continue
            name = local(element)
            if name in POLYGONS or (name == "Tin" and _points_only(element)):
                self.polygons.append(
                    Polygon(place.lod, place.semantic, place.flip, element, place.implicit)
                )
                continue
            if name in NOT_SURFACES:
                continue
            if name == "OrientableSurface" and element.get("orientation") == "-":
                place = place._replace(flip=not place.flip)
            children = [
                child for child in element if not (name == "Solid" and local(child) == "interior")
            ]
            stack += [(child, place) for child in reversed(children)]


def holders_of(element: etree._Element, depth: int = 0) -> Holder:
    """The holder of a city object (or part, ``depth`` parts down) and, nested, of its parts;
    :class:`BrokenObject` when parts nest deeper than :data:`MAX_PART_DEPTH`."""
    parts = []
    for prop in element:
        if local(prop) not in HOLDING_PROPERTIES:
            continue
        for part in prop:
            if not is_feature(local(part)):
                continue
            if depth == MAX_PART_DEPTH:
                raise BrokenObject(f"has parts nested more than {MAX_PART_DEPTH} deep")
            parts.append(holders_of(part, depth + 1))
    return Holder(element, local(element), gml_id_of(element), parts)


def gml_id_of(element: etree._Element) -> str:
    """The element's ``gml:id`` (any GML version), or ``""``."""
    return next((element.get(key) for key in GML_IDS if element.get(key)), "")


class _Place(NamedTuple):
    """Where a polygon (or a link) lies in an object: the holder it belongs to, its LoD,
    semantic type, orientation and the ``ImplicitGeometry`` above it, if any."""

    holder: Holder
    lod: str
    semantic: str
    flip: bool
    implicit: etree._Element | None = None


@dataclass
class _Walker:
    """Finds where elements lie below a holder (:meth:`place`; a top-level object, or a part
    collected alone), remembering what lies above each geometry property met."""

    top: Holder
    holders: dict[Any, Holder]
    root: etree._Element
    """The top-level object's element (a terrain component's LoD may be its relief's)."""
    places: dict[Any, _Place | None] = field(default_factory=dict)

    def place(self, element: etree._Element) -> _Place | None:
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
        found: dict[Any, _Place | None] = {}
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
        found: dict[Any, _Place | None],
    ) -> _Place | None:
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
                return _Place(holder, f"lod{match.group(1)}", semantic, False)
            if name == "tin" and RELIEF_NAMESPACE.fullmatch(namespace(element)):
                above = self._above(element)
                lod = _relief_lod(parent, self.root)
                return None if above is None or lod is None else _Place(above[0], lod, "", False)
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
    where this object's are added), and read their coordinates (:func:`read_coordinates`).
    An object without links (``xlink:href``) is gathered a part at a time, innermost parts
    first, each part's elements freed before the next: its polygons then lie in its own
    elements and nothing else refers to them, so only one part's elements are walked at a
    time."""
    if templates is not None:
        templates.register(top.element)
    if _LINKED(top.element):
        _collect(top, top.element, gml, templates)
        read_coordinates(top)
        return
    _read_object(top, functools.partial(_gathered, top, top.element, gml))


def _gathered(holder: Holder, root: etree._Element, gml: str, rings: _Rings, read: _Read) -> None:
    """Collect and read ``holder``'s parts (each freed: :meth:`Holder.release`), then
    ``holder`` itself (an object without links; ``root``: its element); the heap the parts
    took is handed back every :data:`TRIM_RINGS` rings."""
    for part in holder.parts:
        _gathered(part, root, gml, rings, read)
        part.release()
    _collect(holder, root, gml, None)
    holder.forget_walk()
    _read_holder(holder, rings, read)
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


# --- an object's coordinates, read a part at a time -----------------------------------------------


@dataclass
class _Rings:
    """The coordinates of an object's rings (an array per ``posList`` or ``pos``) and, per
    ring, its value count and width."""

    values: list[np.ndarray] = field(default_factory=list)
    counts: list[int] = field(default_factory=list)
    widths: list[int] = field(default_factory=list)
    trimmed: int = 0
    """Rings read when the heap was last handed back."""


def _ring_values(ring: etree._Element, rings: _Rings) -> None:
    """Add the coordinates of a ``LinearRing`` (its ``posList`` or ``pos`` elements)."""
    count = 0
    dimension = None
    for child in ring:
        name = local(child)
        if name == "posList" or name == "pos":
            try:
                values = parse_floats(child.text or "")
            except ValueError:
                raise BrokenObject("has a coordinate that is not a number") from None
            rings.values.append(values)
            count += len(values)
            dimension = dimension or child.get("srsDimension")
    if dimension is None:
        declared = (a.get("srsDimension") for a in ring.iterancestors())
        dimension = next((d for d in declared if d), "3")
    try:
        width = int(dimension)
    except ValueError:
        raise BrokenObject(f"has an srsDimension of {dimension!r}") from None
    if width not in (2, 3) or count % width:
        raise BrokenObject(f"has a ring of {count} values, not whole points of dimension {width}")
    rings.counts.append(count)
    rings.widths.append(width)


def _polygon_rings(polygon: Polygon, element: etree._Element, rings: _Rings) -> list[int]:
    """Add the rings of ``polygon`` (its ``element``; a ``Tin``'s control points, noted with
    its ``maxLength``); its layout: its number of rings, then their indices, exterior first."""
    exterior: list[int] = []
    interior: list[int] = []
    if local(element) == "Tin":  # its control points, triangulated later
        polygon.tin = True
        polygon.max_length = _max_length(element)
        for points in element:
            if local(points) == "controlPoint":
                exterior.append(len(rings.counts))
                _ring_values(points, rings)
    for boundary in element:
        kind = local(boundary)
        into = exterior if kind in _EXTERIOR else interior if kind in _INTERIOR else None
        if into is None:
            continue
        for ring in boundary:
            into.append(len(rings.counts))
            _ring_values(ring, rings)
    return [len(exterior) + len(interior), *exterior[::-1], *interior]


def _max_length(tin: etree._Element) -> float | None:
    """A ``Tin``'s ``maxLength`` when it gives a positive number, else None."""
    limit = next((e.text for e in tin if local(e) == "maxLength"), None)
    try:
        max_length = float(limit) if limit is not None else None
    except ValueError:
        return None
    return max_length if max_length is not None and max_length > 0 else None


@dataclass
class _Read:
    """An object whose rings were read: its polygons, their rings' layout (per polygon: its
    number of rings, then their indices, exterior first), the rings' points ((n, 3) float64 in
    the document's CRS, 2-D rings with z = 0) and each ring's number of points, and, for its
    implicit geometry, which points are in a frame of their own (a mask) and the placements
    (matrix, reference point) that :attr:`Polygon.placed_by` indexes."""

    top: Holder
    polygons: list[Polygon]
    layout: list[int]
    points: np.ndarray
    lengths: np.ndarray
    relative: np.ndarray | None = None
    placements: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)


def read_coordinates(top: Holder) -> None:
    """Read the coordinates of the polygons of ``top`` (a collected top-level object) and of
    its parts into :attr:`Holder.read`, or why they cannot be read into
    :attr:`Holder.broken`. A part at a time: each part's elements are freed once its polygons
    are read, and the polygons let go of their elements, so that an object of many parts
    never holds its whole tree and all its coordinates at once."""
    for holder in top.walk():
        holder.forget_walk()
    _read_object(top, functools.partial(_holder_rings, top))


def _read_object(top: Holder, read_rings: Callable[[_Rings, _Read], None]) -> None:
    """Read the coordinates of ``top``'s polygons, which ``read_rings`` adds to the rings and
    the read it is given (:class:`BrokenObject` when one cannot be read), into
    :attr:`Holder.read`, or why they cannot be read into :attr:`Holder.broken`."""
    rings = _Rings()
    read = _Read(top, [], [], np.zeros((0, 3)), np.zeros(0, dtype=np.int64))
    try:
        read_rings(rings, read)
    except BrokenObject as exc:
        _broken(top, str(exc))
        return
    _finish(top, rings, read)


def _broken(top: Holder, reason: str) -> None:
    """Note why ``top``'s coordinates cannot be read; let go of its polygons and elements."""
    top.broken = reason
    for holder in reversed(list(top.walk())):  # parts before what holds them
        holder.polygons = []
        if holder.element is not None:
            holder.element.clear(keep_tail=False)


def _finish(top: Holder, rings: _Rings, read: _Read) -> None:
    """Put the ``rings`` read of ``top``'s polygons into ``read`` as points, and that into
    :attr:`Holder.read` (or why they cannot be read into :attr:`Holder.broken`); free the
    object's elements."""
    top.element.clear(keep_tail=False)
    flat = np.concatenate(rings.values) if rings.values else np.zeros(0)
    del rings.values[:]
    if problem := _range_problem(flat):
        top.broken = problem
        return
    widths = np.array(rings.widths, dtype=np.int64)
    read.lengths = np.array(rings.counts, dtype=np.int64) // np.maximum(widths, 1)
    if (widths == 3).all():
        read.points = flat.reshape(-1, 3)
    else:
        pieces = np.split(flat, np.cumsum(rings.counts)[:-1])
        read.points = np.concatenate(
            [
                np.pad(v.reshape(-1, 2), ((0, 0), (0, 1))) if w == 2 else v.reshape(-1, 3)
                for v, w in zip(pieces, rings.widths, strict=True)
            ]
        )
    if read.placements:
        ring_relative = np.zeros(len(read.lengths), dtype=bool)
        cursor = 0
        for polygon in read.polygons:
            n = read.layout[cursor]
            if polygon.placed_by is not None:
                ring_relative[read.layout[cursor + 1 : cursor + 1 + n]] = True
            cursor += 1 + n
        read.relative = np.repeat(ring_relative, read.lengths)
    top.read = read


def _holder_rings(holder: Holder, rings: _Rings, read: _Read) -> None:
    """Add the rings of ``holder``'s polygons (:func:`_read_holder`), then those of its parts,
    each part's elements freed once read."""
    _read_holder(holder, rings, read)
    for part in holder.parts:
        _holder_rings(part, rings, read)
        part.release()


def _read_holder(holder: Holder, rings: _Rings, read: _Read) -> None:
    """Add the rings of ``holder``'s polygons to ``rings`` and ``read`` (their layout, and the
    placements of implicit ones), the polygons letting go of their elements;
    :class:`BrokenObject` when a ring or a placement cannot be read."""
    serials: dict[int, int] = {}
    placed: dict[int, int] = {}
    for polygon in holder.polygons:  # numbered while every element is held
        polygon.serial = serials.setdefault(id(polygon.element), len(serials))
        if polygon.implicit is not None:
            polygon.placed_by = placed.setdefault(id(polygon.implicit), len(placed))
    placements: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(placed)
    for polygon in holder.polygons:
        assert polygon.element is not None  # not read before
        read.layout += _polygon_rings(polygon, polygon.element, rings)
        if polygon.implicit is not None and polygon.placed_by is not None:
            if placements[polygon.placed_by] is None:
                try:
                    placements[polygon.placed_by] = placement(polygon.implicit)
                except ValueError as exc:
                    raise BrokenObject(str(exc)) from None
            polygon.placed_by += len(read.placements)
        polygon.element = polygon.implicit = None
    read.placements += [each for each in placements if each is not None]
    read.polygons += holder.polygons


# --- a batch of objects ---------------------------------------------------------------------------


def _metric(reads: list[_Read], crs: Crs) -> np.ndarray:
    """The points of ``reads`` in metres (a geographic CRS's frame centred on the first
    object's own points); the points of implicit polygons are left in their frames, and their
    reference points are projected into :attr:`_Read.placements`."""
    points = np.concatenate([read.points for read in reads])
    if not any(read.placements for read in reads):
        return crs.to_metric(points, first=len(reads[0].points))
    relative = np.concatenate(
        [r.relative if r.relative is not None else np.zeros(len(r.points), bool) for r in reads]
    )
    references = [(read, key) for read in reads for key in range(len(read.placements))]
    absolute = points[~relative]
    first = int((~relative[: len(reads[0].points)]).sum()) or None
    together = np.vstack([absolute, [read.placements[key][1] for read, key in references]])
    metric = crs.to_metric(together, first=first)
    points = points.copy()
    points[~relative] = metric[: len(absolute)]
    for (read, key), reference in zip(references, metric[len(absolute) :], strict=True):
        read.placements[key] = (read.placements[key][0], reference)
    return points


def _coordinates(tops: list[Holder], crs: Crs) -> tuple[list[tuple[Holder, str]], list[Holder]]:
    """Put the rings of every polygon of ``tops`` (as :func:`read_coordinates` read them) into
    ``Polygon.rings`` in metres (a geographic CRS's frame centred on the first object read;
    implicit geometry placed); the objects that could not be read (with the reason) and those
    that were."""
    broken: list[tuple[Holder, str]] = []
    reads: list[_Read] = []
    for top in tops:
        if top.read is None:
            broken.append((top, top.broken))
        else:
            reads.append(top.read)
            top.read = None
    if not reads:
        return broken, []
    metric = _metric(reads, crs)
    counts = np.concatenate([read.lengths for read in reads])
    pieces = np.split(metric, np.cumsum(counts)[:-1]) if len(counts) else []
    offset = start = 0  # of the object's first ring, and of its first point
    read_tops = []
    for read in reads:
        cursor = 0
        absolute = read.points if read.relative is None else read.points[~read.relative]
        problem = crs.beyond_range(absolute) or _range_problem(
            metric[start : start + len(read.points)]
        )
        start += len(read.points)
        for polygon in read.polygons:
            n = read.layout[cursor]
            polygon.rings = [pieces[offset + i] for i in read.layout[cursor + 1 : cursor + 1 + n]]
            if polygon.placed_by is not None:
                matrix, reference = read.placements[polygon.placed_by]
                polygon.rings = [placed(ring, matrix, reference) for ring in polygon.rings]
                problem = problem or next(filter(None, map(_range_problem, polygon.rings)), None)
            cursor += 1 + n
        offset += len(read.lengths)
        if problem:
            broken.append((read.top, problem))
        else:
            read_tops.append(read.top)
    return broken, read_tops


def _range_problem(values: np.ndarray) -> str | None:
    """Why coordinates ``values`` cannot be read (one not finite, or beyond
    :data:`~..geometry_checks.MAX_MAGNITUDE`), or None."""
    largest = float(np.maximum.reduce(np.abs(values), axis=None, initial=0.0))
    if not np.isfinite(largest):
        return "has NaN or infinite coordinates"
    try:
        check_magnitude(largest, "")
    except InputError as exc:
        return str(exc)
    return None


def _dedup_keys(polygons: list[Polygon]) -> list[Any]:
    """Per polygon (each with rings), a key that two polygons share when they are of the same
    LoD and their exterior rings have the same distinct points to :data:`_DEDUP_DECIMALS`
    decimals, whatever their start and direction. The rounded bounding box stands in for the
    points where no other polygon has the same box."""
    exteriors = [polygon.rings[0] for polygon in polygons]
    lengths = np.array([len(ring) for ring in exteriors], dtype=np.int64)
    rounded = np.round(np.concatenate(exteriors), _DEDUP_DECIMALS)
    boxes = np.zeros((len(polygons), 6))
    full = lengths > 0
    if full.any():
        starts = (np.cumsum(lengths) - lengths)[full]
        boxes[full] = np.hstack(
            [np.minimum.reduceat(rounded, starts), np.maximum.reduceat(rounded, starts)]
        )
    keys: list[Any] = [
        (polygon.lod, n > 0, box.tobytes())
        for polygon, n, box in zip(polygons, lengths.tolist(), boxes, strict=True)
    ]
    shared = Counter(keys)
    ends = np.cumsum(lengths).tolist()
    for i, key in enumerate(keys):
        if shared[key] > 1:
            ring = rounded[ends[i] - lengths[i] : ends[i]]
            keys[i] = (polygons[i].lod, frozenset(map(tuple, ring.tolist())))
    return keys


def _kept(holder: Holder) -> list[Polygon]:
    """The holder's polygons to triangulate: those with semantics first, each element and
    each exterior ring once per LoD; polygons without rings are counted as degenerate."""
    ordered = sorted(holder.polygons, key=lambda p: not p.semantic)
    with_rings = [p for p in ordered if p.rings]
    holder.degenerate += len(ordered) - len(with_rings)
    if not with_rings:
        return []
    seen: set[Any] = set()
    kept = []
    for polygon, key in zip(with_rings, _dedup_keys(with_rings), strict=True):
        by_element = (polygon.lod, polygon.serial)
        if by_element in seen or key in seen:
            continue
        seen.add(by_element)
        seen.add(key)
        kept.append(polygon)
    return kept


@dataclass
class _Group:
    """The triangles of one LoD and semantic type of a holder: where its pieces lie in the
    batch's vertex and face arrays."""

    holder: Holder
    lod: str
    semantic: str
    vertices: slice
    faces: slice


def _groups(holders: list[Holder]) -> tuple[list[_Group], np.ndarray, np.ndarray]:
    """Triangulate the kept polygons of ``holders`` together; the groups by holder, LoD (in
    order) and semantic type (as met), with the batch's vertices and faces (each group's
    faces indexing the batch's vertices)."""
    kept = [(holder, _kept(holder)) for holder in holders]
    polygons = [polygon for _, polygons in kept for polygon in polygons]
    tin = [polygon.tin for polygon in polygons]
    rings = iter(triangulate_many([p.rings for p, t in zip(polygons, tin, strict=True) if not t]))
    results = (
        _tin_triangles(polygon) if t else next(rings)
        for polygon, t in zip(polygons, tin, strict=True)
    )
    pieces: list[tuple[np.ndarray, np.ndarray, bool]] = []
    groups: list[_Group] = []
    vertex_at = face_at = 0
    for holder, polygons in kept:
        by_lod: dict[str, dict[str, list[tuple[np.ndarray, np.ndarray, bool]]]] = {}
        for polygon in polygons:
            triangles = next(results)
            if triangles is None:
                holder.degenerate += 1
                continue
            by_semantic = by_lod.setdefault(polygon.lod, {})
            by_semantic.setdefault(polygon.semantic, []).append((*triangles, polygon.flip))
        for lod in sorted(by_lod):
            for semantic, group in by_lod[lod].items():
                n_vertices = sum(len(v) for v, _, _ in group)
                n_faces = sum(len(f) for _, f, _ in group)
                groups.append(
                    _Group(
                        holder,
                        lod,
                        semantic,
                        slice(vertex_at, vertex_at + n_vertices),
                        slice(face_at, face_at + n_faces),
                    )
                )
                pieces += group
                vertex_at += n_vertices
                face_at += n_faces
    if not pieces:
        return groups, np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    vertices = np.concatenate([v for v, _, _ in pieces])
    faces = np.concatenate([f for _, f, _ in pieces])
    counts = np.array([len(f) for _, f, _ in pieces], dtype=np.int64)
    starts = np.cumsum([0] + [len(v) for v, _, _ in pieces[:-1]])
    faces = faces + np.repeat(starts, counts)[:, None]
    flip = np.repeat([f for _, _, f in pieces], counts)
    if flip.any():
        faces[flip] = faces[flip][:, ::-1]
    return groups, vertices, faces


def _points_only(tin: etree._Element) -> bool:
    """Whether a ``Tin`` gives its control points alone, no triangles."""
    return not any(local(e) == "Triangle" for e in tin.iterdescendants())


def _tin_triangles(polygon: Polygon) -> Triangles | None:
    """The triangles of a ``Tin`` given by its control points (``polygon.rings``): their
    Delaunay triangulation in plan, without triangles longer than its ``maxLength``."""
    points = [ring for ring in polygon.rings if len(ring)]
    if not points:
        return None
    return points_surface(np.concatenate(points), polygon.max_length)


def triangulate_batch(
    tops: list[Holder], crs: Crs, palette: Palette, tally: InputTally
) -> list[tuple[Holder, str]]:
    """Triangulate the polygons of a batch of top-level objects (and their parts), their
    coordinates read (:func:`read_coordinates`) and put in metres here, into each holder's
    :attr:`Holder.surfaces`: one checked :class:`Surface` per LoD and semantic type, coloured
    by it, without faces that have no area (counted in :attr:`Holder.dropped`). The objects
    that could not be read, with the reason. The holders are triangulated
    :data:`TRIANGULATED` polygons at a time (each one's polygons let go once it has its
    surfaces), which bounds the per-polygon arrays held at once."""
    broken, tops = _coordinates(tops, crs)
    chunk: list[Holder] = []
    polygons = 0
    for holder in (holder for top in tops for holder in top.walk()):
        chunk.append(holder)
        polygons += len(holder.polygons)
        if polygons >= TRIANGULATED:
            _triangulated(chunk, palette, tally)
            chunk, polygons = [], 0
    _triangulated(chunk, palette, tally)
    return broken


def _triangulated(holders: list[Holder], palette: Palette, tally: InputTally) -> None:
    """Triangulate the polygons of ``holders`` into their :attr:`Holder.surfaces` (as
    :func:`triangulate_batch` says); their polygons are let go."""
    if not holders:
        return
    groups, vertices, faces = _groups(holders)
    for holder in holders:
        holder.polygons = []
    tally.count(
        sum(g.vertices.stop - g.vertices.start for g in groups),
        sum(g.faces.stop - g.faces.start for g in groups),
    )
    keep = faces_with_area(vertices, faces)
    boxes = _group_bounds(groups, vertices, faces[keep])
    for group, box in zip(groups, boxes, strict=True):
        first = group.vertices.start
        kept = faces[group.faces][keep[group.faces]] - first
        group.holder.dropped += (group.faces.stop - group.faces.start) - len(kept)
        if len(kept):
            surface = Surface(
                vertices[group.vertices].copy(),
                kept,
                base_color=palette.of(group.semantic or None, group.holder.kind).copy(),
            )
            surface.derived("bounds", lambda box=box: box)  # what Surface.bounds computes
            group.holder.surfaces.setdefault(group.lod, []).append(surface)


def _group_bounds(groups: list[_Group], vertices: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """Per group, the (2, 3) bounds of its vertices that the ``kept`` faces use (all at once;
    infinite for a group whose faces were all dropped)."""
    if not groups:
        return np.zeros((0, 2, 3))
    used = np.zeros(len(vertices) + 1, dtype=bool)  # and a row past the end, for reduceat
    used[kept.ravel()] = True
    padded = np.vstack([vertices, np.zeros((1, 3))])
    low = np.where(used[:, None], padded, np.inf)
    high = np.where(used[:, None], padded, -np.inf)
    ends = np.array([(g.vertices.start, g.vertices.stop) for g in groups], dtype=np.int64).ravel()
    return np.stack(
        [np.minimum.reduceat(low, ends)[::2], np.maximum.reduceat(high, ends)[::2]], axis=1
    )
