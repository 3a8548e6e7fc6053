"""Texture coordinates of a triangulated polygon (:func:`polygon_coordinates`), a texture
cut to what a surface's coordinates cover (:func:`cropped`), so that a building that uses a
corner of a city's shared atlas carries that corner alone (in memory, to the workers and into
every output), and images packed into bounded atlas pages (:func:`packed`). Coordinates are
relative to the image, origin at its bottom left (as :class:`~.model.Surface` holds them)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .errors import UsageError

GUTTER = 4
"""Texels kept around what the coordinates cover: the image's own, so that filtering and
mipmaps near a face's edge still see what the source shows there."""
EDGE = 1e-3
"""How far coordinates may stray past the image's edges and still be cut to it (rounding);
coordinates further out repeat the image, which is kept whole."""


def cropped(uv: np.ndarray, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The part of ``image`` ((h, w, 4), top row first) that ``uv`` ((n, 2)) cover, with
    :data:`GUTTER` texels around, and ``uv`` in it; ``image`` and ``uv`` themselves where the
    coordinates leave the image (a repeated texture) or cover all of it."""
    low, high = uv.min(axis=0), uv.max(axis=0)
    if low.min() < -EDGE or high.max() > 1.0 + EDGE:
        return uv, image
    h, w = image.shape[:2]
    x0 = max(math.floor(low[0] * w) - GUTTER, 0)
    x1 = min(math.ceil(high[0] * w) + GUTTER, w)
    y0 = max(math.floor((1.0 - high[1]) * h) - GUTTER, 0)
    y1 = min(math.ceil((1.0 - low[1]) * h) + GUTTER, h)
    if (x0, y0, x1, y1) == (0, 0, w, h):
        return uv, image
    part = np.ascontiguousarray(image[y0:y1, x0:x1])
    u = (uv[:, 0] * w - x0) / (x1 - x0)
    v = 1.0 - ((1.0 - uv[:, 1]) * h - y0) / (y1 - y0)
    return np.column_stack([u, v]), part


def polygon_coordinates(
    vertices: np.ndarray,
    faces: np.ndarray,
    rings: Sequence[np.ndarray],
    uv: Sequence[np.ndarray | None],
) -> tuple[np.ndarray | None, str | None]:
    """The texture coordinates (n, 2) of ``vertices``, the points of a polygon's ``rings``
    (each with its coordinates ``uv``, a row per point, or None) that triangulating kept and
    ``faces`` join; or None and what is wrong with them: a vertex whose ring has none,
    coordinates that are not finite, or that cover no area. Where ``vertices`` are the rings'
    points in order without their closing ones (as triangulating keeps them), those are theirs;
    else each vertex takes the first point's at its position."""
    out = _in_order(vertices, rings, uv)
    if out is None:
        at: dict[bytes, np.ndarray] = {}
        for points, coordinates in zip(rings, uv, strict=True):
            if coordinates is not None:
                for point, pair in zip(points, coordinates, strict=True):
                    at.setdefault(point.tobytes(), pair)
        found = [at.get(point.tobytes()) for point in vertices]
        if any(each is None for each in found):
            return None, "have rings without texture coordinates"
        out = np.array(found, dtype=np.float64).reshape(-1, 2)
    fault = _fault(out, faces)
    return (out, None) if fault is None else (None, fault)


SMALL_POLYGON = 32
"""Faces of a polygon up to which its texture coordinates are checked number by number (numpy
calls cost more than that)."""


def _fault(uv: np.ndarray, faces: np.ndarray) -> str | None:
    """What is wrong with texture coordinates ``uv`` of ``faces``: numbers that are not
    finite, or no face covering any area; None when nothing is."""
    not_finite = "have texture coordinates that are not finite numbers"
    if len(faces) <= SMALL_POLYGON:
        pairs = uv.tolist()
        if not all(math.isfinite(u) and math.isfinite(v) for u, v in pairs):
            return not_finite
        area = 0.0
        for i, j, k in faces.tolist():
            (au, av), (bu, bv), (cu, cv) = pairs[i], pairs[j], pairs[k]
            area += abs((bu - au) * (cv - av) - (bv - av) * (cu - au))
    else:
        if not np.isfinite(uv).all():
            return not_finite
        corners = uv[faces]
        sides, others = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
        area = float(np.abs(sides[:, 0] * others[:, 1] - sides[:, 1] * others[:, 0]).sum())
    return None if area > 0.0 else "have texture coordinates that cover no area (a 0×0 footprint)"


def _in_order(
    vertices: np.ndarray, rings: Sequence[np.ndarray], uv: Sequence[np.ndarray | None]
) -> np.ndarray | None:
    """The texture coordinates of ``vertices`` where they are the points of ``rings`` in
    order, each ring without its closing point, and every ring has coordinates; else None."""
    if len(rings) == 1:  # most polygons: no generator
        if uv[0] is None or len(rings[0]) - 1 != len(vertices):
            return None
        points, coordinates = rings[0][:-1], uv[0][:-1]
    elif any(each is None for each in uv) or sum(len(r) - 1 for r in rings) != len(vertices):
        return None
    else:
        points = np.concatenate([ring[:-1] for ring in rings])
        coordinates = np.concatenate([each[:-1] for each in uv])  # type: ignore[index]
    if points.shape != vertices.shape or points.tobytes() != vertices.tobytes():
        return None  # the same bytes, as the vertices are told apart by position
    return np.array(coordinates, dtype=np.float64)


ATLAS_SIZE = 4096
"""Default side of an atlas page, in texels (``--atlas-size``)."""
PADDING = 4
"""Texels between two images of an atlas page, filled with each image's own edge texels, so
that filtering and the first mipmaps do not bleed one image into the next."""


@dataclass(frozen=True)
class Atlas:
    """Images packed into pages (each (h, w, 4) uint8, sides at most the atlas size); per
    image, its page and the transform of its texture coordinates into that page
    (``scale``, ``offset``: ``uv · scale + offset``)."""

    pages: tuple[np.ndarray, ...]
    page_of: tuple[int, ...]
    scale: np.ndarray
    offset: np.ndarray

    def coordinates(self, image: np.ndarray | int, uv: np.ndarray) -> np.ndarray:
        """``uv`` of image number ``image`` (one, or one per row) in its page."""
        return uv * self.scale[image] + self.offset[image]


def check_atlas_size(size: int) -> None:
    """:class:`UsageError` unless ``size`` is a power of two from 64 to 16,384 texels."""
    if not (isinstance(size, int) and 64 <= size <= 16384 and size & (size - 1) == 0):
        raise UsageError(
            f"must be a power of two from 64 to 16384 texels, got {size}", "atlas_size"
        )


def packed(images: Sequence[np.ndarray], size: int = ATLAS_SIZE) -> Atlas:
    """``images`` packed into as few pages of at most ``size`` × ``size`` texels as shelves
    allow, tallest first (ties in order, so the same images give the same pages); an image
    larger than a page (with its padding) is halved until it fits."""
    fitted = [_fitted(image, size - 2 * PADDING) for image in images]
    order = sorted(range(len(fitted)), key=lambda k: (-fitted[k].shape[0], k))
    spots: dict[int, tuple[int, int, int]] = {}
    pages: list[list[tuple[int, int, int]]] = []  # per page, its shelves: y, height, x at
    for k in order:
        h, w = fitted[k].shape[0] + 2 * PADDING, fitted[k].shape[1] + 2 * PADDING
        spots[k] = _place(pages, h, w, size)
    made = []
    for shelves in pages:
        height = _power_of_two(max(y + h for y, h, _ in shelves))
        width = _power_of_two(max(x for _, _, x in shelves))
        made.append(np.full((height, width, 4), (0, 0, 0, 255), dtype=np.uint8))  # opaque
    scale = np.zeros((len(images), 2))
    offset = np.zeros((len(images), 2))
    for k, (page, x, y) in spots.items():
        image = fitted[k]
        h, w = image.shape[:2]
        target = made[page]
        _put(target[y : y + h + 2 * PADDING, x : x + w + 2 * PADDING], image)
        height, width = target.shape[:2]
        scale[k] = (w / width, h / height)
        offset[k] = ((x + PADDING) / width, 1.0 - (y + PADDING + h) / height)
    return Atlas(tuple(made), tuple(spots[k][0] for k in range(len(images))), scale, offset)


def _put(spot: np.ndarray, image: np.ndarray) -> None:
    """Write ``image`` in the middle of ``spot``, :data:`PADDING` texels from each side, and
    its edge texels repeated out to them (as ``np.pad``'s ``edge`` mode, without its copy)."""
    h, w = image.shape[:2]
    spot[PADDING : PADDING + h, PADDING : PADDING + w] = image
    spot[:PADDING, PADDING : PADDING + w] = image[:1]
    spot[PADDING + h :, PADDING : PADDING + w] = image[-1:]
    spot[:, :PADDING] = spot[:, PADDING : PADDING + 1]
    spot[:, PADDING + w :] = spot[:, PADDING + w - 1 : PADDING + w]


def _place(
    pages: list[list[tuple[int, int, int]]], h: int, w: int, size: int
) -> tuple[int, int, int]:
    """Where an image of ``h`` × ``w`` texels (padding included) goes: page, x, y; on the
    first shelf of a page with room for it, else on a new shelf, else on a new page."""
    for page, shelves in enumerate(pages):
        for k, (y, height, x) in enumerate(shelves):
            if h <= height and x + w <= size:
                shelves[k] = (y, height, x + w)
                return page, x, y
        top = shelves[-1][0] + shelves[-1][1]
        if top + h <= size:
            shelves.append((top, h, w))
            return page, 0, top
    pages.append([(0, h, w)])
    return len(pages) - 1, 0, 0


def _fitted(image: np.ndarray, side: int) -> np.ndarray:
    """``image`` halved (2×2 means, odd edges kept) until neither side exceeds ``side``."""
    while max(image.shape[:2]) > side:
        h, w = image.shape[:2]
        padded = np.pad(image, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge").astype(np.uint16)
        image = ((padded[0::2, 0::2] + padded[1::2, 0::2] + padded[0::2, 1::2]
                  + padded[1::2, 1::2] + 2) // 4).astype(np.uint8)  # fmt: skip
    return image


def _power_of_two(n: int) -> int:
    """The least power of two at least ``n`` (mipmaps of whole halves)."""
    return 1 << max(int(n) - 1, 0).bit_length()
