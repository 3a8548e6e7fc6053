"""CityObjects: each read (up to the triangulation of its polygons) into a :class:`Read`, then
finished into its node, checked and counted in the tally, or left out and recorded; and the
tree of a file's (or a feature's) objects, from ``children`` and ``parents``, filtered by
type, each object's parts merged into it."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from ...errors import InputError
from ...model import Mesh, Node, PackedNode
from ...model.lods import finest
from ..geometry_checks import check_extent
from .geometry import SURFACE_DEPTH, Lod, lod_key, lod_label, read_lod
from .source import Context
from .templates import instance_nodes, placement, template_mesh, world_bounds
from .triangulation import triangulate_batch


@dataclass(eq=False)
class Read:
    """A CityObject read up to the triangulation of its polygons: its node (children and
    geometry not yet attached), its LoDs, its geometry instances, and the first problem met
    reading it. The LoDs are those before the problem: finishing the object checks them
    first and then raises it, as reading it in one go would have."""

    key: str
    ctx: Context
    node: Node | None = None
    kind: str = ""
    lods: list[Lod] = field(default_factory=list)
    instances: list[dict[str, Any]] = field(default_factory=list)
    problem: Exception | None = None


PART_TYPES = frozenset(
    {
        *(f"Building{p}" for p in ("Part", "Installation", "ConstructiveElement", "Furniture")),
        *("BuildingStorey", "BuildingRoom", "BuildingUnit"),
        *(f"Bridge{p}" for p in ("Part", "Installation", "ConstructiveElement", "Furniture")),
        "BridgeRoom",
        *(f"Tunnel{p}" for p in ("Part", "Installation", "ConstructiveElement", "Furniture")),
        "TunnelHollowSpace",
    }
)
"""CityJSON's 2nd-level types: the parts of the 1st-level object they are children of."""

MAX_DEPTH = 32
"""Levels of ``children``/``parents`` below a root that are read; an object deeper is left out
(with the objects below it) and reported."""

_MALFORMED = (TypeError, ValueError, AttributeError, KeyError, IndexError)
"""What JSON of a shape CityJSON does not give raises somewhere in an object."""


def read_object(key: str, obj: Any, ctx: Context) -> Read:
    """CityObject ``key`` read (not yet triangulated); a problem is kept in the result."""
    read = Read(key, ctx)
    try:
        if not isinstance(obj, dict):
            raise InputError("is not a JSON object", key)
        read.kind = kind = str(obj.get("type", ""))
        own = obj.get("attributes")
        attributes = {**(own if isinstance(own, dict) else {}), "id": key, "type": kind}
        read.node = Node(id=key, type=kind, attributes=attributes, crs=ctx.crs)
        by_lod: dict[str, list[dict[str, Any]]] = {}
        for geometry in obj.get("geometry") or []:
            if not isinstance(geometry, dict):
                raise InputError("has a geometry that is not a JSON object", key)
            if geometry.get("type") == "GeometryInstance":
                read.instances.append(geometry)
            elif geometry.get("type") in SURFACE_DEPTH:
                by_lod.setdefault(lod_label(geometry.get("lod", "")), []).append(geometry)
        for label in sorted(by_lod, key=lod_key):
            read.lods.append(read_lod(label, by_lod[label], ctx.vertices, ctx, key, kind))
    except (InputError, *_MALFORMED) as exc:
        read.problem = exc
    return read


def read_kept(key: str, obj: Any, ctx: Context, below: int | None = None) -> Read:
    """Object ``key`` read (:func:`read_object`), or, when it is nested too deep, its problem
    (``below``: how many objects are left out with it)."""
    if below is not None:
        problem = InputError(
            f"is nested more than {MAX_DEPTH} levels deep in children/parents: left out "
            f"with the {below:,} object(s) below it",
            key,
        )
        return Read(key, ctx, problem=problem)
    return read_object(key, obj, ctx)


def _node(read: Read) -> tuple[Node, int]:
    """The node of a read and triangulated object with its LoDs and geometry instances, and
    how many of its faces were dropped. :class:`InputError` (naming the object) when it
    cannot be converted."""
    key, ctx, kind = read.key, read.ctx, read.kind
    dropped = 0
    for lod in read.lods:
        dropped += lod.dropped
        if lod.mesh is not None:
            check_extent(lod.mesh.bounds, key)
    if read.problem is not None:
        raise read.problem
    node = read.node
    assert node is not None
    node.lods = {lod.label: lod.mesh for lod in read.lods if lod.mesh is not None}
    if node.lods:
        node.geometry = finest(node.lods)
    placed = []
    for geometry in read.instances:
        shared = template_mesh(geometry.get("template"), ctx, key, kind)
        if shared is not None:
            transform = placement(geometry, ctx, key)
            check_extent(world_bounds(shared[1], transform), key)
            placed.append((shared, transform))
    instance_nodes(node, placed)
    return node, dropped


def checked_node(read: Read) -> Node | None:
    """:func:`_node`, or None when the object is left out (recorded in the tally: an object
    that cannot be converted, or one whose faces all had no area)."""
    key, ctx = read.key, read.ctx
    tally = ctx.tally
    try:
        node, dropped = _node(read)
    except InputError as exc:
        read.problem = None  # its traceback holds the read: no cycle left for the collector
        tally.add_skipped(key, str(exc))
        return None
    except _MALFORMED as exc:
        # JSON of an unexpected shape somewhere in the object: leave the object out
        read.problem = None
        error = InputError(f"has malformed content ({type(exc).__name__}: {exc})", key)
        tally.add_skipped(key, str(error))
        return None
    for lod in read.lods:
        for fault, count in lod.faults.items():
            tally.warn(
                f"{tally.source}: {key}: {count:,} surface(s) {fault}; they take their "
                "material or class colour"
            )
    tally.dropped_faces += dropped
    if dropped and node.geometry is None and not node.children:
        tally.skip(key, dropped)
        return None
    if dropped:
        tally.dropped_by_object[key] = dropped
    templates = {id(e[1]) for e in ctx.shared.values() if e is not None} if read.instances else ()
    for mesh in {id(m): m for n in node.walk() for m in n.lods.values()}.values():
        if id(mesh) in templates:
            if id(mesh) in ctx.counted:
                continue  # a template's mesh counts once, where it is first used
            ctx.counted.add(id(mesh))
        tally.count(mesh.vertex_count, mesh.face_count)
    return node


def checked_nodes(reads: list[Read]) -> Iterator[Node | None]:
    """:func:`checked_node` of each object read, their polygons triangulated together; each
    is finished (and recorded in the tally) as it is yielded."""
    triangulate_batch([lod for read in reads for lod in read.lods])
    return map(checked_node, reads)


def _keys(values: Any) -> list[str]:
    """The strings of a JSON list (``children``, ``parents``); nothing for anything else."""
    return [v for v in values if isinstance(v, str)] if isinstance(values, list) else []


def _children(objects: dict[str, Any]) -> dict[str, list[str]]:
    """Child keys of every object, from ``children`` and ``parents`` alike, in file order."""
    found: dict[str, dict[str, None]] = {key: {} for key in objects}
    for key, obj in objects.items():
        if not isinstance(obj, dict):
            continue
        for child in _keys(obj.get("children")):
            if child in objects and child != key:
                found[key][child] = None
        for parent in _keys(obj.get("parents")):
            if parent in objects and parent != key:
                found[parent][key] = None
    return {key: list(kids) for key, kids in found.items()}


@dataclass
class Objects:
    """The CityObjects of a file or of a CityJSONSeq feature: their child keys and which of
    them are read (each at most once), in the order their tree is built (children before
    their parent, parents in file order); those nested deeper than :data:`MAX_DEPTH` (and
    how many objects below them are left out with them)."""

    objects: dict[str, Any]
    types: frozenset[str] | None
    children: dict[str, list[str]] = field(init=False)
    below: set[str] = field(init=False)
    """The keys of objects that are another's child."""
    order: list[str] = field(init=False)
    too_deep: dict[str, int] = field(init=False, default_factory=dict)

    def __post_init__(self) -> None:
        self.children = _children(self.objects)
        self.below = {child for kids in self.children.values() for child in kids}
        order: list[str] = []
        self.roots(lambda key: order.append(key))
        self.order = order

    def read(self, key: str, ctx: Context) -> Read:
        """Object ``key`` read (:func:`read_kept`)."""
        return read_kept(key, self.objects[key], ctx, self.too_deep.get(key))

    def alone(self, key: str) -> bool:
        """Whether object ``key`` has neither children nor a parent: its node is a root that
        nothing is joined to (so a worker may pack it)."""
        return not self.children[key] and key not in self.below

    def roots(self, node_of: Callable[[str], Node | PackedNode | None]) -> list[Node | PackedNode]:
        """The root nodes: each object of a kept type (all, when ``types`` is None, else those
        types and the descendants of kept objects; a ``type`` that is not a string is of no
        type) that ``node_of`` gives a node with geometry or children, its children below it;
        kept descendants of objects left out (None) take their place; a packed node (of an
        object :meth:`alone`) as it is. Objects in a cycle of ``children``/``parents`` that no
        root reaches hang below the first of them in file order."""
        objects, types, children, below = self.objects, self.types, self.children, self.below
        seen: set[str] = set()

        def build(key: str, kept: bool, depth: int) -> list[Node | PackedNode]:
            if key in seen:  # a cycle, or a second parent
                return []
            seen.add(key)
            if depth > MAX_DEPTH:
                self.too_deep[key] = _mark_below(key, children, seen)
                node_of(key)
                return []
            kind = objects[key].get("type") if isinstance(objects[key], dict) else None
            kept = kept or types is None or (isinstance(kind, str) and kind in types)
            kids = [node for child in children[key] for node in build(child, kept, depth + 1)]
            node = node_of(key) if kept else None
            if node is None:
                return kids
            if isinstance(node, PackedNode):  # alone: no parts to absorb, no children
                return [node]
            node.children.extend(kids)
            if node.type not in PART_TYPES and node.transform is None:
                _absorb_parts(node)
            return [node] if node.geometry is not None or node.children else []

        roots = [node for key in objects if key not in below for node in build(key, False, 0)]
        return roots + [node for key in objects if key not in seen for node in build(key, False, 0)]


def _mark_below(key: str, children: dict[str, list[str]], seen: set[str]) -> int:
    """Mark the objects below ``key`` not yet seen as seen; how many they are."""
    stack, count = list(children[key]), 0
    while stack:
        child = stack.pop()
        if child not in seen:
            seen.add(child)
            count += 1
            stack.extend(children[child])
    return count


def _parts(node: Node) -> Iterator[Node]:
    """The descendants of ``node`` reached through children of a 2nd-level type."""
    for child in node.children:
        if child.type in PART_TYPES:
            yield child
            yield from _parts(child)


def _absorb_parts(node: Node) -> None:
    """Merge the LoDs of ``node``'s parts into its own, as a CityGML building absorbs its parts:
    each LoD label's surfaces become one mesh, the finest its geometry. The parts keep their
    nodes (attributes, LoDs) as children without geometry of their own; a part placed as a
    geometry instance stays an object of its own."""
    parts = [part for part in _parts(node) if part.transform is None and part.lods]
    if not parts:
        return
    merged: dict[str, list] = {}
    for each in (node, *parts):
        for label, mesh in each.lods.items():
            merged.setdefault(label, []).extend(mesh.parts)
        each.geometry = None
    node.lods = {label: Mesh(surfaces) for label, surfaces in merged.items()}
    node.geometry = finest(node.lods)
