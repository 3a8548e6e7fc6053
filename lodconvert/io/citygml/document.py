"""A CityGML document streamed a batch of city objects at a time: the root checked first, then
only the root's children (members) reach Python, each member's objects are collected (their
coordinates read and their elements freed a part at a time), and a batch of them is
triangulated together before their nodes are handed on."""

from __future__ import annotations

import zipfile
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lxml import etree

from ...errors import InputError
from ...heap import return_freed_heap
from ...limits import Limits
from ...model import Mesh, Node, Surface
from ...model.lods import finest
from ...semantics import DEFAULT_PALETTE, Palette
from ..crs import Crs
from ..geometry_checks import InputTally, check_extent
from ..images import Images
from ..mesh import object_id
from .appearance import Appearances, Look
from .attributes import attributes_of
from .holders import BrokenObject, Holder, gml_id_of, holders_of
from .implicit import Templates
from .member_bytes import without_appearance_members
from .names import (
    CITYGML_NAMESPACE,
    GML_NAMESPACES,
    MEMBERS,
    NOT_OBJECTS,
    is_feature,
    local,
    namespace,
)
from .source import Stream, first_look, open_document, parser_options
from .triangulation import triangulate_batch
from .walk import check_depth, gather

BATCH = 64
"""City objects triangulated together (their coordinates are held until then)."""
TRIM_FACES = 1 << 18
"""Triangles read between two hand-backs of the heap that freed XML elements leave
(:func:`~lodconvert.heap.return_freed_heap`)."""
_ROOT_CHILDREN = tuple(f"{{*}}{name}" for name in sorted(MEMBERS | {"boundedBy"}))
"""Tags of the root's children that reach Python (any namespace; nested ones are passed)."""


@dataclass
class Document:
    """The state of one streamed document: its version, CRS, the run's checks and what was
    counted along the way (:attr:`stats`, kept in the scene's attributes)."""

    path: Path
    limits: Limits
    types: frozenset[str] | None
    tally: InputTally
    palette: Palette = DEFAULT_PALETTE
    version: str = ""
    gml: str = GML_NAMESPACES[0]
    crs: Crs | None = None
    taken: set[str] = field(default_factory=set)
    trimmed: int = 0
    """Triangles read when the heap was last handed back (:data:`TRIM_FACES`)."""
    templates: Templates = field(default_factory=Templates)
    """Relative geometries of implicit geometry, for links from later objects."""
    appearances: Appearances | None = None
    """The document's appearances at its root, in the theme read; ``None`` when the
    document holds no appearance at all (then none is looked for)."""
    images: Images | None = None
    """The images its appearances name (with :attr:`appearances`)."""
    stats: dict[str, dict[str, int]] = field(
        default_factory=lambda: {
            "unresolved_links": {},
            "degenerate_polygons": {},
            "not_read": {},
            "empty": {},
        }
    )
    """Counts by object id (links not resolved, degenerate polygons) or by type (features not
    read, objects with nothing in them: no id is taken and nothing else kept for those)."""

    @property
    def source(self) -> str:
        return str(self.path)

    def nodes(self) -> Iterator[Node]:
        """The document's city objects with geometry, one at a time, as it is parsed."""
        stream = open_document(self.path, self.limits)
        try:
            yield from self.read(stream)
        finally:
            stream.close()

    def read(self, stream: Stream) -> Iterator[Node]:
        """The city objects with geometry of the document ``stream`` holds (the file's, or a
        run of its members inside its root: :mod:`.parallel`), as it is parsed."""
        try:
            replay, root = first_look(stream, self.limits, self.source)
            self.check_root(root)
            objects = replay
            if self.appearances is not None:  # those at the root are read apart
                objects = without_appearance_members(replay, replay.head) or replay
            events = etree.iterparse(
                objects, events=("end",), tag=_ROOT_CHILDREN, **parser_options(self.limits)
            )
            batch: list[tuple[Node, Holder]] = []
            for _, element in events:
                parent = element.getparent()
                if parent is None or parent.getparent() is not None:
                    continue  # not a child of the root
                for collected in self._member(element):
                    batch.append(collected)
                    del collected  # held by the batch alone, freed with it
                    if len(batch) >= BATCH:
                        yield from self._finished(batch)
                if not batch:
                    _free(element)
            yield from self._finished(batch)
        except etree.XMLSyntaxError as exc:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise InputError(f"is not well-formed XML ({reason})", self.source) from None
        except (OSError, EOFError, zlib.error, zipfile.BadZipFile) as exc:
            raise InputError(f"cannot be read ({exc})", self.source) from None

    def check_root(self, root: etree._Element) -> None:
        """Refuse a root that is not a CityGML ``CityModel``; note the version."""
        version = CITYGML_NAMESPACE.fullmatch(namespace(root))
        if version is None or local(root) != "CityModel":
            name = namespace(root)
            raise InputError(
                f"is not CityGML: its root element is <{local(root)}>"
                + (f" in namespace {name}" if name else " without a namespace"),
                self.source,
            )
        self.version = version.group(1)
        self.gml = GML_NAMESPACES[1 if self.version == "3.0" else 0]

    def _member(self, element: etree._Element) -> Iterator[tuple[Node, Holder]]:
        """The objects of one child of the root, collected (nodes without geometry yet); the
        root's envelope gives the CRS."""
        name = local(element)
        if name == "boundedBy" and self.crs is None:
            srs = next((e.get("srsName") for e in element.iter() if e.get("srsName")), None)
            self.crs = Crs.of(srs, self.source) if srs else None
        if name in MEMBERS:
            for child in element:
                if (collected := self._collected(child)) is not None:
                    yield collected

    def _collected(self, element: etree._Element) -> tuple[Node, Holder] | None:
        """A top-level city object's node (parts as children, without geometry) and its
        holder with the polygons found in it and their coordinates read (its elements freed,
        a part at a time); None when the object is not read (or skipped: elements nested
        deeper than the ``xml_depth`` limit, checked before it is walked, parts nested too
        deep, no polygon; an object with no element in it is only counted)."""
        kind = local(element)
        if not len(element) and is_feature(kind) and kind not in NOT_OBJECTS:
            self._count("empty", kind)
            return None
        if not is_feature(kind) or kind in NOT_OBJECTS:
            self._count("not_read", kind or "?")
            return None
        if self.types is not None and kind not in self.types:
            self._count("not_read", kind)
            return None
        if self.crs is None:
            srs = next((e.get("srsName") for e in element.iter() if e.get("srsName")), None)
            self.crs = Crs.of(srs, self.source) if srs else Crs()
        try:
            check_depth(element, self.limits.xml_depth)
            top = holders_of(element)
        except BrokenObject as exc:
            self._skip(object_id(gml_id_of(element) or kind, self.taken), str(exc))
            return None
        for holder in top.walk():
            holder.attributes = attributes_of(holder.element, holder.kind, holder.gml_id)
        if self.appearances is not None:
            top.looks = self._looks(element, top.gml_id or kind)
        gather(top, self.gml, self.templates)
        if not top.broken and not any(holder.polygons for holder in top.walk()):
            node_id = object_id(top.gml_id or kind, self.taken)
            if unresolved := sum(holder.unresolved for holder in top.walk()):
                self.stats["unresolved_links"][node_id] = unresolved
            self._skip(node_id, "has no surface geometry")
            return None
        return self._node(top), top

    def _looks(
        self, element: etree._Element, name: str
    ) -> Callable[[etree._Element, list[etree._Element]], Look | None]:
        """What the polygons of the object ``element`` (``name`` in messages) wear: its own
        appearances (in the theme read), else the document's."""
        shared = self.appearances
        assert shared is not None and self.images is not None
        own = Appearances(shared.wanted, shared.theme)
        for appearance in element.iter("{*}Appearance"):
            own.add(appearance)
        shared.themes += [theme for theme in own.themes if theme not in shared.themes]
        shared.theme = self.images.theme = shared.theme or own.theme
        for problem in dict.fromkeys(own.problems):
            self.tally.warn(f"{self.source}: {name}: {problem} (not read)")
        if own.empty:
            return shared.look

        def look(polygon: etree._Element, rings: list[etree._Element]) -> Look | None:
            return own.look(polygon, rings) or shared.look(polygon, rings)

        return look

    def _node(self, holder: Holder) -> Node:
        """The node of a holder and, as its children, of its parts (ids taken in document
        order); each holder learns the name its messages use."""
        node = Node(
            id=object_id(holder.gml_id or holder.kind, self.taken),
            type=holder.kind,
            attributes=holder.attributes,
        )
        holder.where = f"{self.source}: {node.id}"
        node.children = [self._node(part) for part in holder.parts]
        return node

    def _finished(self, batch: list[tuple[Node, Holder]]) -> Iterator[Node]:
        """Triangulate a batch of collected objects (emptying ``batch``); their nodes with
        geometry (those left with nothing, or unreadable, are recorded as skipped), made
        before the first is given, so that what their reading took is freed by then (and,
        every :data:`TRIM_FACES` triangles, handed back)."""
        if not batch:
            return
        assert self.crs is not None
        broken = dict(
            (id(top), reason)
            for top, reason in triangulate_batch(
                [top for _, top in batch],
                self.crs,
                self.palette,
                self.tally,
                self.images,
            )
        )
        nodes = [
            finished
            for node, top in batch
            if (finished := self._node_of(node, top, broken.get(id(top)))) is not None
        ]
        batch.clear()  # the holders, and the elements they keep
        if self.tally.faces - self.trimmed >= TRIM_FACES:
            return_freed_heap()
            self.trimmed = self.tally.faces
        yield from nodes

    def _node_of(self, node: Node, top: Holder, broken: str | None) -> Node | None:
        """``node`` with its geometry (:meth:`_with_geometry`), or None where the object is
        ``broken`` (recorded as skipped, with the reason) or left with nothing."""
        if broken is not None:
            self._skip(node.id, broken)
            return None
        return self._with_geometry(node, top)

    def _with_geometry(self, node: Node, top: Holder) -> Node | None:
        """``node`` with its LoDs (its own surfaces and its parts') and geometry; None when
        it has nothing left (then recorded in the tally)."""
        unresolved = degenerate = dropped = 0
        merged: dict[str, list] = {}
        for holder, each in zip(top.walk(), node.walk(), strict=True):
            each.crs = self.crs.scene_crs if self.crs is not None else None
            each.lods = {lod: Mesh(parts) for lod, parts in holder.surfaces.items()}
            unresolved += holder.unresolved
            degenerate += holder.degenerate
            dropped += holder.dropped
            for lod, parts in holder.surfaces.items():
                merged.setdefault(lod, []).extend(parts)
        if unresolved:
            self.stats["unresolved_links"][node.id] = unresolved
        if degenerate:
            self.stats["degenerate_polygons"][node.id] = degenerate
        dropped += degenerate
        if dropped:
            self.tally.dropped_faces += dropped
            self.tally.dropped_by_object[node.id] = dropped
        node.lods = {lod: Mesh(_joined(parts)) for lod, parts in merged.items()}
        node.geometry = finest(node.lods)
        if node.geometry is None:
            if dropped:
                self.tally.skip(node.id, dropped)
            else:
                self._skip(node.id, "has no surface geometry")
            return None
        try:
            check_extent(node.geometry.bounds, node.id)
        except InputError as exc:
            self._skip(node.id, str(exc).removeprefix(f"{node.id}: "))
            return None
        return node

    def _count(self, key: str, name: str) -> None:
        self.stats[key][name] = self.stats[key].get(name, 0) + 1

    def _skip(self, node_id: str, reason: str) -> None:
        """Record object ``node_id`` as skipped for ``reason``."""
        self.tally.add_skipped(node_id, str(InputError(reason, node_id)))


def _free(element: etree._Element) -> None:
    """Free a child of the root and the children before it."""
    element.clear(keep_tail=False)
    while element.getprevious() is not None:
        del element.getparent()[0]


def _joined(surfaces: list[Surface]) -> list[Surface]:
    """``surfaces`` (of an object and its parts, in one LoD) joined into one surface per
    colour, in the order each colour first comes: an object of many parts is a few surfaces,
    however many parts it has. Textured surfaces stay as they are."""
    by_color: dict[bytes | int, list[Surface]] = {}
    for surface in surfaces:
        assert surface.base_color is not None  # as triangulate_batch makes them
        key = surface.base_color.tobytes() if surface.texture is None else id(surface)
        by_color.setdefault(key, []).append(surface)
    return [group[0] if len(group) == 1 else _one_surface(group) for group in by_color.values()]


def _one_surface(group: list[Surface]) -> Surface:
    """The surfaces of ``group`` (of one colour) as one, its bounds theirs."""
    starts = np.cumsum([0] + [len(s.vertices) for s in group[:-1]])
    joined = Surface(
        np.concatenate([s.vertices for s in group]),
        np.concatenate([s.faces + start for s, start in zip(group, starts, strict=True)]),
        base_color=group[0].base_color,
    )
    boxes = np.stack([s.bounds for s in group])
    joined.derived("bounds", lambda: np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)]))
    return joined
