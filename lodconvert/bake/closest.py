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
    d1, d2 = _dots(abx, aby, abz, acx, acy, acz, px - ax, py - ay, pz - az)
    if abx == 0.0 and aby == 0.0 and abz == 0.0:  # the segment AC, or a point
        length = acx * acx + acy * acy + acz * acz
        f = min(max(d2 / length if length > 0.0 else 0.0, 0.0), 1.0)
        return _step(ax, ay, az, f, acx, acy, acz)
    if d1 < ZERO and d2 < ZERO:
        return ax, ay, az
    d3, d4 = _dots(abx, aby, abz, acx, acy, acz, px - bx, py - by, pz - bz)
    done, qx, qy, qz, vc = _by_corner(bx, by, bz, ax, ay, az, abx, aby, abz, d3, d4, d1, d2)
    if done:
        return qx, qy, qz
    d5, d6 = _dots(abx, aby, abz, acx, acy, acz, px - cx, py - cy, pz - cz)
    done, qx, qy, qz, vb = _by_corner(cx, cy, cz, ax, ay, az, acx, acy, acz, d6, d5, d2, d1)
    if done:
        return qx, qy, qz
    va = d3 * d6 - d5 * d4
    if va < ZERO and d4 - d3 > -ZERO and d5 - d6 > -ZERO:
        d43 = d4 - d3
        return _step(bx, by, bz, d43 / (d43 + (d5 - d6)), cx - bx, cy - by, cz - bz)
    denom = 1.0 / (va + vb + vc)
    qx, qy, qz = _step(ax, ay, az, vb * denom, abx, aby, abz)
    return _step(qx, qy, qz, vc * denom, acx, acy, acz)


@compiled
def _by_corner(
    xx: float, xy: float, xz: float, ax: float, ay: float, az: float,
    sx: float, sy: float, sz: float, along: float, across: float, at_a: float, across_a: float,
) -> tuple[bool, float, float, float, float]:  # fmt: skip
    """The nearest point where it is corner X (B or C) of a triangle or lies on side AX
    (``s``: X - A), from the point's dot products with AX and the other side taken from X
    (``along``, ``across``) and from A (``at_a``, ``across_a``): whether found, the point,
    and the barycentric numerator of the third corner (what the inside needs)."""
    if along > -ZERO and across <= along:
        return True, xx, xy, xz, 0.0
    third = at_a * across - along * across_a
    if third < ZERO and at_a > -ZERO and along < ZERO:
        qx, qy, qz = _step(ax, ay, az, at_a / (at_a - along), sx, sy, sz)
        return True, qx, qy, qz, third
    return False, 0.0, 0.0, 0.0, third


@compiled
def _dots(
    ux: float, uy: float, uz: float, vx: float, vy: float, vz: float,
    dx: float, dy: float, dz: float,
) -> tuple[float, float]:  # fmt: skip
    """``u`` · ``d`` and ``v`` · ``d``."""
    return ux * dx + uy * dy + uz * dz, vx * dx + vy * dy + vz * dz


@compiled
def _step(
    ox: float, oy: float, oz: float, t: float, dx: float, dy: float, dz: float
) -> tuple[float, float, float]:
    """``o`` + ``t`` ``d``."""
    return ox + t * dx, oy + t * dy, oz + t * dz
