"""Triangulating a batch of read LoDs (:class:`~.geometry.Lod`) together, as
:func:`~lodconvert.polygons.triangulate` makes each polygon's triangles, in one
:func:`~lodconvert.polygons.triangulate_many` call, and giving each LoD its mesh: one surface
per part, of its triangles with area, and how many faces it dropped."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...model import WHITE, Mesh, Surface
from ...polygons import triangulate_many
from ...textures import cropped, polygon_coordinates
from ..geometry_checks import faces_with_area
from .geometry import Lod, Textured


def _opened(lengths: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Which points of rings (``lengths``, laid end to end) stay once each ring drops a
    repeated closing point and then repeated neighbours (by position), as
    :func:`~lodconvert.polygons.triangulate` opens rings."""
    keep = np.ones(len(points), dtype=bool)
    if not len(points):
        return keep
    ends = lengths.cumsum()
    longer = lengths > 1
    last = ends[longer] - 1
    keep[last[(points[last] == points[(ends - lengths)[longer]]).all(axis=1)]] = False
    ring = np.arange(len(lengths)).repeat(lengths)
    keep[1:] &= ~((points[1:] == points[:-1]).all(axis=1) & (ring[1:] == ring[:-1]))
    return keep


@dataclass
class _Triangles:
    """A batch's triangles: ``faces`` indexing its vertex list, each of polygon ``polygon``
    (in polygon order), and ``own`` triangles of polygons with vertices of their own (where
    triangulating dropped or merged points): polygon, points, faces."""

    faces: np.ndarray
    polygon: np.ndarray
    own: list[tuple[int, np.ndarray, np.ndarray]]
    degenerate: np.ndarray
    """Per polygon, whether it is degenerate (no triangles)."""


def _triangles(
    vertices: np.ndarray, index: np.ndarray, ring_lengths: np.ndarray, ring_counts: np.ndarray
) -> _Triangles:
    """Triangulate polygons (``ring_counts`` rings each, of ``ring_lengths`` indices into
    ``vertices``, laid end to end in ``index``) together, as
    :func:`~lodconvert.polygons.triangulate` does one at a time: a lone ring of three indices
    is its own triangle (no ear clipping, no check: a triangle without area is dropped
    later); a polygon without rings or without points in its exterior is degenerate; the
    rest are opened, then ear-clipped in one :func:`triangulate_many` call, and their
    triangles index ``vertices`` where their points are the opened rings' own."""
    ring_starts = ring_lengths.cumsum() - ring_lengths
    first_ring = ring_counts.cumsum() - ring_counts
    has_rings = ring_counts > 0
    first_length = np.zeros(len(ring_counts), dtype=np.int64)
    first_length[has_rings] = ring_lengths[first_ring[has_rings]]
    triangle = (ring_counts == 1) & (first_length == 3)
    general = ~triangle & (first_length > 0)
    degenerate = ~triangle & ~general
    corners = ring_starts[first_ring[triangle]]
    faces = [index[corners[:, None] + np.arange(3)]]
    polygon = [np.flatnonzero(triangle)]
    own: list[tuple[int, np.ndarray, np.ndarray]] = []
    if general.any():
        in_general = general.repeat(ring_counts)
        lengths = ring_lengths[in_general]
        chosen = index[in_general.repeat(ring_lengths)]
        points = vertices[chosen]
        keep = _opened(lengths, points)
        chosen, points = chosen[keep], points[keep]
        ring = np.arange(len(lengths)).repeat(lengths)
        lengths = np.bincount(ring[keep], minlength=len(lengths))
        counts = ring_counts[general]
        rings = np.split(points, lengths.cumsum()[:-1])
        ends = counts.cumsum()
        results = triangulate_many(
            [
                rings[end - count : end]
                for count, end in zip(counts.tolist(), ends.tolist(), strict=True)
            ],
            fan=False,
        )
        sizes = np.bincount(
            np.arange(len(counts)).repeat(counts), weights=lengths, minlength=len(counts)
        ).astype(np.int64)
        starts = sizes.cumsum() - sizes
        ids = np.flatnonzero(general)
        mapped, clipped, counted = [], [], []
        for k, result, size, start in zip(
            ids.tolist(), results, sizes.tolist(), starts.tolist(), strict=True
        ):
            if result is None:
                degenerate[k] = True
            elif len(result[0]) == size:
                mapped.append(result[1] + start)
                clipped.append(k)
                counted.append(len(result[1]))
            else:
                own.append((k, *result))
        if mapped:
            faces.append(chosen[np.concatenate(mapped)])
            polygon.append(np.repeat(clipped, counted))
    return _Triangles(np.concatenate(faces), np.concatenate(polygon), own, degenerate)


def triangulate_batch(lods: list[Lod]) -> None:
    """Triangulate the polygons of ``lods`` (one batch) together and give each LoD its mesh:
    per part, the triangles of its polygons (in polygon order) that have area, on only the
    vertices they use (those of the vertex list, in index order, then the points of polygons
    with points of their own), and how many faces it dropped."""
    if not lods:
        return
    offsets: dict[int, int] = {}
    lists: list[np.ndarray] = []
    for lod in lods:
        if id(lod.vertices) not in offsets:
            offsets[id(lod.vertices)] = sum(map(len, lists))
            lists.append(lod.vertices)
    vertices = lists[0] if len(lists) == 1 else np.concatenate(lists)
    polygons = [len(lod.ring_counts) for lod in lods]
    part_counts = np.array([len(lod.colors) for lod in lods], dtype=np.int64)
    part_starts = part_counts.cumsum() - part_counts
    parts = int(part_counts.sum())
    part = np.concatenate([lod.part_of for lod in lods]) + part_starts.repeat(polygons)
    found = _triangles(
        vertices,
        np.concatenate([lod.index + offsets[id(lod.vertices)] for lod in lods]),
        np.concatenate([lod.ring_lengths for lod in lods]),
        np.concatenate([lod.ring_counts for lod in lods]),
    )
    indexed = _by_part(vertices, found.faces, found.polygon, part, parts)
    own = _own_by_part(found.own, part)
    degenerate = np.bincount(
        np.arange(len(lods)).repeat(polygons)[found.degenerate], minlength=len(lods)
    )
    for k, lod in enumerate(lods):
        surfaces = []
        lod.dropped = int(degenerate[k])
        for rank, p in enumerate(range(int(part_starts[k]), int(part_starts[k] + part_counts[k]))):
            points, faces, keep = indexed(p)
            if p in own:
                chunks, all_faces, keeps = [points], [faces], [keep]
                offset = len(points)
                for own_points, own_faces, own_keep in own[p]:
                    chunks.append(own_points)
                    all_faces.append(own_faces + offset)
                    keeps.append(own_keep)
                    offset += len(own_points)
                points = np.concatenate(chunks)
                faces, keep = np.concatenate(all_faces), np.concatenate(keeps)
            lost = len(keep) - int(np.count_nonzero(keep))
            lod.dropped += lost
            if lost:
                points, faces = _compact(points, faces[keep])
            if len(faces):
                color = lod.colors[rank].copy()
                surfaces.append(Surface(vertices=points, faces=faces, base_color=color))
        surfaces += _textured_surfaces(lod)
        lod.mesh = Mesh(surfaces) if surfaces else None


def _textured_surfaces(lod: Lod) -> list[Surface]:
    """The surfaces of ``lod``'s textured polygons: one per texture, semantic class and
    material, its texture cut to what it covers (those whose coordinates cannot be used take
    their colour, and are warned of), on points of their own."""
    if not lod.textured:
        return []
    triangulated = triangulate_many([polygon.rings for polygon in lod.textured])
    groups: dict[tuple[Any, ...], list[tuple[np.ndarray, np.ndarray, np.ndarray | None]]] = {}
    colors: dict[tuple[Any, ...], np.ndarray] = {}
    images: dict[tuple[Any, ...], Textured] = {}
    faults: Counter[str] = Counter()
    for polygon, triangles in zip(lod.textured, triangulated, strict=True):
        if triangles is None:
            lod.dropped += 1
            continue
        points, faces = triangles
        keep = faces_with_area(points, faces)
        lod.dropped += len(faces) - int(np.count_nonzero(keep))
        if not keep.any():
            continue
        uv, fault = polygon_coordinates(points, faces[keep], polygon.rings, polygon.uv)
        if fault is not None:
            faults[fault] += 1
        key = (*polygon.key, polygon.color.tobytes()) if uv is None else polygon.key[:1]
        colors[key], images[key] = polygon.color, polygon
        groups.setdefault(key, []).append((points, faces[keep], uv))
    lod.faults.update(faults)
    surfaces = []
    for key, pieces in groups.items():
        starts = np.cumsum([0] + [len(points) for points, _, _ in pieces[:-1]])
        surface = Surface(
            np.concatenate([points for points, _, _ in pieces]),
            np.concatenate(
                [faces + start for (_, faces, _), start in zip(pieces, starts, strict=True)]
            ),
            base_color=colors[key].copy(),
        )
        if pieces[0][2] is not None:
            uv = np.concatenate([uv for _, _, uv in pieces if uv is not None])
            surface.uv, surface.texture = cropped(uv, images[key].image)
            surface.base_color = WHITE.copy()  # the texture carries the colour
            surface.photographic = images[key].photographic
        surfaces.append(surface)
    return surfaces


def _by_part(
    vertices: np.ndarray, faces: np.ndarray, polygon: np.ndarray, part_of: np.ndarray, parts: int
) -> Callable[[int], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """For ``faces`` indexing ``vertices``, each of a ``polygon`` whose part (one of
    ``parts``) ``part_of`` gives: per part, the vertices its faces use (in index order), its
    faces (polygon by polygon) indexing those, and whether each has area."""
    part = part_of[polygon]
    order = np.argsort(part * len(part_of) + polygon, kind="stable")
    faces, part = faces[order], part[order]
    with_area = faces_with_area(vertices, faces)
    face_ends = np.bincount(part, minlength=parts).cumsum()
    used, inverse = np.unique(faces, return_inverse=True)
    width = max(len(used), 1)
    pairs, local = np.unique(part.repeat(3) * width + inverse.ravel(), return_inverse=True)
    used_part = pairs // width
    used = used[pairs - used_part * width]
    used_counts = np.bincount(used_part, minlength=parts)
    used_ends = used_counts.cumsum()
    local = (local - (used_ends - used_counts)[part.repeat(3)]).reshape(-1, 3)

    def of(p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f0, f1 = (int(face_ends[p - 1]) if p else 0), int(face_ends[p])
        u0, u1 = (int(used_ends[p - 1]) if p else 0), int(used_ends[p])
        return vertices[used[u0:u1]], local[f0:f1].copy(), with_area[f0:f1]

    return of


def _own_by_part(
    own: list[tuple[int, np.ndarray, np.ndarray]], part: np.ndarray
) -> dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """Per part, the polygons with points of their own (in polygon order): points, faces and
    whether each face has area."""
    if not own:
        return {}
    sizes = np.array([len(points) for _, points, _ in own], dtype=np.int64)
    starts = (sizes.cumsum() - sizes).tolist()
    with_area = faces_with_area(
        np.concatenate([points for _, points, _ in own]),
        np.concatenate([faces + start for (_, _, faces), start in zip(own, starts, strict=True)]),
    )
    by_part: dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
    at = 0
    for polygon, points, faces in own:
        keep = with_area[at : at + len(faces)]
        by_part.setdefault(int(part[polygon]), []).append((points, faces, keep))
        at += len(faces)
    return by_part


def _compact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices ``faces`` use, in index order, and the faces re-indexed to them."""
    used, local = np.unique(faces, return_inverse=True)
    return vertices[used], local.reshape(-1, 3).astype(np.int64)
