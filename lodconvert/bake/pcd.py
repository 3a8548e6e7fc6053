"""Backend-independent steps of PCD baking: hole filling, merging, de-duplication, colours.

A backend rasterises the 6 directions into :class:`SlabHits`; this module turns them into one
point cloud on the level's grid:

1. hole filling per slab image (:mod:`.filters`);
2. all directions merged; each hit becomes a point at its pixel centre and hit depth;
3. thin-feature rescue: surface samples (face centroids, and points along each face's longest
   edge at most a pitch apart) whose cell has no ray hit in it or next to it — a part thinner
   than the pitch, missed by every pixel centre — are added; they lie on the surface;
4. one point per occupied cell: the hit nearest the cell centre (so points stay on the surface);
5. colour from the source surface at the point, normal of the face it lies on.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..model import BakeParams, Mesh, PointCloud
from .filters import fill_holes
from .grid import Grid, SlabHits


class Backend(Protocol):
    """A rasteriser of the 6 axis directions onto a level grid."""

    name: str
    renderer: str

    def rasterize(self, surface: Mesh, grid: Grid) -> list[SlabHits]:
        """Nearest hit per (slab, pixel) for +x, -x, +y, -y, +z, -z (in any order)."""
        ...

    def release(self) -> None:
        """Free what the backend holds (a GL context, say)."""
        ...


def occupied_hits(
    surface: Mesh, params: BakeParams, backend: Backend, bounds: np.ndarray | None = None
) -> tuple[Grid, np.ndarray, np.ndarray]:
    """Grid, hit positions (k, 3) and hit faces (k,) after hole filling, before rescue."""
    grid = Grid.for_bounds(
        surface.bounds if bounds is None else bounds, params.resolution, params.slices
    )
    raw = backend.rasterize(surface, grid)
    filled = [fill_holes(h, grid, params.filter) for h in raw]
    if filled:
        positions = np.concatenate([h.positions(grid) for h in filled])
        faces = np.concatenate([h.face for h in filled]).astype(np.int64)
    else:
        positions = np.zeros((0, 3))
        faces = np.zeros(0, dtype=np.int64)
    return grid, positions, faces


def _edge_table(surface: Mesh) -> dict[str, np.ndarray]:
    """Per non-degenerate face: centroid, and start, vector and length of its longest edge."""
    tri = surface.triangles
    edges = tri[:, [1, 2, 0]] - tri
    area2 = np.linalg.norm(np.cross(edges[:, 0], -edges[:, 2]), axis=1)
    face_ids = np.flatnonzero(area2 > 0)
    tri, edges = tri[face_ids], edges[face_ids]
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


def surface_samples(surface: Mesh, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on every non-degenerate face: its centroid, and samples at most ``pitch`` apart
    along its longest edge (a sliver thinner than the pitch lies within a pitch of them)."""
    table = surface.derived("edge-table", lambda: _edge_table(surface))
    count = np.maximum(1, np.ceil(table["length"] / pitch).astype(np.int64))
    if int(count.max(initial=1)) == 1:
        along_rows = np.arange(len(count))
        t = np.full(len(count), 0.5)
    else:
        along_rows = np.repeat(np.arange(len(count)), count)
        k = np.arange(len(along_rows)) - np.repeat(np.cumsum(count) - count, count)
        t = (k + 0.5) / count[along_rows]
    along = table["start"][along_rows] + table["edge"][along_rows] * t[:, None]
    points = np.concatenate([table["centroid"], along])
    return points, np.concatenate([table["face"], table["face"][along_rows]])


def rescue_thin_features(
    surface: Mesh, grid: Grid, positions: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Add the surface samples that no hit is near (see module docstring)."""
    samples, sample_faces = surface_samples(surface, grid.pitch)
    if len(positions):
        near = grid.neighbourhood_keys(grid.cell_keys(positions))
        keys = grid.cell_keys(samples)
        at = np.minimum(np.searchsorted(near, keys), len(near) - 1)
        new = near[at] != keys
    else:
        new = np.ones(len(samples), dtype=bool)
    return (
        np.concatenate([positions, samples[new]]),
        np.concatenate([faces, sample_faces[new]]),
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
    surface: Mesh, params: BakeParams, backend: Backend, bounds: np.ndarray | None = None
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
