"""The tileset writer: LOD parents and objects (:func:`~lodconvert.bakery.iter_chains` with
cells) → a tile tree planned by :mod:`.plan`, one GLB per tile (:mod:`.content`), placed in
ECEF (:mod:`.placement`). Each tile's GLB is a :class:`~.task.TileTask`, run where its coarsest
cell was baked (with workers: that cell's tiles come back with it) or by the run's executor;
results come back in order and are written here, so the tree is the same for any worker count
and no worker needs the staging folder. Tiles that an interrupted run of the same key left
whole are kept (:mod:`.records`). The tree, the geometricError and resuming:
``docs/3d-tiles.md``.
"""

from __future__ import annotations

import json
import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import LodConvertError, UsageError
from ...model import CellChain, LodChain
from ...textures import ATLAS_SIZE, check_atlas_size
from .. import OutputInfo, Pieces
from ..gltf.compression import MESHOPT, check_compression
from ..gltf.texture_copies import check_texture_format
from .placement import Placement, world_to_frame
from .plan import MadeTiles, Tile, TilePlan
from .records import TileRecords
from .task import TILES, TileResult, TileTask, Where

if TYPE_CHECKING:
    from ...context import RunContext

DEFAULT_SSE = 16.0
"""CesiumJS's default maximumScreenSpaceError."""
EXTERNAL_BYTES = 2_000_000
"""Largest tileset JSON written as one file: past it, each child of the root is an external
tileset of its own (``tiles/NAME.json``)."""


class TilesetWriter:
    """Writes the tiles of the items it is given into a :class:`~lodconvert.sinks.DirectorySink`
    as ``plan`` plans them (each tile's GLB made by ``executor``, in this process without one,
    or where its coarsest cell was baked: its ``pieces``) and, at the end, ``tileset.json``;
    ``progress`` hears how many tiles an interrupted run's folder gave."""

    def __init__(
        self,
        sink: Any,
        info: OutputInfo,
        plan: TilePlan,
        executor: Any = None,
        progress: Callable[[str], None] | None = None,
        pieces: Pieces | None = None,
    ) -> None:
        self.sink, self.info, self.plan = sink, info, plan
        self.executor, self.progress, self.pieces = executor, progress, pieces
        self.placement = Placement(info.georef, info.crs, info.source)
        self.records = TileRecords(sink)
        self.made = self.reused = 0

    def _write(self, name: str, data: bytes) -> str:
        """Write the file ``name`` into the tiles folder; returns ``name``."""
        with self.sink.file(f"{TILES}/{name}") as handle:
            handle.write(data)
        return name

    def _frame_of(self, ecef: np.ndarray) -> np.ndarray:
        """The ENU frame at the centre of ECEF points' bounding box."""
        return self.placement.enu_frame((ecef.min(axis=0) + ecef.max(axis=0)) / 2.0)

    def tops(self, items: Iterable[LodChain | CellChain]) -> Iterator[Tile]:
        """The root's children: a tile per coarsest cell, and one per run of objects that
        follow a cell (those its plan left out, of the same coarsest grid cell). A cell whose
        tiles were made where it was baked has them written here at once."""
        pending: list[LodChain] = []
        last = "objects"
        for item in items:
            if isinstance(item, CellChain):
                if pending:
                    yield self.plan.objects_tile(f"{last}_beside", pending)
                    pending = []
                last = item.cell_id
                made = self.pieces.take(item) if self.pieces is not None else None
                yield self.plan.cell_tile(item) if made is None else self._written(made)
            else:
                pending.append(item)
        if pending:
            yield self.plan.objects_tile(f"{last}_beside", pending)

    def _written(self, made: MadeTiles) -> Tile:
        """The tree of tiles ``made`` where their cell was baked, each file written here (or,
        in a resumed run, kept where an interrupted run made it of the same)."""
        if made.error is not None:
            raise LodConvertError(made.error)
        for name, result in made.results:
            assert result.key is not None
            kept = self.records.kept(name, result.key) if self.sink.resumed else None
            if kept is None:
                self.records.written(name, result)
            self.made, self.reused = self.made + 1, self.reused + (kept is not None)
        if made.point_scale is not None:
            self.plan.point_scale = max(self.plan.point_scale or 0.0, made.point_scale)
        return made.tile

    def _placed(self, items: Iterable[LodChain | CellChain]) -> list[Tile]:
        """The root's children (:meth:`tops`), every tile's content made by its task (or, in a
        resumed run, kept where an interrupted run made it of the same) and written here. A
        kept tile is placed at once, so only the tasks in flight are held."""
        children: list[Tile] = []
        waiting: deque[tuple[Tile, TileTask]] = deque()
        queued = self.plan.queued

        def tasks() -> Iterator[TileTask]:
            for top in self.tops(items):
                children.append(top)
                for tile, task in queued:
                    kept = self.records.kept(task.name, task.key) if self.sink.resumed else None
                    if kept is None:
                        waiting.append((tile, task))
                        yield task
                    else:
                        tile.frame, tile.box = kept.frame, kept.box
                        self.made, self.reused = self.made + 1, self.reused + 1
                queued.clear()

        results: Iterable[TileResult] = (
            self.executor.results(tasks())
            if self.executor is not None
            else (task.run() for task in tasks())
        )
        for result in results:
            tile, task = waiting.popleft()
            if result.error is not None:
                raise LodConvertError(result.error)
            placed = self.records.written(task.name, result)
            tile.frame, tile.box = placed.frame, placed.box
            self.made += 1
        if self.sink.resumed and self.progress is not None:
            kept = f"{self.reused} of {self.made} tiles"
            self.progress(f"{kept} kept from an interrupted run's folder")
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
        root.error = max(2.0 * largest, self.plan.error(float(np.linalg.norm(high - low))))
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
            "sse": self.plan.sse,
            "view": {"height_px": view.height_px, "fov_y_deg": view.fov_y_deg},
            "geometric_error": "sse * switch distance / focal_px, focal_px = "
            "height_px / (2 tan(fov_y / 2))",
            "options": self.info.options,
        }
        if self.plan.point_scale is not None:
            extras["point_cloud_shading"] = {
                "attenuation": True,
                "geometricErrorScale": self.plan.point_scale,
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


def tile_plan(
    info: OutputInfo,
    sse: float = DEFAULT_SSE,
    atlas_size: int = ATLAS_SIZE,
    compress: str | None = None,
    texture_format: str = "default",
) -> TilePlan:
    """How the tiles of a run writing ``info``'s scene are planned: geometric errors for
    ``sse``, textures packed into atlas pages of at most ``atlas_size`` texels a side, geometry
    compressed as ``compress`` says (``None``: ``meshopt``), pages with a copy where
    ``texture_format`` asks for one (``webp``, ``ktx2``)."""
    if not (math.isfinite(sse) and sse > 0):
        raise UsageError(f"must be a positive number of pixels, got {sse:g}", "sse")
    check_atlas_size(atlas_size)
    placement = Placement(info.georef, info.crs, info.source)
    georef = info.georef
    named = f"{placement.label}|{georef.frame}|{georef.crs.to_wkt()}"
    where = Where(georef, info.crs, info.source, named)
    return TilePlan(
        where, info.generator, sse, info.view.focal_px, atlas_size,
        check_compression(compress or MESHOPT), check_texture_format(texture_format),
    )  # fmt: skip


def cell_tiles(info: OutputInfo, **options: Any) -> Callable[[CellChain], MadeTiles]:
    """The registry's ``cell_formatter``: a coarsest cell's tiles planned as :func:`tile_plan`
    says (with the write ``options``) and made where the cell is baked (:meth:`TilePlan.made`)."""
    return tile_plan(info, **options).made


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
    :func:`~lodconvert.bakery.iter_chains` yields them with cells) into ``sink``, planned as
    :func:`tile_plan` says (with the same options), each tile's GLB made by the executor of the
    run's ``context`` (``None``: here) or, where ``pieces`` holds them, where its coarsest cell
    was baked."""
    plan = tile_plan(info, sse, atlas_size, compress, texture_format)
    executor, progress = (context.executor, context.progress) if context else (None, None)
    writer = TilesetWriter(sink, info, plan, executor, progress, pieces)
    writer.write(chains, "tileset.json")
