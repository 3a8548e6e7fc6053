"""The polygons of a CityJSON geometry: its ``boundaries`` nested by geometry type, read into
rings of vertex indices, each surface's semantic class and material, and the parts (one per
class and material, coloured) they fall in; a :class:`Lod` holds one LoD of an object so read,
waiting to be triangulated with its batch (:mod:`.triangulation`). LoD labels and their
order."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
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


def _material_values(geometry: dict[str, Any], depth: int, count: int, ctx: Context) -> list[Any]:
    """Each surface's material index in the theme read (:meth:`Context.theme_of`; None:
    none)."""
    theme = ctx.theme_of(geometry.get("material"))
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


def _materials(geometry: dict[str, Any], depth: int, count: int, ctx: Context) -> list[Any]:
    """Each surface's material index in the theme read, or -1; an index is any ``int``, in
    range or not (those out of range take their class's colour)."""
    materials = _material_values(geometry, depth, count, ctx)
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
    textured: list[Textured] = field(default_factory=list)
    """Its polygons that wear a texture, read apart from ``index`` (their points are their
    own: a vertex has texture coordinates per polygon)."""
    mesh: Mesh | None = None
    """One surface per part with faces, in part order; None when no part has any."""
    dropped: int = 0
    """Degenerate polygons and triangles without area."""
    faults: Counter[str] = field(default_factory=Counter)
    """Textured polygons whose texture coordinates could not be used, by what is wrong."""


@dataclass(frozen=True)
class Textured:
    """A polygon that wears a texture: its rings' points and texture coordinates ((k, 2),
    the ring's points in order), its image and key (the texture's index, semantic class and
    material: an object's polygons of one texture are one surface, whose image is cut once),
    its colour without the texture, and whether the image is a photograph (a JPEG)."""

    rings: list[np.ndarray]
    uv: list[np.ndarray]
    image: np.ndarray
    key: tuple[int, int, Any]
    color: np.ndarray
    photographic: bool = False


def read_lod(
    label: str,
    geometries: list[dict[str, Any]],
    vertices: np.ndarray,
    ctx: Context,
    where: str,
    kind: str,
) -> Lod:
    """The polygons of ``geometries`` (of one LoD) indexing ``vertices``, each in its part (one
    per semantic class and material, coloured), those that wear a texture apart. Raises
    :class:`InputError` for bad indices or boundaries."""
    indices, lengths, counts, keys = [], [], [], []
    textured: list[Textured] = []
    faults: Counter[str] = Counter()
    for geometry in geometries:
        depth = SURFACE_DEPTH[geometry["type"]]
        try:
            surfaces = _surfaces(geometry.get("boundaries"), depth)
            index, ring_lengths, ring_counts = _rings(surfaces)
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
        pairs = list(
            zip(
                _classes(geometry, depth, len(ring_counts)),
                _materials(geometry, depth, len(ring_counts), ctx),
                strict=True,
            )
        )
        worn = _textures(geometry, depth, surfaces, ctx, where, faults)
        if worn:
            points = np.split(vertices[index], np.cumsum(ring_lengths)[:-1])
            first = np.cumsum([0, *ring_counts])
            plain = np.ones(len(ring_counts), dtype=bool)
            for k, (texture, image, uv) in worn.items():
                klass, material = pairs[k]
                color = _color(_CLASSES[klass], material, ctx, kind)
                rings = points[first[k] : first[k + 1]]
                photo = ctx.images is not None and ctx.images.photographic(
                    ctx.textures[texture].get("image", "")
                )
                textured.append(
                    Textured(rings, uv, image, (texture, klass, material), color, photo)
                )
                plain[k] = False
            ring_kept = plain.repeat(ring_counts)
            index = index[ring_kept.repeat(ring_lengths)]
            ring_lengths = [n for n, kept in zip(ring_lengths, ring_kept, strict=True) if kept]
            ring_counts = [n for n, kept in zip(ring_counts, plain, strict=True) if kept]
            pairs = [pair for pair, kept in zip(pairs, plain, strict=True) if kept]
        keys += pairs
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
        textured=textured,
        faults=faults,
    )


def _textures(
    geometry: dict[str, Any],
    depth: int,
    surfaces: list[Any],
    ctx: Context,
    where: str,
    faults: Counter[str],
) -> dict[int, tuple[int, np.ndarray, list[np.ndarray]]]:
    """By surface, the texture it wears in the theme read: the texture's index, its image and
    each ring's texture coordinates. A surface whose texture values do not fit its rings
    (counted in ``faults``) or whose image cannot be used wears none."""
    if ctx.images is None or not ctx.textures:
        return {}
    theme = ctx.theme_of(geometry.get("texture"))
    if not isinstance(theme, dict):
        return {}
    values = _values(theme.get("values"), depth, len(surfaces))
    worn: dict[int, tuple[int, np.ndarray, list[np.ndarray]]] = {}
    for k, (rings, value) in enumerate(zip(surfaces, values, strict=True)):
        found = _texture_of(rings, value, ctx, faults)
        if found is None:
            continue
        texture, uv = found
        entry = ctx.textures[texture]
        uri = entry.get("image") if isinstance(entry, dict) else None
        image = (
            ctx.images.image(uri, f"{ctx.tally.source}: {where}") if isinstance(uri, str) else None
        )
        if image is None:
            if not isinstance(uri, str):
                faults["name a texture without an image"] += 1
            continue
        worn[k] = (texture, image, uv)
    return worn


def _texture_of(
    rings: list[Any], value: Any, ctx: Context, faults: Counter[str]
) -> tuple[int, list[np.ndarray]] | None:
    """A surface's texture index and its rings' texture coordinates from its texture value
    (per ring: the texture's index, then an index into ``vertices-texture`` per point), or
    None where it wears none or they do not fit (counted in ``faults``)."""
    if not isinstance(value, list) or not value or value[0] in ([None], None):
        return None
    if len(value) != len(rings):
        faults["have texture values that do not match their rings"] += 1
        return None
    texture = value[0][0] if isinstance(value[0], list) and value[0] else None
    if not isinstance(texture, int) or isinstance(texture, bool):
        faults["have a texture index that is not a whole number"] += 1
        return None
    if not 0 <= texture < len(ctx.textures):
        faults[f"name texture {texture}, which does not exist"] += 1
        return None
    uv = []
    for ring, entry in zip(rings, value, strict=True):
        if not isinstance(entry, list) or len(entry) != len(ring) + 1 or entry[0] != texture:
            faults["have texture values that do not match their rings"] += 1
            return None
        at = entry[1:]
        if not all(isinstance(i, int) and not isinstance(i, bool) for i in at) or not all(
            0 <= i < len(ctx.texture_vertices) for i in at
        ):
            faults["refer to texture vertices that do not exist"] += 1
            return None
        coordinates = ctx.texture_vertices[at]
        if not np.isfinite(coordinates).all():
            faults["have texture coordinates that are not two finite numbers"] += 1
            return None
        uv.append(coordinates)
    return texture, uv


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
