"""The compiled loops of a far level's texture bake (:mod:`.far_textures`): the pairs of a
source face and a chart whose boxes overlap (:func:`overlapping`), and source faces drawn into
the samples of the charts that see them, the outermost kept at each (:func:`outermost`)."""

from __future__ import annotations

import numpy as np

from ..compiled import compiled


@compiled
def outermost(
    triangles: np.ndarray,
    faces: np.ndarray,
    charts: np.ndarray,
    frame: np.ndarray,
    pitch: np.ndarray,
    layout: np.ndarray,
    n: int,
    front: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Draw each pair of a source face and the chart that sees it (``faces[p]`` of
    ``triangles``, ``charts[p]``) into the chart's samples, ``n`` a texel side, keeping at each
    sample the outermost face no more than ``front`` in front (the first pair of equals).
    ``frame``: per chart, its origin and its ``u``, ``v`` and normal axes ((c, 4, 3));
    ``pitch``: its sample side (metres); ``layout``: its first texel, first sample and width
    and height in texels ((c, 4)). Returns, for each sample drawn, in order: its texel, its
    pair, and its barycentric coordinates of the pair's second and third corners."""
    slots = 0
    for c in range(len(layout)):
        slots = max(slots, layout[c, 1] + layout[c, 2] * layout[c, 3] * n * n)
    best = np.full(slots, -np.inf)
    pair = np.full(slots, -1)
    bary = np.zeros((slots, 2))
    flat = np.empty((3, 2))
    depth = np.empty(3)
    for p in range(len(faces)):
        f, c = faces[p], charts[p]
        for k in range(3):
            rx = triangles[f, k, 0] - frame[c, 0, 0]
            ry = triangles[f, k, 1] - frame[c, 0, 1]
            rz = triangles[f, k, 2] - frame[c, 0, 2]
            for a in range(2):
                along = rx * frame[c, 1 + a, 0] + ry * frame[c, 1 + a, 1] + rz * frame[c, 1 + a, 2]
                flat[k, a] = along / pitch[c] - 0.5
            depth[k] = rx * frame[c, 3, 0] + ry * frame[c, 3, 1] + rz * frame[c, 3, 2]
        width = layout[c, 2] * n
        x0, x1 = _span(flat[0, 0], flat[1, 0], flat[2, 0], width)
        y0, y1 = _span(flat[0, 1], flat[1, 1], flat[2, 1], layout[c, 3] * n)
        ax, ay = flat[0, 0], flat[0, 1]
        e1x, e1y = flat[1, 0] - ax, flat[1, 1] - ay
        e2x, e2y = flat[2, 0] - ax, flat[2, 1] - ay
        det = e1x * e2y - e1y * e2x
        if det == 0.0:
            continue
        for y in range(y0, y1):
            py = y - ay
            for x in range(x0, x1):
                px = x - ax
                s = (px * e2y - py * e2x) / det
                t = (e1x * py - e1y * px) / det
                u = 1.0 - s - t
                if u < -1e-9 or s < -1e-9 or t < -1e-9:
                    continue
                at = u * depth[0] + s * depth[1] + t * depth[2]
                k = layout[c, 1] + y * width + x
                if at <= front and at > best[k]:
                    best[k] = at
                    pair[k] = p
                    bary[k, 0] = s
                    bary[k, 1] = t
    return _drawn(pair, bary, charts, layout, n)


@compiled
def _span(a: float, b: float, c: float, limit: int) -> tuple[int, int]:
    """The samples from the first to past the last whose centres (whole numbers) lie between
    the least and the greatest of ``a``, ``b`` and ``c``, within ``[0, limit)``."""
    least, most = min(min(a, b), c), max(max(a, b), c)
    top = float(limit)
    return int(min(max(np.ceil(least), 0.0), top)), int(min(max(np.floor(most) + 1.0, 0.0), top))


@compiled
def _drawn(
    pair: np.ndarray, bary: np.ndarray, charts: np.ndarray, layout: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The samples drawn (``pair`` set), in order: each one's texel (of its chart's, laid out
    by ``layout``), pair and barycentric coordinates."""
    count = 0
    for k in range(len(pair)):
        if pair[k] >= 0:
            count += 1
    texel = np.empty(count, np.int64)
    which = np.empty(count, np.int64)
    weights = np.empty((count, 2))
    i = 0
    for k in range(len(pair)):
        p = pair[k]
        if p < 0:
            continue
        c = charts[p]
        local = k - layout[c, 1]
        width = layout[c, 2] * n
        y, x = local // width, local % width
        texel[i] = layout[c, 0] + (y // n) * layout[c, 2] + x // n
        which[i] = p
        weights[i, 0], weights[i, 1] = bary[k, 0], bary[k, 1]
        i += 1
    return texel, which, weights


@compiled
def overlapping(
    low: np.ndarray, high: np.ndarray, near: np.ndarray, far: np.ndarray, facing: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i, j), in order, of boxes ``low[i]``–``high[i]`` and ``near[j]``–``far[j]``
    ((n, 3) and (m, 3)) that overlap, of those that ``facing`` ((n, m) bool) holds."""
    count = 0
    for i in range(facing.shape[0]):
        for j in range(facing.shape[1]):
            count += facing[i, j]
    first = np.empty(count, np.int64)
    second = np.empty(count, np.int64)
    found = 0
    for i in range(facing.shape[0]):
        for j in range(facing.shape[1]):
            if (
                facing[i, j]
                and low[i, 0] <= far[j, 0]
                and high[i, 0] >= near[j, 0]
                and low[i, 1] <= far[j, 1]
                and high[i, 1] >= near[j, 1]
                and low[i, 2] <= far[j, 2]
                and high[i, 2] >= near[j, 2]
            ):
                first[found] = i
                second[found] = j
                found += 1
    return first[:found], second[:found]
