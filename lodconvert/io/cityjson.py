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

Geometry: Solid, MultiSolid, CompositeSolid, MultiSurface and CompositeSurface, polygons with
holes triangulated by :func:`lodconvert.polygons.triangulate` (points and lines are ignored).
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

Checks (:mod:`.geometry_checks`): degenerate polygons (:class:`DegenerateRing`) and triangles
without area are dropped and counted; an object with a boundary index out of range, a malformed
boundary, bad coordinates or an extent the outputs cannot hold is reported (one line naming file
and object) in the tally's ``skipped`` and left out, the rest convert; so is an object whose
JSON is not of the shape CityJSON gives it.

CRS: ``metadata.referenceSystem`` in its URL or URN form becomes ``EPSG:<code>`` on the scene
and every node; none declared leaves it ``None``. A geographic CRS is refused (not supported
yet). CityJSONSeq is read line by line: the header line (``transform``, ``metadata``,
``geometry-templates``) first, then one ``CityJSONFeature`` per line, whose nodes are yielded
as they are read, so memory holds one feature at a time; a line that is not a feature is
reported and skipped.
"""

from __future__ import annotations

import gzip
import json
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import InputError
from ..limits import DEFAULT_LIMITS, Limits
from ..model import Mesh, Node, Scene, Surface
from ..polygons import DegenerateRing, triangulate
from ..semantics import DEFAULT_PALETTE, Palette
from . import Format
from .geometry_checks import (
    InputTally,
    attach_tally,
    check_extent,
    checked_vertices,
    kept_faces,
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
    """Ids of the meshes already counted against the limits (shared ones count once)."""
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
    return _cityjson(_parsed(text, str(path)), "CityJSON", str(path))


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


def _classes(geometry: dict[str, Any], depth: int, count: int) -> list[str | None]:
    """Each surface's semantic class (one of :data:`_CLASSES`, None for any other)."""
    semantics = geometry.get("semantics")
    if not isinstance(semantics, dict):
        return [None] * count
    kinds = [s.get("type") if isinstance(s, dict) else None for s in semantics.get("surfaces", [])]
    classes: list[str | None] = []
    for value in _values(semantics.get("values"), depth, count):
        kind = kinds[value] if isinstance(value, int) and 0 <= value < len(kinds) else None
        classes.append(kind if kind in _CLASSES else None)
    return classes


def _opened(ring: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Ring indices without a repeated closing point and repeated neighbours (by position),
    as :func:`triangulate` opens rings."""
    points = vertices[ring]
    if len(ring) > 1 and np.array_equal(points[0], points[-1]):
        ring, points = ring[:-1], points[:-1]
    if len(ring) > 1:
        ring = ring[np.r_[True, np.any(points[1:] != points[:-1], axis=1)]]
    return ring


@dataclass
class _Part:
    """Triangles of one part being gathered: faces indexing the vertex list, and faces of
    their own vertices (polygons whose triangulation does not map back to the list)."""

    indexed: list[np.ndarray] = field(default_factory=list)
    own: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)

    def add_polygon(self, rings: list[np.ndarray], vertices: np.ndarray) -> None:
        """Triangulate one polygon (exterior, holes) of vertex indices; raises
        :class:`DegenerateRing`."""
        if len(rings) == 1 and len(rings[0]) == 3:
            self.indexed.append(rings[0][None])
            return
        if not rings or not len(rings[0]):
            raise DegenerateRing("a polygon without points")
        opened = [_opened(ring, vertices) for ring in rings]
        points, faces = triangulate([vertices[ring] for ring in opened])
        index = np.concatenate(opened)
        if len(index) == len(points) and np.array_equal(vertices[index], points):
            self.indexed.append(index[faces])
        else:
            self.own.append((points, faces))

    def surface(self, vertices: np.ndarray, color: np.ndarray, where: str) -> tuple[Surface, int]:
        """The part as a Surface of its triangles with area, holding only the vertices they
        use, and how many triangles without area were dropped."""
        faces = np.concatenate(self.indexed) if self.indexed else np.zeros((0, 3), np.int64)
        chunks, all_faces = list(_compact(vertices, faces)), []
        all_faces.append(chunks.pop())
        offset = len(chunks[0])
        for points, own in self.own:
            chunks.append(points)
            all_faces.append(own + offset)
            offset += len(points)
        points = checked_vertices(np.concatenate(chunks), where)
        kept, dropped = kept_faces(points, np.concatenate(all_faces), where)
        if dropped:
            points, kept = _compact(points, kept)
        return Surface(vertices=points, faces=kept, base_color=color.copy()), dropped


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
    parts: dict[tuple[int, Any], _Part] = {}
    dropped = 0
    for geometry in geometries:
        depth = _SURFACE_DEPTH[geometry["type"]]
        try:
            surfaces = _surfaces(geometry.get("boundaries"), depth)
            rings = [[np.asarray(r, dtype=np.int64).ravel() for r in s] for s in surfaces]
        except (TypeError, ValueError, OverflowError) as exc:
            raise InputError(
                f"has malformed {geometry['type']} boundaries ({exc})", where
            ) from None
        flat = [r for s in rings for r in s]
        index = np.concatenate(flat) if flat else np.zeros(0, np.int64)
        bad = (index < 0) | (index >= len(vertices))
        if bad.any():
            raise InputError(
                f"refers to vertices that do not exist (index {int(index[bad][0])}; "
                f"{len(vertices):,} vertices, 0 to {len(vertices) - 1:,})",
                where,
            )
        classes = _classes(geometry, depth, len(rings))
        materials = _material_values(geometry, depth, len(rings))
        for polygon, kind_of, material in zip(rings, classes, materials, strict=True):
            key = (_CLASSES.index(kind_of), material if isinstance(material, int) else -1)
            try:
                parts.setdefault(key, _Part()).add_polygon(polygon, vertices)
            except DegenerateRing:
                dropped += 1
    surfaces = []
    for (klass, material), part in sorted(parts.items(), key=lambda item: item[0]):
        surface, lost = part.surface(vertices, _color(_CLASSES[klass], material, ctx, kind), where)
        dropped += lost
        if len(surface.faces):
            surfaces.append(surface)
    return (Mesh(surfaces) if surfaces else None), dropped


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


def _node(key: str, obj: dict[str, Any], ctx: _Context) -> tuple[Node, int]:
    """The node of CityObject ``key`` (its children not yet attached) with its LoDs and
    geometry instances, and how many of its faces were dropped. :class:`InputError` (naming
    ``key``) when the object cannot be converted."""
    kind = str(obj.get("type", ""))
    own = obj.get("attributes")
    attributes = {**(own if isinstance(own, dict) else {}), "id": key, "type": kind}
    node = Node(id=key, type=kind, attributes=attributes, crs=ctx.crs)
    by_lod: dict[str, list[dict[str, Any]]] = {}
    instances = []
    for geometry in obj.get("geometry") or []:
        if not isinstance(geometry, dict):
            raise InputError("has a geometry that is not a JSON object", key)
        if geometry.get("type") == "GeometryInstance":
            instances.append(geometry)
        elif geometry.get("type") in _SURFACE_DEPTH:
            by_lod.setdefault(_lod_label(geometry.get("lod", "")), []).append(geometry)
    dropped = 0
    for label in sorted(by_lod, key=_lod_key):
        mesh, lost = _mesh(by_lod[label], ctx.vertices, ctx, key, kind)
        dropped += lost
        if mesh is not None:
            check_extent(mesh.bounds, key)
            node.lods[label] = mesh
    if node.lods:
        node.geometry = node.lods[max(node.lods, key=_lod_key)]
    placed = []
    for geometry in instances:
        shared = _template(geometry.get("template"), ctx, key, kind)
        if shared is not None:
            transform = _placement(geometry, ctx, key)
            check_extent(_world_bounds(shared[1], transform), key)
            placed.append((shared, transform))
    _instance_nodes(node, placed)
    return node, dropped


def _checked_node(key: str, obj: Any, ctx: _Context) -> Node | None:
    """:func:`_node`, or None when the object is left out (recorded in the tally: an object
    that cannot be converted, or one whose faces all had no area)."""
    tally = ctx.tally
    try:
        if not isinstance(obj, dict):
            raise InputError("is not a JSON object", key)
        node, dropped = _node(key, obj, ctx)
    except InputError as exc:
        tally.skipped.append({"id": key, "reason": str(exc)})
        return None
    except (TypeError, ValueError, AttributeError, KeyError, IndexError) as exc:
        # JSON of an unexpected shape somewhere in the object: leave the object out
        error = InputError(f"has malformed content ({type(exc).__name__}: {exc})", key)
        tally.skipped.append({"id": key, "reason": str(error)})
        return None
    tally.dropped_faces += dropped
    if dropped and node.geometry is None and not node.children:
        tally.skip(key, dropped)
        return None
    if dropped:
        tally.dropped_by_object[key] = dropped
    for mesh in {id(m): m for n in node.walk() for m in n.lods.values()}.values():
        if id(mesh) not in ctx.counted:
            ctx.counted.add(id(mesh))
            tally.count(mesh.vertex_count, mesh.face_count)
    return node


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


def _object_nodes(
    objects: dict[str, Any], ctx: _Context, types: frozenset[str] | None
) -> Iterator[Node]:
    """The root nodes of ``objects``: each object of a kept type (all, when ``types`` is
    None, else those types and the descendants of kept objects) with geometry or children,
    its children below it; kept descendants of objects left out take their place."""
    children = _children(objects)
    below = {child for kids in children.values() for child in kids}
    seen: set[str] = set()

    def build(key: str, kept: bool) -> list[Node]:
        if key in seen:  # a cycle, or a second parent
            return []
        seen.add(key)
        obj = objects[key]
        kept = kept or types is None or (isinstance(obj, dict) and obj.get("type") in types)
        kids = [node for child in children[key] for node in build(child, kept)]
        node = _checked_node(key, obj, ctx) if kept else None
        if node is None:
            return kids
        node.children.extend(kids)
        return [node] if node.geometry is not None or node.children else []

    for key in objects:
        if key not in below:
            yield from build(key, False)


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
    nodes = list(_object_nodes(data.get("CityObjects") or {}, ctx, types))
    size = sum(1 for node in nodes for n in node.walk() if n.geometry is not None)
    if not size and not tally.skipped:
        if tally.dropped_faces:
            raise tally.nothing_left()
        which = f"of type {', '.join(sorted(types))} " if types is not None else ""
        raise InputError(f"has no CityObject {which}with surfaces", str(path))
    scene = Scene(source=str(path), nodes=nodes, crs=crs, size=size)
    scene.attributes["cityjson_version"] = str(data.get("version"))
    return attach_tally(scene, tally)


def _feature_nodes(
    handle: IO[str], header: dict[str, Any], ctx: _Context, types: frozenset[str] | None
) -> Iterator[Node]:
    """The nodes of each ``CityJSONFeature`` line of ``handle``, one feature at a time; a
    line that is not one is recorded as skipped."""
    tally = ctx.tally
    with handle:
        for number, line in enumerate(handle, start=2):
            if not line.strip():
                continue
            where = f"line {number}"
            try:
                feature = _cityjson(_parsed(line, where), "CityJSONFeature", where)
                appearance = feature.get("appearance") or {}
                local = _Context(
                    tally=tally,
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
                tally.skipped.append({"id": where, "reason": str(exc)})
                continue
            tally.count(len(local.vertices), 0, declared=True)
            yield from _object_nodes(feature.get("CityObjects") or {}, local, types)


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
