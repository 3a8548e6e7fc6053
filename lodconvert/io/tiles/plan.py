"""A tileset's tile tree planned from its LOD parents and objects: each tile's
:class:`~.task.TileTask` (its levels placed, one feature per object) and geometric error
(sse·d / focal_px for content that switches at d). The writer plans in the main process
(:mod:`.writer`); a coarsest cell's task plans and makes its own tiles where it was baked
(:meth:`TilePlan.made`), so that its objects' geometry reaches no other process. The tree:
``docs/3d-tiles.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ...model import CellChain, Level, LodChain
from ..gltf.compression import position_tolerance
from .metadata import Feature
from .placement import world_to_frame
from .task import MARGIN, Placed, TileResult, TileTask, Where


@dataclass
class Tile:
    """One tile: its ENU frame in ECEF (``frame``, 4×4; ``None`` until its content's task has
    run), its content's box in that frame (``box``: min and max corners; ``None``: no
    content), its children and geometric error."""

    frame: np.ndarray | None
    box: np.ndarray | None
    error: float
    content: str | None = None
    children: list[Tile] = field(default_factory=list)
    extras: dict[str, Any] = field(default_factory=dict)
    _volume: np.ndarray | None = field(default=None, repr=False, compare=False)

    def corners(self) -> np.ndarray:
        """The 8 corners (ECEF) of this tile's bounding volume."""
        low, high = self.volume()
        assert self.frame is not None
        grid = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
        local = low + grid * (high - low)
        return local @ self.frame[:3, :3].T + self.frame[:3, 3]

    def volume(self) -> np.ndarray:
        """Min and max corners (in this frame) enclosing the content and every child; found
        once, when the tree is whole (every frame and box known)."""
        if self._volume is None:
            boxes = [] if self.box is None else [self.box]
            assert self.frame is not None
            for child in self.children:
                inside = world_to_frame(self.frame, child.corners())
                boxes.append(np.stack([inside.min(axis=0), inside.max(axis=0)]))
            low = np.min([b[0] for b in boxes], axis=0)
            high = np.max([b[1] for b in boxes], axis=0)
            self._volume = np.stack([low - MARGIN, high + MARGIN])
        return self._volume


@dataclass(frozen=True)
class MadeTiles:
    """A coarsest cell's tiles made where it was baked: the tree (``tile``, every frame and
    box known), each tile's result in the order planned (its GLB and key, for the main process
    to write), the largest point scale its far levels ask for, or why a tile could not be made
    (``error``)."""

    tile: Tile
    results: tuple[tuple[str, TileResult], ...] = ()
    point_scale: float | None = None
    error: str | None = None


@dataclass
class TilePlan:
    """How a run's tiles are planned: placed by ``where``, written by ``generator``, their
    geometric errors from ``sse`` and the reference view's ``focal_px``, their textures packed
    into atlas pages of ``atlas_size`` texels, their geometry compressed as ``compress`` says,
    pages with a ``copy`` where asked (``webp``, ``ktx2``). The tiles planned wait in
    ``queued`` (each with its task), and ``point_scale`` is the largest its far points ask for."""

    where: Where
    generator: str
    sse: float
    focal_px: float
    atlas_size: int
    compress: str
    copy: str
    queued: list[tuple[Tile, TileTask]] = field(default_factory=list)
    point_scale: float | None = None

    def error(self, distance: float) -> float:
        """The geometric error of content that switches at ``distance``."""
        return self.sse * distance / self.focal_px

    def _tile(
        self, name: str, error: float, sources: tuple[Placed, ...], features: tuple[Feature, ...]
    ) -> Tile:
        """A tile whose content ``name`` (``.glb``) is made by a task queued here (its frame
        and box are filled in from the task's result); see :class:`TileTask`."""
        task = TileTask(
            f"{name}.glb", self.where, sources, features, self.generator, self.atlas_size,
            self.compress, self.copy, position_tolerance(error),
        )  # fmt: skip
        tile = Tile(None, None, error, task.name)
        self.queued.append((tile, task))
        return tile

    def mesh_tile(self, name: str, entries: list[tuple[LodChain, Level]], error: float) -> Tile:
        """A tile of the mesh levels of ``entries`` (each a chain and one of its levels), one
        feature per chain."""
        sources = tuple(
            Placed(level.geometry, chain.origin, chain.transform) for chain, level in entries
        )
        return self._tile(name, error, sources, tuple(_feature(chain) for chain, _ in entries))

    def far_tile(self, cell: CellChain, children: list[Tile]) -> Tile:
        """A cell's tile: its far level, switching to ``children`` at its first cutoff."""
        far = cell.far
        extras: dict[str, Any] = {"cell": cell.cell_id, "tier": cell.tier, "kind": far.kind}
        if cell.facts.get("beside"):
            extras["beside"] = True
        error = self.error(cell.cutoffs[0])
        tile = self._tile(cell.cell_id, error, (Placed(far.geometry, cell.origin),), ())
        if far.points is not None and far.params is not None:
            scale = far.params.point_size / self.sse
            self.point_scale = max(self.point_scale or 0.0, scale)
            extras.update(point_size_px=far.params.point_size, spacing=far.spacing)
        tile.children, tile.extras = children, extras
        return tile

    def objects_tile(self, name: str, chains: list[LodChain]) -> Tile:
        """The tile of objects drawn with their own levels: their coarsest mesh levels, refined
        into a leaf of their finest (the leaf alone where none has two mesh levels)."""
        leaf = self.mesh_tile(f"{name}_finest", [(c, _mesh_levels(c)[0][1]) for c in chains], 0.0)
        switches = [
            chain.cutoffs[levels[-1][0] - 1]
            for chain in chains
            if len(levels := _mesh_levels(chain)) > 1
        ]
        if not switches:
            return leaf
        coarsest = [(c, _mesh_levels(c)[-1][1]) for c in chains]
        block = self.mesh_tile(f"{name}_coarsest", coarsest, self.error(max(switches)))
        block.children = [leaf]
        return block

    def cell_tile(self, cell: CellChain) -> Tile:
        """The tile of a LOD parent and everything under it."""
        children = [self.cell_tile(m) for m in cell.members if isinstance(m, CellChain)]
        objects = [m for m in cell.members if isinstance(m, LodChain)]
        if objects:
            children.append(self.objects_tile(cell.cell_id, objects))
        return self.far_tile(cell, children)

    def made(self, cell: CellChain) -> MadeTiles:
        """The tiles of ``cell`` (with its members and their geometry) planned and made here,
        each task run in turn; the first that fails ends it (``error``)."""
        plan = replace(self, queued=[], point_scale=None)
        top = plan.cell_tile(cell)
        results = []
        for tile, task in plan.queued:
            result = task.run()
            if result.error is not None:
                return MadeTiles(top, error=result.error)
            tile.frame, tile.box = result.frame, result.box
            results.append((task.name, result))
        return MadeTiles(top, tuple(results), plan.point_scale)

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled without what it has queued (a plan travels to a cell's task empty)."""
        values = (self.where, self.generator, self.sse, self.focal_px, self.atlas_size)
        return TilePlan, (*values, self.compress, self.copy)


def _mesh_levels(chain: LodChain) -> list[tuple[int, Level]]:
    """The chain's mesh levels (index, level), finest first."""
    return [(i, level) for i, level in enumerate(chain.levels) if not level.is_points]


def _feature(chain: LodChain) -> Feature:
    """An object's feature: its id, its ``type`` attribute and its other attributes."""
    attributes = {k: v for k, v in chain.metadata.items() if k not in ("id", "type")}
    kind = chain.metadata.get("type")
    return chain.object_id, kind if isinstance(kind, str) else "", attributes
