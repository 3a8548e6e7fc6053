"""Backend-independent steps of PCD baking: hole filling, merging, de-duplication, colours.

A backend rasterises the 6 directions into :class:`SlabHits`; this module turns them into one
point cloud on the level's grid:

1. hole filling per slab image (:mod:`.filters`);
2. all directions merged; each hit becomes a point at its pixel centre and hit depth;
3. thin-feature rescue: a cell that holds the centroid of a face but no ray hit (a part thinner
   than the pitch, missed by every pixel centre) gets that centroid, which lies on the surface;
4. one point per occupied cell: the hit nearest the cell centre (so points stay on the surface);
5. colour from the source surface at the point, normal of the face it lies on.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..scene import BakeParams, PointCloud, Surface
from .filters import fill_holes
from .grid import Grid, SlabHits


class Backend(Protocol):
    """A rasteriser of the 6 axis directions onto a level grid."""

    name: str
    renderer: str

    def rasterize(self, vertices: np.ndarray, faces: np.ndarray, grid: Grid) -> list[SlabHits]:
        """Nearest hit per (slab, pixel) for +x, -x, +y, -y, +z, -z (in any order)."""
        ...


def occupied_hits(
    surface: Surface, params: BakeParams, backend: Backend, bounds: np.ndarray | None = None
) -> tuple[Grid, np.ndarray, np.ndarray]:
    """Grid, hit positions (k, 3) and hit faces (k,) after hole filling, before rescue."""
    grid = Grid.for_bounds(
        surface.bounds if bounds is None else bounds, params.resolution, params.slices
    )
    raw = backend.rasterize(surface.vertices, surface.faces, grid)
    filled = [fill_holes(h, grid, params.filter) for h in raw]
    if filled:
        positions = np.concatenate([h.positions(grid) for h in filled])
        faces = np.concatenate([h.face for h in filled]).astype(np.int64)
    else:
        positions = np.zeros((0, 3))
        faces = np.zeros(0, dtype=np.int64)
    return grid, positions, faces


def rescue_thin_features(
    surface: Surface, grid: Grid, positions: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Add face centroids that fall in cells no hit occupies (see module docstring)."""
    tri = surface.vertices[surface.faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    face_ids = np.flatnonzero(area2 > 0)
    centroids = tri[face_ids].mean(axis=1)
    hit_keys = np.unique(grid.cell_keys(positions)) if len(positions) else np.zeros(0, np.int64)
    keys = grid.cell_keys(centroids)
    new = ~np.isin(keys, hit_keys)
    return (
        np.concatenate([positions, centroids[new]]),
        np.concatenate([faces, face_ids[new]]),
    )


def one_per_cell(grid: Grid, positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Indices of the point nearest each occupied cell's centre, ordered by cell key."""
    if len(positions) == 0:
        return np.zeros(0, dtype=np.int64)
    keys = grid.cell_keys(positions)
    d2 = ((positions - grid.cell_centers(keys)) ** 2).sum(axis=1)
    order = np.lexsort((faces, d2, keys))
    sorted_keys = keys[order]
    first = np.r_[True, sorted_keys[1:] != sorted_keys[:-1]]
    return order[first]


def bake_points(
    surface: Surface, params: BakeParams, backend: Backend, bounds: np.ndarray | None = None
) -> tuple[PointCloud, Grid]:
    """Bake one point level of ``surface`` (world coordinates) on the grid of ``params``."""
    grid, positions, faces = occupied_hits(surface, params, backend, bounds)
    positions, faces = rescue_thin_features(surface, grid, positions, faces)
    pick = one_per_cell(grid, positions, faces)
    positions, faces = positions[pick], faces[pick]
    cloud = PointCloud(
        positions=positions,
        colors=surface.colors_at(faces, positions),
        normals=surface.face_normals(faces),
    )
    return cloud, grid
