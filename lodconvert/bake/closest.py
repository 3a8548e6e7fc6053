"""Distances from points to triangles in a compiled loop (numba): what a simplified far mesh's
colour matching measures (:mod:`.qem`), as trimesh's ``closest_point`` finds the nearest point
(Ericson's regions, its tolerance and its order of operations) without its temporaries."""

from __future__ import annotations

import math

import numpy as np

from ..compiled import compiled

ZERO = 1e-13
"""What trimesh's tolerance counts as zero."""


@compiled
def distances(triangles: np.ndarray, near: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The distance ((n, k)) from each of ``points`` ((n, 3)) to each of its triangles: row
    ``i`` of ``near`` ((n, k)) numbers them in ``triangles`` ((m, 3, 3))."""
    out = np.empty(near.shape)
    for i in range(near.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        for j in range(near.shape[1]):
            t = triangles[near[i, j]]
            qx, qy, qz = _closest(
                t[0, 0], t[0, 1], t[0, 2], t[1, 0], t[1, 1], t[1, 2], t[2, 0], t[2, 1], t[2, 2],
                px, py, pz,
            )  # fmt: skip
            dx, dy, dz = qx - px, qy - py, qz - pz
            out[i, j] = math.sqrt(dx * dx + dy * dy + dz * dz)
    return out


@compiled
def _closest(
    ax: float, ay: float, az: float, bx: float, by: float, bz: float,
    cx: float, cy: float, cz: float, px: float, py: float, pz: float,
) -> tuple[float, float, float]:  # fmt: skip
    """The point of triangle ``a``, ``b``, ``c`` nearest to ``p``."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if abx == 0.0 and aby == 0.0 and abz == 0.0:  # the segment AC, or a point
        length = acx * acx + acy * acy + acz * acz
        f = (apx * acx + apy * acy + apz * acz) / length if length > 0.0 else 0.0
        f = min(max(f, 0.0), 1.0)
        return ax + f * acx, ay + f * acy, az + f * acz
    if d1 < ZERO and d2 < ZERO:
        return ax, ay, az
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 > -ZERO and d4 <= d3:
        return bx, by, bz
    vc = d1 * d4 - d3 * d2
    if vc < ZERO and d1 > -ZERO and d3 < ZERO:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 > -ZERO and d5 <= d6:
        return cx, cy, cz
    vb = d5 * d2 - d1 * d6
    if vb < ZERO and d2 > -ZERO and d6 < ZERO:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz
    va = d3 * d6 - d5 * d4
    if va < ZERO and d4 - d3 > -ZERO and d5 - d6 > -ZERO:
        d43 = d4 - d3
        w = d43 / (d43 + (d5 - d6))
        return bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz)
    denom = 1.0 / (va + vb + vc)
    v, w = vb * denom, vc * denom
    return ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w
