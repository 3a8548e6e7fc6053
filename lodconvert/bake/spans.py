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
out); a point covers the pixel centres in the square of its size around it. Each silhouette is
drawn a bit a pixel, 64 pixels a word (a span sets a mask in a word or two), and the two are
counted word by word, a view at a time, so that memory is two images of one view."""

from __future__ import annotations

import math

import numpy as np

from ..compiled import compiled

Counts = np.ndarray
"""Per view: the pixels of the first silhouette, of the second and of both ((views, 3) int64)."""


@compiled
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


STOP_MARGIN = 1e-9
"""How far below the F asked for a view's F must be for :func:`counts_against` to stop: F
computed another way (precision and recall first) cannot round back above it."""
ALL = np.uint64(0xFFFFFFFFFFFFFFFF)
"""A word of 64 pixels, all set."""


@compiled
def _fill_faces(bits: np.ndarray, u: np.ndarray, v: np.ndarray, faces: np.ndarray) -> None:
    """Set the pixels of ``bits`` (rows of 64-pixel words) that the faces cover (``u``, ``v``:
    pixel coordinates from the image's corner)."""
    rows, cols = bits.shape[0], bits.shape[1] * 64
    for f in range(faces.shape[0]):
        i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0, x1, y1, x2, y2 = u[i], v[i], u[j], v[j], u[k], v[k]
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
            _span(bits, r, first, last)


@compiled
def _fill_points(bits: np.ndarray, u: np.ndarray, v: np.ndarray, size: float) -> None:
    """Set the pixels of ``bits`` whose centres lie in the squares of side ``size`` pixels (at
    least one) around the points."""
    rows, cols = bits.shape[0], bits.shape[1] * 64
    half = max(size, 1.0) / 2.0
    for i in range(u.shape[0]):
        x, y = u[i] - 0.5, v[i] - 0.5  # in pixel centres
        first = max(math.ceil(x - half - 1e-9), 0)
        last = min(math.floor(x + half + 1e-9), cols - 1)
        for r in range(
            max(math.ceil(y - half - 1e-9), 0), min(math.floor(y + half + 1e-9), rows - 1) + 1
        ):
            _span(bits, r, first, last)


@compiled
def _span(bits: np.ndarray, r: int, first: int, last: int) -> None:
    """Set pixels ``first`` to ``last`` of row ``r`` (none where ``last`` is before ``first``):
    a mask a word."""
    if last < first:
        return
    for w in range(first >> 6, (last >> 6) + 1):
        low = max(first - (w << 6), 0)
        high = min(last - (w << 6), 63)
        bits[r, w] |= (ALL >> np.uint64(63 - high + low)) << np.uint64(low)


@compiled
def _ones(x: np.uint64) -> int:
    """How many bits of ``x`` are set."""
    x = x - ((x >> np.uint64(1)) & np.uint64(0x5555555555555555))
    x = (x & np.uint64(0x3333333333333333)) + ((x >> np.uint64(2)) & np.uint64(0x3333333333333333))
    x = (x + (x >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return int((x * np.uint64(0x0101010101010101)) >> np.uint64(56))


@compiled
def silhouettes(
    positions: np.ndarray,
    faces: np.ndarray,
    bases: np.ndarray,
    distance: float,
    focal: float,
    margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The silhouettes of mesh (``positions``, ``faces``) in each view of ``bases``
    ((views, 3, 3), :func:`_project`): where each view's image lies (its corner's whole pixels,
    rows and words: (views, 4)) and its bits ((views, rows, words), uint64), each image the
    mesh's bounds with ``margin`` of its size more on every side (at least 2 pixels), so that
    another level drawn against it mostly falls inside (:func:`counts_against`)."""
    views = bases.shape[0]
    frames = np.zeros((views, 4), dtype=np.int64)
    for view in range(views):
        u, v = _project(positions, bases[view], distance, focal)
        if u.shape[0] == 0:
            continue
        pad = math.ceil(margin * max(u.max() - u.min(), v.max() - v.min())) + 2
        frames[view, 0] = math.floor(u.min()) - pad
        frames[view, 1] = math.floor(v.min()) - pad
        frames[view, 2] = math.floor(v.max()) + pad + 1 - frames[view, 1]
        frames[view, 3] = (math.floor(u.max()) + pad + 1 - frames[view, 0] + 63) // 64
    bits = np.zeros((views, frames[:, 2].max(), frames[:, 3].max()), dtype=np.uint64)
    for view in range(views):
        if frames[view, 2]:
            u, v = _project(positions, bases[view], distance, focal)
            u -= frames[view, 0]
            v -= frames[view, 1]
            _fill_faces(bits[view, : frames[view, 2], : frames[view, 3]], u, v, faces)
    return frames, bits


@compiled
def counts_against(
    frames: np.ndarray,
    bits: np.ndarray,
    other: np.ndarray,
    other_faces: np.ndarray,
    point_px: float,
    bases: np.ndarray,
    distance: float,
    focal: float,
    stop_below: float,
) -> np.ndarray:
    """Per view, the pixels of the silhouette (``frames``, ``bits``: :func:`silhouettes`), of
    ``other`` and of both (:data:`Counts`): ``other`` is a mesh with ``other_faces``, or, with
    ``point_px`` above 0, points that many pixels wide. -1 in a view whose image ``other`` does
    not fit in (to be drawn apart, :func:`overlap_counts`). Once a view's F (``2·both /
    (first + second)``) is below ``stop_below`` (by more than :data:`STOP_MARGIN`), the views
    after it are not drawn: -2 in each."""
    views = bases.shape[0]
    counts = np.zeros((views, 3), dtype=np.int64)
    half = max(point_px, 1.0) / 2.0 + 1.0 if point_px > 0.0 else 0.0
    for view in range(views):
        c0, r0, rows, words = frames[view, 0], frames[view, 1], frames[view, 2], frames[view, 3]
        ou, ov = _project(other, bases[view], distance, focal)
        if ou.shape[0] and (
            ou.min() - half < c0
            or ov.min() - half < r0
            or ou.max() + half >= c0 + words * 64
            or ov.max() + half >= r0 + rows
        ):
            counts[view, 0] = -1
            continue
        ou -= c0
        ov -= r0
        second = _other_drawn(rows, words, ou, ov, other_faces, point_px)
        _count(bits[view, :rows, :words], second, counts[view])
        seen = counts[view, 0] + counts[view, 1]
        if seen and 2.0 * counts[view, 2] / seen < stop_below - STOP_MARGIN:
            counts[view + 1 :, 0] = -2
            break
    return counts


@compiled
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
        words = (math.floor(hi_u) + pad + 1 - c0 + 63) // 64
        rows = math.floor(hi_v) + pad + 1 - r0
        for us, vs in ((u, v), (ou, ov)):  # from the image's corner, on whole pixels
            us -= c0
            vs -= r0
        first = np.zeros((rows, words), dtype=np.uint64)
        _fill_faces(first, u, v, faces)
        _count(first, _other_drawn(rows, words, ou, ov, other_faces, point_px), counts[view])
    return counts


@compiled
def _other_drawn(
    rows: int, words: int, u: np.ndarray, v: np.ndarray, faces: np.ndarray, point_px: float
) -> np.ndarray:
    """The silhouette ((rows, words) bits) of a mesh with ``faces``, or, with ``point_px``
    above 0, of points that many pixels wide, at pixel coordinates ``u``, ``v``."""
    bits = np.zeros((rows, words), dtype=np.uint64)
    if point_px > 0.0:
        _fill_points(bits, u, v, point_px)
    else:
        _fill_faces(bits, u, v, faces)
    return bits


@compiled
def _count(first: np.ndarray, second: np.ndarray, counts: np.ndarray) -> None:
    """Add the pixels of silhouette ``first``, of ``second`` and of both (same shape) to
    ``counts``."""
    for r in range(first.shape[0]):
        for w in range(first.shape[1]):
            counts[0] += _ones(first[r, w])
            counts[1] += _ones(second[r, w])
            counts[2] += _ones(first[r, w] & second[r, w])
