"""CityJSON reader: CityJSON 1.1 and 2.0 (``.json``, ``.city.json``) and CityJSONSeq
(``.city.jsonl``), each also gzip-compressed (``.gz``). CityJSON 1.0 is read the same way (its
numeric ``lod`` values become labels: ``2`` → ``"2"``); other versions are refused.

Every CityObject with geometry or with children becomes a :class:`Node`: ``id`` is its key (the
writers make it a valid X3D DEF; the raw key is kept in ``attributes["id"]``), ``type`` its
CityObject type, ``attributes`` its own ``attributes`` plus ``id`` and ``type`` (which win over
source attributes of those names). Children (``children``/``parents``: BuildingParts,
Installations…) are the ``children`` of their parent's node; an object without geometry of its
own is a node without geometry whose children carry it. ``types`` keeps only objects of those
types and the descendants of kept ones (a kept descendant of a dropped object becomes a root).

Geometry: Solid, MultiSolid, CompositeSolid, MultiSurface and CompositeSurface (points and
lines are ignored). Polygons with holes are triangulated :data:`BATCH` objects at a time, in one
:func:`lodconvert.polygons.triangulate_many` call that ear-clips each as
:func:`~lodconvert.polygons.triangulate` would (a lone ring of three indices is kept as it is).
Every LoD of an object is one :class:`Mesh` in ``node.lods`` under the ``lod`` string (``"1.2"``);
``node.geometry`` is the highest of them (in numeric order of the label). A mesh has one part
per semantic class — roof, wall, ground, other (:mod:`lodconvert.semantics`) — and material: the
``diffuseColor`` (and ``transparency``) of ``appearance.materials`` in the first theme each
geometry lists wins over the class colour. CityJSON materials follow X3D's, whose colours are
taken as sRGB as X3D browsers draw them, so they become the part's sRGB base colour unchanged.
Surfaces of no semantic class take their object type's colour where
:data:`lodconvert.semantics.TYPE_COLORS` has one. Textures are not read.

Vertices: the integer ``vertices`` are scaled and translated by ``transform`` into float64
coordinates of the file's CRS, kept as they are (no origin is taken off: the pipeline stores
each chain relative to its own float64 centre). A file without ``transform`` (which CityJSON
1.1 and 2.0 require) has its vertices taken as given, integers or not. Geometry templates are
read once per template into one :class:`Mesh` that every ``GeometryInstance`` node shares, in
the template's frame, with the instance's ``transform``: its ``transformationMatrix`` (4×4, row
by row) moved to its reference point. An object with several instances, or instances beside
geometry of its own, gets one child node per instance (``<id>-instance<k>``).

Checks (:mod:`.geometry_checks`): degenerate polygons (those
:func:`~lodconvert.polygons.triangulate` refuses) and triangles without area are dropped and
counted; an object with a boundary index out of range, a malformed boundary, bad coordinates or
an extent the outputs cannot hold is reported (one line naming file and object) in the tally's
``skipped`` and left out, the rest of its batch converts; so is an object whose JSON is not of
the shape CityJSON gives it.

CRS: ``metadata.referenceSystem`` in its URL or URN form becomes ``EPSG:<code>`` on the scene
and every node; none declared leaves it ``None``. A geographic CRS is refused (not supported
yet). CityJSONSeq is read line by line: the header line (``transform``, ``metadata``,
``geometry-templates``) first, then one ``CityJSONFeature`` per line; features are read until
they hold :data:`BATCH` objects, then triangulated together and their nodes yielded, so memory
holds one batch of features at a time; a line that is not a feature is reported and skipped.
"""

from __future__ import annotations

import gc
import gzip
import json
import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from itertools import chain, repeat
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import InputError
from ..limits import DEFAULT_LIMITS, Limits
from ..model import Mesh, Node, Scene, Surface
from ..polygons import triangulate_many
from ..semantics import DEFAULT_PALETTE, Palette
from . import Format
from .geometry_checks import (
    InputTally,
    attach_tally,
    check_extent,
    checked_vertices,
    faces_with_area,
)

_CLASSES = ("RoofSurface", "WallSurface", "GroundSurface", None)
"""Semantic classes in part order (None: any other surface)."""
_SURFACE_DEPTH = {
    "MultiSurface": 1,
    "CompositeSurface": 1,
    "Solid": 2,
    "MultiSolid": 3,
    "CompositeSolid": 3,
}
"""How deep the list of surfaces is nested in each geometry type's ``boundaries``."""
_EPSG = re.compile(r"EPSG(?:/[^/]*/|:[^:]*:|:)(\d+)\s*$", re.IGNORECASE)
_VERSIONS = ("1.", "2.")
BATCH = 64
"""City objects whose polygons are triangulated together (a CityJSONSeq reader holds the
features they come in until then)."""


@dataclass
class _Context:
    """What the geometry of a file (or a CityJSONSeq feature) is read against."""

    tally: InputTally
    vertices: np.ndarray
    crs: str | None
    materials: list[dict[str, Any]] = field(default_factory=list)
    templates: list[dict[str, Any]] = field(default_factory=list)
    template_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    shared: dict[int, tuple[str, Mesh] | None] = field(default_factory=dict)
    """Template index → its (lod, Mesh), read once, or None when it holds no face."""
    counted: set[int] = field(default_factory=set)
    """Ids of the templates' meshes already counted against the limits (each counts once; they
    live as long as ``shared``, so no other mesh takes their id, as the meshes of objects
    already handed on, and freed, do)."""
    palette: Palette = DEFAULT_PALETTE
    """Colours of the semantic classes."""


# --- reading the file -----------------------------------------------------------------------------


def _open_text(path: Path) -> IO[str]:
    """``path`` opened as UTF-8 text, through gzip when it ends in ``.gz``."""
    if path.name.lower().endswith(".gz"):
        return gzip.open(path, "rt", encoding="utf-8")
    return path.open(encoding="utf-8")


def _document(path: Path, limits: Limits) -> dict[str, Any]:
    """The JSON object of a ``.json`` file; :class:`InputError` unless it is CityJSON."""
    try:
        with _open_text(path) as handle:
            text = handle.read(limits.decompressed_bytes + 1)
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot be read ({exc})", str(path)) from None
    if len(text) > limits.decompressed_bytes:
        raise InputError(
            f"is larger than the limit of {limits.decompressed_bytes:,} bytes "
            "(raise it with --limit decompressed_bytes=N)",
            str(path),
        )
    collecting = gc.isenabled()
    gc.disable()  # JSON makes no cycles; full passes would scan the growing document again
    try:
        data = _parsed(text, str(path))
    finally:
        if collecting:
            gc.enable()
    return _cityjson(data, "CityJSON", str(path))


def _parsed(text: str, where: str) -> Any:
    """``text`` parsed as JSON; :class:`InputError` saying it is not CityJSON otherwise."""
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise InputError(f"is not CityJSON (not valid JSON: {exc})", where) from None


def _cityjson(data: Any, kind: str, where: str) -> dict[str, Any]:
    """``data`` when it is a JSON object of ``type`` ``kind`` (of a version read, for a
    ``CityJSON`` object); :class:`InputError` otherwise."""
    if not isinstance(data, dict):
        raise InputError(f"is not CityJSON (a JSON {type(data).__name__}, not an object)", where)
    if data.get("type") != kind:
        raise InputError(f"is not CityJSON (its type is {data.get('type')!r}, not {kind!r})", where)
    version = str(data.get("version", ""))
    if kind == "CityJSON" and not version.startswith(_VERSIONS):
        raise InputError(f"is CityJSON {version or 'of no version'}; 1.1 and 2.0 are read", where)
    if not isinstance(data.get("CityObjects", {}), dict):
        raise InputError("is not CityJSON (its CityObjects is not an object)", where)
    return data


def _declared(metadata: Any, crs: str | None) -> Any:
    """The metadata whose reference system is read: ``crs`` given by the user wins."""
    return {"referenceSystem": crs} if crs is not None else metadata


def _scene_crs(metadata: Any, where: str) -> str | None:
    """``metadata.referenceSystem`` as ``EPSG:<code>`` (other forms as given), or None;
    :class:`InputError` for a geographic CRS."""
    system = metadata.get("referenceSystem") if isinstance(metadata, dict) else None
    if not system:
        return None
    match = _EPSG.search(str(system))
    if not match:
        return str(system)
    crs = f"EPSG:{int(match.group(1))}"
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    try:
        geographic = CRS.from_user_input(crs).is_geographic
    except CRSError:
        return crs
    if geographic:
        raise InputError(
            f"has a geographic CRS ({crs}: angles, not metres); geographic CRSs are not "
            "supported yet",
            where,
        )
    return crs


def _vertices(values: Any, transform: Any, where: str) -> np.ndarray:
    """A vertex list in float64 (scaled and translated by ``transform`` where given)."""
    try:
        v = np.asarray(values if values else np.zeros((0, 3)), dtype=np.float64)
        if isinstance(transform, dict):
            v = v * np.asarray(transform["scale"], dtype=np.float64) + np.asarray(
                transform["translate"], dtype=np.float64
            )
    except (ValueError, TypeError, KeyError) as exc:
        raise InputError(f"has malformed vertices or transform ({exc})", where) from None
    return checked_vertices(v.reshape(-1, 3) if v.size == 0 else v, where)


def _context(
    data: dict[str, Any], tally: InputTally, crs: str | None, palette: Palette
) -> _Context:
    """The context of a CityJSON document: vertices, materials, templates."""
    where = tally.source
    tally.count(len(data.get("vertices") or ()), 0, declared=True)
    appearance = data.get("appearance") or {}
    templates = data.get("geometry-templates") or {}
    return _Context(
        tally=tally,
        vertices=_vertices(data.get("vertices"), data.get("transform"), where),
        crs=crs,
        materials=list(appearance.get("materials") or []),
        templates=list(templates.get("templates") or []),
        template_vertices=_vertices(templates.get("vertices-templates"), None, where),
        palette=palette,
    )


# --- geometry -------------------------------------------------------------------------------------


def _surfaces(boundaries: Any, depth: int) -> list[Any]:
    """The surfaces (lists of rings) of ``boundaries`` nested ``depth`` lists deep."""
    items = [boundaries]
    for _ in range(depth):
        items = [inner for outer in items for inner in (outer or [])]
    return items


def _values(values: Any, depth: int, count: int) -> list[Any]:
    """Per-surface values (semantics, materials) nested like the surfaces, padded with None
    (all None when they are not nested so)."""
    try:
        flat = _surfaces(values, depth) if isinstance(values, list) else []
    except TypeError:
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


_LIST = {list}
_INDICES = {int, type(None)}


def _rings(surfaces: list[Any]) -> tuple[np.ndarray, list[int], list[int]]:
    """Every ring's vertex indices end to end (int64), each ring's length and each surface's
    number of rings. Rings that are lists of numbers are read in one go; anything else ring
    by ring as ``np.asarray(ring, dtype=np.int64).ravel()``, which also says what is wrong
    (TypeError, ValueError, OverflowError)."""
    if set(map(type, surfaces)) <= _LIST:
        rings = list(chain.from_iterable(surfaces))
        if set(map(type, rings)) <= _LIST:
            try:
                index = np.array(list(chain.from_iterable(rings)), dtype=np.int64)
            except (TypeError, ValueError, OverflowError):
                index = None  # read ring by ring below, for the error of the ring at fault
            if index is not None and index.ndim == 1:
                return index, list(map(len, rings)), list(map(len, surfaces))
    arrays = [[np.asarray(r, dtype=np.int64).ravel() for r in s] for s in surfaces]
    flat = [ring for surface in arrays for ring in surface]
    index = np.concatenate(flat) if flat else np.zeros(0, np.int64)
    return index, [len(ring) for ring in flat], [len(surface) for surface in arrays]


@dataclass(eq=False)
class _Lod:
    """The polygons of one LoD of an object (or of one template), read and checked, waiting
    to be triangulated with the rest of a batch (:func:`_triangulate`), which sets ``mesh``
    and ``dropped``."""

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


def _read_lod(
    label: str,
    geometries: list[dict[str, Any]],
    vertices: np.ndarray,
    ctx: _Context,
    where: str,
    kind: str,
) -> _Lod:
    """The polygons of ``geometries`` (of one LoD) indexing ``vertices``, each in its part (one
    per semantic class and material, coloured). Raises :class:`InputError` for bad indices or
    boundaries."""
    indices, lengths, counts, keys = [], [], [], []
    for geometry in geometries:
        depth = _SURFACE_DEPTH[geometry["type"]]
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
        classes = _classes(geometry, depth, len(ring_counts))
        keys += zip(classes, _materials(geometry, depth, len(ring_counts)), strict=True)
        indices.append(index)
        lengths += ring_lengths
        counts += ring_counts
    parts = sorted(dict.fromkeys(keys))
    rank = {key: k for k, key in enumerate(parts)}
    return _Lod(
        label=label,
        vertices=vertices,
        index=np.concatenate(indices) if indices else np.zeros(0, np.int64),
        ring_lengths=np.array(lengths, dtype=np.int64),
        ring_counts=np.array(counts, dtype=np.int64),
        part_of=np.fromiter(map(rank.__getitem__, keys), dtype=np.int64, count=len(keys)),
        colors=[_color(_CLASSES[klass], material, ctx, kind) for klass, material in parts],
    )


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


def _triangulate(lods: list[_Lod]) -> None:
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
        lod.mesh = Mesh(surfaces) if surfaces else None


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


def _color(kind: str | None, material: Any, ctx: _Context, object_type: str) -> np.ndarray:
    """A part's sRGB RGBA colour: its material's, else its semantic class's."""
    if isinstance(material, int) and 0 <= material < len(ctx.materials):
        entry = ctx.materials[material]
        diffuse = entry.get("diffuseColor") if isinstance(entry, dict) else None
        if isinstance(diffuse, list) and len(diffuse) == 3:
            alpha = 1.0 - float(entry.get("transparency", 0.0))
            rgba = np.clip(np.nan_to_num(np.array([*diffuse, alpha], dtype=np.float64)), 0, 1)
            return np.rint(rgba * 255).astype(np.uint8)
    return ctx.palette.of(kind, object_type)


def _mesh(
    geometries: list[dict[str, Any]], vertices: np.ndarray, ctx: _Context, where: str, kind: str
) -> tuple[Mesh | None, int]:
    """The Mesh of ``geometries`` (of one LoD) indexing ``vertices``, one part per semantic
    class and material, and how many faces were dropped (degenerate polygons, triangles
    without area). Raises :class:`InputError` for bad indices or boundaries."""
    lod = _read_lod("", geometries, vertices, ctx, where, kind)
    _triangulate([lod])
    return lod.mesh, lod.dropped


def _lod_key(label: str) -> tuple[float, ...]:
    """Numeric sort key of a LoD label (``"2.2"`` → (2, 2)); non-numeric labels sort first."""
    try:
        return tuple(float(p) for p in label.split("."))
    except ValueError:
        return (-1.0,)


def _lod_label(value: Any) -> str:
    """A LoD as its label (CityJSON 1.0 wrote numbers: ``2`` → ``"2"``)."""
    return f"{value:g}" if isinstance(value, int | float) else str(value)


def _template(index: Any, ctx: _Context, where: str, kind: str) -> tuple[str, Mesh] | None:
    """Template ``index`` as its (LoD label, Mesh), read once per file (coloured for the
    type ``kind`` of the first object using it)."""
    if not isinstance(index, int) or not 0 <= index < len(ctx.templates):
        raise InputError(f"uses template {index!r}; the file has {len(ctx.templates)}", where)
    if index not in ctx.shared:
        template = ctx.templates[index]
        if template.get("type") not in _SURFACE_DEPTH:
            ctx.shared[index] = None
        else:
            mesh, dropped = _mesh([template], ctx.template_vertices, ctx, where, kind)
            ctx.tally.dropped_faces += dropped
            label = _lod_label(template.get("lod", ""))
            ctx.shared[index] = (label, mesh) if mesh is not None else None
    return ctx.shared[index]


def _placement(geometry: dict[str, Any], ctx: _Context, where: str) -> np.ndarray:
    """An instance's 4×4 transform: its ``transformationMatrix`` moved to its reference
    point."""
    try:
        matrix = np.asarray(geometry.get("transformationMatrix", np.eye(4)), dtype=np.float64)
        matrix = matrix.reshape(4, 4).copy()
        (point,) = geometry["boundaries"]
        matrix[:3, 3] += ctx.vertices[int(point)]
    except (TypeError, ValueError, KeyError, IndexError) as exc:
        raise InputError(f"has a malformed GeometryInstance ({exc})", where) from None
    if not np.isfinite(matrix).all():
        raise InputError("has a GeometryInstance with a non-finite transformationMatrix", where)
    return matrix


def _world_bounds(mesh: Mesh, transform: np.ndarray | None) -> np.ndarray:
    """(2, 3) bounds of ``mesh`` placed by ``transform``."""
    if transform is None:
        return mesh.bounds
    corners = np.array(np.meshgrid(*mesh.bounds.T)).reshape(3, -1).T
    placed = corners @ transform[:3, :3].T + transform[:3, 3]
    return np.stack([placed.min(axis=0), placed.max(axis=0)])


# --- objects --------------------------------------------------------------------------------------


def _instance_nodes(node: Node, placed: list[tuple[tuple[str, Mesh], np.ndarray]]) -> None:
    """Give ``node`` its geometry instances: placing the node itself when it has one and no
    geometry of its own, else as child nodes ``<id>-instance<k>``."""
    if len(placed) == 1 and node.geometry is None:
        (label, mesh), node.transform = placed[0]
        node.geometry, node.lods = mesh, {label: mesh}
        return
    for k, ((label, mesh), transform) in enumerate(placed, start=1):
        child_id = f"{node.id}-instance{k}"
        node.children.append(
            Node(
                id=child_id,
                geometry=mesh,
                type=node.type,
                attributes={**node.attributes, "id": child_id},
                crs=node.crs,
                transform=transform,
                lods={label: mesh},
            )
        )


@dataclass(eq=False)
class _Read:
    """A CityObject read up to the triangulation of its polygons: its node (children and
    geometry not yet attached), its LoDs, its geometry instances, and the first problem met
    reading it. The LoDs are those before the problem: finishing the object checks them
    first and then raises it, as reading it in one go would have."""

    key: str
    ctx: _Context
    node: Node | None = None
    kind: str = ""
    lods: list[_Lod] = field(default_factory=list)
    instances: list[dict[str, Any]] = field(default_factory=list)
    problem: Exception | None = None


_MALFORMED = (TypeError, ValueError, AttributeError, KeyError, IndexError)
"""What JSON of a shape CityJSON does not give raises somewhere in an object."""


def _read_object(key: str, obj: Any, ctx: _Context) -> _Read:
    """CityObject ``key`` read (not yet triangulated); a problem is kept in the result."""
    read = _Read(key, ctx)
    try:
        if not isinstance(obj, dict):
            raise InputError("is not a JSON object", key)
        read.kind = kind = str(obj.get("type", ""))
        own = obj.get("attributes")
        attributes = {**(own if isinstance(own, dict) else {}), "id": key, "type": kind}
        read.node = Node(id=key, type=kind, attributes=attributes, crs=ctx.crs)
        by_lod: dict[str, list[dict[str, Any]]] = {}
        for geometry in obj.get("geometry") or []:
            if not isinstance(geometry, dict):
                raise InputError("has a geometry that is not a JSON object", key)
            if geometry.get("type") == "GeometryInstance":
                read.instances.append(geometry)
            elif geometry.get("type") in _SURFACE_DEPTH:
                by_lod.setdefault(_lod_label(geometry.get("lod", "")), []).append(geometry)
        for label in sorted(by_lod, key=_lod_key):
            read.lods.append(_read_lod(label, by_lod[label], ctx.vertices, ctx, key, kind))
    except (InputError, *_MALFORMED) as exc:
        read.problem = exc
    return read


def _node(read: _Read) -> tuple[Node, int]:
    """The node of a read and triangulated object with its LoDs and geometry instances, and
    how many of its faces were dropped. :class:`InputError` (naming the object) when it
    cannot be converted."""
    key, ctx, kind = read.key, read.ctx, read.kind
    dropped = 0
    for lod in read.lods:
        dropped += lod.dropped
        if lod.mesh is not None:
            check_extent(lod.mesh.bounds, key)
    if read.problem is not None:
        raise read.problem
    node = read.node
    assert node is not None
    node.lods = {lod.label: lod.mesh for lod in read.lods if lod.mesh is not None}
    if node.lods:
        node.geometry = node.lods[max(node.lods, key=_lod_key)]
    placed = []
    for geometry in read.instances:
        shared = _template(geometry.get("template"), ctx, key, kind)
        if shared is not None:
            transform = _placement(geometry, ctx, key)
            check_extent(_world_bounds(shared[1], transform), key)
            placed.append((shared, transform))
    _instance_nodes(node, placed)
    return node, dropped


def _checked_node(read: _Read) -> Node | None:
    """:func:`_node`, or None when the object is left out (recorded in the tally: an object
    that cannot be converted, or one whose faces all had no area)."""
    key, ctx = read.key, read.ctx
    tally = ctx.tally
    try:
        node, dropped = _node(read)
    except InputError as exc:
        read.problem = None  # its traceback holds the read: no cycle left for the collector
        tally.skipped.append({"id": key, "reason": str(exc)})
        return None
    except _MALFORMED as exc:
        # JSON of an unexpected shape somewhere in the object: leave the object out
        read.problem = None
        error = InputError(f"has malformed content ({type(exc).__name__}: {exc})", key)
        tally.skipped.append({"id": key, "reason": str(error)})
        return None
    tally.dropped_faces += dropped
    if dropped and node.geometry is None and not node.children:
        tally.skip(key, dropped)
        return None
    if dropped:
        tally.dropped_by_object[key] = dropped
    templates = {id(e[1]) for e in ctx.shared.values() if e is not None} if read.instances else ()
    for mesh in {id(m): m for n in node.walk() for m in n.lods.values()}.values():
        if id(mesh) in templates:
            if id(mesh) in ctx.counted:
                continue  # a template's mesh counts once, where it is first used
            ctx.counted.add(id(mesh))
        tally.count(mesh.vertex_count, mesh.face_count)
    return node


def _checked_nodes(objects: list[tuple[str, Any, _Context]]) -> Iterator[Node | None]:
    """:func:`_checked_node` of each object, their polygons triangulated together; each is
    finished (and recorded in the tally) as it is yielded."""
    reads = [_read_object(key, obj, ctx) for key, obj, ctx in objects]
    _triangulate([lod for read in reads for lod in read.lods])
    return map(_checked_node, reads)


def _keys(values: Any) -> list[str]:
    """The strings of a JSON list (``children``, ``parents``); nothing for anything else."""
    return [v for v in values if isinstance(v, str)] if isinstance(values, list) else []


def _children(objects: dict[str, Any]) -> dict[str, list[str]]:
    """Child keys of every object, from ``children`` and ``parents`` alike, in file order."""
    found: dict[str, dict[str, None]] = {key: {} for key in objects}
    for key, obj in objects.items():
        if not isinstance(obj, dict):
            continue
        for child in _keys(obj.get("children")):
            if child in objects and child != key:
                found[key][child] = None
        for parent in _keys(obj.get("parents")):
            if parent in objects and parent != key:
                found[parent][key] = None
    return {key: list(kids) for key, kids in found.items()}


@dataclass
class _Objects:
    """The CityObjects of a file or of a CityJSONSeq feature: their child keys and which of
    them are read (each at most once), in the order their tree is built (children before
    their parent, parents in file order)."""

    objects: dict[str, Any]
    types: frozenset[str] | None
    children: dict[str, list[str]] = field(init=False)
    order: list[str] = field(init=False)

    def __post_init__(self) -> None:
        self.children = _children(self.objects)
        order: list[str] = []
        self.roots(lambda key: order.append(key))
        self.order = order

    def roots(self, node_of: Callable[[str], Node | None]) -> list[Node]:
        """The root nodes: each object of a kept type (all, when ``types`` is None, else those
        types and the descendants of kept objects) that ``node_of`` gives a node with geometry
        or children, its children below it; kept descendants of objects left out (None) take
        their place."""
        objects, types, children = self.objects, self.types, self.children
        below = {child for kids in children.values() for child in kids}
        seen: set[str] = set()

        def build(key: str, kept: bool) -> list[Node]:
            if key in seen:  # a cycle, or a second parent
                return []
            seen.add(key)
            obj = objects[key]
            kept = kept or types is None or (isinstance(obj, dict) and obj.get("type") in types)
            kids = [node for child in children[key] for node in build(child, kept)]
            node = node_of(key) if kept else None
            if node is None:
                return kids
            node.children.extend(kids)
            return [node] if node.geometry is not None or node.children else []

        return [node for key in objects if key not in below for node in build(key, False)]


def _object_nodes(
    objects: dict[str, Any], ctx: _Context, types: frozenset[str] | None
) -> list[Node]:
    """The root nodes of ``objects`` (:meth:`_Objects.roots`), read :data:`BATCH` objects at a
    time."""
    tree = _Objects(objects, types)
    nodes: dict[str, Node | None] = {}
    for at in range(0, len(tree.order), BATCH):
        keys = tree.order[at : at + BATCH]
        nodes.update(
            zip(keys, _checked_nodes([(key, objects[key], ctx) for key in keys]), strict=True)
        )
    return tree.roots(nodes.__getitem__)


# --- the readers ----------------------------------------------------------------------------------


def _types(types: Iterable[str] | None) -> frozenset[str] | None:
    return frozenset(types) if types is not None else None


def _read_document(
    path: Path, limits: Limits, types: frozenset[str] | None, palette: Palette, crs: str | None
) -> Scene:
    """A ``.json`` CityJSON file: every node built before the scene is returned."""
    data = _document(path, limits)
    tally = InputTally(str(path), limits)
    crs = _scene_crs(_declared(data.get("metadata"), crs), str(path))
    ctx = _context(data, tally, crs, palette)
    nodes = _object_nodes(data.get("CityObjects") or {}, ctx, types)
    size = sum(1 for node in nodes for n in node.walk() if n.geometry is not None)
    if not size and not tally.skipped:
        if tally.dropped_faces:
            raise tally.nothing_left()
        which = f"of type {', '.join(sorted(types))} " if types is not None else ""
        raise InputError(f"has no CityObject {which}with surfaces", str(path))
    scene = Scene(source=str(path), nodes=nodes, crs=crs, size=size)
    scene.attributes["cityjson_version"] = str(data.get("version"))
    return attach_tally(scene, tally)


@dataclass
class _Feature:
    """A CityJSONSeq line waiting in a batch: a feature's context and objects, or the problem
    that has the line skipped."""

    where: str
    ctx: _Context | None = None
    tree: _Objects | None = None
    problem: InputError | None = None


def _feature(
    line: str, where: str, header: dict[str, Any], ctx: _Context, types: frozenset[str] | None
) -> _Feature:
    """The ``CityJSONFeature`` of a line, against the header's transform and context."""
    try:
        feature = _cityjson(_parsed(line, where), "CityJSONFeature", where)
        appearance = feature.get("appearance") or {}
        local = _Context(
            tally=ctx.tally,
            vertices=_vertices(feature.get("vertices"), header.get("transform"), where),
            crs=ctx.crs,
            materials=list(appearance.get("materials") or ctx.materials),
            templates=ctx.templates,
            template_vertices=ctx.template_vertices,
            shared=ctx.shared,
            counted=ctx.counted,
            palette=ctx.palette,
        )
    except InputError as exc:
        return _Feature(where, problem=exc)
    return _Feature(where, local, _Objects(feature.get("CityObjects") or {}, types))


def _feature_nodes(
    handle: IO[str], header: dict[str, Any], ctx: _Context, types: frozenset[str] | None
) -> Iterator[Node]:
    """The nodes of each ``CityJSONFeature`` line of ``handle``, a line that is not one
    recorded as skipped. Lines are read until they hold :data:`BATCH` objects (or are that
    many), whose polygons are triangulated together; their nodes are then yielded feature by
    feature, so memory holds one batch of features at a time."""
    waiting: list[_Feature] = []
    objects = 0
    with handle:
        for number, line in enumerate(handle, start=2):
            if not line.strip():
                continue
            feature = _feature(line, f"line {number}", header, ctx, types)
            waiting.append(feature)
            objects += len(feature.tree.objects) if feature.tree is not None else 0
            if objects >= BATCH or len(waiting) >= BATCH:
                yield from _finished_features(waiting, ctx.tally)
                waiting, objects = [], 0
        yield from _finished_features(waiting, ctx.tally)


def _finished_features(waiting: list[_Feature], tally: InputTally) -> Iterator[Node]:
    """The root nodes of a batch of features, in line order, their polygons triangulated
    together; each feature's vertices are counted, and its objects finished, as it comes."""
    reads = [
        [_read_object(key, f.tree.objects[key], f.ctx) for key in f.tree.order]
        if f.ctx is not None and f.tree is not None
        else []
        for f in waiting
    ]
    _triangulate([lod for each in reads for read in each for lod in read.lods])
    for feature, each in zip(waiting, reads, strict=True):
        if feature.ctx is None or feature.tree is None:
            tally.skipped.append({"id": feature.where, "reason": str(feature.problem)})
            continue
        tally.count(len(feature.ctx.vertices), 0, declared=True)
        nodes = {read.key: _checked_node(read) for read in each}
        yield from feature.tree.roots(nodes.__getitem__)


def _read_sequence(
    path: Path, limits: Limits, types: frozenset[str] | None, palette: Palette, crs: str | None
) -> Scene:
    """A CityJSONSeq file: the header read now, the features' nodes yielded lazily."""
    try:
        handle = _open_text(path)
        first = handle.readline(limits.decompressed_bytes)
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot be read ({exc})", str(path)) from None
    try:
        header = _cityjson(_parsed(first, str(path)), "CityJSON", str(path))
        tally = InputTally(str(path), limits)
        crs = _scene_crs(_declared(header.get("metadata"), crs), str(path))
        ctx = _context(header, tally, crs, palette)
    except InputError:
        handle.close()
        raise
    scene = Scene(source=str(path), nodes=_feature_nodes(handle, header, ctx, types), crs=crs)
    scene.attributes["cityjson_version"] = str(header.get("version"))
    return attach_tally(scene, tally)


def read_cityjson(
    path: Path,
    limits: Limits = DEFAULT_LIMITS,
    types: Iterable[str] | None = None,
    colors: Palette = DEFAULT_PALETTE,
    crs: str | None = None,
) -> Scene:
    """Read a CityJSON (``.json``) or CityJSONSeq (``.jsonl``) file, ``.gz`` or not, into a
    Scene (see the module docstring); :class:`InputError` with a one-line reason when it
    cannot be. ``types``: keep only CityObjects of these types (and their descendants);
    ``colors``: the semantic classes' colours (:mod:`lodconvert.semantics`); ``crs``
    replaces the CRS the file declares.
    The scene carries an :class:`~.geometry_checks.InputTally` of dropped faces and skipped
    objects."""
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file" if not path.exists() else "is not a file", str(path))
    if path.stat().st_size == 0:
        raise InputError("is empty", str(path))
    name = path.name.lower().removesuffix(".gz")
    read = _read_sequence if name.endswith(".jsonl") else _read_document
    return read(path, limits, _types(types), colors, crs)


FORMAT = Format(
    name="cityjson",
    suffixes=(".json", ".jsonl"),
    read=read_cityjson,
    read_options=("limits", "types", "colors", "crs"),
)
