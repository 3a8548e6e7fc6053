"""The polygons of a CityJSON geometry: its ``boundaries`` nested by geometry type, read into
rings of vertex indices, each surface's semantic class and material, and the parts (one per
class and material, coloured) they fall in; a :class:`Lod` holds one LoD of an object so read,
waiting to be triangulated with its batch (:mod:`.triangulation`). LoD labels and their
order."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain, repeat
from typing import Any

import numpy as np

from ...errors import InputError
from ...model import Mesh
from .jsonkind import json_shown
from .source import Context
from .vertices import check_used

_CLASSES = ("RoofSurface", "WallSurface", "GroundSurface", None)
"""Semantic classes in part order (None: any other surface)."""
SURFACE_DEPTH = {
    "MultiSurface": 1,
    "CompositeSurface": 1,
    "Solid": 2,
    "MultiSolid": 3,
    "CompositeSolid": 3,
}
"""How deep the list of surfaces is nested in each geometry type's ``boundaries``."""
_LIST = {list}
_INT = {int}
_LISTED = {list, type(None)}
_INDICES = {int, type(None)}


def _surfaces(boundaries: Any, depth: int) -> list[Any]:
    """The surfaces (lists of rings) of ``boundaries`` nested ``depth`` lists deep (null
    taken as an empty list); ``ValueError`` for a level that is not a list."""
    items = [boundaries]
    for _ in range(depth):
        if not set(map(type, items)) <= _LISTED:
            raise ValueError(f"a boundary is {_first_other(items, _LISTED)}, not a list")
        items = [inner for outer in items if outer is not None for inner in outer]
    return items


def _values(values: Any, depth: int, count: int) -> list[Any]:
    """Per-surface values (semantics, materials) nested like the surfaces, padded with None
    (all None when they are not nested so)."""
    try:
        flat = _surfaces(values, depth) if isinstance(values, list) else []
    except ValueError:
        flat = []
    return (flat + [None] * count)[:count]


def _material_values(geometry: dict[str, Any], depth: int, count: int) -> list[Any]:
    """Each surface's material index in the first theme the geometry lists (None: none)."""
    themes = geometry.get("material")
    if not isinstance(themes, dict) or not themes:
        return [None] * count
    theme = next(iter(themes.values()))
    if not isinstance(theme, dict):
        return [None] * count
    if "value" in theme:
        return [theme["value"]] * count
    return _values(theme.get("values"), depth, count)


def _classes(geometry: dict[str, Any], depth: int, count: int) -> list[int]:
    """Each surface's semantic class, as its index in :data:`_CLASSES` (that of None for any
    other)."""
    other = _CLASSES.index(None)
    semantics = geometry.get("semantics")
    if not isinstance(semantics, dict):
        return [other] * count
    kinds = [s.get("type") if isinstance(s, dict) else None for s in semantics.get("surfaces", [])]
    of = {k: _CLASSES.index(kind) if kind in _CLASSES else other for k, kind in enumerate(kinds)}
    values = _values(semantics.get("values"), depth, count)
    if set(map(type, values)) <= _INDICES:
        return list(map(of.get, values, repeat(other, count)))
    return [of[v] if isinstance(v, int) and 0 <= v < len(kinds) else other for v in values]


def _materials(geometry: dict[str, Any], depth: int, count: int) -> list[Any]:
    """Each surface's material index in the first theme the geometry lists, or -1; an index
    is any ``int``, in range or not (those out of range take their class's colour)."""
    materials = _material_values(geometry, depth, count)
    types = set(map(type, materials))
    if types <= {int}:
        return materials
    if types <= {type(None)}:
        return [-1] * count
    return [m if isinstance(m, int) else -1 for m in materials]


def _rings(surfaces: list[Any]) -> tuple[np.ndarray, list[int], list[int]]:
    """Every ring's vertex indices end to end (int64), each ring's length and each surface's
    number of rings. ``ValueError`` (or ``OverflowError``) naming what is wrong unless every
    surface is a list of rings and every ring a list of whole numbers (not ``16.5``,
    ``"16"`` or ``true``) of int64."""
    if not set(map(type, surfaces)) <= _LIST:
        raise ValueError(f"a surface is {_first_other(surfaces, _LIST)}, not a list of rings")
    rings = list(chain.from_iterable(surfaces))
    if not set(map(type, rings)) <= _LIST:
        raise ValueError(f"a ring is {_first_other(rings, _LIST)}, not a list of indices")
    flat = list(chain.from_iterable(rings))
    if not set(map(type, flat)) <= _INT:
        raise ValueError(f"an index is {_first_other(flat, _INT)}, not a whole number")
    return np.array(flat, dtype=np.int64), list(map(len, rings)), list(map(len, surfaces))


def _first_other(values: list[Any], wanted: set[type]) -> str:
    """The first of ``values`` of none of the types ``wanted``, shown as JSON."""
    return json_shown(next(v for v in values if type(v) not in wanted))


@dataclass(eq=False)
class Lod:
    """The polygons of one LoD of an object (or of one template), read and checked, waiting
    to be triangulated with the rest of a batch
    (:func:`~.triangulation.triangulate_batch`), which sets ``mesh`` and ``dropped``."""

    label: str
    vertices: np.ndarray
    """The vertex list ``index`` refers to."""
    index: np.ndarray
    """Every ring's vertex indices (int64), end to end."""
    ring_lengths: np.ndarray
    ring_counts: np.ndarray
    """Rings per polygon (the exterior first)."""
    part_of: np.ndarray
    """Per polygon, its part: the rank of its (semantic class, material) in sorted order."""
    colors: list[np.ndarray]
    """Per part, its sRGB RGBA colour."""
    mesh: Mesh | None = None
    """One surface per part with faces, in part order; None when no part has any."""
    dropped: int = 0
    """Degenerate polygons and triangles without area."""


def read_lod(
    label: str,
    geometries: list[dict[str, Any]],
    vertices: np.ndarray,
    ctx: Context,
    where: str,
    kind: str,
) -> Lod:
    """The polygons of ``geometries`` (of one LoD) indexing ``vertices``, each in its part (one
    per semantic class and material, coloured). Raises :class:`InputError` for bad indices or
    boundaries."""
    indices, lengths, counts, keys = [], [], [], []
    for geometry in geometries:
        depth = SURFACE_DEPTH[geometry["type"]]
        try:
            index, ring_lengths, ring_counts = _rings(_surfaces(geometry.get("boundaries"), depth))
        except (TypeError, ValueError, OverflowError) as exc:
            raise InputError(
                f"has malformed {geometry['type']} boundaries ({exc})", where
            ) from None
        bad = (index < 0) | (index >= len(vertices))
        if bad.any():
            raise InputError(
                f"refers to vertices that do not exist (index {int(index[bad][0])}; "
                f"{len(vertices):,} vertices, 0 to {len(vertices) - 1:,})",
                where,
            )
        check_used(vertices, index, where)
        classes = _classes(geometry, depth, len(ring_counts))
        keys += zip(classes, _materials(geometry, depth, len(ring_counts)), strict=True)
        indices.append(index)
        lengths += ring_lengths
        counts += ring_counts
    parts = sorted(dict.fromkeys(keys))
    rank = {key: k for k, key in enumerate(parts)}
    return Lod(
        label=label,
        vertices=vertices,
        index=np.concatenate(indices) if indices else np.zeros(0, np.int64),
        ring_lengths=np.array(lengths, dtype=np.int64),
        ring_counts=np.array(counts, dtype=np.int64),
        part_of=np.fromiter(map(rank.__getitem__, keys), dtype=np.int64, count=len(keys)),
        colors=[_color(_CLASSES[klass], material, ctx, kind) for klass, material in parts],
    )


def _color(kind: str | None, material: Any, ctx: Context, object_type: str) -> np.ndarray:
    """A part's sRGB RGBA colour: its material's, else its semantic class's."""
    if isinstance(material, int) and 0 <= material < len(ctx.materials):
        entry = ctx.materials[material]
        diffuse = entry.get("diffuseColor") if isinstance(entry, dict) else None
        if isinstance(diffuse, list) and len(diffuse) == 3:
            alpha = 1.0 - float(entry.get("transparency", 0.0))
            rgba = np.clip(np.nan_to_num(np.array([*diffuse, alpha], dtype=np.float64)), 0, 1)
            return np.rint(rgba * 255).astype(np.uint8)
    return ctx.palette.of(kind, object_type)


def lod_key(label: str) -> tuple[float, ...]:
    """Numeric sort key of a LoD label (``"2.2"`` → (2, 2)); non-numeric labels sort first."""
    try:
        return tuple(float(p) for p in label.split("."))
    except ValueError:
        return (-1.0,)


def lod_label(value: Any) -> str:
    """A LoD as its label (CityJSON 1.0 wrote numbers: ``2`` → ``"2"``)."""
    return f"{value:g}" if isinstance(value, int | float) else str(value)
