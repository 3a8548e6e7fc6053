"""Hole filling on slab images, as in the PCD paper (OpenCV's 3×3 median and Gaussian blurs,
evaluated exactly on the pixels next to covered ones, so that time follows the hits).

Each (direction, slab) image is a coverage mask. The median filter (3×3) marks a pixel covered
when most of its neighbourhood is; the Gaussian filter (3×3, σ auto) when the blurred mask is at
least one half. Filters only add pixels (pinholes between points); they never remove one, so
thin features seen edge-on survive. A filled pixel takes the mean depth of its covered
neighbours and the face of its first covered neighbour (fixed order), so it lies on the local
surface and takes that surface's colour.
"""

from __future__ import annotations

import itertools
from typing import Literal

import numpy as np

from .grid import Grid, SlabHits

FilterName = Literal["median", "gaussian", "none"]
FILTERS: tuple[FilterName, ...] = ("median", "gaussian", "none")

# Neighbour offsets (dy, dx) in the fixed order used to pick a filled pixel's face.
_NEIGHBOURS = ((0, -1), (0, 1), (-1, 0), (1, 0), (-1, -1), (-1, 1), (1, -1), (1, 1))
# Per neighbour weight, and least total of the covered ones, of each filter (in 1/16 for the
# Gaussian: 2 for the 4 edge neighbours, 1 for the corners, 8 for one half).
_WEIGHTS = {"median": (1,) * 8, "gaussian": (2, 2, 2, 2, 1, 1, 1, 1)}
_THRESHOLD = {"median": 5, "gaussian": 8}


def _filled(
    mask: np.ndarray, kind: FilterName, y: np.ndarray, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns (row-major) of the pixels the filter adds to the padded image ``mask``
    (uint8 0/255) whose covered pixels are ``y``, ``x``. A filled pixel is an uncovered one next
    to a covered one, so only those are tested, with the filters' exact 3×3 weights: the median
    of a binary 3×3 is set when at least 5 of the 9 are, the Gaussian (σ auto: 1/4, 1/2, 1/4
    per axis) when the weights of the covered neighbours add up to at least 1/2."""
    rows, cols = mask.shape
    near = np.sort(np.concatenate([(y + dy) * cols + (x + dx) for dy, dx in _NEIGHBOURS]))
    near = near[np.r_[True, near[1:] != near[:-1]]]
    ny, nx = np.divmod(near, cols)
    # the one-pixel padding ring is outside the image
    keep = (ny > 0) & (ny < rows - 1) & (nx > 0) & (nx < cols - 1)
    ny, nx = ny[keep], nx[keep]
    ny, nx = ny[mask[ny, nx] == 0], nx[mask[ny, nx] == 0]
    score = np.zeros(len(ny), dtype=np.int64)
    for (dy, dx), weight in zip(_NEIGHBOURS, _WEIGHTS[kind], strict=True):
        score += weight * (mask[ny + dy, nx + dx] > 0)
    grown = score >= _THRESHOLD[kind]
    return ny[grown], nx[grown]


def fill_holes(hits: SlabHits, grid: Grid, kind: FilterName) -> SlabHits:
    """``hits`` plus the pixels the hole filter adds in each slab image."""
    if kind == "none" or len(hits) == 0:
        return hits
    rows, cols = grid.image_shape(hits.axis)
    order = np.argsort(hits.slab, kind="stable")
    slab_sorted = hits.slab[order]
    bounds = np.flatnonzero(np.r_[True, slab_sorted[1:] != slab_sorted[:-1], True])
    added: list[tuple[np.ndarray, ...]] = []
    mask = np.zeros((rows + 2, cols + 2), dtype=np.uint8)
    depth = np.zeros((rows + 2, cols + 2), dtype=np.float64)
    face = np.full((rows + 2, cols + 2), -1, dtype=np.int64)
    for a, b in itertools.pairwise(bounds):
        sel = order[a:b]
        y = hits.iv[sel] + 1
        x = hits.iu[sel] + 1
        mask[y, x] = 255
        depth[y, x] = hits.depth[sel]
        face[y, x] = hits.face[sel]
        new_y, new_x = _filled(mask, kind, y, x)
        if len(new_y):
            covered = np.stack([mask[new_y + dy, new_x + dx] > 0 for dy, dx in _NEIGHBOURS])
            depths = np.stack([depth[new_y + dy, new_x + dx] for dy, dx in _NEIGHBOURS])
            faces = np.stack([face[new_y + dy, new_x + dx] for dy, dx in _NEIGHBOURS])
            n = covered.sum(axis=0)
            ok = n > 0
            mean_depth = (depths * covered).sum(axis=0)[ok] / n[ok]
            first = np.argmax(covered, axis=0)[ok]
            cols_idx = np.flatnonzero(ok)
            added.append(
                (
                    np.full(ok.sum(), slab_sorted[a]),
                    new_x[ok] - 1,
                    new_y[ok] - 1,
                    mean_depth,
                    faces[first, cols_idx],
                )
            )
        mask[y, x] = 0
        face[y, x] = -1
    if not added:
        return hits
    slab, iu, iv, dep, fc = (np.concatenate(p) for p in zip(*added, strict=True))
    return SlabHits(
        axis=hits.axis,
        sign=hits.sign,
        slab=np.concatenate([hits.slab, slab]),
        iu=np.concatenate([hits.iu, iu]),
        iv=np.concatenate([hits.iv, iv]),
        depth=np.concatenate([hits.depth, dep]),
        face=np.concatenate([hits.face, fc]),
    )
