"""The level grid shared by every backend: cells, image planes and slabs.

For a level with resolution T3 and T1 slices, the grid pitch is ``h = L / T3`` (L = the longest
side of the bounding box) and slabs are ``t = L / T1`` thick. Looking along axis ``a`` the image
plane spans axes ``u = (a+1) % 3`` and ``v = (a+2) % 3``; pixel ``(iu, iv)`` has its centre at
``lo[u] + (iu + 0.5)·h, lo[v] + (iv + 0.5)·h``. Slab ``s`` covers depths
``lo[a] + s·t … lo[a] + (s+1)·t`` (the last slab is closed). Flat extents get one slab and one
pixel row, so flat and thin objects bake like any other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Grid:
    """Cells of pitch ``pitch`` from corner ``lo``; ``cells[a]`` cells along axis a, and
    ``slabs[a]`` slabs of thickness ``slab`` along axis a."""

    lo: np.ndarray
    pitch: float
    slab: float
    cells: tuple[int, int, int]
    slabs: tuple[int, int, int]

    @classmethod
    def for_bounds(cls, bounds: np.ndarray, resolution: int, slices: int) -> Grid:
        """The grid of a level over ``bounds`` ((2, 3) min/max corners)."""
        lo = np.asarray(bounds[0], dtype=np.float64)
        extent = np.asarray(bounds[1], dtype=np.float64) - lo
        longest = float(extent.max())
        if not longest > 0:
            raise ValueError("object has zero extent")
        pitch = longest / resolution
        slab = longest / slices
        cells = tuple(max(1, math.ceil(e / pitch - 1e-9)) for e in extent)
        slabs = tuple(max(1, math.ceil(e / slab - 1e-9)) for e in extent)
        return cls(lo=lo, pitch=pitch, slab=slab, cells=cells, slabs=slabs)  # type: ignore[arg-type]

    @property
    def size(self) -> int:
        """Cells as the slab images hold them: slabs × pixels, the most over the three view
        axes (T3 × T3 × T1 for a cube)."""
        return max(
            self.slabs[a] * self.cells[(a + 1) % 3] * self.cells[(a + 2) % 3] for a in range(3)
        )

    @staticmethod
    def plane_axes(axis: int) -> tuple[int, int]:
        """The (u, v) axes of the image plane seen along ``axis``."""
        return (axis + 1) % 3, (axis + 2) % 3

    def image_shape(self, axis: int) -> tuple[int, int]:
        """(rows, cols) = (cells along v, cells along u) of the image seen along ``axis``."""
        u, v = self.plane_axes(axis)
        return self.cells[v], self.cells[u]

    def slab_of(self, axis: int, depth: np.ndarray) -> np.ndarray:
        """Slab index of each depth (a world coordinate along ``axis``), clamped into range."""
        s = np.floor((depth - self.lo[axis]) / self.slab).astype(np.int64)
        return np.clip(s, 0, self.slabs[axis] - 1)

    def cell_keys(self, points: np.ndarray) -> np.ndarray:
        """One int64 key per point for the cell that holds it (cells clamped into the grid)."""
        idx = np.floor((points - self.lo) / self.pitch).astype(np.int64)
        n = np.asarray(self.cells, dtype=np.int64)
        idx = np.clip(idx, 0, n - 1)
        return (idx[:, 0] * n[1] + idx[:, 1]) * n[2] + idx[:, 2]

    def cell_index(self, keys: np.ndarray) -> np.ndarray:
        """Integer cell coordinates (k, 3) of the given keys."""
        n = self.cells
        return np.stack([keys // (n[1] * n[2]), (keys // n[2]) % n[1], keys % n[2]], axis=1)

    def cell_centers(self, keys: np.ndarray) -> np.ndarray:
        """World centres (k, 3) of the cells with the given keys."""
        return self.lo + (self.cell_index(keys).astype(np.float64) + 0.5) * self.pitch


def distinct_triangles(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first and the last index of each group of identical triangles in ``tri`` (n, 3, 3)
    (bit for bit the same corners in the same order), in order of first index: a face repeated
    many times is rasterised once. Rows are hashed first; only a mesh with equal hashes (a
    repeated face, or a rare collision) pays for the exact grouping."""
    n = len(tri)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    rows = np.ascontiguousarray(tri, dtype=np.float64).reshape(n, -1)
    words = rows.view(np.uint64)
    digest = words[:, 0].copy()
    for k in range(1, words.shape[1]):  # FNV-style mixing, wrapping in uint64
        digest = (digest * np.uint64(0x100000001B3)) ^ words[:, k]
    ordered = np.sort(digest)
    if not (ordered[1:] == ordered[:-1]).any():
        every = np.arange(n, dtype=np.int64)
        return every, every.copy()
    _, first, group = np.unique(
        rows.view(f"V{rows.shape[1] * 8}").ravel(), return_index=True, return_inverse=True
    )
    last = np.zeros(len(first), dtype=np.int64)
    np.maximum.at(last, group.ravel(), np.arange(n))
    order = np.argsort(first)
    return first[order].astype(np.int64), last[order]


@dataclass
class SlabHits:
    """Covered pixels of one view direction: per hit the slab, pixel (iu, iv), depth (world
    coordinate along the axis) and face index. ``sign`` +1 looks along +axis from the low side
    (nearest hit = smallest depth per slab), -1 looks back from the high side."""

    axis: int
    sign: int
    slab: np.ndarray
    iu: np.ndarray
    iv: np.ndarray
    depth: np.ndarray
    face: np.ndarray

    def __len__(self) -> int:
        return len(self.depth)

    def positions(self, grid: Grid) -> np.ndarray:
        """World positions (k, 3) of the hits: pixel centres in the plane, depth on the axis."""
        u, v = grid.plane_axes(self.axis)
        p = np.empty((len(self.depth), 3), dtype=np.float64)
        p[:, self.axis] = self.depth
        p[:, u] = grid.lo[u] + (self.iu + 0.5) * grid.pitch
        p[:, v] = grid.lo[v] + (self.iv + 0.5) * grid.pitch
        return p
