"""Hole filling on slab images (OpenCV), as in the PCD paper.

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


def _filled(mask: np.ndarray, kind: FilterName) -> np.ndarray:
    """Boolean image of the pixels the filter adds to ``mask`` (uint8 0/255)."""
    import cv2  # OpenCV loads in ~0.2 s: only when a hole filter runs

    if kind == "median":
        grown = cv2.medianBlur(mask, 3) > 0
    else:
        grown = cv2.GaussianBlur(mask.astype(np.float32) / 255.0, (3, 3), 0) >= 0.5
    grown &= mask == 0
    grown[[0, -1], :] = False  # the one-pixel padding ring is outside the image
    grown[:, [0, -1]] = False
    return grown


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
        new_y, new_x = np.nonzero(_filled(mask, kind))
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
