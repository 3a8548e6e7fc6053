"""Silhouettes of meshes and point clouds in perspective views, compared pixel by pixel in
compiled loops (numba): what the planner's guard counts for each view of
:mod:`lodconvert.views`.

A view is a camera at ``distance`` from the frame's origin, looking at it, with three unit
vectors: right and up in its image, and towards it. A point ``p`` lands at
``(p·right, p·up) · focal / (distance - p·towards)`` pixels, and pixel ``(r, c)`` of a view's
image has its centre at whole pixels plus a half from where the origin lands, as in a GL render
of an even number of pixels looking at the origin; every level of an object, in the same frame,
falls on the same pixels. A face covers, in each pixel row its projection crosses,
the span of pixel centres between its edges there (edges inclusive, faces seen edge-on left
out); a point covers the pixel centres in the square of its size around it. The images of one
view are drawn into one byte each (the first silhouette's bit 1, the second's bit 2) and
counted, a view at a time, so that memory is one image."""

from __future__ import annotations

import math

import numba
import numpy as np

Counts = np.ndarray
"""Per view: the pixels of the first silhouette, of the second and of both ((views, 3) int64)."""


@numba.njit(cache=True, nogil=True)
def _project(
    positions: np.ndarray, basis: np.ndarray, distance: float, focal: float
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (u, v) of ``positions`` seen from ``distance`` along ``basis[2]``
    (``basis``: right, up, towards the camera), ``focal`` pixels of focal length."""
    n = positions.shape[0]
    u = np.empty(n)
    v = np.empty(n)
    for i in range(n):
        x, y, z = positions[i, 0], positions[i, 1], positions[i, 2]
        scale = focal / (distance - (x * basis[2, 0] + y * basis[2, 1] + z * basis[2, 2]))
        u[i] = (x * basis[0, 0] + y * basis[0, 1] + z * basis[0, 2]) * scale
        v[i] = (x * basis[1, 0] + y * basis[1, 1] + z * basis[1, 2]) * scale
    return u, v


@numba.njit(cache=True, nogil=True)
def _fill_faces(
    image: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    faces: np.ndarray,
    c0: int,
    r0: int,
    bit: np.uint8,
    counts: np.ndarray,
) -> None:
    """Set ``bit`` in the pixels of ``image`` (its pixel (0, 0) at whole pixels (c0, r0)) that
    the faces cover, counting (:func:`_set`) the pixels it is new in."""
    rows, cols = image.shape
    for f in range(faces.shape[0]):
        i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0, x1, y1, x2, y2 = u[i] - c0, v[i] - r0, u[j] - c0, v[j] - r0, u[k] - c0, v[k] - r0
        if (x1 - x0) * (y2 - y0) == (x2 - x0) * (y1 - y0):
            continue  # seen edge-on
        if y1 < y0:
            x0, y0, x1, y1 = x1, y1, x0, y0
        if y2 < y1:
            x1, y1, x2, y2 = x2, y2, x1, y1
            if y1 < y0:
                x0, y0, x1, y1 = x1, y1, x0, y0
        # corners by height: edge 0-2 on one side, 0-1 then 1-2 on the other
        long_slope = (x2 - x0) / (y2 - y0)
        lower = (x1 - x0) / (y1 - y0) if y1 > y0 else 0.0
        upper = (x2 - x1) / (y2 - y1) if y2 > y1 else 0.0
        for r in range(max(math.ceil(y0 - 0.5), 0), min(math.floor(y2 - 0.5), rows - 1) + 1):
            y = r + 0.5
            a = x0 + (y - y0) * long_slope
            if y > y1:
                b = x1 + (y - y1) * upper
            elif y1 > y0:
                b = x0 + (y - y0) * lower
            else:  # on edge 0-1, level with this row
                a, b = x0, x1
            first = max(math.ceil(min(a, b) - 0.5), 0)
            last = min(math.floor(max(a, b) - 0.5), cols - 1)
            _set(image, r, first, last, bit, counts)


@numba.njit(cache=True, nogil=True)
def _fill_points(
    image: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    size: float,
    c0: int,
    r0: int,
    bit: np.uint8,
    counts: np.ndarray,
) -> None:
    """Set ``bit`` in the pixels of ``image`` whose centres lie in the squares of side ``size``
    pixels (at least one) around the points, counting as :func:`_fill_faces` does."""
    rows, cols = image.shape
    half = max(size, 1.0) / 2.0
    for i in range(u.shape[0]):
        x, y = u[i] - c0 - 0.5, v[i] - r0 - 0.5  # in pixel centres
        first = max(math.ceil(x - half - 1e-9), 0)
        last = min(math.floor(x + half + 1e-9), cols - 1)
        low = max(math.ceil(y - half - 1e-9), 0)
        high = min(math.floor(y + half + 1e-9), rows - 1)
        for r in range(low, high + 1):
            _set(image, r, first, last, bit, counts)


@numba.njit(cache=True, nogil=True)
def _set(
    image: np.ndarray, r: int, first: int, last: int, bit: np.uint8, counts: np.ndarray
) -> None:
    """Set ``bit`` in pixels ``first`` to ``last`` of row ``r``."""
    for c in range(first, last + 1):
        image[r, c] |= bit


@numba.njit(cache=True, nogil=True)
def _count(image: np.ndarray, counts: np.ndarray) -> None:
    """Count the pixels with bit 1, with bit 2 and with both into ``counts``."""
    first = second = both = 0
    for value in image.ravel():
        first += value & 1
        second += value >> 1
        both += value >> 1 & value
    counts[0], counts[1], counts[2] = first, second, both


@numba.njit(cache=True, nogil=True)
def overlap_counts(
    positions: np.ndarray,
    faces: np.ndarray,
    other: np.ndarray,
    other_faces: np.ndarray,
    point_px: float,
    bases: np.ndarray,
    distance: float,
    focal: float,
) -> np.ndarray:
    """Per view of ``bases`` ((views, 3, 3), :func:`_project`), the pixels of mesh
    (``positions``, ``faces``), of ``other`` and of both (:data:`Counts`): ``other`` is a
    mesh with ``other_faces``, or, with ``point_px`` above 0, points that many pixels wide."""
    counts = np.zeros((bases.shape[0], 3), dtype=np.int64)
    pad = math.ceil(max(point_px, 1.0) / 2.0) + 1
    buffer = np.zeros(0, dtype=np.uint8)
    for view in range(bases.shape[0]):
        u, v = _project(positions, bases[view], distance, focal)
        ou, ov = _project(other, bases[view], distance, focal)
        if u.shape[0] + ou.shape[0] == 0:
            continue
        lo_u, hi_u, lo_v, hi_v = math.inf, -math.inf, math.inf, -math.inf
        for us, vs in ((u, v), (ou, ov)):
            if us.shape[0]:
                lo_u, hi_u = min(lo_u, us.min()), max(hi_u, us.max())
                lo_v, hi_v = min(lo_v, vs.min()), max(hi_v, vs.max())
        c0, r0 = math.floor(lo_u) - pad, math.floor(lo_v) - pad
        cols = math.floor(hi_u) + pad + 1 - c0
        rows = math.floor(hi_v) + pad + 1 - r0
        if buffer.shape[0] < rows * cols:
            buffer = np.zeros(rows * cols, dtype=np.uint8)
        else:
            buffer[: rows * cols] = 0
        image = buffer[: rows * cols].reshape(rows, cols)
        _fill_faces(image, u, v, faces, c0, r0, np.uint8(1), counts[view])
        if point_px > 0.0:
            _fill_points(image, ou, ov, point_px, c0, r0, np.uint8(2), counts[view])
        else:
            _fill_faces(image, ou, ov, other_faces, c0, r0, np.uint8(2), counts[view])
        _count(image, counts[view])
    return counts
