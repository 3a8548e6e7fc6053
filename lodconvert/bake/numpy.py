"""CPU backend: vectorised axis-ray rasterisation with numpy.

Every pixel centre of an image plane is a ray parallel to the view axis. A triangle covers the
pixel centres inside its projection (edges inclusive, as GL's fill rule does up to ties); the
hit depth is the triangle's plane at that centre. Per slab, the nearest hit seen from each side
is what the GL backend's depth test keeps, so both backends yield the same cells.

The per-face tables (projected bounds, barycentric and depth planes in world coordinates) do
not depend on the level, so they are computed once per surface and shared by all its levels.

Memory follows the hits, not the faces: candidate (face, pixel) pairs are tested a chunk at a
time (a quarter of the working-memory budget), and each chunk is folded into the nearest hits
found so far, so that overlapping faces cost time, not memory.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from ..limits import DEFAULT_LIMITS
from ..model import Mesh
from .grid import Grid, SlabHits, distinct_triangles

CANDIDATE_BYTES = 160
"""Working memory per candidate (face, pixel) pair tested at once."""
MIN_CHUNK = 1 << 16
PROJECTED = 1 << 16
"""Faces projected at a time by :func:`_projections`."""
EPS = 1e-9
PLANE_U, PLANE_V = np.array([1, 2, 0]), np.array([2, 0, 1])
"""The image plane's (u, v) axes seen along x, y and z (:meth:`Grid.plane_axes`)."""
NEXT = PLANE_U
"""The corner after each of a triangle's three."""


class NumpyBackend:
    """Axis-ray rasteriser; needs nothing beyond numpy."""

    name = "numpy"
    renderer = "numpy axis-ray rasteriser (CPU)"

    def release(self) -> None:
        """Nothing to free (the GL backend frees its context here)."""

    def rasterize(
        self, surface: Mesh, grid: Grid, memory_bytes: int = DEFAULT_LIMITS.memory_bytes
    ) -> Iterator[SlabHits]:
        """Covered pixels of all 6 view directions (+x, -x, +y, -y, +z, -z), one at a time,
        testing at most ``memory_bytes`` worth of candidates at once."""
        for axis in range(3):
            table = surface.derived(f"numpy-axis-{axis}", lambda a=axis: face_table(surface, a))
            yield from rasterize_axis(table, grid, axis, memory_bytes)


def face_table(surface: Mesh, axis: int) -> dict[str, np.ndarray]:
    """Per distinct face not degenerate in projection along ``axis``: projected bounds and the
    planes of two barycentric coordinates and of the depth, as ``(a, b, c)`` of ``a·u + b·v +
    c``, all relative to ``centre``. Identical faces share a row: ``face`` is the first of them
    (the one nearest hits from the low side keep), ``face_last`` the last (from the high side)."""
    first, last = surface.derived("distinct", lambda: distinct_triangles(surface.triangles))
    tri = surface.triangles[first]
    u, v = Grid.plane_axes(axis)
    # Planes are set up relative to the bounding-box centre, so that coordinates far from the
    # origin (georeferenced data) keep their precision.
    centre = surface.bounds.mean(axis=0)
    pu, pv, w = tri[:, :, u] - centre[u], tri[:, :, v] - centre[v], tri[:, :, axis] - centre[axis]
    ax, bx, cx = pu[:, 0], pu[:, 1], pu[:, 2]
    ay, by, cy = pv[:, 0], pv[:, 1], pv[:, 2]
    area = _projected_area(pu, pv)
    idx = np.flatnonzero(_not_edge_on(area, surface))
    ax, ay, bx, by, cx, cy, area = (a[idx] for a in (ax, ay, bx, by, cx, cy, area))
    inv = (1.0 / area)[:, None]
    b0 = np.stack([by - cy, cx - bx, bx * cy - by * cx], axis=1) * inv
    b1 = np.stack([cy - ay, ax - cx, cx * ay - cy * ax], axis=1) * inv
    w = w[idx]
    plane = (w[:, 0] - w[:, 2])[:, None] * b0 + (w[:, 1] - w[:, 2])[:, None] * b1
    plane[:, 2] += w[:, 2]
    return {
        "centre": centre,
        "face": first[idx],
        "face_last": last[idx],
        "umin": pu[idx].min(axis=1),
        "umax": pu[idx].max(axis=1),
        "vmin": pv[idx].min(axis=1),
        "vmax": pv[idx].max(axis=1),
        "b0": b0,
        "b1": b1,
        "plane": plane,
    }


def _projected_area(pu: np.ndarray, pv: np.ndarray) -> np.ndarray:
    """Twice the signed areas of triangles with corners ``pu``, ``pv`` ((m, 3) each)."""
    return (pu[:, 1] - pu[:, 0]) * (pv[:, 2] - pv[:, 0]) - (pv[:, 1] - pv[:, 0]) * (
        pu[:, 2] - pu[:, 0]
    )


def _not_edge_on(area: np.ndarray, surface: Mesh) -> np.ndarray:
    """Which faces of ``surface`` (``area``: twice their projected areas) are not seen edge-on:
    they cover pixels."""
    extent = float(np.ptp(surface.bounds, axis=0).max())
    return np.abs(area) > 1e-15 * extent * extent


def _projections(surface: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The corners of ``surface``'s faces not seen edge-on along x, then along y, then along
    z, projected: u and v ((3, m) each: corner, face) relative to ``centre``, the bounding
    box's centre (returned last), and the axis each face is seen along (m,). Found
    :data:`PROJECTED` faces at a time, so that what it takes besides them is bounded."""
    centre = surface.bounds.mean(axis=0)
    found: list[list[tuple[np.ndarray, np.ndarray]]] = [[], [], []]  # per axis
    for start in range(0, len(surface.faces), PROJECTED):
        tri = surface.vertices[surface.faces[start : start + PROJECTED]] - centre
        side, other = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        area = side[:, PLANE_U] * other[:, PLANE_V] - side[:, PLANE_V] * other[:, PLANE_U]
        seen = _not_edge_on(area, surface)
        corners = tri.transpose(1, 2, 0)  # corner, coordinate, face
        for axis in range(3):
            face = np.flatnonzero(seen[:, axis])
            found[axis].append((corners[:, PLANE_U[axis], face], corners[:, PLANE_V[axis], face]))
    pieces = [piece for each in found for piece in each]
    axes = np.repeat(np.arange(3), [sum(u.shape[1] for u, _ in each) for each in found])
    return (
        np.concatenate([u for u, _ in pieces], axis=1),
        np.concatenate([v for _, v in pieces], axis=1),
        axes,
        centre,
    )


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


def _extremes(
    low: tuple[np.ndarray, ...], high: tuple[np.ndarray, ...]
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """Per key, the (key, depth, face) with the least (depth, face) among ``low`` and the one
    with the greatest among ``high``, both ordered by key."""
    picked = []
    for (key, depth, face), last in ((low, False), (high, True)):
        order = np.lexsort((face, depth, key))
        sorted_keys = key[order]
        change = sorted_keys[1:] != sorted_keys[:-1]
        ends = np.r_[change, True] if last else np.r_[True, change]
        pick = order[ends] if len(key) else order
        picked.append((key[pick], depth[pick], face[pick]))
    return picked[0], picked[1]


def rasterize_axis(
    table: dict[str, np.ndarray],
    grid: Grid,
    axis: int,
    memory_bytes: int = DEFAULT_LIMITS.memory_bytes,
) -> list[SlabHits]:
    """Nearest hit per (slab, pixel) seen from both sides of ``axis``: two :class:`SlabHits`.

    Candidates are tested in chunks of a quarter of ``memory_bytes``; each chunk's hits are
    folded into the nearest so far (ties go to the lower face from the low side, the higher
    from the high side, whatever the chunking)."""
    u, v = grid.plane_axes(axis)
    rows_n, cols_n = grid.image_shape(axis)
    centre = table["centre"]
    iu0, nu = _pixel_range(table["umin"], table["umax"], grid.lo[u] - centre[u], grid.pitch, cols_n)
    iv0, nv = _pixel_range(table["vmin"], table["vmax"], grid.lo[v] - centre[v], grid.pitch, rows_n)
    count = nu * nv
    live = np.flatnonzero(count)
    count = count[live]
    chunk = max(MIN_CHUNK, memory_bytes // (4 * CANDIDATE_BYTES))
    empty = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.float64), table["face"][:0])
    low = high = empty
    for part in _chunks(count, chunk):
        c = count[part]
        rows = np.repeat(live[part], c)
        offset = np.arange(len(rows)) - np.repeat(np.cumsum(c) - c, c)
        width = nu[rows]
        rows, iu, iv, depth = _candidates(
            table, rows, iu0[rows] + offset % width, iv0[rows] + offset // width, grid, axis
        )
        key = (grid.slab_of(axis, depth) * rows_n + iv) * cols_n + iu
        low, high = _extremes(
            tuple(
                np.concatenate(p) for p in zip(low, (key, depth, table["face"][rows]), strict=True)
            ),
            tuple(
                np.concatenate(p)
                for p in zip(high, (key, depth, table["face_last"][rows]), strict=True)
            ),
        )
    return [
        SlabHits(
            axis=axis,
            sign=sign,
            slab=key // (rows_n * cols_n),
            iu=key % cols_n,
            iv=(key // cols_n) % rows_n,
            depth=depth,
            face=face,
        )
        for sign, (key, depth, face) in ((1, low), (-1, high))
    ]


def _chunks(count: np.ndarray, chunk: int) -> Iterator[slice]:
    """Consecutive slices of ``count`` each summing to at most ``chunk`` (or one item)."""
    cum = np.cumsum(count)
    start = 0
    while start < len(count):
        base = cum[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(cum, base + chunk, side="right")))
        yield slice(start, stop)
        start = stop


def silhouettes(
    surfaces: Sequence[Mesh], grid: Grid, memory_bytes: int = DEFAULT_LIMITS.memory_bytes
) -> list[list[np.ndarray]]:
    """The silhouettes of each of ``surfaces`` along x, y and z: the pixels of ``grid``'s
    images ((rows, cols) bool) whose rays :func:`rasterize_axis` finds a hit on, without depths.
    Each face covers, in each pixel row its projection crosses, the span of pixel centres
    between its edges there (edges inclusive, faces seen edge-on left out). All images are
    filled at once, a quarter of ``memory_bytes`` worth of spans at a time."""
    filled, layout = _filled(surfaces, grid, memory_bytes)
    images = [filled[s : s + rows * w].reshape(rows, w)[:, : w - 1] for s, rows, w in layout]
    return [images[i : i + 3] for i in range(0, len(images), 3)]


def _edges(pu: np.ndarray, pv: np.ndarray) -> np.ndarray:
    """Per edge (edge k of a face runs from its corner k to the next) of the faces whose
    projected corners are ``pu`` and ``pv`` ((3, m) each): its lowest and highest v, its start,
    its rise in v (1 where it has none) and its run in u ((6, 3, m))."""
    after_v, after_u = pv[NEXT], pu[NEXT]
    return np.stack(
        [
            np.minimum(pv, after_v),
            np.maximum(pv, after_v),
            pv,
            np.where(pv != after_v, after_v - pv, 1.0),
            pu,
            after_u - pu,
        ]
    )


def _filled(
    surfaces: Sequence[Mesh], grid: Grid, memory_bytes: int
) -> tuple[np.ndarray, list[tuple[int, int, int]]]:
    """The silhouettes of :func:`silhouettes` laid out one after another in one flat array,
    each image's rows a column wider (that column never filled), and where each image starts
    in it with its rows and width, per surface along x, y and z."""
    projected = [s.derived("numpy-projections", lambda s=s: _projections(s)) for s in surfaces]
    shapes = [grid.image_shape(axis) for axis in range(3)]
    layout, at = [], 0
    for _ in surfaces:
        for rows, cols in shapes:
            layout.append((at, rows, cols + 1))  # a column more, where spans that reach the
            at += rows * (cols + 1)  # last one end
    start, rows_of, width = np.array(layout, dtype=np.int64).T
    chunk = max(MIN_CHUNK, memory_bytes // (4 * CANDIDATE_BYTES))
    edges = np.zeros(at, dtype=np.int64)
    for index, (pu, pv, axis, centre) in enumerate(projected):  # a surface at a time
        origin_u, origin_v = grid.lo[PLANE_U] - centre[PLANE_U], grid.lo[PLANE_V] - centre[PLANE_V]
        images = 3 * index + axis  # each face's image
        iv0, nv = _pixel_range(
            pv.min(axis=0), pv.max(axis=0), origin_v[axis], grid.pitch, rows_of[images]
        )
        live = np.flatnonzero(nv)
        count = nv[live]
        for part in _chunks(count, chunk):
            c, faces = count[part], live[part]
            local = np.repeat(np.arange(len(c)), c)
            iv = iv0[faces][local] + np.arange(len(local)) - np.repeat(np.cumsum(c) - c, c)
            seen = axis[faces][local]
            y = origin_v[seen] + (iv + 0.5) * grid.pitch
            low_v, high_v, ay, rise, ax, run = np.take(
                _edges(pu[:, faces], pv[:, faces]), local, axis=2
            )
            crosses = (low_v <= y) & (y <= high_v)
            x = ax + (y - ay) / rise * run  # (y - ay) / rise lies in [0, 1] where it crosses
            low = np.where(crosses, x, np.inf).min(axis=0)
            high = np.where(crosses, x, -np.inf).max(axis=0)
            found = low <= high
            iv, seen = iv[found], seen[found]
            cols = width[3 * index + seen]
            first, n = _pixel_range(low[found], high[found], origin_u[seen], grid.pitch, cols - 1)
            spans = n > 0
            begins = (start[3 * index + seen] + iv * cols + first)[spans]
            edges += np.bincount(begins, minlength=at)
            edges -= np.bincount(begins + n[spans], minlength=at)
    # Every span ends in its own row, so each row sums to nothing: one running sum fills all.
    return edges.cumsum() > 0, layout
