"""Hole filling on slab images, as in the PCD paper (OpenCV's 3×3 median and Gaussian blurs,
evaluated exactly on the pixels next to covered ones, so that time follows the hits).

Each (direction, slab) image is a coverage mask. The median filter (3×3) marks a pixel covered
when most of its neighbourhood is; the Gaussian filter (3×3, σ auto) when the blurred mask is at
least one half. Filters only add pixels (pinholes between points); they never remove one, so
thin features seen edge-on survive. A filled pixel takes the mean depth of its covered
neighbours and the face of its first covered neighbour (fixed order), so it lies on the local
surface and takes that surface's colour. The slab images of a direction are filtered together,
stacked (each in its own padding ring) up to :data:`STACK_PIXELS` pixels at a time.
"""

from __future__ import annotations

import itertools
from typing import Literal

import numpy as np

from .grid import Grid, SlabHits

FilterName = Literal["median", "gaussian", "none"]
FILTERS: tuple[FilterName, ...] = ("median", "gaussian", "none")
STACK_PIXELS = 1 << 16
"""Pixels of the slab images filtered at once (17 bytes each: coverage, depth and face): small
images go many at a time, large ones one by one, as fast as before."""

# Neighbour offsets (dy, dx) in the fixed order used to pick a filled pixel's face.
_NEIGHBOURS = ((0, -1), (0, 1), (-1, 0), (1, 0), (-1, -1), (-1, 1), (1, -1), (1, 1))
# Per neighbour weight, and least total of the covered ones, of each filter (in 1/16 for the
# Gaussian: 2 for the 4 edge neighbours, 1 for the corners, 8 for one half).
_WEIGHTS = {"median": (1,) * 8, "gaussian": (2, 2, 2, 2, 1, 1, 1, 1)}
_THRESHOLD = {"median": 5, "gaussian": 8}


def _filled(
    mask: np.ndarray, kind: FilterName, y: np.ndarray, x: np.ndarray, height: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns (row-major) of the pixels the filter adds to ``mask`` (uint8 0/255:
    padded images of ``height`` rows, the whole mask by default, stacked) whose covered pixels
    are ``y``, ``x``. A filled pixel is an uncovered one next to a covered one, so only those
    are tested, with the filters' exact 3×3 weights: the median of a binary 3×3 is set when at
    least 5 of the 9 are, the Gaussian (σ auto: 1/4, 1/2, 1/4 per axis) when the weights of
    the covered neighbours add up to at least 1/2."""
    rows, cols = mask.shape
    height = rows if height is None else height
    near = np.sort(np.concatenate([(y + dy) * cols + (x + dx) for dy, dx in _NEIGHBOURS]))
    near = near[np.r_[True, near[1:] != near[:-1]]]
    ny, nx = np.divmod(near, cols)
    # each image's one-pixel padding ring is outside it
    row = ny % height if height < rows else ny
    keep = (row > 0) & (row < height - 1) & (nx > 0) & (nx < cols - 1)
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
    height = rows + 2
    order = np.argsort(hits.slab, kind="stable")
    ordered = hits.slab[order]
    new_slab = np.r_[True, ordered[1:] != ordered[:-1]]
    slabs, image = ordered[new_slab], np.cumsum(new_slab) - 1  # in ``order``
    stacked = max(1, STACK_PIXELS // (height * (cols + 2)))
    bounds = np.searchsorted(image, np.arange(0, len(slabs) + stacked, stacked))
    mask = np.zeros((min(stacked, len(slabs)) * height, cols + 2), dtype=np.uint8)
    depth = np.zeros(mask.shape, dtype=np.float64)
    face = np.full(mask.shape, -1, dtype=np.int64)
    added: list[tuple[np.ndarray, ...]] = []
    for first, (a, b) in enumerate(itertools.pairwise(bounds)):
        sel = order[a:b]
        images = image[a:b] - first * stacked
        y = images * height + hits.iv[sel] + 1
        x = hits.iu[sel] + 1
        mask[y, x] = 255
        depth[y, x] = hits.depth[sel]
        face[y, x] = hits.face[sel]
        new_y, new_x = _filled(mask, kind, y, x, height)
        if len(new_y):
            covered = np.stack([mask[new_y + dy, new_x + dx] > 0 for dy, dx in _NEIGHBOURS])
            depths = np.stack([depth[new_y + dy, new_x + dx] for dy, dx in _NEIGHBOURS])
            faces = np.stack([face[new_y + dy, new_x + dx] for dy, dx in _NEIGHBOURS])
            summed = (depths * covered).sum(axis=0)
            slab = new_y // height
            alone = np.bincount(slab)[slab] == 1
            summed[alone] = _pairwise(depths[:, alone] * covered[:, alone])
            added.append(
                (
                    slabs[slab + first * stacked],
                    new_x - 1,
                    new_y % height - 1,
                    summed / covered.sum(axis=0),
                    faces[np.argmax(covered, axis=0), np.arange(len(new_y))],
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


def _pairwise(depths: np.ndarray) -> np.ndarray:
    """Sums of ``depths`` (8, k) over the first axis in the order numpy sums 8 contiguous
    values (pairwise), as it summed a slab image's one filled pixel alone (more than one it
    sums neighbour by neighbour, as ``sum(axis=0)`` here)."""
    d = depths
    return ((d[0] + d[1]) + (d[2] + d[3])) + ((d[4] + d[5]) + (d[6] + d[7]))
