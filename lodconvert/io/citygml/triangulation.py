"""The triangles of a batch of CityGML objects (:func:`triangulate_batch`): the polygons of
its holders, each once (:func:`_kept`), triangulated together so that the per-polygon work runs
as array operations over thousands of polygons instead of a few dozen, into one checked
:class:`Surface` per LoD and semantic type; a ``Tin`` given by its control points alone is
triangulated in plan.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...model import Surface
from ...model.geometry import WHITE
from ...polygons import Triangles, points_surface, triangulate_many
from ...semantics import Palette
from ...textures import cropped, polygon_coordinates
from ..crs import Crs
from ..geometry_checks import InputTally, faces_with_area
from ..images import Images
from .coordinates import in_metres
from .holders import Holder, Polygon

TRIANGULATED = 4096
"""Polygons triangulated together at most, but for one holder's (a batch's per-polygon
arrays cost some 1 KB a polygon; thousands together already run as array operations)."""
_DEDUP_DECIMALS = 6
"""A polygon whose exterior ring repeats another's of the same LoD to this many decimals is
read once (a solid's copy of a thematic surface's polygon)."""


def _dedup_keys(polygons: list[Polygon]) -> list[Any]:
    """Per polygon (each with rings), a key that two polygons share when they are of the same
    LoD and their exterior rings have the same distinct points to :data:`_DEDUP_DECIMALS`
    decimals, whatever their start and direction. The rounded bounding box stands in for the
    points where no other polygon has the same box."""
    exteriors = [polygon.rings[0] for polygon in polygons]
    lengths = np.array([len(ring) for ring in exteriors], dtype=np.int64)
    rounded = np.round(np.concatenate(exteriors), _DEDUP_DECIMALS)
    boxes = np.zeros((len(polygons), 6))
    full = lengths > 0
    if full.any():
        starts = (np.cumsum(lengths) - lengths)[full]
        boxes[full] = np.hstack(
            [np.minimum.reduceat(rounded, starts), np.maximum.reduceat(rounded, starts)]
        )
    keys: list[Any] = [
        (polygon.lod, n > 0, box.tobytes())
        for polygon, n, box in zip(polygons, lengths.tolist(), boxes, strict=True)
    ]
    shared = Counter(keys)
    ends = np.cumsum(lengths).tolist()
    for i, key in enumerate(keys):
        if shared[key] > 1:
            ring = rounded[ends[i] - lengths[i] : ends[i]]
            keys[i] = (polygons[i].lod, frozenset(map(tuple, ring.tolist())))
    return keys


def _kept(holder: Holder) -> list[Polygon]:
    """The holder's polygons to triangulate: those with semantics first, each element and
    each exterior ring once per LoD; polygons without rings are counted as degenerate."""
    ordered = sorted(holder.polygons, key=lambda p: not p.semantic)
    with_rings = [p for p in ordered if p.rings]
    holder.degenerate += len(ordered) - len(with_rings)
    if not with_rings:
        return []
    seen: set[Any] = set()
    kept = []
    for polygon, key in zip(with_rings, _dedup_keys(with_rings), strict=True):
        by_element = (polygon.lod, polygon.serial)
        if by_element in seen or key in seen:
            continue
        seen.add(by_element)
        seen.add(key)
        kept.append(polygon)
    return kept


@dataclass
class _Group:
    """The triangles of one LoD, semantic type and look of a holder: where its pieces lie in
    the batch's vertex and face arrays, and their texture coordinates (with ``image``)."""

    holder: Holder
    lod: str
    semantic: str
    vertices: slice
    faces: slice
    image: str | None = None
    color: np.ndarray | None = None
    uv: np.ndarray | None = None


_Piece = tuple[np.ndarray, np.ndarray, bool, np.ndarray | None]
"""A polygon's triangles: vertices, faces, whether reversed, texture coordinates or None."""


def _groups(
    holders: list[Holder], images: Images | None
) -> tuple[list[_Group], np.ndarray, np.ndarray]:
    """Triangulate the kept polygons of ``holders`` together; the groups by holder, LoD (in
    order) and semantic type (as met), with the batch's vertices and faces (each group's
    faces indexing the batch's vertices)."""
    kept = [(holder, _kept(holder)) for holder in holders]
    polygons = [polygon for _, polygons in kept for polygon in polygons]
    tin = [polygon.tin for polygon in polygons]
    rings = iter(triangulate_many([p.rings for p, t in zip(polygons, tin, strict=True) if not t]))
    results = (
        _tin_triangles(polygon) if t else next(rings)
        for polygon, t in zip(polygons, tin, strict=True)
    )
    pieces: list[_Piece] = []
    groups: list[_Group] = []
    vertex_at = face_at = 0
    for holder, polygons in kept:
        by_lod: dict[str, dict[tuple[Any, ...], list[_Piece]]] = {}
        faults: Counter[str] = Counter()
        for polygon in polygons:
            triangles = next(results)
            if triangles is None:
                holder.degenerate += 1
                continue
            uv = _texture_coordinates(polygon, *triangles, faults, images, holder.where)
            look = polygon.look
            if uv is not None and look is not None:  # one surface per image: one crop of it
                key: tuple[Any, ...] = ("", look.image, None)
            else:
                color = look.color if look is not None else None
                key = (polygon.semantic, None, None if color is None else color.tobytes())
            by_key = by_lod.setdefault(polygon.lod, {})
            by_key.setdefault(key, []).append((*triangles, polygon.flip, uv))
        for fault, count in faults.items():
            holder.texture_faults.append(f"{count:,} polygon(s) {fault}")
        for lod in sorted(by_lod):
            for (semantic, image, color), group in by_lod[lod].items():
                n_vertices = sum(len(piece[0]) for piece in group)
                n_faces = sum(len(piece[1]) for piece in group)
                groups.append(
                    _Group(
                        holder,
                        lod,
                        semantic,
                        slice(vertex_at, vertex_at + n_vertices),
                        slice(face_at, face_at + n_faces),
                        image,
                        None if color is None else np.frombuffer(color, dtype=np.uint8).copy(),
                        np.concatenate([piece[3] for piece in group]) if image else None,
                    )
                )
                pieces += group
                vertex_at += n_vertices
                face_at += n_faces
    if not pieces:
        return groups, np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    vertices = np.concatenate([piece[0] for piece in pieces])
    faces = np.concatenate([piece[1] for piece in pieces])
    counts = np.array([len(piece[1]) for piece in pieces], dtype=np.int64)
    starts = np.cumsum([0] + [len(piece[0]) for piece in pieces[:-1]])
    faces = faces + np.repeat(starts, counts)[:, None]
    flip = np.repeat([piece[2] for piece in pieces], counts)
    if flip.any():
        faces[flip] = faces[flip][:, ::-1]
    return groups, vertices, faces


def _texture_coordinates(
    polygon: Polygon,
    vertices: np.ndarray,
    faces: np.ndarray,
    faults: Counter[str],
    images: Images | None,
    where: str,
) -> np.ndarray | None:
    """The texture coordinates (n, 2) of the triangulated ``vertices`` of ``polygon`` (each a
    point of its rings), or None where it wears no texture, its image cannot be used (warned
    of by ``images``, for the object ``where``) or its coordinates cannot (counted in
    ``faults`` by what is wrong): then it takes its material or class colour."""
    look = polygon.look
    if look is None or look.image is None or look.uv is None or images is None:
        return None
    image = images.image(look.image, where)
    if image is None:
        return None
    rings = look.uv
    if look.texels:  # a georeferenced texture's texels: coordinates of this image's size
        height, width = image.shape[:2]
        rings = tuple(
            None
            if each is None
            else np.column_stack([(each[:, 0] + 0.5) / width, 1.0 - (each[:, 1] + 0.5) / height])
            for each in rings
        )
    if len(rings) != len(polygon.rings) or any(
        uv is not None and len(uv) != len(ring)
        for uv, ring in zip(rings, polygon.rings, strict=False)
    ):
        faults["have texture coordinates that do not match their rings' points"] += 1
        return None
    uv, fault = polygon_coordinates(vertices, faces, polygon.rings, rings)
    if fault is not None:
        faults[fault] += 1
    return uv


def _tin_triangles(polygon: Polygon) -> Triangles | None:
    """The triangles of a ``Tin`` given by its control points (``polygon.rings``): their
    Delaunay triangulation in plan, without triangles longer than its ``maxLength``."""
    points = [ring for ring in polygon.rings if len(ring)]
    if not points:
        return None
    return points_surface(np.concatenate(points), polygon.max_length)


def triangulate_batch(
    tops: list[Holder],
    crs: Crs,
    palette: Palette,
    tally: InputTally,
    images: Images | None = None,
) -> list[tuple[Holder, str]]:
    """Triangulate the polygons of a batch of top-level objects (and their parts), their
    coordinates read (:func:`~.coordinates.read_coordinates`) and put in metres here
    (:func:`~.coordinates.in_metres`), into each holder's :attr:`Holder.surfaces`: one checked
    :class:`Surface` per LoD, semantic type and look, coloured by its material or type or
    textured with the image of ``images`` it wears (cut to what it covers), without faces that
    have no area (counted in :attr:`Holder.dropped`). The objects that could not be read, with
    the reason. The holders are triangulated :data:`TRIANGULATED` polygons at a time (each
    one's polygons let go once it has its surfaces), which bounds the per-polygon arrays held
    at once."""
    broken, tops = in_metres(tops, crs)
    chunk: list[Holder] = []
    polygons = 0
    for holder in (holder for top in tops for holder in top.walk()):
        chunk.append(holder)
        polygons += len(holder.polygons)
        if polygons >= TRIANGULATED:
            _triangulated(chunk, palette, tally, images)
            chunk, polygons = [], 0
    _triangulated(chunk, palette, tally, images)
    return broken


def _triangulated(
    holders: list[Holder], palette: Palette, tally: InputTally, images: Images | None
) -> None:
    """Triangulate the polygons of ``holders`` into their :attr:`Holder.surfaces` (as
    :func:`triangulate_batch` says); their polygons are let go."""
    if not holders:
        return
    groups, vertices, faces = _groups(holders, images)
    for holder in holders:
        holder.polygons = []
        for fault in holder.texture_faults:
            tally.warn(f"{holder.where}: {fault}; they take their material or class colour")
        holder.texture_faults = []
    tally.count(
        sum(g.vertices.stop - g.vertices.start for g in groups),
        sum(g.faces.stop - g.faces.start for g in groups),
    )
    keep = faces_with_area(vertices, faces)
    boxes = _group_bounds(groups, vertices, faces[keep])
    for group, box in zip(groups, boxes, strict=True):
        first = group.vertices.start
        kept = faces[group.faces][keep[group.faces]] - first
        group.holder.dropped += (group.faces.stop - group.faces.start) - len(kept)
        if len(kept):
            surface = Surface(
                vertices[group.vertices].copy(), kept, base_color=_color(group, palette)
            )
            if group.image is not None and images is not None and group.uv is not None:
                image = images.image(group.image, group.holder.where)
                assert image is not None  # as _texture_coordinates found it
                surface.uv, surface.texture = cropped(group.uv, image)
                surface.base_color = WHITE.copy()  # the texture carries the colour
                surface.photographic = images.photographic(group.image)
            surface.derived("bounds", lambda box=box: box)  # what Surface.bounds computes
            group.holder.surfaces.setdefault(group.lod, []).append(surface)


def _color(group: _Group, palette: Palette) -> np.ndarray:
    """A group's colour without its texture: its material's, else its semantic type's."""
    if group.color is not None:
        return group.color.copy()
    return palette.of(group.semantic or None, group.holder.kind).copy()


def _group_bounds(groups: list[_Group], vertices: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """Per group, the (2, 3) bounds of its vertices that the ``kept`` faces use (all at once;
    infinite for a group whose faces were all dropped)."""
    if not groups:
        return np.zeros((0, 2, 3))
    used = np.zeros(len(vertices) + 1, dtype=bool)  # and a row past the end, for reduceat
    used[kept.ravel()] = True
    padded = np.vstack([vertices, np.zeros((1, 3))])
    low = np.where(used[:, None], padded, np.inf)
    high = np.where(used[:, None], padded, -np.inf)
    ends = np.array([(g.vertices.start, g.vertices.stop) for g in groups], dtype=np.int64).ravel()
    return np.stack(
        [np.minimum.reduceat(low, ends)[::2], np.maximum.reduceat(high, ends)[::2]], axis=1
    )
