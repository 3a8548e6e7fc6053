"""The tileset writer: LOD parents and objects (:func:`~lodconvert.bakery.iter_chains` with
cells) → a tile tree, one GLB per tile (:mod:`.content`), placed in ECEF (:mod:`.placement`).
Each tile's GLB is a :class:`~.task.TileTask` run by the run's executor, the one that bakes;
results come back in order and are written here, so the tree is the same for any worker count
and no worker needs the staging folder. Tiles that an interrupted run of the same key left
whole are kept (:mod:`.task`). The root holds a tile per coarsest cell and, beside each, one
for the objects no cell admitted; a cell's tile shows its far level, its children its finer
cells' tiles and its objects' coarsest then finest levels, ``REPLACE`` everywhere. A tile that
switches to its children at distance d has geometricError sse·d / focal_px. The tree, the
geometricError and resuming: ``docs/3d-tiles.md``.
"""

from __future__ import annotations

import json
import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import LodConvertError, UsageError
from ...model import CellChain, Level, LodChain
from ...textures import ATLAS_SIZE, check_atlas_size
from .. import OutputInfo, Pieces
from ..gltf.compression import (
    MESHOPT,
    check_compression,
    check_texture_format,
    position_tolerance,
)
from .metadata import Feature
from .placement import Placement, world_to_frame

if TYPE_CHECKING:
    from ...context import RunContext

from .records import TileRecords
from .task import MARGIN, TILES, Placed, TileResult, TileTask, Where

DEFAULT_SSE = 16.0
"""CesiumJS's default maximumScreenSpaceError."""
EXTERNAL_BYTES = 2_000_000
"""Largest tileset JSON written as one file: past it, each child of the root is an external
tileset of its own (``tiles/NAME.json``)."""


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


def _mesh_levels(chain: LodChain) -> list[tuple[int, Level]]:
    """The chain's mesh levels (index, level), finest first."""
    return [(i, level) for i, level in enumerate(chain.levels) if not level.is_points]


def _feature(chain: LodChain) -> Feature:
    """An object's feature: its id, its ``type`` attribute and its other attributes."""
    attributes = {k: v for k, v in chain.metadata.items() if k not in ("id", "type")}
    kind = chain.metadata.get("type")
    return chain.object_id, kind if isinstance(kind, str) else "", attributes


class TilesetWriter:
    """Writes the tiles of the items it is given into a :class:`~lodconvert.sinks.DirectorySink`
    (each tile's GLB by ``executor``; in this process without one) and, at the end,
    ``tileset.json``; ``progress`` hears how many tiles an interrupted run's folder gave."""

    def __init__(
        self,
        sink: Any,
        info: OutputInfo,
        sse: float,
        executor: Any = None,
        progress: Callable[[str], None] | None = None,
        atlas_size: int = ATLAS_SIZE,
        compress: str = MESHOPT,
        webp: bool = False,
    ) -> None:
        self.sink, self.info, self.sse, self.atlas_size = sink, info, sse, atlas_size
        self.compress, self.webp = compress, webp
        self.executor, self.progress = executor, progress
        self.placement = Placement(info.georef, info.crs, info.source)
        georef = info.georef
        named = f"{self.placement.label}|{georef.frame}|{georef.crs.to_wkt()}"
        self.where = Where(georef, info.crs, info.source, named)
        self.point_scale: float | None = None
        self._queued: list[tuple[Tile, TileTask]] = []
        self.records = TileRecords(sink)

    def error(self, distance: float) -> float:
        """The geometric error of content that switches at ``distance``."""
        return self.sse * distance / self.info.view.focal_px

    def _write(self, name: str, data: bytes) -> str:
        """Write the file ``name`` into the tiles folder; returns ``name``."""
        with self.sink.file(f"{TILES}/{name}") as handle:
            handle.write(data)
        return name

    def _frame_of(self, ecef: np.ndarray) -> np.ndarray:
        """The ENU frame at the centre of ECEF points' bounding box."""
        return self.placement.enu_frame((ecef.min(axis=0) + ecef.max(axis=0)) / 2.0)

    def _tile(
        self, name: str, error: float, sources: tuple[Placed, ...], features: tuple[Feature, ...]
    ) -> Tile:
        """A tile whose content ``name`` (``.glb``) is made by a task queued for the executor
        (its frame and box are filled in from the task's result); see :class:`TileTask`."""
        task = TileTask(
            f"{name}.glb", self.where, sources, features, self.info.generator, self.atlas_size,
            self.compress, self.webp, position_tolerance(error),
        )  # fmt: skip
        tile = Tile(None, None, error, task.name)
        self._queued.append((tile, task))
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

    def tops(self, items: Iterable[LodChain | CellChain]) -> Iterator[Tile]:
        """The root's children: a tile per coarsest cell, and one per run of objects that
        follow a cell (those its plan left out, of the same coarsest grid cell)."""
        pending: list[LodChain] = []
        last = "objects"
        for item in items:
            if isinstance(item, CellChain):
                if pending:
                    yield self.objects_tile(f"{last}_beside", pending)
                    pending = []
                last = item.cell_id
                yield self.cell_tile(item)
            else:
                pending.append(item)
        if pending:
            yield self.objects_tile(f"{last}_beside", pending)

    def _placed(self, items: Iterable[LodChain | CellChain]) -> list[Tile]:
        """The root's children (:meth:`tops`), every tile's content made by its task (or, in a
        resumed run, kept where an interrupted run made it of the same) and written here. A
        kept tile is placed at once, so only the tasks in flight are held."""
        children: list[Tile] = []
        waiting: deque[tuple[Tile, TileTask]] = deque()
        made = reused = 0

        def tasks() -> Iterator[TileTask]:
            nonlocal made, reused
            for top in self.tops(items):
                children.append(top)
                for tile, task in self._queued:
                    kept = self.records.kept(task) if self.sink.resumed else None
                    if kept is None:
                        waiting.append((tile, task))
                        yield task
                    else:
                        tile.frame, tile.box = kept.frame, kept.box
                        made, reused = made + 1, reused + 1
                self._queued.clear()

        results: Iterable[TileResult] = (
            self.executor.results(tasks())
            if self.executor is not None
            else (task.run() for task in tasks())
        )
        for result in results:
            tile, task = waiting.popleft()
            if result.error is not None:
                raise LodConvertError(result.error)
            placed = self.records.written(task, result)
            tile.frame, tile.box = placed.frame, placed.box
            made += 1
        if self.sink.resumed and self.progress is not None:
            self.progress(f"{reused} of {made} tiles kept from an interrupted run's folder")
        return children

    def write(self, items: Iterable[LodChain | CellChain], name: str) -> None:
        """Every item's tiles, then the tileset JSON (``name``) and its external tilesets."""
        children = self._placed(items)
        if not children:  # nothing converted: the run fails and says why
            return
        ecef = np.stack([c.frame[:3, 3] for c in children])
        root = Tile(self._frame_of(ecef), None, 0.0, children=children)
        low, high = root.volume()
        largest = max(child.error for child in children)
        root.error = max(2.0 * largest, self.error(float(np.linalg.norm(high - low))))
        text = _dumped(self._tileset(root, None, f"{TILES}/"))
        if len(text) > EXTERNAL_BYTES:
            text = _dumped(self._tileset(root, None, f"{TILES}/", external=True))
        with self.sink.file(name) as handle:
            handle.write(text)
        if self.sink.resumed:
            self._drop_stale(children)

    def _drop_stale(self, children: list[Tile]) -> None:
        """Remove the files of the tiles folder that an interrupted run wrote and this one
        does not refer to."""
        kept: set[str] = set()
        stack = list(children)
        while stack:
            tile = stack.pop()
            kept.update([tile.content] if tile.content else [])
            kept.add(f"{(tile.content or 'tile').removesuffix('.glb')}.json")
            stack.extend(tile.children)
        self.sink.prune(TILES, kept)

    def _asset(self) -> dict[str, Any]:
        """The tileset's ``asset``: version, generator, and in ``extras.lodconvert`` the
        source, CRS, heights, --sse, reference view, options and point shading."""
        view = self.info.view
        extras: dict[str, Any] = {
            "source": self.info.source,
            "crs": self.placement.label,
            "heights": self.placement.heights(),
            "sse": self.sse,
            "view": {"height_px": view.height_px, "fov_y_deg": view.fov_y_deg},
            "geometric_error": "sse * switch distance / focal_px, focal_px = "
            "height_px / (2 tan(fov_y / 2))",
            "options": self.info.options,
        }
        if self.point_scale is not None:
            extras["point_cloud_shading"] = {
                "attenuation": True,
                "geometricErrorScale": self.point_scale,
            }
        return {
            "version": "1.1",
            "generator": self.info.generator,
            "extras": {"lodconvert": extras},
        }

    def _tileset(
        self, root: Tile, parent: np.ndarray | None, folder: str, external: bool = False
    ) -> dict[str, Any]:
        """A tileset JSON of the tree under ``root`` (its transform relative to ``parent``),
        written in a file from which the tiles folder is ``folder``."""
        return {
            "asset": self._asset(),
            "geometricError": root.error,
            "root": self._json(root, parent, folder, external),
        }

    def _json(
        self, tile: Tile, parent: np.ndarray | None, folder: str, external: bool = False
    ) -> dict[str, Any]:
        """A tile's JSON; with ``external``, its children each an external tileset."""
        low, high = tile.volume()
        centre, half = (low + high) / 2.0, (high - low) / 2.0
        relative = tile.frame if parent is None else np.linalg.solve(parent, tile.frame)
        out: dict[str, Any] = {
            "boundingVolume": {"box": [*centre, half[0], 0, 0, 0, half[1], 0, 0, 0, half[2]]},
            "geometricError": tile.error,
            "refine": "REPLACE",
            "transform": [float(v) for v in relative.T.ravel()],
        }
        if tile.content is not None:
            out["content"] = {"uri": folder + tile.content}
        out = _plain(out)
        if tile.children:  # each child's JSON plain already
            out["children"] = [
                self._reference(child, tile.frame)
                if external
                else self._json(child, tile.frame, folder)
                for child in tile.children
            ]
        if tile.extras:
            out["extras"] = _plain(tile.extras)
        return out

    def _reference(self, tile: Tile, parent: np.ndarray) -> dict[str, Any]:
        """A tile whose content is ``tile``'s subtree as an external tileset."""
        name = f"{(tile.content or 'tile').removesuffix('.glb')}.json"
        self._write(name, _dumped(self._tileset(tile, parent, "")))
        inside = world_to_frame(parent, tile.corners())
        low, high = inside.min(axis=0), inside.max(axis=0)
        centre, half = (low + high) / 2.0, (high - low) / 2.0
        box = [*centre, half[0], 0, 0, 0, half[1], 0, 0, 0, half[2]]
        return _plain(
            {
                "boundingVolume": {"box": box},
                "geometricError": tile.error,
                "refine": "REPLACE",
                "content": {"uri": f"{TILES}/{name}"},
            }
        )


def _plain(value: Any) -> Any:
    """``value`` as JSON data: numpy scalars unpacked, no negative zero."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and value == 0.0:
        return 0.0  # no negative zero
    return value


def _dumped(tileset: dict[str, Any]) -> bytes:
    """A tileset JSON's compact UTF-8 bytes."""
    text = json.dumps(tileset, separators=(",", ":"), ensure_ascii=False, allow_nan=False)
    return text.encode("utf-8")


def write_tileset(
    chains: Iterable[LodChain | CellChain],
    sink: Any,
    info: OutputInfo,
    context: RunContext | None = None,
    pieces: Pieces | None = None,
    sse: float = DEFAULT_SSE,
    atlas_size: int = ATLAS_SIZE,
    compress: str | None = None,
    texture_format: str = "default",
) -> None:
    """The registry's ``write``: the tileset of ``chains`` (LOD parents and objects, as
    :func:`~lodconvert.bakery.iter_chains` yields them with cells) into ``sink``, each tile's
    GLB made by the executor of the run's ``context`` (``None``: here), its textures packed
    into atlas pages of at most ``atlas_size`` texels a side, its geometry compressed as
    ``compress`` says (``None``: ``meshopt``), its pages with a WebP copy where
    ``texture_format`` is ``webp``; a tileset takes no ``pieces``."""
    if not (math.isfinite(sse) and sse > 0):
        raise UsageError(f"must be a positive number of pixels, got {sse:g}", "sse")
    check_atlas_size(atlas_size)
    compress = check_compression(compress or MESHOPT)
    webp = check_texture_format(texture_format)
    executor, progress = (context.executor, context.progress) if context else (None, None)
    writer = TilesetWriter(sink, info, sse, executor, progress, atlas_size, compress, webp)
    writer.write(chains, "tileset.json")
