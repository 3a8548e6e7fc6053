"""A far level's own texture, baked from the textured geometry it stands for at the resolution
it is seen at (:func:`in_source_textures`): LOD1 and block proxies over textured buildings.
How, and what it measures: ``docs/textures.md``."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..colors import linear_rgba, srgb_rgba
from ..components import components
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
light is the texel); fewer where a level's texels would take more than :data:`MOST_SAMPLES`."""
MOST_SAMPLES = 1 << 22
"""The most points read for one far level's texture (memory: some 24 bytes each)."""
CHART_TEXELS = 256
"""The most texels a side of one chart (a flat piece of the far level); a larger piece takes
larger texels."""
MOST_TEXELS = 1 << 22
"""The most texels of one far level's texture (2,048² in all); a level that would take more
takes larger texels."""
BOX_BATCH = 1 << 16
"""Source faces whose boxes are made and paired with charts at once."""
TESTED_PAIRS = 1 << 24
"""The most pairs of a source face and a chart whose boxes are all tested, without a tree."""


def _seen_by(source: Mesh, charts: _Charts, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of a face of ``source`` and a chart that may see it, in order: their boxes
    overlap, the chart's grown by ``margin``, and the face faces the chart's way (its normal
    more than :data:`FACING` along the chart's)."""
    low, high = _bounds(source.triangles)
    normals = source.face_normals(np.arange(len(low))).astype(np.float64)
    near, far = charts.low - margin, charts.high + margin
    return _overlapping(_Boxes(low, high, normals), _Boxes(near, far, charts.normal))


def _bounds(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least and greatest coordinates of each of ``triangles`` ((m, 3, d)): their boxes
    (corner by corner: a reduction over an axis of three is slower)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    return np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)


class _Boxes(NamedTuple):
    """Boxes (``low``–``high``, (n, 3) each) facing ``normal`` (unit, (n, 3))."""

    low: np.ndarray
    high: np.ndarray
    normal: np.ndarray


def _overlapping(first: _Boxes, second: _Boxes) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i, j) of boxes ``first[i]`` and ``second[j]`` that overlap and face the same
    way (normals more than :data:`FACING` along each other), each once, in order: every pair
    tested, :data:`BOX_BATCH` · 16 at a time (facing by a matrix product, boxes in a compiled
    loop), where there are at most :data:`TESTED_PAIRS`;
    else the second boxes in a tree (shapely's STRtree, in plan), the first queried
    :data:`BOX_BATCH` at a time, then tested in full."""
    (low, high, normal), (near, far, towards) = first, second
    found = [(np.zeros(0, dtype=np.int64),) * 2]
    if len(low) * len(near) <= TESTED_PAIRS:
        from .texels import overlapping  # numba: loaded where a texture is baked

        step = max(1, 16 * BOX_BATCH // max(len(near), 1))
        for start in range(0, len(low), step):
            end = start + step
            facing = normal[start:end] @ towards.T > FACING
            i, j = overlapping(low[start:end], high[start:end], near, far, facing)
            found.append((i + start, j))
        i, j = (np.concatenate(parts) for parts in zip(*found, strict=True))
        return i, j
    import shapely

    tree = shapely.STRtree(shapely.box(near[:, 0], near[:, 1], far[:, 0], far[:, 1]))
    for start in range(0, len(low), BOX_BATCH):
        lo, hi = low[start : start + BOX_BATCH], high[start : start + BOX_BATCH]
        i, j = tree.query(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
        i += start
        kept = ((low[i] <= far[j]) & (high[i] >= near[j])).all(axis=1)
        kept &= np.einsum("pj,pj->p", normal[i], towards[j]) > FACING
        found.append((i[kept], j[kept]))
    i, j = (np.concatenate(parts) for parts in zip(*found, strict=True))
    order = np.lexsort((j, i))
    return i[order], j[order]


def _textured(mesh: Mesh) -> bool:
    """Whether a part of ``mesh`` has a texture."""
    return any(part.texture is not None and part.uv is not None for part in mesh.parts)


def in_source_textures(mesh: Mesh, source: Mesh, pixel: float) -> Mesh:
    """``mesh`` (a far level of ``source``, in its frame, seen from where a pixel spans
    ``pixel`` metres) with a texture of its own baked from ``source``'s, or itself where
    ``source`` has no texture (or ``mesh`` no face). Every flat connected piece (a chart) is drawn,
    :data:`TEXELS_PER_PIXEL` texels a pixel, as ``source`` looks from outside straight at it:
    each texel the mean, in linear light, of the colours at :data:`SAMPLES` × :data:`SAMPLES`
    points, each of the outermost face there no more than a pixel in front of the chart, of
    those it may see (:func:`_seen_by`); a texel under none the mean of its chart's others, a
    chart under none its first face's colour. The charts are packed into one texture
    (:func:`_squarest`)."""
    if not _textured(source) or not mesh.face_count:
        return mesh
    faces = np.arange(mesh.face_count)
    normals = mesh.face_normals(faces).astype(np.float64)
    charts = _charts(mesh, normals)
    frames = _Charts(mesh.triangles, normals, charts, pixel / TEXELS_PER_PIXEL)
    face, chart = _seen_by(source, frames, MARGIN_PX * pixel)
    own = mesh.face_colors(frames.first)
    images = frames.images(source, face, chart, own, front=pixel)
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
    """``part`` with one vertex per position and texture coordinate, in the order of those
    rows (as ``np.unique(axis=0)`` gives them, found by a sort of the columns: faster)."""
    keys = np.column_stack([part.vertices, part.uv])
    order = np.lexsort(keys.T[::-1])  # stable: each row's first copy first
    ranked = keys[order]
    new = np.ones(len(keys), dtype=bool)
    new[1:] = (ranked[1:] != ranked[:-1]).any(axis=1)
    first = order[new]
    corners = np.empty(len(keys), dtype=np.int64)
    corners[order] = np.cumsum(new) - 1
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
    count = len(triangles)
    links = np.stack([owner, edge.reshape(-1) + count])  # each face to its edges
    return components(links, count + int(edge.max()) + 1)[:count]  # numbered by first face


def _row_ids(rows: np.ndarray) -> np.ndarray:
    """For each of ``rows`` (float64), the number of its value among the distinct rows."""
    raw = np.ascontiguousarray(rows, dtype=np.float64) + 0.0  # -0.0 is 0.0
    whole = raw.view(np.dtype((np.void, raw.itemsize * raw.shape[1])))
    return np.unique(whole, return_inverse=True)[1].reshape(-1)


def _texels(extent: np.ndarray, texel: np.ndarray) -> np.ndarray:
    """How many texels of ``texel`` metres (one per chart) a side cover charts of ``extent``
    ((k, 2) metres): at least one."""
    return np.maximum(np.ceil(extent / texel[:, None] - 1e-9), 1).astype(np.int64)


class _Charts:
    """The flat pieces of a far level (charts): each one's plane axes (``u``, ``v``, its
    ``normal``), box (``low``, ``high``), the corner of the rectangle its faces cover in its
    plane (``origin``), its texel side (at least the one asked for, :data:`CHART_TEXELS` at
    most a side, :data:`MOST_TEXELS` in all) and ``size`` in texels."""

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
        self.size = _texels(extent, self.texel)
        total = int((self.size[:, 0] * self.size[:, 1]).sum())
        if total > MOST_TEXELS:  # larger texels, all alike
            self.texel = self.texel * math.sqrt(total / MOST_TEXELS)
            self.size = _texels(extent, self.texel)
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
        own: np.ndarray,
        front: float,
    ) -> list[np.ndarray]:
        """Each chart's texels (rows from the top) as ``faces`` of ``source`` (each seen by
        the chart beside it in ``charts``) show them from outside along its normal, no more
        than ``front`` in front of it; ``own`` (RGBA per chart, its first face's colour)
        where none of them lies under a chart."""
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
        fallback = linear_rgba(own)[:, :3]
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
        texels = int((self.size[:, 0] * self.size[:, 1]).sum())
        n = max(1, min(SAMPLES, math.isqrt(MOST_SAMPLES // texels)))  # points a texel side
        frame = np.stack([self.origin, self.u, self.v, self.normal], axis=1)
        layout = np.column_stack([starts, starts * n * n, self.size])
        from .texels import outermost  # numba: loaded where a texture is baked

        triangles = np.ascontiguousarray(source.triangles, dtype=np.float64)
        texel, which, drawn = outermost(
            triangles, faces, charts, frame, self.texel / n, layout, n, front
        )
        s, t = drawn.T
        weights = np.clip(np.column_stack([1.0 - s - t, s, t]), 0.0, 1.0)
        weights /= weights.sum(axis=1, keepdims=True)
        return texel, source.colors_at(faces[which], None, weights)
