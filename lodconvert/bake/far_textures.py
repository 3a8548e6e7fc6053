"""A far level's own texture, baked from the textured geometry it stands for at the resolution
it is seen at (:func:`in_source_textures`): LOD1 and block proxies over textured buildings.
How, and what it measures: ``docs/textures.md``."""

from __future__ import annotations

import math

import numpy as np

from ..colors import linear_rgba, srgb_rgba
from ..model import Mesh, Surface
from ..textures import ATLAS_SIZE, PADDING, Atlas, packed

MARGIN_PX = 1.0
"""How far (pixels at the switch-in distance) the source may lie from a chart's box and still
be seen by it."""
TEXELS_PER_PIXEL = 2.0
"""Texels a side of a baked texture per pixel of the level at its switch-in distance: what
mipmaps need to draw it there without losing what the pixels show."""
FACING = 0.1
"""How far along a chart's normal a face's normal must point for the chart to see it."""
SAMPLES = 8
"""Points a side of each baked texel where the source's texture is read (their mean in linear
light is the texel)."""
CHART_TEXELS = 256
"""The most texels a side of one chart (a flat piece of the far level); a larger piece takes
larger texels."""
GRID = 1024
"""The most squares across the grid in which boxes are paired."""
SAMPLE_BATCH = 1 << 21
"""The most candidate (sample, source face) pairs tested at once."""


def _seen_by(source: Mesh, charts: _Charts, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of a face of ``source`` and a chart that may see it: their boxes overlap, the
    chart's grown by ``margin``, and the face faces the chart's way (its normal more than
    :data:`FACING` along the chart's)."""
    triangles = source.triangles
    low, high = triangles.min(axis=1), triangles.max(axis=1)
    near, far = charts.low - margin, charts.high + margin
    face, chart = _overlapping(low, high, near, far)
    normals = source.face_normals(np.arange(len(triangles))).astype(np.float64)
    facing = np.einsum("pj,pj->p", normals[face], charts.normal[chart]) > FACING
    return face[facing], chart[facing]


def _overlapping(
    low: np.ndarray, high: np.ndarray, near: np.ndarray, far: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i, j) of boxes ``low[i]``–``high[i]`` and ``near[j]``–``far[j]`` that
    overlap, each once, in order: found among those that share a square of a grid in plan
    (its side the median of the ``near``–``far`` boxes', or larger, so that at most
    :data:`GRID` squares span them all), then tested in full."""
    if not len(low):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    corner = np.minimum(low.min(axis=0), near.min(axis=0))[:2]
    extent = float((np.maximum(high.max(axis=0), far.max(axis=0))[:2] - corner).max())
    side = max(float(np.median((far - near)[:, :2].max(axis=1))), extent / GRID, 1e-9)
    first, first_square = _squares(low, high, corner, side)
    second, second_square = _squares(near, far, corner, side)
    order = np.argsort(first_square, kind="stable")
    first, first_square = first[order], first_square[order]
    start = np.searchsorted(first_square, second_square, "left")
    counts = np.searchsorted(first_square, second_square, "right") - start
    j = np.repeat(second, counts)
    offsets = np.arange(len(j)) - np.repeat(np.cumsum(counts) - counts, counts)
    i = first[np.repeat(start, counts) + offsets]
    pairs = np.unique(i * len(near) + j)
    i, j = pairs // len(near), pairs % len(near)
    overlap = ((low[i] <= far[j]) & (high[i] >= near[j])).all(axis=1)
    return i[overlap], j[overlap]


def _squares(
    low: np.ndarray, high: np.ndarray, corner: np.ndarray, side: float
) -> tuple[np.ndarray, np.ndarray]:
    """Each box ``low``–``high`` once per square of a grid in plan (from ``corner``, ``side``
    metres) that it touches: the box, and the square's number."""
    a = np.floor((low[:, :2] - corner) / side).astype(np.int64)
    b = np.floor((high[:, :2] - corner) / side).astype(np.int64)
    span = b - a + 1
    counts = span[:, 0] * span[:, 1]
    box = np.repeat(np.arange(len(low)), counts)
    local = np.arange(len(box)) - np.repeat(np.cumsum(counts) - counts, counts)
    x = a[box, 0] + local % span[box, 0]
    y = a[box, 1] + local // span[box, 0]
    return box, x * (1 << 31) + y


def textured(mesh: Mesh) -> bool:
    """Whether a part of ``mesh`` has a texture."""
    return any(part.texture is not None and part.uv is not None for part in mesh.parts)


def in_source_textures(
    mesh: Mesh, source: Mesh, pixel: float, colours: np.ndarray | None = None
) -> Mesh:
    """``mesh`` (a far level of ``source``, in its frame, seen from where a pixel spans
    ``pixel`` metres; ``colours``: RGBA per face where none of ``source`` lies under it, its
    own by default) with a texture of its own baked from ``source``'s, or itself where
    ``source`` has no texture (or ``mesh`` no face). Every flat connected piece (a chart) is drawn,
    :data:`TEXELS_PER_PIXEL` texels a pixel, as ``source`` looks from outside straight at it:
    each texel the mean, in linear light, of the colours at :data:`SAMPLES` × :data:`SAMPLES`
    points, each of the outermost face there no more than a pixel in front of the chart, of
    those it may see (:func:`_seen_by`); a texel under none the mean of its chart's others, a
    chart under none its first face's colour. The charts are packed into one texture
    (:func:`_squarest`)."""
    if not textured(source) or not mesh.face_count:
        return mesh
    faces = np.arange(mesh.face_count)
    colours = mesh.face_colors(faces) if colours is None else colours
    normals = mesh.face_normals(faces).astype(np.float64)
    charts = _charts(mesh, normals)
    frames = _Charts(mesh.triangles, normals, charts, pixel / TEXELS_PER_PIXEL)
    face, chart = _seen_by(source, frames, MARGIN_PX * pixel)
    images = frames.images(source, face, chart, colours, front=pixel)
    uv = frames.coordinates(mesh.triangles, charts)
    atlas = _squarest(images)
    uv = atlas.coordinates(np.repeat(charts, 3), uv.reshape(-1, 2)).reshape(-1, 3, 2)
    photographic = any(p.photographic for p in source.parts if p.texture is not None)
    parts = []
    for page, texture in enumerate(atlas.pages):
        on_page = np.flatnonzero(np.array(atlas.page_of)[charts] == page)
        corners = mesh.triangles[on_page].reshape(-1, 3)
        parts.append(
            Surface(
                corners,
                np.arange(len(corners)).reshape(-1, 3),
                uv=uv[on_page].reshape(-1, 2),
                texture=texture,
                photographic=photographic,
            )
        )
    return Mesh([_welded(part) for part in parts])


def _squarest(images: list[np.ndarray]) -> Atlas:
    """``images`` packed on the smallest square page that holds them all (from the side of
    their padded area), or on pages of :data:`~lodconvert.textures.ATLAS_SIZE` texels."""
    area = sum((i.shape[0] + 2 * PADDING) * (i.shape[1] + 2 * PADDING) for i in images)
    side = max(64, 1 << math.isqrt(max(area - 1, 0)).bit_length())
    while side < ATLAS_SIZE:
        atlas = packed(images, side)
        if len(atlas.pages) == 1:
            return atlas
        side *= 2
    return packed(images, ATLAS_SIZE)


def _welded(part: Surface) -> Surface:
    """``part`` with one vertex per position and texture coordinate."""
    keys = np.column_stack([part.vertices, part.uv])
    _, first, corners = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return Surface(
        part.vertices[first],
        corners.reshape(-1)[part.faces],
        uv=part.uv[first],
        texture=part.texture,
        photographic=part.photographic,
    )


def _charts(mesh: Mesh, normals: np.ndarray) -> np.ndarray:
    """The chart of each face of ``mesh``: faces in one plane (normals to a thousandth, offsets
    to the centimetre) joined by an edge share one."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    triangles = mesh.triangles
    offsets = np.einsum("ij,ij->i", triangles[:, 0], normals)
    planes = np.column_stack([np.round(normals, 3), np.round(offsets, 2)])
    plane = _row_ids(planes)
    corner = _row_ids(triangles.reshape(-1, 3)).reshape(-1, 3)
    edges = np.sort(np.concatenate([corner[:, [0, 1]], corner[:, [1, 2]], corner[:, [2, 0]]]), 1)
    owner = np.tile(np.arange(len(triangles)), 3)
    points = int(corner.max()) + 1
    keys = (edges[:, 0] * points + edges[:, 1]) * (int(plane.max()) + 1) + plane[owner]
    _, edge = np.unique(keys, return_inverse=True)
    edge = edge.reshape(-1)
    count = len(triangles)
    links = coo_matrix(
        (np.ones(len(owner)), (owner, edge + count)), shape=(count + edge.max() + 1,) * 2
    )
    _, labels = connected_components(links, directed=False)
    _, chart = np.unique(labels[:count], return_inverse=True)  # numbered by first face
    return chart.reshape(-1)


def _row_ids(rows: np.ndarray) -> np.ndarray:
    """For each of ``rows`` (float64), the number of its value among the distinct rows."""
    raw = np.ascontiguousarray(rows, dtype=np.float64) + 0.0  # -0.0 is 0.0
    whole = raw.view(np.dtype((np.void, raw.itemsize * raw.shape[1])))
    return np.unique(whole, return_inverse=True)[1].reshape(-1)


class _Charts:
    """The flat pieces of a far level (charts): each one's plane axes (``u``, ``v``, its
    ``normal``), box (``low``, ``high``), the corner of the rectangle its faces cover in its
    plane (``origin``), its texel side (at least the one asked for, :data:`CHART_TEXELS` at
    most a side) and ``size`` in texels."""

    def __init__(
        self, triangles: np.ndarray, normals: np.ndarray, charts: np.ndarray, texel: float
    ) -> None:
        count = int(charts.max()) + 1
        normal = np.stack([np.bincount(charts, normals[:, k], count) for k in range(3)], 1)
        self.normal = normal / np.linalg.norm(normal, axis=1, keepdims=True)
        axis = np.eye(3)[np.argmin(np.abs(self.normal), axis=1)]
        across = np.cross(axis, self.normal)
        self.u = across / np.linalg.norm(across, axis=1, keepdims=True)
        self.v = np.cross(self.normal, self.u)
        along = [np.einsum("mkj,mj->mk", triangles, axes[charts]) for axes in (self.u, self.v)]
        low = np.full((count, 2), np.inf)
        high = np.full((count, 2), -np.inf)
        for k, values in enumerate(along):
            np.minimum.at(low[:, k], charts, values.min(axis=1))
            np.maximum.at(high[:, k], charts, values.max(axis=1))
        self.low, self.high = np.full((count, 3), np.inf), np.full((count, 3), -np.inf)
        np.minimum.at(self.low, charts, triangles.min(axis=1))
        np.maximum.at(self.high, charts, triangles.max(axis=1))
        _, first = np.unique(charts, return_index=True)
        offset = np.einsum("mj,mj->m", triangles[first, 0], self.normal)
        self.origin = low[:, :1] * self.u + low[:, 1:] * self.v + offset[:, None] * self.normal
        extent = high - low
        self.texel = np.maximum(texel, extent.max(axis=1) / CHART_TEXELS)
        self.size = np.maximum(np.ceil(extent / self.texel[:, None] - 1e-9), 1).astype(np.int64)
        self.first = first

    def coordinates(self, triangles: np.ndarray, charts: np.ndarray) -> np.ndarray:
        """Texture coordinates (m, 3, 2) of ``triangles`` in their ``charts``' images."""
        rel = triangles - self.origin[charts][:, None]
        flat = np.stack([np.einsum("mkj,mj->mk", rel, a[charts]) for a in (self.u, self.v)], -1)
        return flat / (self.size * self.texel[:, None])[charts][:, None]

    def images(
        self,
        source: Mesh,
        faces: np.ndarray,
        charts: np.ndarray,
        colours: np.ndarray,
        front: float,
    ) -> list[np.ndarray]:
        """Each chart's texels (rows from the top) as ``faces`` of ``source`` (each seen by
        the chart beside it in ``charts``) show them from outside along its normal, no more
        than ``front`` in front of it; ``colours`` (per face of the far level) where none of
        them lies under a chart."""
        texels = self.size[:, 0] * self.size[:, 1]
        starts = np.cumsum(texels) - texels
        owner = np.repeat(np.arange(len(texels)), texels)
        sums = np.zeros((int(texels.sum()), 3))
        hits = np.zeros(len(sums))
        if len(faces):
            texel, seen = self._seen(source, faces, charts, front, starts)
            linear = linear_rgba(seen)[:, :3]
            hits = np.bincount(texel, minlength=len(sums)).astype(np.float64)
            sums = np.stack([np.bincount(texel, linear[:, k], len(sums)) for k in range(3)], 1)
        chart_hits = np.bincount(owner, hits, len(texels))
        chart_sums = np.stack([np.bincount(owner, sums[:, k], len(texels)) for k in range(3)], 1)
        fallback = linear_rgba(colours[self.first])[:, :3]
        seen_any = chart_hits > 0
        fallback[seen_any] = chart_sums[seen_any] / chart_hits[seen_any, None]
        linear = np.ones((len(sums), 4))
        linear[:, :3] = fallback[owner]
        hit = hits > 0
        linear[hit, :3] = sums[hit] / hits[hit, None]
        rgba = srgb_rgba(linear)
        return [
            np.ascontiguousarray(rgba[start : start + n].reshape(h, w, 4)[::-1])
            for start, n, (w, h) in zip(starts, texels, self.size, strict=True)
        ]

    def _seen(
        self,
        source: Mesh,
        faces: np.ndarray,
        charts: np.ndarray,
        front: float,
        starts: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The texel (of all charts', each chart's from ``starts``) of each sample under a
        face of ``faces`` seen by its chart in ``charts``, and the colour of the outermost
        such face at it."""
        rel = source.triangles[faces] - self.origin[charts][:, None]
        pitch = (self.texel / SAMPLES)[charts][:, None]
        flat = np.stack([np.einsum("pkj,pj->pk", rel, a[charts]) for a in (self.u, self.v)], -1)
        flat = flat / pitch[..., None] - 0.5
        depth = np.einsum("pkj,pj->pk", rel, self.normal[charts])
        limits = (self.size * SAMPLES)[charts]
        low = np.clip(np.ceil(flat.min(axis=1)), 0, limits).astype(np.int64)
        high = np.clip(np.floor(flat.max(axis=1)) + 1, 0, limits).astype(np.int64)
        span = np.maximum(high - low, 0)
        counts = span[:, 0] * span[:, 1]
        found: list[tuple[np.ndarray, ...]] = []
        start = 0
        ends = np.cumsum(counts)
        while start < len(faces):
            done = ends[start - 1] if start else 0
            stop = max(start + 1, int(np.searchsorted(ends, done + SAMPLE_BATCH, "right")))
            stop = min(stop, len(faces))
            found.append(_inside(flat, depth, low, span, counts, start, stop))
            start = stop
        which, x, y, bary, at = (np.concatenate(parts) for parts in zip(*found, strict=True))
        behind = at <= front
        which, x, y, bary, at = which[behind], x[behind], y[behind], bary[behind], at[behind]
        chart = charts[which]
        width = (self.size[:, 0] * SAMPLES)[chart]
        sample = starts[chart] * SAMPLES * SAMPLES + y * width + x
        first = np.lexsort((-at, sample))  # the outermost face at each sample
        keep = first[np.r_[True, sample[first][1:] != sample[first][:-1]][: len(first)]]
        which, x, y, bary, chart = which[keep], x[keep], y[keep], bary[keep], chart[keep]
        points = np.einsum("kj,kjd->kd", bary, source.triangles[faces[which]])
        texel = starts[chart] + (y // SAMPLES) * self.size[chart, 0] + x // SAMPLES
        return texel, source.colors_at(faces[which], points)


def _inside(
    flat: np.ndarray,
    depth: np.ndarray,
    low: np.ndarray,
    span: np.ndarray,
    counts: np.ndarray,
    start: int,
    stop: int,
) -> tuple[np.ndarray, ...]:
    """Of faces ``start`` to ``stop`` (corners ``flat`` in sample units, ``depth`` along the
    normal; the bounding box of each from ``low``, ``span`` samples, ``counts`` in all), each
    sample inside one: the face, the sample's column and row, its barycentric coordinates and
    its depth."""
    faces = np.arange(start, stop)
    which = np.repeat(faces, counts[faces])
    firsts = np.cumsum(counts[faces]) - counts[faces]
    local = np.arange(len(which)) - np.repeat(firsts, counts[faces])
    columns = np.maximum(span[which, 0], 1)
    x = low[which, 0] + local % columns
    y = low[which, 1] + local // columns
    a, b, c = (flat[which, k] for k in range(3))
    e1, e2 = b - a, c - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    px, py = x - a[:, 0], y - a[:, 1]
    safe = np.where(det != 0, det, 1.0)
    s = (px * e2[:, 1] - py * e2[:, 0]) / safe
    t = (e1[:, 0] * py - e1[:, 1] * px) / safe
    bary = np.column_stack([1.0 - s - t, s, t])
    inside = (det != 0) & (bary >= -1e-9).all(axis=1)
    which, bary = which[inside], bary[inside]
    at = np.einsum("kj,kj->k", bary, depth[which])
    return which, x[inside], y[inside], bary, at
