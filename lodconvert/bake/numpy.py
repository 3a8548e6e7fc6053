"""CPU backend: vectorised axis-ray rasterisation with numpy.

Every pixel centre of an image plane is a ray parallel to the view axis. A triangle covers the
pixel centres inside its projection (edges inclusive, as GL's fill rule does up to ties); the
hit depth is the triangle's plane at that centre. Per slab, the nearest hit seen from each side
is what the GL backend's depth test keeps, so both backends yield the same cells.
"""

from __future__ import annotations

import numpy as np

from .grid import Grid, SlabHits

# Candidate (face, pixel) pairs tested at once; bounds peak memory (~150 bytes per candidate).
CHUNK = 1 << 21
EPS = 1e-9


class NumpyBackend:
    """Axis-ray rasteriser; needs nothing beyond numpy."""

    name = "numpy"
    renderer = "numpy axis-ray rasteriser (CPU)"

    def rasterize(self, vertices: np.ndarray, faces: np.ndarray, grid: Grid) -> list[SlabHits]:
        """Covered pixels of all 6 view directions (+x, -x, +y, -y, +z, -z)."""
        tri = vertices[faces]
        hits: list[SlabHits] = []
        for axis in range(3):
            hits.extend(rasterize_axis(tri, grid, axis))
        return hits


def _face_setup(tri: np.ndarray, grid: Grid, axis: int) -> dict[str, np.ndarray]:
    """Per face: pixel bounding range and barycentric/depth plane coefficients, for the faces
    whose projection contains at least one pixel centre candidate."""
    u, v = grid.plane_axes(axis)
    rows, cols = grid.image_shape(axis)
    # Pixel coordinates in which pixel (iu, iv) has its centre at (iu, iv).
    pu = (tri[:, :, u] - grid.lo[u]) / grid.pitch - 0.5
    pv = (tri[:, :, v] - grid.lo[v]) / grid.pitch - 0.5
    iu0 = np.maximum(np.ceil(pu.min(axis=1) - EPS), 0).astype(np.int64)
    iu1 = np.minimum(np.floor(pu.max(axis=1) + EPS), cols - 1).astype(np.int64)
    iv0 = np.maximum(np.ceil(pv.min(axis=1) - EPS), 0).astype(np.int64)
    iv1 = np.minimum(np.floor(pv.max(axis=1) + EPS), rows - 1).astype(np.int64)
    nu = iu1 - iu0 + 1
    nv = iv1 - iv0 + 1
    ax, ay = pu[:, 0], pv[:, 0]
    bx, by = pu[:, 1], pv[:, 1]
    cx, cy = pu[:, 2], pv[:, 2]
    area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    keep = (nu > 0) & (nv > 0) & (np.abs(area) > 1e-12)
    idx = np.flatnonzero(keep)
    ax, ay, bx, by, cx, cy, area = (a[idx] for a in (ax, ay, bx, by, cx, cy, area))
    # b0(x, y) = ((bx-x)(cy-y) - (by-y)(cx-x)) / area, b1 likewise with (c, a); b2 = 1 - b0 - b1.
    b0 = np.stack([(by - cy), (cx - bx), bx * cy - by * cx], axis=1) / area[:, None]
    b1 = np.stack([(cy - ay), (ax - cx), cx * ay - cy * ax], axis=1) / area[:, None]
    w = tri[idx][:, :, axis]
    # Depth plane: w(x, y) = w0·b0 + w1·b1 + w2·(1 - b0 - b1).
    dw0 = (w[:, 0] - w[:, 2])[:, None]
    dw1 = (w[:, 1] - w[:, 2])[:, None]
    plane = dw0 * b0 + dw1 * b1
    plane[:, 2] += w[:, 2]
    return {
        "face": idx,
        "iu0": iu0[idx],
        "iv0": iv0[idx],
        "nu": nu[idx],
        "count": (nu * nv)[idx],
        "b0": b0,
        "b1": b1,
        "plane": plane,
    }


def _candidates(setup: dict[str, np.ndarray], start: int, stop: int) -> tuple[np.ndarray, ...]:
    """Test the (face, pixel) candidates of faces ``start:stop``; return the inside ones as
    (face row, iu, iv, depth)."""
    count = setup["count"][start:stop]
    rows = np.repeat(np.arange(start, stop), count)
    first = np.cumsum(count) - count
    offset = np.arange(len(rows)) - np.repeat(first, count)
    nu = setup["nu"][rows]
    iu = setup["iu0"][rows] + offset % nu
    iv = setup["iv0"][rows] + offset // nu
    x = iu.astype(np.float64)
    y = iv.astype(np.float64)
    b0c = setup["b0"][rows]
    b1c = setup["b1"][rows]
    b0 = b0c[:, 0] * x + b0c[:, 1] * y + b0c[:, 2]
    b1 = b1c[:, 0] * x + b1c[:, 1] * y + b1c[:, 2]
    inside = (b0 >= -EPS) & (b1 >= -EPS) & (b0 + b1 <= 1.0 + EPS)
    rows, iu, iv, x, y = rows[inside], iu[inside], iv[inside], x[inside], y[inside]
    pl = setup["plane"][rows]
    depth = pl[:, 0] * x + pl[:, 1] * y + pl[:, 2]
    return rows, iu, iv, depth


def rasterize_axis(tri: np.ndarray, grid: Grid, axis: int) -> list[SlabHits]:
    """Nearest hit per (slab, pixel) seen from both sides of ``axis``: two :class:`SlabHits`."""
    setup = _face_setup(tri, grid, axis)
    parts: list[tuple[np.ndarray, ...]] = []
    cum = np.cumsum(setup["count"])
    start = 0
    total_faces = len(cum)
    while start < total_faces:
        base = cum[start - 1] if start else 0
        stop = int(np.searchsorted(cum, base + CHUNK, side="right"))
        stop = max(stop, start + 1)
        parts.append(_candidates(setup, start, stop))
        start = stop
    if parts:
        rows, iu, iv, depth = (np.concatenate(p) for p in zip(*parts, strict=True))
    else:
        rows = iu = iv = np.zeros(0, dtype=np.int64)
        depth = np.zeros(0, dtype=np.float64)
    face = setup["face"][rows]
    slab = grid.slab_of(axis, depth)
    rows_n, cols_n = grid.image_shape(axis)
    key = (slab * rows_n + iv) * cols_n + iu
    # Sort by key, then depth, then face (deterministic ties): the first of a key group is the
    # nearest hit from the low side, the last the nearest from the high side.
    order = np.lexsort((face, depth, key))
    key = key[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if len(key) else key
    ends = np.r_[starts[1:], len(key)] - 1 if len(key) else key
    out = []
    for sign, pick in ((1, order[starts]), (-1, order[ends])):
        out.append(
            SlabHits(
                axis=axis,
                sign=sign,
                slab=slab[pick],
                iu=iu[pick],
                iv=iv[pick],
                depth=depth[pick],
                face=face[pick],
            )
        )
    return out
