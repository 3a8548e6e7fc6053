"""The scene tree: a :class:`Scene` of :class:`Node` s, each with identity, attributes, an
optional geometry (one or more parts), an optional placement and children.

A node's geometry is in its own frame. World coordinates are ``origin + transform · local``:
``origin`` is a float64 offset (georeferenced data keeps its millions here, so local values stay
small), ``transform`` a 4×4 placement (a mesh instanced by several scene-graph nodes keeps one
shared :class:`~.geometry.Mesh` and one transform per instance). Children are placed in their
parent's frame. Readers may yield nodes lazily; nothing here knows a file format.
"""

from __future__ import annotations

import pickle
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .geometry import Mesh, Surface
from .safe_text import ObjectText, object_text


@dataclass
class Node:
    """One object of a scene.

    ``type`` says what it is (``mesh`` for a mesh file's objects; ``Building``,
    ``BuildingPart``, ``group``… for city models); ``attributes`` are JSON-able facts kept with
    it; ``crs`` names the coordinate reference system of ``origin`` and the geometry, where known.
    """

    id: str
    geometry: Mesh | None = None
    type: str = "mesh"
    attributes: dict[str, Any] = field(default_factory=dict)
    crs: str | None = None
    origin: np.ndarray | None = None
    transform: np.ndarray | None = None
    children: list[Node] = field(default_factory=list)
    lods: dict[str, Mesh] = field(default_factory=dict)
    """The source's own levels of detail, by their label as the source names them (CityGML
    ``"lod2"``, CityJSON ``"2.2"``…), each in the node's frame; ``geometry`` is the finest of
    them (what a reader without LoDs sets alone)."""
    cut: tuple[str, ...] = ()
    """What :meth:`written` cut before (a node parked on disk keeps its text bounded)."""

    def __post_init__(self) -> None:
        if isinstance(self.geometry, Surface):
            self.geometry = Mesh.of(self.geometry)

    @property
    def offset(self) -> np.ndarray:
        """``origin`` as a float64 (3,) vector (zero when none is set)."""
        return np.zeros(3) if self.origin is None else np.asarray(self.origin, dtype=np.float64)

    def walk(self) -> Iterator[Node]:
        """This node and its descendants, depth first."""
        yield self
        for child in self.children:
            yield from child.walk()

    def parts(self) -> Iterator[Node]:
        """The descendants without geometry of their own (building parts, rooms… whose LoDs a
        reader merged into this node's), depth first, not below a child with geometry (an
        object of its own)."""
        for child in self.children:
            if child.geometry is None:
                yield child
                yield from child.parts()

    def object_attributes(self) -> dict[str, Any]:
        """What an output keeps with this node's object: its attributes and, under ``parts``
        (unless the node has an attribute of that name), those of each of its :meth:`parts`
        that has any."""
        parts = [part.attributes for part in self.parts() if part.attributes]
        if not parts or "parts" in self.attributes:
            return dict(self.attributes)
        return {**self.attributes, "parts": parts}

    def written(self) -> ObjectText:
        """This node's object's id and attributes (:meth:`object_attributes`) as every output
        keeps them, bounded and cleaned (:mod:`.safe_text`), with what was cut for that."""
        text = object_text(self.id, self.object_attributes())
        return replace(text, cut=self.cut + text.cut) if self.cut else text

    def parked(self) -> Node:
        """This node as it waits to be baked apart from the others: without its children (each
        with geometry is an object of its own), its id and attributes (its parts' with them)
        as outputs keep them (:meth:`written`)."""
        text = self.written()
        return replace(self, id=text.id, children=[], attributes=text.attributes, cut=text.cut)

    def placed_centre(self) -> tuple[float, float, float]:
        """Where its geometry's bounding-box centre is, in scene coordinates."""
        assert self.geometry is not None
        centre = np.append(self.geometry.bounds.mean(axis=0), 1.0)
        if self.transform is not None:
            centre = np.asarray(self.transform, dtype=np.float64) @ centre
        x, y, z = self.offset + centre[:3]
        return float(x), float(y), float(z)

    def ground_centre(self) -> tuple[float, float]:
        """Where its geometry's bounding-box centre is, seen from above, in scene coordinates."""
        x, y, _ = self.placed_centre()
        return x, y

    def is_city_object(self) -> bool:
        """Whether it has source LoDs of its own."""
        return bool(self.lods)

    def geometry_bytes(self) -> int:
        """Bytes of the arrays of its geometry and source LoDs (each array once)."""
        arrays = {
            id(value): value.nbytes
            for mesh in (self.geometry, *self.lods.values())
            if mesh is not None
            for part in mesh.parts
            for value in vars(part).values()
            if isinstance(value, np.ndarray)
        }
        return sum(arrays.values())


@dataclass(frozen=True)
class PackedNode:
    """A node with geometry and no transform, parked (:meth:`Node.parked`) and pickled by the
    worker that read it, with what the main process plans with: the main process passes it on
    to the worker that bakes it without unpickling it (docs/cluster.md)."""

    id: str
    type: str
    city: bool
    """Whether it has source LoDs of its own (a city object)."""
    centre: tuple[float, float, float]
    """:meth:`Node.placed_centre`."""
    weight: int
    """:meth:`Node.geometry_bytes`."""
    data: bytes

    transform = None
    """Placed by no transform (nodes that are keep sharing their geometry, unpacked)."""

    @classmethod
    def of(cls, node: Node) -> PackedNode:
        """``node`` parked and packed."""
        parked = node.parked()
        data = pickle.dumps(parked, protocol=pickle.HIGHEST_PROTOCOL)
        return cls(
            parked.id, parked.type, parked.is_city_object(), parked.placed_centre(),
            parked.geometry_bytes(), data,
        )  # fmt: skip

    def node(self) -> Node:
        """The parked node, unpickled."""
        node = pickle.loads(self.data)
        assert isinstance(node, Node)
        return node

    # what the main process asks of a node it parks, as a Node answers it

    def walk(self) -> Iterator[PackedNode]:
        """Itself (it has no children)."""
        yield self

    def parked(self) -> PackedNode:
        """Itself: it was parked where it was packed."""
        return self

    def is_city_object(self) -> bool:
        return self.city

    def placed_centre(self) -> tuple[float, float, float]:
        return self.centre

    def ground_centre(self) -> tuple[float, float]:
        return self.centre[0], self.centre[1]

    def geometry_bytes(self) -> int:
        return self.weight


def with_geometry(nodes: Iterable[Node | PackedNode]) -> Iterator[Node | PackedNode]:
    """The nodes of the trees of ``nodes`` that carry geometry, depth first (packed ones all
    do)."""
    walked = (n for node in nodes for n in node.walk())
    return (n for n in walked if isinstance(n, PackedNode) or n.geometry is not None)


def unpacked(node: Node | PackedNode) -> Node:
    """``node``, unpacked where it is packed."""
    return node.node() if isinstance(node, PackedNode) else node


@dataclass
class Scene:
    """What a reader produced: its nodes (a list, or an iterator consumed once) and scene-wide
    facts (source file, CRS, attributes, size)."""

    source: str
    nodes: Iterable[Node | PackedNode] = field(default_factory=list)
    """Its nodes; those read by workers may come packed (:class:`PackedNode`)."""
    crs: str | None = None
    attributes: dict[str, Any] = field(default_factory=dict)
    size: int | None = None
    """How many nodes with geometry the scene holds, where the reader knows before yielding
    them (for progress)."""
    city: bool = False
    """Whether a city model's reader made it: its objects are city objects, with their own
    LoDs and plots, in the CRS the file declares (or none)."""

    def __iter__(self) -> Iterator[Node | PackedNode]:
        return iter(self.nodes)

    def walk(self) -> Iterator[Node | PackedNode]:
        """Every node, depth first (consumes a lazy scene)."""
        for node in self.nodes:
            yield from node.walk()

    def with_geometry(self) -> Iterator[Node | PackedNode]:
        """The nodes that carry geometry, depth first (packed ones all do)."""
        return with_geometry(self.nodes)
