"""The coordinates of a CityGML object's polygons: read a part at a time
(:func:`read_coordinates`: each part's elements freed once read, so that an object of many
parts never holds its whole tree and all its coordinates at once), checked (finite, within
range) and, for a batch of objects together, put in metres (:func:`in_metres`: a geographic
CRS's frame centred on the batch's first object, implicit geometry placed by :mod:`.implicit`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from lxml import etree

from ...errors import InputError
from ..crs import Crs
from ..geometry_checks import check_magnitude
from ..numbers import parse_floats
from .appearance import Look
from .holders import BrokenObject, Holder, Polygon, Read
from .implicit import placed, placement
from .names import local

_EXTERIOR = frozenset({"exterior", "outerBoundaryIs"})
_INTERIOR = frozenset({"interior", "innerBoundaryIs"})


@dataclass
class Rings:
    """The coordinates of an object's rings (an array per ``posList`` or ``pos``) and, per
    ring, its value count and width."""

    values: list[np.ndarray] = field(default_factory=list)
    counts: list[int] = field(default_factory=list)
    widths: list[int] = field(default_factory=list)
    trimmed: int = 0
    """Rings read when the heap was last handed back."""


def _ring_values(ring: etree._Element, rings: Rings) -> None:
    """Add the coordinates of a ``LinearRing`` (its ``posList`` or ``pos`` elements)."""
    count = 0
    dimension = None
    for child in ring:
        name = local(child)
        if name == "posList" or name == "pos":
            try:
                values = parse_floats(child.text or "")
            except ValueError:
                raise BrokenObject("has a coordinate that is not a number") from None
            rings.values.append(values)
            count += len(values)
            dimension = dimension or child.get("srsDimension")
    if dimension is None:
        declared = (a.get("srsDimension") for a in ring.iterancestors())
        dimension = next((d for d in declared if d), "3")
    try:
        width = int(dimension)
    except ValueError:
        raise BrokenObject(f"has an srsDimension of {dimension!r}") from None
    if width not in (2, 3) or count % width:
        raise BrokenObject(f"has a ring of {count} values, not whole points of dimension {width}")
    rings.counts.append(count)
    rings.widths.append(width)


def _polygon_rings(
    polygon: Polygon, element: etree._Element, rings: Rings, found: list[etree._Element] | None
) -> list[int]:
    """Add the rings of ``polygon`` (its ``element``; a ``Tin``'s control points, noted with
    its ``maxLength``), their elements to ``found`` (but a ``Tin``'s) in the order they are
    read; its layout: its number of rings, then their indices, exterior first."""
    exterior: list[int] = []
    interior: list[int] = []
    if local(element) == "Tin":  # its control points, triangulated later
        polygon.tin = True
        polygon.max_length = _max_length(element)
        for points in element:
            if local(points) == "controlPoint":
                exterior.append(len(rings.counts))
                _ring_values(points, rings)
    for boundary in element:
        kind = local(boundary)
        into = exterior if kind in _EXTERIOR else interior if kind in _INTERIOR else None
        if into is None:
            continue
        for ring in boundary:
            into.append(len(rings.counts))
            _ring_values(ring, rings)
        if found is not None:
            found.extend(boundary)
    return [len(exterior) + len(interior), *exterior[::-1], *interior]


def _look(look: Look | None, rings: Rings, first_ring: int, first_value: int) -> Look | None:
    """``look``, a world-to-texture (or plan-to-texel) matrix turned into texture coordinates
    (or texels) for the rings read from number ``first_ring`` on (their coordinates as the
    document gives them, from array ``first_value`` of :attr:`Rings.values`)."""
    if look is None or (look.matrix is None and look.plan is None):
        return look
    counts, widths = rings.counts[first_ring:], rings.widths[first_ring:]
    if not counts:
        return Look(None, None, None, look.color)
    flat = np.concatenate(rings.values[first_value:])
    uv = []
    for values, width in zip(np.split(flat, np.cumsum(counts)[:-1]), widths, strict=True):
        points = np.zeros((len(values) // width, 4))
        points[:, :width] = values.reshape(-1, width)
        points[:, 3] = 1.0
        if look.plan is not None:  # texels, from plan coordinates
            uv.append(points[:, [0, 1, 3]] @ look.plan.T)
            continue
        s, t, q = (points @ look.matrix.T).T
        with np.errstate(divide="ignore", invalid="ignore"):
            uv.append(np.column_stack([s / q, t / q]))
    return Look(look.image, tuple(uv), None, look.color, texels=look.plan is not None)


def _max_length(tin: etree._Element) -> float | None:
    """A ``Tin``'s ``maxLength`` when it gives a positive number, else None."""
    limit = next((e.text for e in tin if local(e) == "maxLength"), None)
    try:
        max_length = float(limit) if limit is not None else None
    except ValueError:
        return None
    return max_length if max_length is not None and max_length > 0 else None


def read_coordinates(top: Holder) -> None:
    """Read the coordinates of the polygons of ``top`` (a collected top-level object) and of
    its parts into :attr:`Holder.read`, or why they cannot be read into
    :attr:`Holder.broken`. A part at a time: each part's elements are freed once its polygons
    are read, and the polygons let go of their elements, so that an object of many parts
    never holds its whole tree and all its coordinates at once."""
    for holder in top.walk():
        holder.forget_walk()
    read_object(top, functools.partial(_holder_rings, top))


def read_object(top: Holder, read_rings: Callable[[Rings, Read], None]) -> None:
    """Read the coordinates of ``top``'s polygons, which ``read_rings`` adds to the rings and
    the read it is given (:class:`BrokenObject` when one cannot be read), into
    :attr:`Holder.read`, or why they cannot be read into :attr:`Holder.broken`."""
    rings = Rings()
    read = Read(top, [], [], np.zeros((0, 3)), np.zeros(0, dtype=np.int64))
    try:
        read_rings(rings, read)
    except BrokenObject as exc:
        _broken(top, str(exc))
        return
    _finish(top, rings, read)


def _broken(top: Holder, reason: str) -> None:
    """Note why ``top``'s coordinates cannot be read; let go of its polygons and elements."""
    top.broken = reason
    for holder in reversed(list(top.walk())):  # parts before what holds them
        holder.polygons = []
        if holder.element is not None:
            holder.element.clear(keep_tail=False)


def _finish(top: Holder, rings: Rings, read: Read) -> None:
    """Put the ``rings`` read of ``top``'s polygons into ``read`` as points, and that into
    :attr:`Holder.read` (or why they cannot be read into :attr:`Holder.broken`); free the
    object's elements."""
    top.element.clear(keep_tail=False)
    flat = np.concatenate(rings.values) if rings.values else np.zeros(0)
    del rings.values[:]
    if problem := _range_problem(flat):
        top.broken = problem
        return
    widths = np.array(rings.widths, dtype=np.int64)
    read.lengths = np.array(rings.counts, dtype=np.int64) // np.maximum(widths, 1)
    if (widths == 3).all():
        read.points = flat.reshape(-1, 3)
    else:
        pieces = np.split(flat, np.cumsum(rings.counts)[:-1])
        read.points = np.concatenate(
            [
                np.pad(v.reshape(-1, 2), ((0, 0), (0, 1))) if w == 2 else v.reshape(-1, 3)
                for v, w in zip(pieces, rings.widths, strict=True)
            ]
        )
    if read.placements:
        ring_relative = np.zeros(len(read.lengths), dtype=bool)
        cursor = 0
        for polygon in read.polygons:
            n = read.layout[cursor]
            if polygon.placed_by is not None:
                ring_relative[read.layout[cursor + 1 : cursor + 1 + n]] = True
            cursor += 1 + n
        read.relative = np.repeat(ring_relative, read.lengths)
    top.read = read


def _holder_rings(holder: Holder, rings: Rings, read: Read) -> None:
    """Add the rings of ``holder``'s polygons (:func:`read_holder`), then those of its parts,
    each part's elements freed once read."""
    read_holder(holder, rings, read)
    for part in holder.parts:
        _holder_rings(part, rings, read)
        part.release()


def read_holder(holder: Holder, rings: Rings, read: Read) -> None:
    """Add the rings of ``holder``'s polygons to ``rings`` and ``read`` (their layout, and the
    placements of implicit ones), the polygons letting go of their elements;
    :class:`BrokenObject` when a ring or a placement cannot be read."""
    serials: dict[int, int] = {}
    placed: dict[int, int] = {}
    for polygon in holder.polygons:  # numbered while every element is held
        polygon.serial = serials.setdefault(id(polygon.element), len(serials))
        if polygon.implicit is not None:
            polygon.placed_by = placed.setdefault(id(polygon.implicit), len(placed))
    placements: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(placed)
    looks = read.top.looks
    for polygon in holder.polygons:
        assert polygon.element is not None  # not read before
        start = len(rings.counts), len(rings.values)
        found: list[etree._Element] | None = None if looks is None else []
        read.layout += _polygon_rings(polygon, polygon.element, rings, found)
        if looks is not None and found is not None and not polygon.tin:
            look = looks(polygon.element, found)
            polygon.look = _look(look, rings, *start)
        if polygon.implicit is not None and polygon.placed_by is not None:
            if placements[polygon.placed_by] is None:
                try:
                    placements[polygon.placed_by] = placement(polygon.implicit)
                except ValueError as exc:
                    raise BrokenObject(str(exc)) from None
            polygon.placed_by += len(read.placements)
        polygon.element = polygon.implicit = None
    read.placements += [each for each in placements if each is not None]
    read.polygons += holder.polygons


def _metric(reads: list[Read], crs: Crs) -> np.ndarray:
    """The points of ``reads`` in metres (a geographic CRS's frame centred on the first
    object's own points); the points of implicit polygons are left in their frames, and their
    reference points are projected into :attr:`Read.placements`."""
    points = np.concatenate([read.points for read in reads])
    if not any(read.placements for read in reads):
        return crs.to_metric(points, first=len(reads[0].points))
    relative = np.concatenate(
        [r.relative if r.relative is not None else np.zeros(len(r.points), bool) for r in reads]
    )
    references = [(read, key) for read in reads for key in range(len(read.placements))]
    absolute = points[~relative]
    first = int((~relative[: len(reads[0].points)]).sum()) or None
    together = np.vstack([absolute, [read.placements[key][1] for read, key in references]])
    metric = crs.to_metric(together, first=first)
    points = points.copy()
    points[~relative] = metric[: len(absolute)]
    for (read, key), reference in zip(references, metric[len(absolute) :], strict=True):
        read.placements[key] = (read.placements[key][0], reference)
    return points


def in_metres(tops: list[Holder], crs: Crs) -> tuple[list[tuple[Holder, str]], list[Holder]]:
    """Put the rings of every polygon of ``tops`` (as :func:`read_coordinates` read them) into
    ``Polygon.rings`` in metres (a geographic CRS's frame centred on the first object read;
    implicit geometry placed); the objects that could not be read (with the reason) and those
    that were."""
    broken: list[tuple[Holder, str]] = []
    reads: list[Read] = []
    for top in tops:
        if top.read is None:
            broken.append((top, top.broken))
        else:
            reads.append(top.read)
            top.read = None
    if not reads:
        return broken, []
    metric = _metric(reads, crs)
    counts = np.concatenate([read.lengths for read in reads])
    pieces = np.split(metric, np.cumsum(counts)[:-1]) if len(counts) else []
    offset = start = 0  # of the object's first ring, and of its first point
    read_tops = []
    for read in reads:
        cursor = 0
        absolute = read.points if read.relative is None else read.points[~read.relative]
        problem = crs.beyond_range(absolute) or _range_problem(
            metric[start : start + len(read.points)]
        )
        start += len(read.points)
        for polygon in read.polygons:
            n = read.layout[cursor]
            polygon.rings = [pieces[offset + i] for i in read.layout[cursor + 1 : cursor + 1 + n]]
            if polygon.placed_by is not None:
                matrix, reference = read.placements[polygon.placed_by]
                polygon.rings = [placed(ring, matrix, reference) for ring in polygon.rings]
                problem = problem or next(filter(None, map(_range_problem, polygon.rings)), None)
            cursor += 1 + n
        offset += len(read.lengths)
        if problem:
            broken.append((read.top, problem))
        else:
            read_tops.append(read.top)
    return broken, read_tops


def _range_problem(values: np.ndarray) -> str | None:
    """Why coordinates ``values`` cannot be read (one not finite, or beyond
    :data:`~..geometry_checks.MAX_MAGNITUDE`), or None."""
    largest = float(np.maximum.reduce(np.abs(values), axis=None, initial=0.0))
    if not np.isfinite(largest):
        return "has NaN or infinite coordinates"
    try:
        check_magnitude(largest, "")
    except InputError as exc:
        return str(exc)
    return None
