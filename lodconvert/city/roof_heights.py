"""The height below which a share of a roof's area lies, its triangles' heights varying
linearly across each (:func:`area_percentile`), in compiled loops (numba): the top of a LOD1
prism (:mod:`.prisms`)."""

from __future__ import annotations

import math

import numpy as np

from ..compiled import compiled


@compiled
def _share_below(a: np.ndarray, b: np.ndarray, c: np.ndarray, w: np.ndarray, t: float) -> float:
    """The area, of triangles with ordered corner heights ``a`` ≤ ``b`` ≤ ``c`` and areas ``w``,
    that lies at or below height ``t``."""
    area = 0.0
    for i in range(a.shape[0]):
        if t >= c[i]:
            area += w[i]
        elif t <= a[i]:
            continue
        elif t <= b[i]:
            area += w[i] * (t - a[i]) ** 2 / ((b[i] - a[i]) * (c[i] - a[i]))
        else:
            area += w[i] * (1 - (c[i] - t) ** 2 / ((c[i] - a[i]) * (c[i] - b[i])))
    return area


@compiled
def area_percentile(heights: np.ndarray, weights: np.ndarray, share: float) -> float:
    """The least height below which ``share`` of the area of triangles with corner ``heights``
    ((m, 3)) and areas ``weights`` lies, heights varying linearly across each triangle. That
    area is quadratic in the height between consecutive corner heights: the interval that
    brackets ``share`` is searched for among them, and the quadratic solved there."""
    m = heights.shape[0]
    a, b, c = np.empty(m), np.empty(m), np.empty(m)  # each triangle's heights in order
    for i in range(m):
        x, y, z = heights[i, 0], heights[i, 1], heights[i, 2]
        a[i], c[i] = min(x, y, z), max(x, y, z)
        b[i] = max(min(x, y), min(max(x, y), z))
    ends = np.sort(np.concatenate((a, b, c)))
    total = weights.sum()
    if total <= 0 or ends[-1] <= ends[0]:
        return ends[-1]
    target = share * total
    first, last = 0, len(ends) - 1  # the least corner height with target below it
    while first < last:
        middle = (first + last) // 2
        if _share_below(a, b, c, weights, ends[middle]) >= target:
            last = middle
        else:
            first = middle + 1
    if first == 0:
        return ends[0]
    low, high = ends[first - 1], ends[first]
    rest = target - _share_below(a, b, c, weights, low)
    square, linear = 0.0, 0.0  # the area below low + s, less that below low: square s² + linear s
    for i in range(m):
        if a[i] <= low < b[i]:
            square += weights[i] / ((b[i] - a[i]) * (c[i] - a[i]))
            linear += 2 * weights[i] * (low - a[i]) / ((b[i] - a[i]) * (c[i] - a[i]))
        elif b[i] <= low < c[i]:
            square -= weights[i] / ((c[i] - a[i]) * (c[i] - b[i]))
            linear += 2 * weights[i] * (c[i] - low) / ((c[i] - a[i]) * (c[i] - b[i]))
    reach = linear * linear + 4 * square * rest
    if reach < 0:
        return high  # the area steps up at high
    root = linear + math.sqrt(reach)
    return min(low + 2 * rest / root, high) if root > 0 else high
