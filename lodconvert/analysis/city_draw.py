"""A city flattened for selection and drawing: baked object chains (placed by their
``transform`` where they have one) and LOD parents (every tier) as arrays in scene coordinates,
metres relative to one float64 ``origin`` near the city's middle. Every level part (a surface
of a mesh level, or a point level) is a draw part: one draw call. Each object keeps its
switching centre, bounding sphere, finest-level box and cutoffs; each cell its centre, sphere,
switch and cull distances and far level. See ``docs/render-bench.md`` (the city).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..model import CellChain, Level, LodChain
from .city_cameras import NEAR


@dataclass
class Geometry:
    """Every draw part packed for upload (scene coordinates, float32) and its table: the first
    index (triangles) or point, the GL count, vertices or points drawn, whether it is points,
    and a point level's declared size and design distance."""

    triangle_positions: np.ndarray
    triangle_colors: np.ndarray
    triangle_indices: np.ndarray
    point_positions: np.ndarray
    point_colors: np.ndarray
    first: np.ndarray
    count: np.ndarray
    size: np.ndarray
    points: np.ndarray
    point_size: np.ndarray
    design_distance: np.ndarray


@dataclass
class CityDraw:
    """A city flattened for selection and drawing (module docstring); positions are relative to
    ``origin``. Objects: ``centres`` (N, 3), ``radii`` (N,), finest-level ``boxes`` (N, 2, 3),
    ``cutoffs`` (N, K, +inf padded), ``level_first`` and ``level_parts`` (N, L: first draw part
    and part count of each level, 0 parts past the last), ``object_cell`` (N, finest-tier cell
    or -1). Cells: ``cell_centres``, ``cell_radii``, ``cell_cutoffs`` (C, 2: switch, cull or
    +inf), ``cell_far`` (draw part), ``cell_parent`` (-1 for the coarsest), ``cell_tier`` and
    ``cell_f`` (silhouette F of the far level at its switch-in distance), ``cell_ids``."""

    origin: np.ndarray
    geometry: Geometry
    centres: np.ndarray
    radii: np.ndarray
    boxes: np.ndarray
    cutoffs: np.ndarray
    level_first: np.ndarray
    level_parts: np.ndarray
    object_cell: np.ndarray
    cell_centres: np.ndarray
    cell_radii: np.ndarray
    cell_cutoffs: np.ndarray
    cell_far: np.ndarray
    cell_parent: np.ndarray
    cell_tier: np.ndarray
    cell_f: np.ndarray
    cell_ids: list[str]

    @property
    def objects(self) -> int:
        """Objects in the city."""
        return len(self.centres)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) box of every object's box, scene coordinates."""
        return np.stack([self.boxes[:, 0].min(axis=0), self.boxes[:, 1].max(axis=0)])

    def far_plane(self, eye: np.ndarray) -> float:
        """A far-plane distance beyond every object seen from ``eye``."""
        low, high = self.bounds
        return float(np.linalg.norm(np.maximum(np.abs(eye - low), np.abs(high - eye)))) + NEAR


def scene_points(chain: LodChain | CellChain, local: np.ndarray) -> np.ndarray:
    """World positions (n, 3) of points ``local`` of ``chain``'s frame (relative to its origin,
    then placed by its ``transform`` when it has one)."""
    world = np.asarray(local, dtype=np.float64) + chain.origin
    transform = getattr(chain, "transform", None)
    if transform is None:
        return world
    matrix = np.asarray(transform, dtype=np.float64)
    return world @ matrix[:3, :3].T + matrix[:3, 3]


class _Packer:
    """Collects draw parts into the arrays of a :class:`Geometry`."""

    def __init__(self, origin: np.ndarray) -> None:
        self.origin = origin
        self.arrays: dict[str, list[np.ndarray]] = {
            k: [] for k in ("tri_pos", "tri_col", "tri_idx", "pt_pos", "pt_col")
        }
        self.vertices = self.indices = self.point_count = 0
        self.table: list[tuple[int, int, int, bool, float, float]] = []

    def level(self, chain: LodChain | CellChain, level: Level) -> tuple[int, int, np.ndarray]:
        """Pack ``level`` of ``chain``: its first part, its part count and its box (2, 3)."""
        start = len(self.table)
        placed: list[np.ndarray] = []
        if level.points is not None:
            cloud = level.points
            positions = scene_points(chain, cloud.positions) - self.origin
            self.arrays["pt_pos"].append(positions.astype(np.float32))
            self.arrays["pt_col"].append(np.asarray(cloud.colors, dtype=np.uint8))
            size = level.params.point_size if level.params is not None else 1.0
            design = level.design_distance or 0.0
            self.table.append((self.point_count, len(cloud), len(cloud), True, size, design))
            self.point_count += len(cloud)
            placed.append(positions)
        else:
            assert level.mesh is not None
            for part in level.mesh.parts:
                positions = scene_points(chain, part.vertices) - self.origin
                colors = part.vertex_colors
                if colors is None:
                    colors = np.repeat(part.material_color[None], len(positions), axis=0)
                faces = np.asarray(part.faces, dtype=np.int64) + self.vertices
                self.arrays["tri_pos"].append(positions.astype(np.float32))
                self.arrays["tri_col"].append(np.asarray(colors, dtype=np.uint8))
                self.arrays["tri_idx"].append(faces.astype(np.uint32).ravel())
                self.table.append((self.indices, faces.size, len(positions), False, 1.0, 0.0))
                self.indices += faces.size
                self.vertices += len(positions)
                placed.append(positions)
        every = np.concatenate(placed)
        return start, len(self.table) - start, np.stack([every.min(axis=0), every.max(axis=0)])

    def geometry(self) -> Geometry:
        """The packed arrays and the part table."""

        def joined(key: str, shape: tuple[int, ...], dtype: type) -> np.ndarray:
            found = self.arrays[key]
            return np.concatenate(found) if found else np.zeros(shape, dtype=dtype)

        table = np.array(self.table, dtype=np.float64).reshape(-1, 6)
        return Geometry(
            triangle_positions=joined("tri_pos", (0, 3), np.float32),
            triangle_colors=joined("tri_col", (0, 4), np.uint8),
            triangle_indices=joined("tri_idx", (0,), np.uint32),
            point_positions=joined("pt_pos", (0, 3), np.float32),
            point_colors=joined("pt_col", (0, 4), np.uint8),
            first=table[:, 0].astype(np.int64),
            count=table[:, 1].astype(np.int64),
            size=table[:, 2].astype(np.int64),
            points=table[:, 3].astype(bool),
            point_size=table[:, 4],
            design_distance=table[:, 5],
        )


def _flatten(
    items: Iterable[LodChain | CellChain],
) -> tuple[list[LodChain], list[int], list[CellChain], list[int]]:
    """Objects with their finest-tier cell index (-1: none), and cells (coarsest first) with
    their parent index (-1: a coarsest cell)."""
    objects: list[LodChain] = []
    object_cell: list[int] = []
    cells: list[CellChain] = []
    parents: list[int] = []

    def add(cell: CellChain, parent: int) -> None:
        index = len(cells)
        cells.append(cell)
        parents.append(parent)
        for member in cell.members:
            if isinstance(member, CellChain):
                add(member, index)
            else:
                objects.append(member)
                object_cell.append(index)

    for item in items:
        if isinstance(item, CellChain):
            add(item, -1)
        else:
            objects.append(item)
            object_cell.append(-1)
    return objects, object_cell, cells, parents


def _padded(rows: Sequence[Sequence[float]], width: int, fill: float) -> np.ndarray:
    out = np.full((len(rows), width), fill, dtype=np.float64)
    for i, row in enumerate(rows):
        out[i, : len(row)] = row
    return out


def _centre(chain: LodChain | CellChain) -> np.ndarray:
    return scene_points(chain, np.asarray(chain.center, dtype=np.float64)[None])[0]


def city_draw(items: Iterable[LodChain | CellChain]) -> CityDraw:
    """Flatten object chains and LOD parents (as :func:`~lodconvert.bakery.iter_chains`
    yields them) into a :class:`CityDraw`. Raises :class:`ValueError` for a city without
    objects."""
    objects, object_cell, cells, parents = _flatten(items)
    if not objects:
        raise ValueError("the city has no objects")
    world = np.array([_centre(chain) for chain in objects])
    origin = np.round((world.min(axis=0) + world.max(axis=0)) / 2.0)
    packer = _Packer(origin)
    levels = max(len(chain.levels) for chain in objects)
    level_first = np.zeros((len(objects), levels), dtype=np.int64)
    level_parts = np.zeros((len(objects), levels), dtype=np.int64)
    boxes = np.zeros((len(objects), 2, 3))
    for i, chain in enumerate(objects):
        for j, level in enumerate(chain.levels):
            level_first[i, j], level_parts[i, j], box = packer.level(chain, level)
            if j == 0:
                boxes[i] = box
    far = [packer.level(cell, cell.far)[0] for cell in cells]
    width = max(len(chain.cutoffs) for chain in objects)
    cell_centres = np.array([_centre(cell) for cell in cells]).reshape(-1, 3) - origin
    return CityDraw(
        origin=origin,
        geometry=packer.geometry(),
        centres=world - origin,
        radii=np.array([chain.alpha / 2.0 for chain in objects]),
        boxes=boxes,
        cutoffs=_padded([chain.cutoffs for chain in objects], max(width, 1), math.inf),
        level_first=level_first,
        level_parts=level_parts,
        object_cell=np.array(object_cell, dtype=np.int64),
        cell_centres=cell_centres,
        cell_radii=np.array([cell.alpha / 2.0 for cell in cells]),
        cell_cutoffs=_padded([cell.cutoffs[:2] for cell in cells], 2, math.inf),
        cell_far=np.array(far, dtype=np.int64),
        cell_parent=np.array(parents, dtype=np.int64),
        cell_tier=np.array([cell.tier for cell in cells], dtype=np.int64),
        cell_f=np.array([far_level_f(cell) for cell in cells]),
        cell_ids=[cell.cell_id for cell in cells],
    )


def far_level_f(cell: CellChain) -> float:
    """Silhouette F of ``cell``'s far level against its members at its switch-in distance, as
    the planner measured it (``facts["silhouette_f"]`` of ``facts["kind"]``; NaN if unknown)."""
    scores = cell.facts.get("silhouette_f", {})
    return float(scores.get(cell.facts.get("kind"), math.nan))
