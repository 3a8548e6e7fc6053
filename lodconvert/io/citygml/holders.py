"""The surface holders of CityGML city objects: a top-level object and, nested, each of its
parts and interiors (:class:`Holder`, :func:`holders_of`), the polygons found in each
(:class:`Polygon`: LoD, semantic type, orientation) and the top-level object's coordinates once
read (:class:`Read`). :mod:`.walk` finds the polygons, :mod:`.coordinates` reads their
coordinates and :mod:`.triangulation` makes each holder's surfaces of them; what is read:
``docs/readers.md`` (CityGML).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from lxml import etree

from ...model import Surface
from .appearance import Look
from .implicit import Templates
from .names import (
    GML_IDS,
    HOLDING_PROPERTIES,
    NOT_SURFACES,
    POLYGONS,
    XLINK_HREF,
    is_feature,
    local,
)

MAX_PART_DEPTH = 32
"""Parts nested in parts below a top-level object (a building's parts' parts…) read; an object
whose parts nest deeper is skipped."""


class BrokenObject(ValueError):
    """An object whose geometry cannot be read (the message says why)."""


@dataclass(eq=False, slots=True)
class Polygon:
    """One polygon met in an object: its LoD, semantic type (``""``: none), whether an
    ``OrientableSurface`` reversed it, its element and what places it (until its coordinates
    are read, :func:`~.coordinates.read_coordinates`), and its rings (exterior first; (k, 3)
    float64 in metres) once the batch's coordinates are in metres."""

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
    """Its placement's key in :attr:`Read.placements` (implicit geometry), once read."""
    tin: bool = False
    """Whether it is a ``Tin`` given by its control points (triangulated in plan)."""
    max_length: float | None = None
    """Such a ``Tin``'s ``maxLength`` (longer triangles are left out), when one is given."""
    look: Look | None = None
    """What its appearance in the theme read gives it (:mod:`.appearance`), once read."""


@dataclass(eq=False)
class Holder:
    """A city object or one of its parts: its element and id, its parts, the polygons found in
    it, what was wrong with them, and (after :func:`~.triangulation.triangulate_batch`) its
    surfaces by LoD."""

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
    texture_faults: list[str] = field(default_factory=list)
    """Why some of its polygons' textures are not used (polygons counted by the reason)."""
    """Its attributes, taken before its elements are freed."""
    read: Read | None = None
    """A top-level object's coordinates, once read (:func:`~.coordinates.read_coordinates`)."""
    broken: str = ""
    """Why a top-level object's coordinates cannot be read, if they cannot."""
    looks: Callable[[etree._Element, list[etree._Element]], Look | None] | None = None
    """What a top-level object's polygons wear, asked of each polygon's element and rings'
    elements as its coordinates are read; ``None`` in a document without appearances."""
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
        """Let go of what :func:`~.walk.gather` remembered of the elements walked."""
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

    def reach(self, element: etree._Element, place: Place) -> bool:
        """Whether ``element`` is met for the first time at ``place``'s LoD, with or without a
        semantic type as ``place`` has one (noted): a polygon met again is not read again
        (:mod:`.triangulation` keeps each polygon's first with semantics, else its first), nor is a
        geometry walked again, so that links cost what the object holds."""
        key = (place.lod, bool(place.semantic), element)
        if key in self._reached:
            return False
        self._reached.add(key)
        return True

    def add_linked(
        self, element: etree._Element, place: Place, templates: Templates | None = None
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


class Place(NamedTuple):
    """Where a polygon (or a link) lies in an object: the holder it belongs to, its LoD,
    semantic type, orientation and the ``ImplicitGeometry`` above it, if any."""

    holder: Holder
    lod: str
    semantic: str
    flip: bool
    implicit: etree._Element | None = None


@dataclass
class Read:
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


def _points_only(tin: etree._Element) -> bool:
    """Whether a ``Tin`` gives its control points alone, no triangles."""
    return not any(local(e) == "Triangle" for e in tin.iterdescendants())
