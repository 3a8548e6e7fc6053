"""The compiled loop of a far level's texture bake (:mod:`.far_textures`): source faces drawn
into the samples of the charts that see them, the outermost kept at each."""

from __future__ import annotations

import numpy as np

from ..compiled import compiled


@compiled
def outermost(
    flat: np.ndarray,
    depth: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    base: np.ndarray,
    width: np.ndarray,
    front: float,
    pair: np.ndarray,
    bary: np.ndarray,
) -> None:
    """Draw each pair (a source face seen by a chart: its corners ``flat`` in the chart's
    sample units, ``depth`` along its normal, the samples ``low``–``high`` its box covers)
    into the samples of its chart (from ``base``, rows ``width`` long): at each sample the
    outermost pair no more than ``front`` in front (the first of equals), in ``pair``, with
    its barycentric coordinates of the second and third corners in ``bary``."""
    best = np.full(len(pair), -np.inf)
    for p in range(len(flat)):
        ax, ay = flat[p, 0, 0], flat[p, 0, 1]
        e1x, e1y = flat[p, 1, 0] - ax, flat[p, 1, 1] - ay
        e2x, e2y = flat[p, 2, 0] - ax, flat[p, 2, 1] - ay
        det = e1x * e2y - e1y * e2x
        if det == 0.0:
            continue
        for y in range(low[p, 1], high[p, 1]):
            py = y - ay
            for x in range(low[p, 0], high[p, 0]):
                px = x - ax
                s = (px * e2y - py * e2x) / det
                t = (e1x * py - e1y * px) / det
                u = 1.0 - s - t
                if u < -1e-9 or s < -1e-9 or t < -1e-9:
                    continue
                at = u * depth[p, 0] + s * depth[p, 1] + t * depth[p, 2]
                k = base[p] + y * width[p] + x
                if at <= front and at > best[k]:
                    best[k] = at
                    pair[k] = p
                    bary[k, 0] = s
                    bary[k, 1] = t
