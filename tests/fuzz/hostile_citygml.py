"""Hostile CityGML documents, built small (:data:`~.cases.CASES` and the CityGML reader's tests
scale them as they need): deep nesting, chained links, objects without ids, long texts,
coordinates that are not finite."""

from __future__ import annotations

import gzip

HEAD = (
    "<?xml version='1.0' encoding='UTF-8'?>"
    '<CityModel xmlns="http://www.opengis.net/citygml/2.0" xmlns:gml="http://www.opengis.net/gml" '
    'xmlns:bldg="http://www.opengis.net/citygml/building/2.0" '
    'xmlns:gen="http://www.opengis.net/citygml/generics/2.0" '
    'xmlns:veg="http://www.opengis.net/citygml/vegetation/2.0" '
    'xmlns:xlink="http://www.w3.org/1999/xlink">'
    '<gml:boundedBy><gml:Envelope srsName="EPSG:25832"/></gml:boundedBy>'
)
TAIL = "</CityModel>"
_QUADS = ((0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5))


def cube(x: float = 0.0, size: float = 1.0) -> list[str]:
    """The six faces of a cube at ``x`` as posLists (outward, each ring closed)."""
    corners = [(x + size * i, size * j, size * k) for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    return [
        " ".join(f"{v:g}" for i in (*quad[::-1], quad[-1]) for v in corners[i]) for quad in _QUADS
    ]


def polygon(pos_list: str, gml_id: str = "") -> str:
    """A polygon of one ring."""
    id_attribute = f' gml:id="{gml_id}"' if gml_id else ""
    return (
        f"<gml:Polygon{id_attribute}><gml:exterior><gml:LinearRing><gml:posList>{pos_list}"
        "</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon>"
    )


def surfaces(rings: list[str]) -> str:
    """A ``lod2MultiSurface`` of one polygon per posList of ``rings``."""
    members = "".join(f"<gml:surfaceMember>{polygon(r)}</gml:surfaceMember>" for r in rings)
    return (
        f"<bldg:lod2MultiSurface><gml:MultiSurface>{members}</gml:MultiSurface>"
        "</bldg:lod2MultiSurface>"
    )


def building(inner: str, gml_id: str = "B1", kind: str = "Building") -> str:
    """A city object member (a building, without ``gml:id`` for ``gml_id=""``)."""
    id_attribute = f' gml:id="{gml_id}"' if gml_id else ""
    return f"<cityObjectMember><bldg:{kind}{id_attribute}>{inner}</bldg:{kind}></cityObjectMember>"


def document(*members: str) -> bytes:
    return (HEAD + "".join(members) + TAIL).encode()


def box_building(gml_id: str = "B1", x: float = 0.0, extra: str = "") -> str:
    """A building of one cube (``extra`` before its geometry)."""
    return building(extra + surfaces(cube(x)), gml_id)


def attribute_sets(depth: int) -> str:
    """A generic attribute in ``depth`` nested ``genericAttributeSet``s."""
    inner = '<gen:stringAttribute name="a"><gen:value>v</gen:value></gen:stringAttribute>'
    for _ in range(depth):
        inner = f'<gen:genericAttributeSet name="s">{inner}</gen:genericAttributeSet>'
    return inner


def nested_attribute_sets(depth: int) -> bytes:
    """A building whose generic attribute lies in ``depth`` nested ``genericAttributeSet``s."""
    return document(box_building(extra=attribute_sets(depth)))


def parts(depth: int) -> str:
    """A cube in a ``BuildingPart`` of a part of a part…, ``depth`` deep."""
    inner = surfaces(cube())
    for _ in range(depth):
        inner = (
            "<bldg:consistsOfBuildingPart><bldg:BuildingPart>"
            f"{inner}</bldg:BuildingPart></bldg:consistsOfBuildingPart>"
        )
    return inner


def part_chain(depth: int) -> bytes:
    """A building whose cube lies in a ``BuildingPart`` of a part of a part…, ``depth`` deep."""
    return document(building(parts(depth)))


def composites(depth: int) -> str:
    """A solid whose polygons lie in ``depth`` nested ``CompositeSurface``s."""
    members = "".join(f"<gml:surfaceMember>{polygon(r)}</gml:surfaceMember>" for r in cube())
    inner = f"<gml:CompositeSurface>{members}</gml:CompositeSurface>"
    for _ in range(depth - 1):
        inner = (
            "<gml:CompositeSurface><gml:surfaceMember>"
            f"{inner}</gml:surfaceMember></gml:CompositeSurface>"
        )
    solid = f"<gml:Solid><gml:exterior>{inner}</gml:exterior></gml:Solid>"
    return f"<bldg:lod2Solid>{solid}</bldg:lod2Solid>"


def nested_composites(depth: int) -> bytes:
    """A building whose polygons lie in ``depth`` nested ``CompositeSurface``s."""
    return document(building(composites(depth)))


def links(length: int, fan: int = 1) -> str:
    """A solid that links (``xlink:href``) to a composite surface that links to another…
    ``length`` links down to a cube's six polygons; with ``fan`` > 1 each composite links
    ``fan`` times to the next (``fan**length`` paths to each polygon)."""
    rings = cube()
    members = "".join(
        f"<gml:surfaceMember>{polygon(r, f'p{i}')}</gml:surfaceMember>" for i, r in enumerate(rings)
    )
    composites = [f'<gml:CompositeSurface gml:id="c0">{members}</gml:CompositeSurface>']
    for i in range(1, length):
        link = f'<gml:surfaceMember xlink:href="#c{i - 1}"/>' * fan
        composites.append(f'<gml:CompositeSurface gml:id="c{i}">{link}</gml:CompositeSurface>')
    held = "".join(f"<gml:surfaceMember>{c}</gml:surfaceMember>" for c in composites)
    solid = (
        "<bldg:lod2Solid><gml:Solid><gml:exterior><gml:CompositeSurface>"
        f'<gml:surfaceMember xlink:href="#c{length - 1}"/></gml:CompositeSurface>'
        "</gml:exterior></gml:Solid></bldg:lod2Solid>"
    )
    geometry = (
        f"<bldg:lod2MultiSurface><gml:MultiSurface>{held}</gml:MultiSurface>"
        "</bldg:lod2MultiSurface>"
    )
    return geometry + solid


def link_chain(length: int, fan: int = 1) -> bytes:
    """A building whose solid links (``xlink:href``) to a composite surface that links to
    another… ``length`` links down to its cube's six polygons (``fan`` times each)."""
    return document(building(links(length, fan)))


def with_coordinate(value: str, *more: str) -> bytes:
    """Building ``bad`` with ``value`` for one coordinate, then a good building ``good`` (and
    ``more`` members)."""
    rings = cube()
    rings[1] = rings[1].replace("1", value, 1)
    return document(building(surfaces(rings), "bad"), box_building("good", x=5.0), *more)


def geographic_city(count: int, bad: int, latitude: str = "200") -> bytes:
    """``count`` buildings ``b0``… in EPSG:4979 (latitude, longitude, height), cubes of some
    7 m in a row at 52° N 13° E; building ``b{bad}`` has ``latitude`` for one of its
    points."""
    members = []
    for k in range(count):
        rings = []
        for ring in cube(3.0 * k):
            values = [float(v) for v in ring.split()]
            points = zip(values[::3], values[1::3], values[2::3], strict=True)
            rings.append(
                " ".join(f"{52 + y * 1e-4:.7f} {13 + x * 1e-4:.7f} {z * 7:g}" for x, y, z in points)
            )
        if k == bad:
            rings[1] = latitude + rings[1][rings[1].index(" ") :]
        members.append(building(surfaces(rings), f"b{k}"))
    return document(*members).replace(b"EPSG:25832", b"EPSG:4979")


def without_ids(count: int, parts: bool) -> bytes:
    """``count`` objects without ``gml:id``: parts of one building (``parts``), else buildings
    without geometry (a name alone: each is skipped under an id of its own) before a good one."""
    if parts:
        part = (
            "<bldg:consistsOfBuildingPart><bldg:BuildingPart>{}</bldg:BuildingPart>"
            "</bldg:consistsOfBuildingPart>"
        )
        inner = "".join(part.format(surfaces(cube(2.0 * i)[:1])) for i in range(count))
        return document(building(inner, gml_id=""))
    return document(building("<gml:name>n</gml:name>", gml_id="") * count, box_building("good"))


def many_parts(count: int) -> bytes:
    """A building of ``count`` parts, each a one-metre cube with an id, in a row."""
    part = (
        '<bldg:consistsOfBuildingPart><bldg:BuildingPart gml:id="P{}">{}</bldg:BuildingPart>'
        "</bldg:consistsOfBuildingPart>"
    )
    inner = "".join(part.format(i, surfaces(cube(2.0 * i))) for i in range(count))
    return document(building(inner))


def grid_of_parts(count: int, ids: bool = True) -> bytes:
    """A building of ``count`` parts, each a one-metre cube (with an id, or without), on a
    square grid two metres apart."""
    side = int(count**0.5) + 1
    part = (
        "<bldg:consistsOfBuildingPart><bldg:BuildingPart{}>{}</bldg:BuildingPart>"
        "</bldg:consistsOfBuildingPart>"
    )
    pieces = []
    for i in range(count):
        rings = [_moved(ring, 2.0 * (i % side), 2.0 * (i // side)) for ring in cube()]
        pieces.append(part.format(f' gml:id="P{i}"' if ids else "", surfaces(rings)))
    return document(building("".join(pieces)))


def _moved(pos_list: str, x: float, y: float) -> str:
    """A posList moved by ``x`` and ``y``."""
    values = [float(v) for v in pos_list.split()]
    return " ".join(
        f"{v + (x if k % 3 == 0 else y if k % 3 == 1 else 0):g}" for k, v in enumerate(values)
    )


def scaled_tree(scale: str, gml_id: str = "tree") -> str:
    """A tree member: a square placed by an implicit geometry whose matrix scales it by
    ``scale``."""
    matrix = " ".join(scale if i in (0, 5, 10) else "1" if i == 15 else "0" for i in range(16))
    return (
        f'<cityObjectMember><veg:SolitaryVegetationObject gml:id="{gml_id}">'
        "<veg:lod2ImplicitRepresentation><ImplicitGeometry>"
        f"<transformationMatrix>{matrix}</transformationMatrix>"
        f"<relativeGMLGeometry>{polygon('0 0 0 1 0 0 1 1 0 0 1 0 0 0 0')}</relativeGMLGeometry>"
        "<referencePoint><gml:Point><gml:pos>0 0 0</gml:pos></gml:Point></referencePoint>"
        "</ImplicitGeometry></veg:lod2ImplicitRepresentation>"
        "</veg:SolitaryVegetationObject></cityObjectMember>"
    )


def long_text(size: int, split_by: str = "") -> bytes:
    """A building whose ``gml:description`` is ``size`` bytes, in pieces of 1,000 separated by
    ``split_by`` (a comment, say: libxml2 joins the pieces into one text)."""
    pieces = ["x" * 1000] * (size // 1000)
    return document(
        box_building(extra=f"<gml:description>{split_by.join(pieces)}</gml:description>")
    )


def empty_members_gz(inflated: int) -> bytes:
    """A ``.gml.gz`` of empty building members that inflates to about ``inflated`` bytes (one
    MiB of members compressed once, repeated as gzip members: never held inflated)."""
    member = b"<cityObjectMember><bldg:Building/></cityObjectMember>"
    mib = gzip.compress(member * ((1 << 20) // len(member)), mtime=0)
    return gzip.compress(HEAD.encode(), mtime=0) + mib * (inflated >> 20)
