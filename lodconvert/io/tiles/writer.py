"""The tileset writer: LOD parents and objects (:func:`~lodconvert.pipeline.iter_chains` with
cells) → a tile tree, one GLB per tile (:mod:`.content`), placed in ECEF (:mod:`.placement`).

Tree: the root (no content) holds one tile per coarsest cell and, beside them, the objects no
cell admitted. A cell's tile shows its far level; its children are its finer cells' tiles and,
for the objects among its members, one tile of their coarsest mesh levels whose child, a leaf,
holds their finest. Refinement is ``REPLACE`` everywhere.

geometricError: a tile whose content switches to its children at distance d has
GE = sse·d / focal_px (focal_px = h / (2·tan(fov/2)) of the reference view), so that CesiumJS,
refining where GE·focal/distance exceeds its maximumScreenSpaceError (= sse), refines at d.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import UsageError
from ...model import CellChain, LodChain, Mesh
from .. import OutputInfo
from .content import mesh_glb, points_glb
from .metadata import Feature
from .placement import Placement, world_to_frame

DEFAULT_SSE = 16.0
"""CesiumJS's default maximumScreenSpaceError."""
EXTERNAL_BYTES = 2_000_000
"""Largest tileset JSON written as one file: past it, each child of the root is an external
tileset of its own (``tiles/NAME.json``)."""
MARGIN = 0.001
"""Metres a bounding box is grown by on every side (float32 content rounding, flat content)."""
TILES = "tiles"
# glTF content is y-up; 3D Tiles turns it z-up: (x, y, z) -> (x, -z, y). ENU (e, n, u) is
# therefore written as (e, u, -n).
_ENU_TO_GLTF = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass
class Tile:
    """One tile: its ENU frame in ECEF (``frame``, 4×4), its content's box in that frame
    (``box``: min and max corners; ``None``: no content), its children and geometric error."""

    frame: np.ndarray
    box: np.ndarray | None
    error: float
    content: str | None = None
    children: list[Tile] = field(default_factory=list)
    extras: dict[str, Any] = field(default_factory=dict)

    def corners(self) -> np.ndarray:
        """The 8 corners (ECEF) of this tile's bounding volume."""
        low, high = self.volume()
        grid = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
        local = low + grid * (high - low)
        return local @ self.frame[:3, :3].T + self.frame[:3, 3]

    def volume(self) -> np.ndarray:
        """Min and max corners (in this frame) enclosing the content and every child."""
        boxes = [] if self.box is None else [self.box]
        for child in self.children:
            inside = world_to_frame(self.frame, child.corners())
            boxes.append(np.stack([inside.min(axis=0), inside.max(axis=0)]))
        low = np.min([b[0] for b in boxes], axis=0)
        high = np.max([b[1] for b in boxes], axis=0)
        return np.stack([low - MARGIN, high + MARGIN])


def _mesh_levels(chain: LodChain) -> list[tuple[int, Mesh]]:
    """The chain's mesh levels (index, mesh), finest first."""
    return [(i, lv.mesh) for i, lv in enumerate(chain.levels) if lv.mesh is not None]


def _colors(mesh: Mesh) -> np.ndarray:
    """(n, 4) sRGB bytes per vertex: vertex colours, else each part's material colour (a
    texture's material colour stands in for it)."""
    own = mesh.vertex_colors
    if own is not None:
        return own
    return np.concatenate(
        [np.repeat(p.material_color[None], len(p.vertices), axis=0) for p in mesh.parts]
    )


def _bounds(local: np.ndarray) -> np.ndarray:
    """Min and max corners of points (n, 3)."""
    return np.stack([local.min(axis=0), local.max(axis=0)])


def _feature(chain: LodChain) -> Feature:
    """An object's feature: its id, its ``type`` attribute and its other attributes."""
    attributes = {k: v for k, v in chain.metadata.items() if k not in ("id", "type")}
    kind = chain.metadata.get("type")
    return chain.object_id, kind if isinstance(kind, str) else "", attributes


class TilesetWriter:
    """Writes the tiles of the items it is given into a :class:`~lodconvert.sinks.DirectorySink`
    and, at the end, ``tileset.json``."""

    def __init__(self, sink: Any, info: OutputInfo, sse: float) -> None:
        self.sink, self.info, self.sse = sink, info, sse
        self.placement = Placement(info.georef, info.crs, info.source)
        self.point_scale: float | None = None

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

    def _local(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A tile's frame for scene points (n, 3), and the points in it (ENU, float64)."""
        ecef = self.placement.ecef(points)
        frame = self._frame_of(ecef)
        return frame, world_to_frame(frame, ecef)

    def mesh_tile(self, name: str, entries: list[tuple[LodChain, Mesh]], error: float) -> Tile:
        """A tile of the meshes of ``entries`` (each a chain and one of its levels' meshes),
        one feature per chain."""
        placed = [chain.in_scene(mesh) for chain, mesh in entries]
        starts = np.cumsum([0] + [mesh.vertex_count for mesh in placed])
        frame, local = self._local(np.concatenate([mesh.vertices for mesh in placed]))
        data = mesh_glb(
            local @ _ENU_TO_GLTF.T,
            np.concatenate(
                [mesh.faces + start for mesh, start in zip(placed, starts[:-1], strict=True)]
            ),
            np.concatenate([_colors(mesh) for mesh in placed]),
            np.repeat(np.arange(len(placed)), np.diff(starts)),
            [_feature(chain) for chain, _ in entries],
            self.info.generator,
        )
        return Tile(frame, _bounds(local), error, self._write(f"{name}.glb", data))

    def far_tile(self, cell: CellChain, children: list[Tile]) -> Tile:
        """A cell's tile: its far level, switching to ``children`` at its first cutoff."""
        far = cell.far
        extras: dict[str, Any] = {"cell": cell.cell_id, "tier": cell.tier, "kind": far.kind}
        if far.points is not None:
            frame, local = self._local(far.points.positions + cell.origin)
            data = points_glb(local @ _ENU_TO_GLTF.T, far.points.colors, self.info.generator)
            if far.params is not None:
                scale = far.params.point_size / self.sse
                self.point_scale = max(self.point_scale or 0.0, scale)
                extras.update(point_size_px=far.params.point_size, spacing=far.spacing)
        else:
            assert far.mesh is not None
            frame, local = self._local(far.mesh.vertices + cell.origin)
            gltf = local @ _ENU_TO_GLTF.T
            data = mesh_glb(gltf, far.mesh.faces, _colors(far.mesh), None, [], self.info.generator)
        content = self._write(f"{cell.cell_id}.glb", data)
        return Tile(frame, _bounds(local), self.error(cell.cutoffs[0]), content, children, extras)

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

    def write(self, items: Iterable[LodChain | CellChain], name: str) -> None:
        """Every item's tiles, then the tileset JSON (``name``) and its external tilesets."""
        children = list(self.tops(items))
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
        if tile.children:
            out["children"] = [
                self._reference(child, tile.frame)
                if external
                else self._json(child, tile.frame, folder)
                for child in tile.children
            ]
        if tile.extras:
            out["extras"] = tile.extras
        return {k: _plain(v) for k, v in out.items()}

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
    chains: Iterable[LodChain | CellChain], sink: Any, info: OutputInfo, sse: float = DEFAULT_SSE
) -> None:
    """The registry's ``write``: the tileset of ``chains`` (LOD parents and objects, as
    :func:`~lodconvert.pipeline.iter_chains` yields them with cells) into ``sink``."""
    if not (math.isfinite(sse) and sse > 0):
        raise UsageError(f"must be a positive number of pixels, got {sse:g}", "sse")
    TilesetWriter(sink, info, sse).write(chains, "tileset.json")
