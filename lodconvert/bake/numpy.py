"""CPU backend: vectorised axis-ray rasterisation with numpy.

Every pixel centre of an image plane is a ray parallel to the view axis. A triangle covers the
pixel centres inside its projection (edges inclusive, as GL's fill rule does up to ties); the
hit depth is the triangle's plane at that centre. Per slab, the nearest hit seen from each side
is what the GL backend's depth test keeps, so both backends yield the same cells.

The per-face tables (projected bounds, barycentric and depth planes in world coordinates) do
not depend on the level, so they are computed once per surface and shared by all its levels.
"""

from __future__ import annotations

import numpy as np

from ..model import Mesh
from .grid import Grid, SlabHits

# Candidate (face, pixel) pairs tested at once; bounds peak memory (~150 bytes per candidate).
CHUNK = 1 << 21
EPS = 1e-9


class NumpyBackend:
    """Axis-ray rasteriser; needs nothing beyond numpy."""

    name = "numpy"
    renderer = "numpy axis-ray rasteriser (CPU)"

    def release(self) -> None:
        """Nothing to free (the GL backend frees its context here)."""

    def rasterize(self, surface: Mesh, grid: Grid) -> list[SlabHits]:
        """Covered pixels of all 6 view directions (+x, -x, +y, -y, +z, -z)."""
        hits: list[SlabHits] = []
        for axis in range(3):
            table = surface.derived(f"numpy-axis-{axis}", lambda a=axis: face_table(surface, a))
            hits.extend(rasterize_axis(table, grid, axis))
        return hits


def face_table(surface: Mesh, axis: int) -> dict[str, np.ndarray]:
    """Per face not degenerate in projection along ``axis``: projected bounds and the planes of
    two barycentric coordinates and of the depth, as ``(a, b, c)`` of ``a·u + b·v + c``, all
    relative to ``centre``."""
    tri = surface.triangles
    u, v = Grid.plane_axes(axis)
    # Planes are set up relative to the bounding-box centre, so that coordinates far from the
    # origin (georeferenced data) keep their precision.
    centre = surface.bounds.mean(axis=0)
    pu, pv, w = tri[:, :, u] - centre[u], tri[:, :, v] - centre[v], tri[:, :, axis] - centre[axis]
    ax, bx, cx = pu[:, 0], pu[:, 1], pu[:, 2]
    ay, by, cy = pv[:, 0], pv[:, 1], pv[:, 2]
    area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    extent = float(np.ptp(surface.bounds, axis=0).max())
    idx = np.flatnonzero(np.abs(area) > 1e-15 * extent * extent)
    ax, ay, bx, by, cx, cy, area = (a[idx] for a in (ax, ay, bx, by, cx, cy, area))
    inv = (1.0 / area)[:, None]
    b0 = np.stack([by - cy, cx - bx, bx * cy - by * cx], axis=1) * inv
    b1 = np.stack([cy - ay, ax - cx, cx * ay - cy * ax], axis=1) * inv
    w = w[idx]
    plane = (w[:, 0] - w[:, 2])[:, None] * b0 + (w[:, 1] - w[:, 2])[:, None] * b1
    plane[:, 2] += w[:, 2]
    return {
        "centre": centre,
        "face": idx,
        "umin": pu[idx].min(axis=1),
        "umax": pu[idx].max(axis=1),
        "vmin": pv[idx].min(axis=1),
        "vmax": pv[idx].max(axis=1),
        "b0": b0,
        "b1": b1,
        "plane": plane,
    }


def _pixel_range(lo: np.ndarray, hi: np.ndarray, origin: float, pitch: float, n: int):
    """First pixel and pixel count whose centres fall in [lo, hi] (world), clipped to 0..n-1."""
    first = np.maximum(np.ceil((lo - origin) / pitch - 0.5 - EPS), 0).astype(np.int64)
    last = np.minimum(np.floor((hi - origin) / pitch - 0.5 + EPS), n - 1).astype(np.int64)
    return first, np.maximum(last - first + 1, 0)


def _candidates(
    table: dict[str, np.ndarray],
    rows: np.ndarray,
    iu: np.ndarray,
    iv: np.ndarray,
    grid: Grid,
    axis: int,
) -> tuple[np.ndarray, ...]:
    """Keep the (face row, pixel) candidates whose pixel centre is inside the face; return
    them with their depth."""
    u, v = grid.plane_axes(axis)
    centre = table["centre"]
    x = (grid.lo[u] - centre[u]) + (iu + 0.5) * grid.pitch
    y = (grid.lo[v] - centre[v]) + (iv + 0.5) * grid.pitch
    b0c = table["b0"][rows]
    b1c = table["b1"][rows]
    b0 = b0c[:, 0] * x + b0c[:, 1] * y + b0c[:, 2]
    b1 = b1c[:, 0] * x + b1c[:, 1] * y + b1c[:, 2]
    inside = (b0 >= -EPS) & (b1 >= -EPS) & (b0 + b1 <= 1.0 + EPS)
    rows, iu, iv, x, y = rows[inside], iu[inside], iv[inside], x[inside], y[inside]
    pl = table["plane"][rows]
    return rows, iu, iv, pl[:, 0] * x + pl[:, 1] * y + pl[:, 2] + centre[axis]


def rasterize_axis(table: dict[str, np.ndarray], grid: Grid, axis: int) -> list[SlabHits]:
    """Nearest hit per (slab, pixel) seen from both sides of ``axis``: two :class:`SlabHits`."""
    u, v = grid.plane_axes(axis)
    rows_n, cols_n = grid.image_shape(axis)
    centre = table["centre"]
    iu0, nu = _pixel_range(table["umin"], table["umax"], grid.lo[u] - centre[u], grid.pitch, cols_n)
    iv0, nv = _pixel_range(table["vmin"], table["vmax"], grid.lo[v] - centre[v], grid.pitch, rows_n)
    count = nu * nv
    live = np.flatnonzero(count)
    count = count[live]
    cum = np.cumsum(count)
    parts: list[tuple[np.ndarray, ...]] = []
    start = 0
    while start < len(live):
        base = cum[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(cum, base + CHUNK, side="right")))
        c = count[start:stop]
        rows = np.repeat(live[start:stop], c)
        offset = np.arange(len(rows)) - np.repeat(np.cumsum(c) - c, c)
        width = nu[rows]
        parts.append(
            _candidates(
                table, rows, iu0[rows] + offset % width, iv0[rows] + offset // width, grid, axis
            )
        )
        start = stop
    if parts:
        rows, iu, iv, depth = (np.concatenate(p) for p in zip(*parts, strict=True))
    else:
        rows = iu = iv = np.zeros(0, dtype=np.int64)
        depth = np.zeros(0, dtype=np.float64)
    face = table["face"][rows]
    slab = grid.slab_of(axis, depth)
    key = (slab * rows_n + iv) * cols_n + iu
    # Sort by key, then depth, then face (deterministic ties): the first of a key group is the
    # nearest hit from the low side, the last the nearest from the high side.
    order = np.lexsort((face, depth, key))
    key = key[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if len(key) else key
    ends = np.r_[starts[1:], len(key)] - 1 if len(key) else key
    return [
        SlabHits(
            axis=axis,
            sign=sign,
            slab=slab[pick],
            iu=iu[pick],
            iv=iv[pick],
            depth=depth[pick],
            face=face[pick],
        )
        for sign, pick in ((1, order[starts]), (-1, order[ends]))
    ]
