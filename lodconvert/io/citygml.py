"""CityGML reader: CityGML 1.0, 2.0 and 3.0 (``.gml``, ``.xml``, and a ``.gz`` or ``.zip``
holding one such file), streamed one city object at a time.

Every top-level city object (a ``Building``, ``Bridge``, ``Road``, ``LandUse``, ``WaterBody``,
``PlantCover``, ``GenericCityObject``… typed by its element's local name) becomes one
:class:`Node`. Each LoD the object carries (``lodNSolid``, ``lodNMultiSurface``,
``lodNGeometry``, ``lod0FootPrint``/``lod0RoofEdge``, and the same properties of its thematic
surfaces, openings and installations) is read into ``node.lods`` as ``"lod0"`` … ``"lod4"``, one
:class:`Surface` per semantic type (``RoofSurface``, ``WallSurface``, ``Window``…) coloured by
:mod:`lodconvert.semantics`; ``node.geometry`` is the highest LoD above 0 with faces (LoD 0 when
there is no other). A polygon that a solid refers to (``xlink:href``) and a thematic surface
holds is read once, with its semantics. Building (bridge, tunnel) parts are children of their
object: each keeps its own attributes and LoDs, and their geometry is part of the object's, so
that a building is one object of the output however many parts it has. Interiors (rooms,
furniture) and terrain (``ReliefFeature``) are not read.

Geometry stays in the file's coordinates (float64) when its CRS is projected; a geographic CRS
(latitude, longitude, height: EPSG:6697, 4326, 4979) is projected onto a transverse Mercator
centred on the data (:class:`LocalFrame`), whose PROJ definition becomes the scene's CRS.

The parse is hardened: no DTD is loaded, no entity resolved, no network used, and a document
with a DOCTYPE is refused before its content is read; nesting depth and text sizes are held to
the run's :class:`~lodconvert.limits.Limits`, and so is what a ``.gz`` or ``.zip`` inflates to.
Each city object's elements are freed once it is converted, so memory follows the largest
object, not the file. What a reader must check passes :mod:`.geometry_checks`: a polygon whose
ring is degenerate (fewer than three distinct points, no area) is dropped and counted with the
object's dropped faces; an object left with nothing is recorded as skipped.
"""

from __future__ import annotations

import gzip
import re
import zipfile
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from itertools import chain
from pathlib import Path, PurePosixPath
from typing import IO, Any

import numpy as np
from lxml import etree

from ..errors import InputError
from ..limits import DEFAULT_LIMITS, Limits
from ..model import Mesh, Node, Scene, Surface
from ..polygons import triangulate_many
from ..semantics import DEFAULT_PALETTE, Palette
from . import Format
from .geometry_checks import InputTally, attach_tally, check_extent, checked_vertices, kept_faces
from .mesh import object_id

CITYGML_NAMESPACE = re.compile(r"http://www\.opengis\.net/citygml/(1\.0|2\.0|3\.0)")
"""The core namespace of each CityGML version (the root ``CityModel``'s)."""
_GML_NAMESPACES = ("http://www.opengis.net/gml", "http://www.opengis.net/gml/3.2")
_XLINK_HREF = "{http://www.w3.org/1999/xlink}href"
_LOD_PROPERTY = re.compile(
    r"lod([0-4])(Solid|MultiSolid|MultiSurface|CompositeSurface|Surface|Geometry|FootPrint|RoofEdge)"
)
"""Geometry properties read, with their LoD (curves, points and implicit geometry are not)."""
_PART_PROPERTIES = frozenset(
    {
        "consistsOfBuildingPart",
        "buildingPart",
        "consistsOfBridgePart",
        "bridgePart",
        "consistsOfTunnelPart",
        "tunnelPart",
    }
)
_UNREAD_PROPERTIES = frozenset(
    {
        "address",
        "appearance",
        "externalReference",
        "genericAttribute",
        "interiorRoom",
        "interiorFurniture",
        "interiorBuildingInstallation",
        "buildingRoom",
        "buildingFurniture",
        "roomInstallation",
        "interiorBridgeRoom",
        "interiorBridgeInstallation",
        "bridgeRoom",
        "bridgeFurniture",
        "interiorHollowSpace",
        "hollowSpace",
    }
)
"""Properties of a city object that hold no exterior geometry (or geometry not read)."""
_NOT_OBJECTS = frozenset({"ReliefFeature", "CityObjectGroup", "Appearance", "Version"})
"""Top-level features that are not read as objects (terrain, groups, appearances)."""
_POLYGONS = frozenset({"Polygon", "Triangle", "Rectangle", "PolygonPatch"})
_NOT_SURFACES = frozenset(
    {"Point", "MultiPoint", "LineString", "Curve", "MultiCurve", "CompositeCurve", "Envelope"}
)
_ATTRIBUTES = {
    "function": str,
    "usage": str,
    "class": str,
    "roofType": str,
    "yearOfConstruction": int,
    "dateOfConstruction": str,
    "measuredHeight": float,
    "storeysAboveGround": int,
    "storeysBelowGround": int,
}
"""Thematic attributes kept (by local name), with their JSON type."""
_GENERIC_TYPES = {"int": int, "double": float, "measure": float}
"""JSON type of generic attributes by their kind (``gen:intAttribute`` / ``gen:IntAttribute``);
other kinds are kept as text."""
_EPSG = re.compile(r"EPSG(?:/[\d.]+/|:[\d.]*:|:)(\d+)", re.IGNORECASE)
_LIBXML_TEXT_LIMIT = 10_000_000
"""Bytes of one text node libxml2 accepts without ``huge_tree``."""
_LIBXML_DEPTH_LIMIT = 256
"""Nesting depth libxml2 accepts without ``huge_tree``."""
_CHUNK = 1 << 16
"""Bytes read from the file at a time."""
_DEDUP_DECIMALS = 6
"""A polygon whose exterior ring repeats another's of the same LoD to this many decimals is
read once (a solid's copy of a thematic surface's polygon)."""


@dataclass(frozen=True)
class LocalFrame:
    """A transverse Mercator centred on geographic data (``lat0``, ``lon0`` in degrees) on the
    source's ellipsoid: metres east, north and the source's height."""

    source_crs: str
    lat0: float
    lon0: float
    semi_major: float
    inverse_flattening: float
    lat_axis: int
    lon_axis: int

    @property
    def proj(self) -> str:
        """The frame's PROJ definition."""
        return (
            f"+proj=tmerc +lat_0={self.lat0:.9f} +lon_0={self.lon0:.9f} +k=1 +x_0=0 +y_0=0 "
            f"+a={self.semi_major!r} +rf={self.inverse_flattening!r} +units=m +no_defs"
        )

    def record(self) -> dict[str, Any]:
        """What the scene's attributes keep of the frame (JSON-able)."""
        return {"proj": self.proj, "source_crs": self.source_crs, "center": [self.lat0, self.lon0]}

    def project(self, points: np.ndarray) -> np.ndarray:
        """``points`` (n, 3) in the source's axis order, in this frame's metres."""
        import pyproj

        pipeline = pyproj.Transformer.from_pipeline(
            "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
            f"+step {self.proj.replace(' +units=m +no_defs', '')}"
        )
        x, y = pipeline.transform(points[:, self.lon_axis], points[:, self.lat_axis])
        return np.stack([x, y, points[:, 2]], axis=1)


@dataclass
class _Crs:
    """The document's CRS: its EPSG name (horizontal part), vertical part, and the local frame
    geographic coordinates are projected into (set from the first object's coordinates)."""

    name: str | None = None
    vertical: str | None = None
    geographic: Any = None
    frame: LocalFrame | None = None

    @classmethod
    def of(cls, srs_name: str) -> _Crs:
        codes = _EPSG.findall(srs_name)
        if not codes:
            return cls(name=srs_name)
        crs = cls(name=f"EPSG:{codes[0]}", vertical=f"EPSG:{codes[1]}" if len(codes) > 1 else None)
        crs.geographic = _geographic(int(codes[0]))
        return crs

    @property
    def scene_crs(self) -> str | None:
        """What outputs record: the local frame's PROJ definition, else the EPSG name."""
        return self.frame.proj if self.frame is not None else self.name

    def to_metric(self, points: np.ndarray) -> np.ndarray:
        """``points`` in metres: projected onto the local frame when geographic (the frame is
        centred on these points the first time)."""
        if self.geographic is None or not len(points):
            return points
        if self.frame is None:
            lat_axis, lon_axis = self.geographic["axes"]
            center = (points.min(axis=0) + points.max(axis=0)) / 2.0
            self.frame = LocalFrame(
                self.name or "",
                float(np.round(center[lat_axis], 6)),
                float(np.round(center[lon_axis], 6)),
                self.geographic["a"],
                self.geographic["rf"],
                lat_axis,
                lon_axis,
            )
        return self.frame.project(points)


def _geographic(code: int) -> dict[str, Any] | None:
    """For a geographic (or geographic + vertical) EPSG CRS: the latitude and longitude axis
    indices and its ellipsoid; None for any other (or an unknown) code."""
    import pyproj

    try:
        crs = pyproj.CRS.from_epsg(code)
    except pyproj.exceptions.CRSError:
        return None
    horizontal = crs.sub_crs_list[0] if crs.is_compound else crs
    if not horizontal.is_geographic or horizontal.ellipsoid is None:
        return None
    directions = [axis.direction for axis in horizontal.axis_info]
    return {
        "axes": (directions.index("north"), directions.index("east")),
        "a": horizontal.ellipsoid.semi_major_metre,
        "rf": horizontal.ellipsoid.inverse_flattening,
    }


# --- opening the document -------------------------------------------------------------------------


class _Capped:
    """A binary stream that raises :class:`InputError` once more than ``limit`` bytes came
    out of it (what a compressed input inflates to)."""

    def __init__(self, stream: IO[bytes], limit: int, source: str) -> None:
        self.stream, self.limit, self.source, self.total = stream, limit, source, 0

    def read(self, size: int = -1) -> bytes:
        data = self.stream.read(_CHUNK if size is None or size < 0 else size)
        self.total += len(data)
        if self.total > self.limit:
            raise _inflation_error(self.limit, self.source)
        return data

    def close(self) -> None:
        self.stream.close()


def _inflation_error(limit: int, source: str) -> InputError:
    return InputError(
        f"inflates past the limit of {limit:,} bytes (decompressed_bytes; "
        "raise it with --limit decompressed_bytes=N)",
        source,
    )


def _zip_member(archive: zipfile.ZipFile, limits: Limits, source: str) -> zipfile.ZipInfo:
    """The one CityGML file of a zip; :class:`InputError` for unsafe names (``..``, absolute
    paths), a member declared larger than ``limits.decompressed_bytes``, or not exactly one
    ``.gml``/``.xml`` member."""
    members = []
    for info in archive.infolist():
        name = info.filename.replace("\\", "/")
        parts = PurePosixPath(name).parts
        if name.startswith("/") or ".." in parts or re.match(r"[A-Za-z]:", name):
            raise InputError(f"holds an unsafe member name {info.filename!r}", source)
        if not info.is_dir() and name.lower().endswith((".gml", ".xml")):
            members.append(info)
    if len(members) != 1:
        names = ", ".join(repr(m.filename) for m in members[:3])
        raise InputError(
            f"holds {len(members)} CityGML (.gml/.xml) files{': ' + names if names else ''}; "
            "a .zip input must hold exactly one",
            source,
        )
    if members[0].file_size > limits.decompressed_bytes:
        raise _inflation_error(limits.decompressed_bytes, source)
    return members[0]


def _open(path: Path, limits: Limits) -> IO[bytes] | _Capped:
    """The document's bytes as a stream: the file, or what its ``.gz`` or ``.zip`` inflates
    to, capped at ``limits.decompressed_bytes`` (never written to disk)."""
    source = str(path)
    name = path.name.lower()
    if name.endswith(".zip.gz"):
        raise InputError("is a .zip inside a .gz: give the .zip itself", source)
    if name.endswith(".gz"):
        return _Capped(gzip.open(path, "rb"), limits.decompressed_bytes, source)
    if name.endswith(".zip"):
        try:
            archive = zipfile.ZipFile(path)
            member = _zip_member(archive, limits, source)
            return _Capped(archive.open(member), limits.decompressed_bytes, source)
        except (zipfile.BadZipFile, zlib.error, OSError, EOFError) as exc:
            raise InputError(f"is not a valid zip file ({exc})", source) from None
    return path.open("rb")


# --- geometry -------------------------------------------------------------------------------------


def _local(element: etree._Element) -> str:
    tag = element.tag
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _namespace(element: etree._Element) -> str:
    tag = element.tag
    return tag[1:].split("}", 1)[0] if isinstance(tag, str) and tag.startswith("{") else ""


@dataclass
class _Polygon:
    """One polygon met in an object: its LoD, semantic type, rings (raw coordinates) and
    whether an ``OrientableSurface`` reversed it."""

    lod: str
    semantic: str
    rings: list[np.ndarray]
    flip: bool
    element: etree._Element


@dataclass
class _Object:
    """What is collected of one city object (and of each of its parts) while walking it."""

    element: etree._Element
    source: str
    gml_id: str
    polygons: list[_Polygon] = field(default_factory=list)
    unresolved: int = 0
    _ids: dict[str, etree._Element] | None = None

    def target(self, href: str) -> etree._Element | None:
        """The element of this object that ``href`` (``#id``) refers to, or None."""
        if self._ids is None:
            self._ids = {
                value: e
                for e in self.element.iter()
                for key, value in e.attrib.items()
                if key.endswith("}id")
            }
        return self._ids.get(href.removeprefix("#"))

    def collect(self, feature: etree._Element, semantic: str) -> None:
        """Gather the polygons of ``feature`` (the object, or a thematic surface, opening or
        installation of it, whose local name is ``semantic``)."""
        for prop in feature:
            name = _local(prop)
            if _namespace(prop) in _GML_NAMESPACES or name in _PART_PROPERTIES:
                continue
            lod = _LOD_PROPERTY.fullmatch(name)
            if lod is not None:
                kind = name[4:] if lod.group(2) in ("FootPrint", "RoofEdge") else semantic
                self._surfaces(prop, f"lod{lod.group(1)}", kind, False, set())
            elif name not in _UNREAD_PROPERTIES:
                for child in prop:
                    if _local(child)[:1].isupper():
                        self.collect(child, _local(child))

    def _surfaces(
        self, element: etree._Element, lod: str, semantic: str, flip: bool, seen: set[str]
    ) -> None:
        """Every polygon under ``element`` (a geometry property or geometry), following
        ``xlink:href`` within the object; a solid's interior shells are left out."""
        href = element.get(_XLINK_HREF)
        if href is not None:
            target = self.target(href) if href not in seen else None
            if target is None:
                self.unresolved += href not in seen
                return
            seen = seen | {href}
            element = target
        name = _local(element)
        if name in _POLYGONS:
            rings = _rings(element, self.source)
            self.polygons.append(_Polygon(lod, semantic, rings, flip, element))
            return
        if name in _NOT_SURFACES:
            return
        if name == "OrientableSurface":
            flip ^= element.get("orientation") == "-"
        for child in element:
            if name == "Solid" and _local(child) == "interior":
                continue
            self._surfaces(child, lod, semantic, flip, seen)


def _rings(polygon: etree._Element, source: str) -> list[np.ndarray]:
    """The exterior ring then the interior rings of ``polygon``, each (k, 3) float64."""
    rings: list[np.ndarray] = []
    for boundary in polygon:
        kind = _local(boundary)
        if kind not in ("exterior", "interior", "outerBoundaryIs", "innerBoundaryIs"):
            continue
        for ring in boundary:
            points = _positions(ring, source)
            if kind in ("exterior", "outerBoundaryIs"):
                rings.insert(0, points)
            else:
                rings.append(points)
    return rings


def _positions(ring: etree._Element, source: str) -> np.ndarray:
    """The points of a ``LinearRing`` (its ``posList`` or ``pos`` elements) as (k, 3)."""
    values: list[str] = []
    dimension = None
    for child in ring:
        name = _local(child)
        if name in ("posList", "pos"):
            values.append(child.text or "")
            dimension = dimension or child.get("srsDimension")
    if dimension is None:
        declared = (a.get("srsDimension") for a in ring.iterancestors())
        dimension = next((d for d in declared if d), "3")
    try:
        width = int(dimension)
        flat = np.array(" ".join(values).split(), dtype=np.float64)
    except ValueError:
        raise InputError("has a coordinate that is not a number", source) from None
    if width not in (2, 3) or len(flat) % width:
        raise InputError(
            f"has a ring of {len(flat)} values, not whole points of dimension {width}", source
        )
    points = flat.reshape(-1, width)
    return np.pad(points, ((0, 0), (0, 1))) if width == 2 else points


def _ring_key(lod: str, ring: np.ndarray) -> tuple[str, frozenset[tuple[float, ...]]]:
    """What identifies a polygon's exterior ring within a LoD, whatever its start and
    direction: its distinct points, rounded."""
    return lod, frozenset(map(tuple, np.round(ring, _DEDUP_DECIMALS).tolist()))


def _triangulated(
    polygons: list[_Polygon], crs: _Crs
) -> tuple[dict[str, dict[str, list[tuple[np.ndarray, np.ndarray]]]], int]:
    """The triangles of ``polygons`` (vertices in metres, faces) by LoD and semantic type,
    each polygon once per LoD (the copy with semantics first), and how many were degenerate."""
    ordered = sorted(polygons, key=lambda p: not p.semantic)
    rings = [ring for p in ordered for ring in p.rings]
    if rings:
        metric = crs.to_metric(np.concatenate(rings))
        pieces = iter(np.split(metric, np.cumsum([len(r) for r in rings])[:-1]))
        for p in ordered:
            p.rings = [next(pieces) for _ in p.rings]
    groups: dict[str, dict[str, list[tuple[np.ndarray, np.ndarray]]]] = {}
    seen: set[Any] = set()
    degenerate = 0
    kept: list[_Polygon] = []
    for p in ordered:
        if not p.rings:
            degenerate += 1
            continue
        keys = {(p.lod, p.element), _ring_key(p.lod, p.rings[0])}
        if keys & seen:
            continue
        seen |= keys
        kept.append(p)
    for p, triangles in zip(kept, triangulate_many([p.rings for p in kept]), strict=True):
        if triangles is None:
            degenerate += 1
            continue
        vertices, faces = triangles
        pieces_of = groups.setdefault(p.lod, {}).setdefault(p.semantic, [])
        pieces_of.append((vertices, faces[:, ::-1] if p.flip else faces))
    return groups, degenerate


def _surfaces(
    groups: dict[str, dict[str, list[tuple[np.ndarray, np.ndarray]]]],
    tally: InputTally,
    where: str,
    palette: Palette,
) -> tuple[dict[str, list[Surface]], int]:
    """One checked :class:`Surface` per LoD and semantic type (coloured by it), and how many
    faces without area were dropped."""
    surfaces: dict[str, list[Surface]] = {}
    dropped = 0
    for lod in sorted(groups):
        for semantic, pieces in groups[lod].items():
            offsets = np.cumsum([0] + [len(v) for v, _ in pieces[:-1]])
            vertices = np.concatenate([v for v, _ in pieces])
            faces = np.concatenate([f + o for (_, f), o in zip(pieces, offsets, strict=True)])
            tally.count(len(vertices), len(faces))
            vertices = checked_vertices(vertices, where)
            faces, lost = kept_faces(vertices, faces, where)
            dropped += lost
            if len(faces):
                color = palette.of(semantic).copy()
                surfaces.setdefault(lod, []).append(Surface(vertices, faces, base_color=color))
    return surfaces, dropped


def _finest(lods: dict[str, Mesh]) -> Mesh | None:
    """The highest LoD above 0, else LoD 0, else None."""
    above = [label for label in sorted(lods) if label != "lod0"]
    return lods[above[-1]] if above else lods.get("lod0")


# --- attributes -----------------------------------------------------------------------------------


def _typed(text: str, kind: type) -> Any:
    """``text`` as ``kind`` (int, float or str); as text when it is not one."""
    try:
        return kind(text) if kind is not int else int(float(text))
    except (ValueError, OverflowError):
        return text


def _add(attributes: dict[str, Any], key: str, value: Any) -> None:
    """Set ``key``; a repeated key becomes a list of its values."""
    if key not in attributes:
        attributes[key] = value
    elif isinstance(attributes[key], list):
        attributes[key].append(value)
    else:
        attributes[key] = [attributes[key], value]


def _child_text(element: etree._Element, name: str) -> str | None:
    return next((c.text or "" for c in element if _local(c) == name), None)


def _generic(element: etree._Element, generic: dict[str, Any], prefix: str = "") -> None:
    """Add a generic attribute (2.0 ``gen:stringAttribute name=…``, 3.0
    ``gen:StringAttribute`` with ``gen:name``; sets flattened as ``set.name``)."""
    kind = _local(element)
    name = element.get("name") or _child_text(element, "name") or kind
    if kind.lower() == "genericattributeset":
        for member in element:
            inner = member if _local(member)[:1].isupper() or member.get("name") else None
            for item in [inner] if inner is not None else list(member):
                _generic(item, generic, f"{prefix}{name}.")
        return
    text = (_child_text(element, "value") or "").strip()
    generic[prefix + name] = _typed(text, _GENERIC_TYPES.get(kind[:-9].lower(), str))


def _joined(found: dict[str, str], *names: str) -> str:
    return " ".join(found[n] for n in names if n in found)


def _address(element: etree._Element) -> str:
    """A readable address (``street number, postcode town, country``) from an ``address``
    property; its other words in document order when it is not xAL 2.0."""
    leaves = [
        (_local(e), e.text.strip())
        for e in element.iter()
        if _namespace(e) not in _GML_NAMESPACES and len(e) == 0 and e.text and e.text.strip()
    ]
    found = dict(leaves)
    street = " ".join(
        filter(None, (found.get("ThoroughfareName"), found.get("ThoroughfareNumber")))
    )
    town = _joined(found, "PostalCodeNumber", "LocalityName")
    parts = [p for p in (street, town, found.get("CountryName")) if p]
    return ", ".join(parts) if parts else ", ".join(text for _, text in leaves)


def _attributes(element: etree._Element, kind: str, gml_id: str) -> dict[str, Any]:
    """The object's JSON-able attributes: id, type, name, thematic ones, address, generic."""
    attributes: dict[str, Any] = {"id": gml_id, "type": kind}
    generic: dict[str, Any] = {}
    for prop in element:
        name = _local(prop)
        if _namespace(prop) in _GML_NAMESPACES:
            if name in ("name", "description") and prop.text and prop.text.strip():
                _add(attributes, name, prop.text.strip())
        elif name in _ATTRIBUTES and prop.text and prop.text.strip():
            _add(attributes, name, _typed(prop.text.strip(), _ATTRIBUTES[name]))
        elif name == "address":
            _add(attributes, "address", _address(prop))
        elif name == "height":  # 3.0: con:Height with references, status and value
            for height in prop:
                entry = {_local(e): _typed((e.text or "").strip(), str) for e in height}
                entry["value"] = _typed(str(entry.get("value", "")), float)
                _add(attributes, "heights", entry)
                if entry.get("status") == "measured":
                    attributes.setdefault("measuredHeight", entry["value"])
        elif name == "genericAttribute":
            for item in prop:
                _generic(item, generic)
        elif name.endswith("Attribute") or name == "genericAttributeSet":
            _generic(prop, generic)
    if generic:
        attributes["generic"] = generic
    return attributes


# --- the document, one object at a time -----------------------------------------------------------


@dataclass
class _Document:
    """The state of one streamed document: its version, CRS, the run's checks and what was
    counted along the way (:attr:`stats`, kept in the scene's attributes)."""

    path: Path
    limits: Limits
    types: frozenset[str] | None
    tally: InputTally
    palette: Palette = DEFAULT_PALETTE
    version: str = ""
    crs: _Crs | None = None
    taken: set[str] = field(default_factory=set)
    stats: dict[str, dict[str, int]] = field(
        default_factory=lambda: {"unresolved_links": {}, "degenerate_polygons": {}, "not_read": {}}
    )

    @property
    def source(self) -> str:
        return str(self.path)

    def nodes(self) -> Iterator[Node]:
        """The document's city objects with geometry, one at a time, as it is parsed."""
        limits = self.limits
        huge = limits.xml_text_bytes > _LIBXML_TEXT_LIMIT or limits.xml_depth > _LIBXML_DEPTH_LIMIT
        stream = _open(self.path, limits)
        try:
            events = etree.iterparse(
                stream,
                events=("start", "end"),
                resolve_entities=False,
                no_network=True,
                load_dtd=False,
                huge_tree=huge,
                remove_comments=True,
                remove_pis=True,
            )
            depth = 0
            for event, element in events:
                if event == "start":
                    depth += 1
                    if depth > limits.xml_depth:
                        raise InputError(
                            f"nests XML elements deeper than the limit of {limits.xml_depth} "
                            "(raise it with --limit xml_depth=N)",
                            self.source,
                        )
                    if depth == 1:
                        self._check_root(element)
                    continue
                depth -= 1
                self._check_text(element)
                if depth == 1:
                    yield from self._member(element)
                    element.clear(keep_tail=False)
                    while element.getprevious() is not None:
                        del element.getparent()[0]
        except etree.XMLSyntaxError as exc:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise InputError(f"is not well-formed XML ({reason})", self.source) from None
        except (OSError, EOFError, zlib.error, zipfile.BadZipFile) as exc:
            raise InputError(f"cannot be read ({exc})", self.source) from None
        finally:
            stream.close()

    def _check_root(self, root: etree._Element) -> None:
        """Refuse a DOCTYPE (before any content is read) and a root that is not a CityGML
        ``CityModel``; note the version."""
        if root.getroottree().docinfo.doctype:
            raise InputError(
                "XML with a DOCTYPE is not read (entities are a security risk)", self.source
            )
        version = CITYGML_NAMESPACE.fullmatch(_namespace(root))
        if version is None or _local(root) != "CityModel":
            namespace = _namespace(root)
            raise InputError(
                f"is not CityGML: its root element is <{_local(root)}>"
                + (f" in namespace {namespace}" if namespace else " without a namespace"),
                self.source,
            )
        self.version = version.group(1)

    def _check_text(self, element: etree._Element) -> None:
        limit = self.limits.xml_text_bytes
        for text in (element.text, element.tail):
            if text is not None and len(text) > limit:
                raise InputError(
                    f"has an XML text of {len(text):,} characters, over the limit of {limit:,} "
                    "(raise it with --limit xml_text_bytes=N)",
                    self.source,
                )

    def _member(self, element: etree._Element) -> Iterator[Node]:
        """The nodes of one child of the root: a member's city objects; the root's envelope
        gives the CRS."""
        name = _local(element)
        if name == "boundedBy" and self.crs is None:
            srs = next((e.get("srsName") for e in element.iter() if e.get("srsName")), None)
            self.crs = _Crs.of(srs) if srs else None
        elif name in ("cityObjectMember", "featureMember", "featureMembers", "member"):
            for child in element:
                node = self._object(child)
                if node is not None:
                    yield node

    def _object(self, element: etree._Element) -> Node | None:
        """The node of a top-level city object; None when it is not read or has nothing
        left (then recorded in the tally)."""
        kind = _local(element)
        if not kind[:1].isupper() or kind in _NOT_OBJECTS:
            self._count("not_read", kind or "?")
            return None
        if self.types is not None and kind not in self.types:
            self._count("not_read", kind)
            return None
        if self.crs is None:
            srs = next((e.get("srsName") for e in element.iter() if e.get("srsName")), None)
            self.crs = _Crs.of(srs) if srs else _Crs()
        node, surfaces, problems = self._build(element)
        if problems.unresolved:
            self.stats["unresolved_links"][node.id] = problems.unresolved
        if problems.degenerate:
            self.stats["degenerate_polygons"][node.id] = problems.degenerate
        dropped = problems.degenerate + problems.dropped
        if dropped:
            self.tally.dropped_faces += dropped
            self.tally.dropped_by_object[node.id] = dropped
        node.lods = {lod: Mesh(parts) for lod, parts in surfaces.items()}
        node.geometry = _finest(node.lods)
        if node.geometry is None:
            if dropped:
                self.tally.skip(node.id, dropped)
            else:
                self._skip(node.id, "has no surface geometry")
            return None
        try:
            check_extent(node.geometry.bounds, node.id)
        except InputError as exc:
            self._skip(node.id, str(exc).removeprefix(f"{node.id}: "))
            return None
        return node

    def _build(self, element: etree._Element) -> tuple[Node, dict[str, list[Surface]], _Problems]:
        """A city object's node (its parts as children, each with its own LoDs), the surfaces
        of the object and its parts together by LoD, and what was wrong with them."""
        kind = _local(element)
        gml_id = next((v for k, v in element.attrib.items() if k.endswith("}id")), "")
        node = Node(
            id=object_id(gml_id or kind, self.taken),
            type=kind,
            attributes=_attributes(element, kind, gml_id),
        )
        found = _Object(element, self.source, gml_id)
        found.collect(element, "")
        assert self.crs is not None
        groups, degenerate = _triangulated(found.polygons, self.crs)
        node.crs = self.crs.scene_crs
        own, dropped = _surfaces(groups, self.tally, f"{self.source}: {node.id}", self.palette)
        node.lods = {lod: Mesh(parts) for lod, parts in own.items()}
        problems = _Problems(found.unresolved, degenerate, dropped)
        merged = {lod: list(parts) for lod, parts in own.items()}
        for prop in element:
            if _local(prop) not in _PART_PROPERTIES:
                continue
            for part in (p for p in prop if _local(p)[:1].isupper()):
                child, surfaces, more = self._build(part)
                node.children.append(child)
                problems = problems + more
                for lod, parts in surfaces.items():
                    merged.setdefault(lod, []).extend(parts)
        return node, merged, problems

    def _count(self, key: str, name: str) -> None:
        self.stats[key][name] = self.stats[key].get(name, 0) + 1

    def _skip(self, node_id: str, reason: str) -> None:
        """Record object ``node_id`` as skipped for ``reason``."""
        self.tally.skipped.append({"id": node_id, "reason": str(InputError(reason, node_id))})


@dataclass(frozen=True)
class _Problems:
    """What was wrong with an object's geometry: links not resolved, degenerate polygons,
    faces without area dropped."""

    unresolved: int = 0
    degenerate: int = 0
    dropped: int = 0

    def __add__(self, other: _Problems) -> _Problems:
        return _Problems(
            self.unresolved + other.unresolved,
            self.degenerate + other.degenerate,
            self.dropped + other.dropped,
        )


def read_citygml(
    path: Path,
    limits: Limits = DEFAULT_LIMITS,
    types: frozenset[str] | None = None,
    colors: Palette = DEFAULT_PALETTE,
    crs: str | None = None,
) -> Scene:
    """Read a CityGML file (``.gml``/``.xml``, or a ``.gz``/``.zip`` of one) into a Scene whose
    nodes are streamed; raise :class:`InputError` with a one-line reason. ``crs`` (an EPSG
    name or URN) replaces whatever CRS the document declares.

    ``types``: read only top-level city objects of these types (local names: ``Building``,
    ``Road``…); None reads every type. The document is parsed up to its first city object
    before this returns (so that the scene's CRS is known); the rest as the nodes are taken.
    The scene's attributes hold the CityGML version, the vertical CRS, the local frame of a
    geographic CRS, and counts (links not resolved, degenerate polygons, features not read).
    """
    path = Path(path)
    source = str(path)
    if not path.exists():
        raise InputError("no such file", source)
    if path.is_dir():
        raise InputError("is a directory, not a CityGML file", source)
    if path.stat().st_size == 0:
        raise InputError("is empty", source)
    tally = InputTally(source, limits)
    document = _Document(path, limits, types, tally, colors)
    if crs is not None:
        document.crs = _Crs.of(crs)
    nodes = document.nodes()
    first = next(nodes, None)
    if first is None and len(tally.skipped) == 1:
        raise InputError(tally.skipped[0]["reason"], source)
    if first is None and tally.skipped:
        reason = tally.skipped[0]["reason"]
        raise InputError(f"none of its {len(tally.skipped):,} objects is left ({reason}…)", source)
    if first is None:
        wanted = f" of type {', '.join(sorted(types))}" if types else ""
        raise InputError(f"has no city objects{wanted} with surface geometry", source)
    declared = document.crs or _Crs()
    attributes: dict[str, Any] = {"citygml_version": document.version, "citygml": document.stats}
    if declared.vertical:
        attributes["vertical_crs"] = declared.vertical
    if declared.frame is not None:
        attributes["local_frame"] = declared.frame.record()
    scene = Scene(
        source=source,
        nodes=chain([first], nodes),
        crs=declared.scene_crs,
        attributes=attributes,
    )
    return attach_tally(scene, tally)


FORMAT = Format(
    name="citygml",
    suffixes=(".gml", ".xml", ".zip"),
    read=read_citygml,
    read_options=("limits", "types", "colors", "crs"),
)
