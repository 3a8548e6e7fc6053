"""Backend-independent steps of PCD baking: a backend's :class:`SlabHits` of the 6 directions
become one point cloud on the level's grid — holes filled per slab image (:mod:`.filters`),
directions merged, parts thinner than the pitch rescued by surface samples, one point per
occupied cell (the hit nearest its centre), colours from the source surface and normals of the
faces. Memory follows the occupied cells, not the faces: directions are folded in one at a
time, samples a chunk at a time. The steps: ``docs/baking.md``.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Protocol

import numpy as np

from ..limits import DEFAULT_LIMITS
from ..model import BakeParams, Mesh, PointCloud
from .filters import fill_holes
from .grid import Grid, SlabHits, distinct_triangles


class Backend(Protocol):
    """A rasteriser of the 6 axis directions onto a level grid."""

    name: str
    renderer: str

    def rasterize(self, surface: Mesh, grid: Grid, memory_bytes: int = ...) -> Iterable[SlabHits]:
        """Nearest hit per (slab, pixel) for +x, -x, +y, -y, +z, -z (in any order), working in
        about ``memory_bytes`` at once."""
        ...

    def release(self) -> None:
        """Free what the backend holds (a GL context, say)."""
        ...


SAMPLE_BYTES = 400
"""Working memory per thin-feature sample tested at once (27 neighbour look-ups)."""


def _filled_hits(
    surface: Mesh, grid: Grid, params: BakeParams, backend: Backend, memory_bytes: int
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Hit positions (k, 3) and faces (k,) of each direction after hole filling."""
    for hits in backend.rasterize(surface, grid, memory_bytes):
        filled = fill_holes(hits, grid, params.filter)
        yield filled.positions(grid), filled.face.astype(np.int64)


def occupied_hits(
    surface: Mesh, params: BakeParams, backend: Backend, bounds: np.ndarray | None = None
) -> tuple[Grid, np.ndarray, np.ndarray]:
    """Grid, hit positions (k, 3) and hit faces (k,) after hole filling, before rescue."""
    grid = Grid.for_bounds(
        surface.bounds if bounds is None else bounds, params.resolution, params.slices
    )
    parts = list(_filled_hits(surface, grid, params, backend, DEFAULT_LIMITS.memory_bytes))
    if not parts:
        return grid, np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    positions, faces = (np.concatenate(p) for p in zip(*parts, strict=True))
    return grid, positions, faces


def _edge_table(surface: Mesh) -> dict[str, np.ndarray]:
    """Per distinct non-degenerate face (the first of identical ones): centroid, and start,
    vector and length of its longest edge."""
    first, _ = surface.derived("distinct", lambda: distinct_triangles(surface.triangles))
    tri = surface.triangles[first]
    edges = tri[:, [1, 2, 0]] - tri
    area2 = np.linalg.norm(np.cross(edges[:, 0], -edges[:, 2]), axis=1)
    keep = area2 > 0
    face_ids, tri, edges = first[keep], tri[keep], edges[keep]
    lengths = np.linalg.norm(edges, axis=2)
    longest = np.argmax(lengths, axis=1)
    rows = np.arange(len(face_ids))
    return {
        "face": face_ids,
        "centroid": tri.mean(axis=1),
        "start": tri[rows, longest],
        "edge": edges[rows, longest],
        "length": lengths[rows, longest],
    }


def surface_samples(
    surface: Mesh, pitch: float, chunk: int
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Points (and their faces) on every non-degenerate face, about ``chunk`` at a time: all
    centroids, then samples at most ``pitch`` apart along each face's longest edge (a sliver
    thinner than the pitch lies within a pitch of them)."""
    table = surface.derived("edge-table", lambda: _edge_table(surface))
    face = table["face"]
    for start in range(0, len(face), chunk):
        yield table["centroid"][start : start + chunk], face[start : start + chunk]
    count = np.maximum(1, np.ceil(table["length"] / pitch).astype(np.int64))
    cum = np.cumsum(count)
    start = 0
    while start < len(count):
        base = cum[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(cum, base + chunk, side="right")))
        c = count[start:stop]
        rows = np.repeat(np.arange(start, stop), c)
        t = (np.arange(len(rows)) - np.repeat(np.cumsum(c) - c, c) + 0.5) / count[rows]
        yield table["start"][rows] + table["edge"][rows] * t[:, None], face[rows]
        start = stop


def _near_any(grid: Grid, occupied: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Whether the cell of each point or one of its 26 neighbours is among the sorted keys
    ``occupied``. Each distinct cell of the points is looked up once."""
    if len(occupied) == 0:
        return np.zeros(len(points), dtype=bool)
    keys = grid.cell_keys(points)
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    starts = np.r_[True, ordered[1:] != ordered[:-1]]
    cells = ordered[starts]
    idx = grid.cell_index(cells)
    n = np.asarray(grid.cells, dtype=np.int64)
    near = np.zeros(len(cells), dtype=bool)
    for offset in np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3):
        around = np.clip(idx + offset, 0, n - 1)
        around_keys = (around[:, 0] * n[1] + around[:, 1]) * n[2] + around[:, 2]
        at = np.minimum(np.searchsorted(occupied, around_keys), len(occupied) - 1)
        near |= occupied[at] == around_keys
    out = np.empty(len(points), dtype=bool)
    out[order] = near[np.cumsum(starts) - 1]
    return out


class NearestPerCell:
    """The point nearest each occupied cell's centre among all points added so far, in chunks
    (ties go to the lower face, then to the point added first), ordered by cell key."""

    def __init__(self, grid: Grid) -> None:
        self.grid = grid
        self.keys = np.zeros(0, dtype=np.int64)
        self.d2 = np.zeros(0, dtype=np.float64)
        self.positions = np.zeros((0, 3), dtype=np.float64)
        self.faces = np.zeros(0, dtype=np.int64)

    def add(self, positions: np.ndarray, faces: np.ndarray) -> None:
        """Fold ``positions`` (k, 3) on ``faces`` (k,) into the points kept."""
        if len(positions) == 0:
            return
        keys = self.grid.cell_keys(positions)
        d2 = ((positions - self.grid.cell_centers(keys)) ** 2).sum(axis=1)
        order = np.lexsort((faces, d2, keys))
        sorted_keys = keys[order]
        pick = order[np.r_[True, sorted_keys[1:] != sorted_keys[:-1]]]
        keys, d2, faces, positions = keys[pick], d2[pick], faces[pick], positions[pick]
        if len(self.keys) == 0:
            self.keys, self.d2, self.faces, self.positions = keys, d2, faces, positions
            return
        at = np.searchsorted(self.keys, keys)
        held = np.minimum(at, len(self.keys) - 1)
        same = self.keys[held] == keys
        better = same & (
            (d2 < self.d2[held]) | ((d2 == self.d2[held]) & (faces < self.faces[held]))
        )
        for mine, theirs in (
            (self.d2, d2),
            (self.faces, faces),
            (self.positions, positions),
        ):
            mine[held[better]] = theirs[better]
        new, where = ~same, at[~same]
        self.keys = np.insert(self.keys, where, keys[new])
        self.d2 = np.insert(self.d2, where, d2[new])
        self.faces = np.insert(self.faces, where, faces[new])
        self.positions = np.insert(self.positions, where, positions[new], axis=0)


def bake_points(
    surface: Mesh,
    params: BakeParams,
    backend: Backend,
    bounds: np.ndarray | None = None,
    memory_bytes: int = DEFAULT_LIMITS.memory_bytes,
) -> tuple[PointCloud, Grid]:
    """Bake one point level of ``surface`` (world coordinates) on the grid of ``params``,
    working in chunks of about ``memory_bytes``."""
    grid = Grid.for_bounds(
        surface.bounds if bounds is None else bounds, params.resolution, params.slices
    )
    kept = NearestPerCell(grid)
    for positions, faces in _filled_hits(surface, grid, params, backend, memory_bytes):
        kept.add(positions, faces)
    hit_cells = kept.keys
    chunk = max(1 << 12, memory_bytes // (4 * SAMPLE_BYTES))
    for samples, faces in surface_samples(surface, grid.pitch, chunk):
        new = ~_near_any(grid, hit_cells, samples)
        kept.add(samples[new], faces[new])
    cloud = PointCloud(
        positions=kept.positions,
        colors=surface.colors_at(kept.faces, kept.positions),
        normals=surface.face_normals(kept.faces),
    )
    return cloud, grid
