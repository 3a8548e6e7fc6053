"""XML names the CityGML reader knows: namespaces, local names of geometry properties and
geometries, and the properties it does not read."""

from __future__ import annotations

import re

from lxml import etree

CITYGML_NAMESPACE = re.compile(r"http://www\.opengis\.net/citygml/(1\.0|2\.0|3\.0)")
"""The core namespace of each CityGML version (the root ``CityModel``'s)."""
GML_NAMESPACES = ("http://www.opengis.net/gml", "http://www.opengis.net/gml/3.2")
GML_IDS = tuple(f"{{{ns}}}id" for ns in GML_NAMESPACES)
"""The ``gml:id`` attribute's name in each GML version."""
XLINK_HREF = "{http://www.w3.org/1999/xlink}href"
LOD_PROPERTY = re.compile(
    r"lod([0-4])(Solid|MultiSolid|MultiSurface|CompositeSurface|Surface|Geometry|FootPrint|RoofEdge"
    r"|ImplicitRepresentation)"
)
"""Geometry properties read, with their LoD (curves and points are not; an implicit
representation's geometry is placed by its ``ImplicitGeometry``: :mod:`.implicit`)."""
PART_PROPERTIES = frozenset(
    {
        "consistsOfBuildingPart",
        "buildingPart",
        "consistsOfBridgePart",
        "bridgePart",
        "consistsOfTunnelPart",
        "tunnelPart",
    }
)
"""Properties holding an object's parts (``BuildingPart``…)."""
INTERIOR_PROPERTIES = frozenset(
    {
        "interiorRoom",
        "interiorFurniture",
        "interiorBuildingInstallation",
        "roomInstallation",
        "buildingRoom",
        "buildingFurniture",
        "interiorBridgeRoom",
        "interiorBridgeInstallation",
        "bridgeRoomInstallation",
        "bridgeRoom",
        "bridgeFurniture",
        "interiorHollowSpace",
        "interiorTunnelInstallation",
        "hollowSpaceInstallation",
        "hollowSpace",
        "tunnelFurniture",
    }
)
"""Properties holding an object's interior (CityGML 1.0/2.0 ``interiorRoom`` → ``Room``,
3.0 ``buildingRoom`` → ``BuildingRoom``, furniture, interior installations): read as parts."""
HOLDING_PROPERTIES = PART_PROPERTIES | INTERIOR_PROPERTIES
"""Properties whose features are holders of their own (parts and interiors)."""
UNREAD_PROPERTIES = frozenset(
    {
        "address",
        "appearance",
        "externalReference",
        "genericAttribute",
    }
)
"""Properties of a city object that hold no geometry read."""
NOT_OBJECTS = frozenset({"CityObjectGroup", "Appearance", "Version"})
"""Top-level features that are not read as objects (groups, appearances, versions)."""
RELIEF_NAMESPACE = re.compile(r"http://www\.opengis\.net/citygml/relief/(1\.0|2\.0|3\.0)")
"""The relief (terrain) module's namespace: a ``TINRelief``'s ``tin`` is a geometry property
whose LoD is the ``lod`` of the component (or of its ``ReliefFeature``)."""
POLYGONS = frozenset({"Polygon", "Triangle", "Rectangle", "PolygonPatch"})
NOT_SURFACES = frozenset(
    {"Point", "MultiPoint", "LineString", "Curve", "MultiCurve", "CompositeCurve", "Envelope"}
)
MEMBERS = frozenset({"cityObjectMember", "featureMember", "featureMembers", "member"})
"""Children of the root that hold city objects."""


_CACHED_TAGS = 4096
"""Tags whose local name and namespace are remembered (a document uses a few hundred; a
hostile one with more is answered without the cache)."""
_LOCALS: dict[object, str] = {}
_NAMESPACES: dict[object, str] = {}


def local(element: etree._Element) -> str:
    """The local name of an element's tag ("" for comments and processing instructions)."""
    tag = element.tag
    name = _LOCALS.get(tag)
    if name is None:
        name = tag.rpartition("}")[2] if isinstance(tag, str) else ""
        if len(_LOCALS) < _CACHED_TAGS:
            _LOCALS[tag] = name
    return name


def namespace(element: etree._Element) -> str:
    """The namespace of an element's tag ("" when it has none)."""
    tag = element.tag
    name = _NAMESPACES.get(tag)
    if name is None:
        name = tag[1:].partition("}")[0] if isinstance(tag, str) and tag.startswith("{") else ""
        if len(_NAMESPACES) < _CACHED_TAGS:
            _NAMESPACES[tag] = name
    return name


def is_feature(name: str) -> bool:
    """Whether a local name names a feature (``WallSurface``), not a property (``boundedBy``)."""
    return name[:1].isupper()
