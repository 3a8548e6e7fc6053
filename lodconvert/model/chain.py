"""Level-of-detail chains: :class:`LodChain` (the levels of one object and where they switch),
:class:`Level` and the bake parameters of a point level."""

from __future__ import annotations

import pickle
from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal

import numpy as np

from .geometry import Mesh, PointCloud


@dataclass(frozen=True)
class BakeParams:
    """The paper's per-level parameters: T3 resolution (cells along the longest side), T1 slices
    (slabs along the longest side), T2 point size in pixels at the level's switch-in distance at
    the reference view, and the hole filter."""

    resolution: int
    slices: int
    point_size: float
    filter: Literal["median", "gaussian", "none"] = "median"


MESH_KINDS = ("mesh", "qem", "source", "prism", "merged")
"""Level kinds drawn as triangles: the source mesh, the source decimated by quadric edge
collapse, a city object's own LoD geometry, the prism derived from its footprint, and a LOD
parent's merge of its members' coarsest levels (:mod:`lodconvert.city.hlod`). ``pcd``
levels are baked point clouds. Kinds are data: a level is drawn as triangles when ``mesh`` is
set, whatever its kind."""


@dataclass(frozen=True)
class Counts:
    """How large a level's geometry is, where the geometry itself stayed where the level was
    baked (:meth:`LodChain.without_geometry`): its vertices (points of a point level),
    triangles (``None`` for points) and parts (shapes drawn)."""

    count: int
    faces: int | None
    parts: int = 1


@dataclass
class Packed:
    """A level's geometry pickled where it was baked (:meth:`Level.packed`), passed on
    unopened to the process that draws it, and the tables found for its mesh since
    (``derived``), which it gets back when unpacked."""

    data: bytes
    derived: dict[str, Any] = field(default_factory=dict)

    def opened(self) -> Mesh | PointCloud:
        """The geometry, unpickled; a mesh with the tables found for it since."""
        geometry = pickle.loads(self.data)
        if isinstance(geometry, Mesh):
            geometry._derived.update(self.derived)
        assert isinstance(geometry, Mesh | PointCloud)
        return geometry


@dataclass
class Level:
    """One level of a chain: its ``name`` (``LOD4`` … ``LOD1``, as data, not by position), its
    ``kind`` (``mesh``, ``qem``, ``pcd``, …) and its geometry: ``mesh`` (triangles, one or more
    parts) or ``points``.

    ``spacing`` is the grid pitch of a point level in scene units; ``design_distance`` the
    distance (from the chain centre) its resolution and point size were chosen for: where it
    first shows, or α·β for a baked finest level. At that distance, at the reference view, its
    points are ``params.point_size`` pixels wide; viewers scale them with 1/distance.
    ``bake_seconds`` is the time spent baking it. ``silhouette_f`` is the level's silhouette F
    against the finest level where it switches in, where the planner measured one (prisms).
    Geometry is relative to the chain's origin. A level without its geometry has ``counts``
    in its place (:meth:`without_geometry`).
    """

    name: str
    kind: str
    mesh: Mesh | None = None
    points: PointCloud | None = None
    params: BakeParams | None = None
    spacing: float | None = None
    design_distance: float | None = None
    bake_seconds: float = 0.0
    silhouette_f: float | None = None
    counts: Counts | None = None
    packed_geometry: Packed | None = None
    """Its geometry, pickled (:meth:`packed`), with ``counts`` in its place."""

    def __post_init__(self) -> None:
        if self.mesh is not None and not isinstance(self.mesh, Mesh):
            self.mesh = Mesh.of(self.mesh)
        if [self.mesh, self.points, self.counts].count(None) != 2:
            raise ValueError(f"level {self.name} needs either a mesh, points or counts")

    @property
    def is_points(self) -> bool:
        """Whether the level is drawn as points (else as triangles)."""
        if self.counts is not None:
            return self.counts.faces is None
        return self.points is not None

    @property
    def count(self) -> int:
        """Vertices of a mesh level, points of a point level."""
        if self.counts is not None:
            return self.counts.count
        if self.mesh is not None:
            return self.mesh.vertex_count
        assert self.points is not None
        return len(self.points)

    @property
    def faces(self) -> int | None:
        """Triangles of a mesh level; ``None`` for a point level."""
        if self.counts is not None:
            return self.counts.faces
        return None if self.mesh is None else len(self.mesh.faces)

    @property
    def parts(self) -> int:
        """Shapes it is drawn as: a mesh's parts, one for points."""
        if self.counts is not None:
            return self.counts.parts
        return 1 if self.mesh is None else len(self.mesh.parts)

    def without_geometry(self) -> Level:
        """This level with its geometry's :class:`Counts` in place of the geometry."""
        counts = Counts(self.count, self.faces, self.parts)
        return replace(self, mesh=None, points=None, counts=counts, packed_geometry=None)

    def packed(self) -> Level:
        """This level with its geometry pickled (a mesh with only the derived tables that
        travel, :meth:`~.geometry.Mesh.shipped`) and its :class:`Counts` in its place."""
        geometry = self.points if self.mesh is None else self.mesh.shipped()
        if geometry is None:
            return self
        data = pickle.dumps(geometry, protocol=pickle.HIGHEST_PROTOCOL)
        return replace(self.without_geometry(), packed_geometry=Packed(data))

    def unpacked(self) -> Level:
        """This level with its packed geometry unpickled (itself when none is packed)."""
        if self.packed_geometry is None:
            return self
        geometry = self.packed_geometry.opened()
        if isinstance(geometry, Mesh):
            return replace(self, mesh=geometry, counts=None, packed_geometry=None)
        return replace(self, points=geometry, counts=None, packed_geometry=None)

    @property
    def geometry(self) -> Mesh | PointCloud | Packed:
        """Its mesh, points or packed geometry (a level without any has only counts)."""
        for found in (self.mesh, self.points, self.packed_geometry):
            if found is not None:
                return found
        raise ValueError(f"level {self.name} holds no geometry, only its counts")

    def keep_derived(self, found: dict[str, Any]) -> None:
        """Keep ``found`` (tables derived from this level's mesh elsewhere) with its mesh,
        packed or not."""
        if self.packed_geometry is not None:
            self.packed_geometry.derived.update(found)
        elif self.mesh is not None:
            self.mesh._derived.update(found)


@dataclass
class LodChain:
    """All levels of one object, finest first, and the distances at which they switch.

    ``cutoffs[i]`` is the distance (scene units, from ``center``) beyond which ``levels[i+1]``
    replaces ``levels[i]``. With culling, ``len(cutoffs) == len(levels)`` and the last cutoff is
    where the object disappears; otherwise ``len(cutoffs) == len(levels) - 1``.
    ``origin`` is the world position that level geometry is relative to; ``center`` the
    bounding-box centre relative to that origin (zero unless a writer re-bases it).
    """

    object_id: str
    levels: list[Level]
    cutoffs: list[float]
    origin: np.ndarray
    center: np.ndarray
    alpha: float
    beta: float
    gamma: float
    xs: list[float]
    culled: bool = False
    metadata: dict[str, Any] = field(default_factory=dict)
    dropped: dict[str, str] = field(default_factory=dict)
    """Levels the planner left out (name → why): the finer level stays on in their place."""
    unused: dict[str, str] = field(default_factory=dict)
    """Source LoDs that no level is made from (label → why; :mod:`~lodconvert.model.lods`)."""
    transform: np.ndarray | None = None
    """4×4 placement of the chain's frame (an instance of shared geometry): world =
    ``transform · (origin + local)``; ``None`` is the identity. Instances of one geometry share
    one ``levels`` list, which writers store once."""
    cut: tuple[str, ...] = ()
    """What was cut from the object's id and attributes so that every output holds them
    (:mod:`.safe_text`), one note per kind of cut."""

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled with its ``origin``, ``center`` and ``transform`` as lists of numbers (a
        small array's pickle costs several times theirs, and a city has a chain per
        building)."""
        values = [getattr(self, name) for name in _CHAIN_FIELDS]
        for at in _CHAIN_ARRAYS:
            values[at] = as_numbers(values[at])
        return _chain, tuple(values)

    def in_scene(self, mesh: Mesh) -> Mesh:
        """``mesh`` (one of this chain's levels) in scene coordinates."""
        return in_scene(mesh, self.origin, self.transform)

    def objects(self) -> list[LodChain]:
        """The object chains it holds: itself (as :meth:`CellChain.objects` gives a cell's)."""
        return [self]

    def without_geometry(self) -> LodChain:
        """This chain with every level's geometry left out (:meth:`Level.without_geometry`):
        what is told and written of it where its output was made elsewhere."""
        return replace(self, levels=[level.without_geometry() for level in self.levels])

    def packed(self) -> LodChain:
        """This chain with every level's geometry packed (:meth:`Level.packed`): what a
        worker sends back where the main process only passes geometry on to other tasks."""
        return replace(self, levels=[level.packed() for level in self.levels])

    def unpacked(self) -> LodChain:
        """This chain with every level's geometry unpacked (itself when none is packed)."""
        if all(level.packed_geometry is None for level in self.levels):
            return self
        return replace(self, levels=[level.unpacked() for level in self.levels])


_CHAIN_FIELDS = tuple(f.name for f in fields(LodChain))
_CHAIN_ARRAYS = tuple(_CHAIN_FIELDS.index(name) for name in ("origin", "center", "transform"))


Numbers = tuple[list[Any], str]
"""A small array pickled as its numbers (nested lists) and dtype (:func:`as_numbers`)."""


def as_numbers(array: np.ndarray | None) -> Numbers | None:
    """A small array (a point, a 4×4 matrix) as its numbers and dtype, which pickle several
    times faster than the array; ``None`` stays ``None``."""
    return None if array is None else (array.tolist(), array.dtype.str)


def from_numbers(numbers: Numbers | None) -> np.ndarray | None:
    """The array of :func:`as_numbers` (``None`` stays ``None``)."""
    return None if numbers is None else np.array(numbers[0], dtype=numbers[1])


def _chain(*values: Any) -> LodChain:
    """The chain that :meth:`LodChain.__reduce__` pickled."""
    restored = list(values)
    for at in _CHAIN_ARRAYS:
        restored[at] = from_numbers(restored[at])
    return LodChain(*restored)


def in_scene(mesh: Mesh, origin: np.ndarray, transform: np.ndarray | None) -> Mesh:
    """``mesh`` (relative to ``origin``, placed by ``transform`` as :attr:`LodChain.transform`
    says) in scene coordinates."""
    if transform is None:
        return mesh.translated(origin)
    matrix = np.asarray(transform, dtype=np.float64)
    rotation, shift = matrix[:3, :3].T, matrix[:3, 3]
    return Mesh(
        [replace(part, vertices=(part.vertices + origin) @ rotation + shift) for part in mesh.parts]
    )


@dataclass
class CellChain:
    """A LOD parent (HLOD): the chains of one grid cell's objects (or of finer cells) shown
    near, and one ``far`` level standing for all of them beyond ``cutoffs[0]``.

    ``far`` is relative to ``origin``; ``center`` (relative to ``origin`` as well) is the
    centre of the members' bounding box, from which the cutoffs are measured. With culling,
    ``cutoffs[1]`` is where the cell disappears. ``tier`` is 1 for cells of objects, 2 for cells
    of tier-1 cells and so on; ``size`` the cell's side in metres and ``key`` its column and
    row on the tier's grid. ``facts`` holds what the planner measured (silhouette F of the far
    level against the members at its switch-in distance, the kind chosen and why).
    """

    cell_id: str
    tier: int
    size: float
    key: tuple[int, int]
    members: list[LodChain | CellChain]
    far: Level
    cutoffs: list[float]
    origin: np.ndarray
    center: np.ndarray
    alpha: float
    beta: float
    gamma: float
    xs: list[float]
    culled: bool = False
    facts: dict[str, Any] = field(default_factory=dict)

    def unpacked(self) -> CellChain:
        """This cell with its members' geometry unpacked (:meth:`LodChain.unpacked`)."""
        return replace(self, members=[member.unpacked() for member in self.members])

    def member_ids(self) -> list[str]:
        """Each member's id: an object's, or a finer cell's."""
        return [m.cell_id if isinstance(m, CellChain) else m.object_id for m in self.members]

    def objects(self) -> list[LodChain]:
        """The object chains of this cell and of its finer cells, in order."""
        return [chain for member in self.members for chain in member.objects()]

    def cells(self) -> list[CellChain]:
        """This cell and its finer cells, coarsest first."""
        found = [self]
        for member in self.members:
            if isinstance(member, CellChain):
                found.extend(member.cells())
        return found
