"""Small valid files of every input suffix, generated here (no files checked in): a box as
OBJ, ASCII and binary PLY, ASCII and binary STL, OFF, GLB and glTF (buffer embedded); a house
as CityJSON, CityJSONSeq, CityGML and CityGML in a zip; a building with a part and a tree
placed as a template's instance as CityJSON and CityJSONSeq; a house with hostile id and
attribute text as CityJSON."""

from __future__ import annotations

import gzip
import json
from functools import cache
from pathlib import Path

import trimesh

from lodconvert.io import formats

from . import hostile_citygml as gml

SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def _box() -> trimesh.Trimesh:
    """A unit box with a vertex colour per corner (so colour paths are fuzzed too)."""
    mesh = trimesh.creation.box(extents=(1.0, 2.0, 0.5))
    mesh.visual.vertex_colors = [[40 * i, 255 - 30 * i, 128, 255] for i in range(8)]
    return mesh


@cache
def generated() -> dict[str, tuple[bytes, ...]]:
    """Seed contents by suffix."""
    mesh = _box()
    scene = trimesh.Scene()
    scene.add_geometry(mesh, node_name="box", geom_name="box")
    scene.add_geometry(mesh.copy().apply_translation((3, 0, 0)), node_name="b2", geom_name="b2")
    gltf = trimesh.exchange.gltf.export_gltf(scene, embed_buffers=True)
    obj = (
        "o first\n"
        + mesh.export(file_type="obj")
        + "o second\nv 5 5 5\nv 6 5 5\nv 5 6 5\nf 9 10 11\n"
    )
    return {
        ".obj": (obj.encode(),),
        ".ply": (mesh.export(file_type="ply", encoding="ascii"), mesh.export(file_type="ply")),
        ".stl": (mesh.export(file_type="stl_ascii").encode(), mesh.export(file_type="stl")),
        ".off": (mesh.export(file_type="off").encode(),),
        ".glb": (scene.export(file_type="glb"),),
        ".gltf": (json.dumps(json.loads(gltf["model.gltf"])).encode(),),
        ".json": (_cityjson()[0], _cityjson_parts_and_template()[0], _cityjson_hostile_text()),
        ".jsonl": (_cityjson()[1], _cityjson_parts_and_template()[1]),
        ".gml": (
            _citygml(),
            _citygml_interior_and_terrain(),
            _citygml_implicit(),
            _citygml_structures(),
        ),
        ".xml": (_citygml(),),
        ".zip": (_zipped("city.gml", _citygml()),),
    }


def _cityjson() -> tuple[bytes, bytes]:
    """A CityJSON 2.0 house (a solid with roof/wall/ground semantics, a material) and the
    same as CityJSONSeq (header line, one feature line)."""
    boundaries = [[[[0, 3, 2, 1]], [[4, 5, 6, 7]], [[0, 1, 5, 4]], [[1, 2, 6, 5]]]]
    geometry = {
        "type": "Solid",
        "lod": "2.2",
        "boundaries": boundaries,
        "semantics": {
            "surfaces": [
                {"type": "GroundSurface"},
                {"type": "RoofSurface"},
                {"type": "WallSurface"},
            ],
            "values": [[0, 1, 2, 2]],
        },
        "material": {"m": {"values": [[0, 0, 0, 0]]}},
    }
    vertices = [[0, 0, 0], [1000, 0, 0], [1000, 1000, 0], [0, 1000, 0]]
    vertices += [[x, y, 800] for x, y, _ in vertices]
    header = {
        "type": "CityJSON",
        "version": "2.0",
        "transform": {"scale": [0.01, 0.01, 0.01], "translate": [85000.0, 447000.0, 0.0]},
        "metadata": {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/7415"},
        "appearance": {"materials": [{"name": "m", "diffuseColor": [0.8, 0.4, 0.3]}]},
    }
    house = {"type": "Building", "attributes": {"measuredHeight": 8.0}, "geometry": [geometry]}
    document = {**header, "CityObjects": {"house": house}, "vertices": vertices}
    feature = {
        "type": "CityJSONFeature",
        "id": "house",
        "CityObjects": {"house": house},
        "vertices": vertices,
    }
    sequence = json.dumps({**header, "CityObjects": {}, "vertices": []}) + "\n"
    return json.dumps(document).encode(), (sequence + json.dumps(feature) + "\n").encode()


def _cityjson_hostile_text() -> bytes:
    """The CityJSON house with an id holding U+0001, an attribute holding a lone surrogate
    and one nested 40 objects deep (text every output must bound and clean)."""
    document = json.loads(_cityjson()[0])
    house = document["CityObjects"].pop("house")
    deep: object = "leaf"
    for _ in range(40):
        deep = {"a": deep}
    house["attributes"] = {"name": "x\ud800y", "deep": deep}
    document["CityObjects"]["house\x01"] = house
    return json.dumps(document).encode()


def _cityjson_parts_and_template() -> tuple[bytes, bytes]:
    """A building with a BuildingPart (``children`` and ``parents``) and a tree placed as an
    instance of a geometry template, as CityJSON 2.0 and as CityJSONSeq."""
    square = [[[0, 1, 2, 3]]]
    building = {
        "type": "Building",
        "children": ["part"],
        "geometry": [{"type": "MultiSurface", "lod": "1", "boundaries": square}],
    }
    part = {
        "type": "BuildingPart",
        "parents": ["building"],
        "geometry": [{"type": "MultiSurface", "lod": "2", "boundaries": [[[4, 5, 6, 7]]]}],
    }
    instance = {
        "type": "GeometryInstance",
        "template": 0,
        "boundaries": [8],
        "transformationMatrix": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1],
    }
    tree = {"type": "SolitaryVegetationObject", "geometry": [instance]}
    vertices = [[0, 0, 0], [900, 0, 0], [900, 900, 0], [0, 900, 0]]
    vertices += [[x, y, 500] for x, y, _ in vertices] + [[2000, 2000, 0]]
    header = {
        "type": "CityJSON",
        "version": "2.0",
        "transform": {"scale": [0.01, 0.01, 0.01], "translate": [1000.0, 2000.0, 0.0]},
        "geometry-templates": {
            "templates": [{"type": "MultiSurface", "lod": "2", "boundaries": square}],
            "vertices-templates": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
        },
    }
    objects = {"building": building, "part": part, "tree": tree}
    document = {**header, "CityObjects": objects, "vertices": vertices}
    features = [
        {"CityObjects": {"building": building, "part": part}, "vertices": vertices},
        {"CityObjects": {"tree": tree}, "vertices": vertices},
    ]
    lines = [{**header, "CityObjects": {}, "vertices": []}]
    lines += [{"type": "CityJSONFeature", "id": f"f{k}", **f} for k, f in enumerate(features)]
    sequence = "".join(json.dumps(line) + "\n" for line in lines)
    return json.dumps(document).encode(), sequence.encode()


def _citygml() -> bytes:
    """A CityGML 2.0 building: a roof and a wall surface with a posList each."""
    ring = "0 0 0 10 0 0 10 10 0 0 10 0 0 0 0"
    wall = "0 0 0 10 0 0 10 0 5 0 0 5 0 0 0"

    def surface(kind: str, pos: str) -> str:
        return (
            f"<bldg:boundedBy><bldg:{kind}><bldg:lod2MultiSurface><gml:MultiSurface>"
            "<gml:surfaceMember><gml:Polygon><gml:exterior><gml:LinearRing>"
            f"<gml:posList srsDimension='3'>{pos}</gml:posList>"
            "</gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>"
            f"</gml:MultiSurface></bldg:lod2MultiSurface></bldg:{kind}></bldg:boundedBy>"
        )

    return (
        "<?xml version='1.0' encoding='UTF-8'?>"
        "<core:CityModel xmlns:core='http://www.opengis.net/citygml/2.0' "
        "xmlns:bldg='http://www.opengis.net/citygml/building/2.0' "
        "xmlns:gml='http://www.opengis.net/gml'>"
        "<gml:boundedBy><gml:Envelope srsName='EPSG:25832'/></gml:boundedBy>"
        "<core:cityObjectMember><bldg:Building gml:id='b1'>"
        "<bldg:measuredHeight uom='m'>5</bldg:measuredHeight>"
        + surface("RoofSurface", ring.replace(" 0 ", " 5 ").replace(" 0", " 5"))
        + surface("WallSurface", wall)
        + "</bldg:Building></core:cityObjectMember></core:CityModel>"
    ).encode()


def _citygml_interior_and_terrain() -> bytes:
    """A CityGML 2.0 LoD4 building with a room (its floor a reversed link to the building's
    ground surface) holding furniture, and a terrain TIN of two triangles."""

    def polygon(pos: str, gml_id: str = "") -> str:
        own = f" gml:id='{gml_id}'" if gml_id else ""
        return (
            f"<gml:Polygon{own}><gml:exterior><gml:LinearRing><gml:posList>{pos}</gml:posList>"
            "</gml:LinearRing></gml:exterior></gml:Polygon>"
        )

    def surfaces(*members: str) -> str:
        return (
            "<gml:MultiSurface>"
            + "".join(f"<gml:surfaceMember>{m}</gml:surfaceMember>" for m in members)
            + "</gml:MultiSurface>"
        )

    ground = "0 0 0 0 10 0 10 10 0 10 0 0 0 0 0"
    wall = "1 1 0 9 1 0 9 1 3 1 1 3 1 1 0"
    table = "2 2 1 4 2 1 4 4 1 2 4 1 2 2 1"
    triangle = "-5 -5 0 15 -5 0 15 15 1 -5 -5 0"
    return (
        "<?xml version='1.0' encoding='UTF-8'?>"
        "<CityModel xmlns='http://www.opengis.net/citygml/2.0' "
        "xmlns:bldg='http://www.opengis.net/citygml/building/2.0' "
        "xmlns:dem='http://www.opengis.net/citygml/relief/2.0' "
        "xmlns:xlink='http://www.w3.org/1999/xlink' xmlns:gml='http://www.opengis.net/gml'>"
        "<cityObjectMember><bldg:Building gml:id='b1'><bldg:boundedBy><bldg:GroundSurface>"
        f"<bldg:lod4MultiSurface>{surfaces(polygon(ground, 'g1'))}</bldg:lod4MultiSurface>"
        "</bldg:GroundSurface></bldg:boundedBy><bldg:interiorRoom><bldg:Room gml:id='r1'>"
        "<bldg:lod4Solid><gml:Solid><gml:exterior><gml:CompositeSurface><gml:surfaceMember>"
        "<gml:OrientableSurface orientation='-'><gml:baseSurface xlink:href='#g1'/>"
        "</gml:OrientableSurface></gml:surfaceMember></gml:CompositeSurface></gml:exterior>"
        "</gml:Solid></bldg:lod4Solid><bldg:boundedBy><bldg:InteriorWallSurface>"
        f"<bldg:lod4MultiSurface>{surfaces(polygon(wall))}</bldg:lod4MultiSurface>"
        "</bldg:InteriorWallSurface></bldg:boundedBy><bldg:interiorFurniture>"
        "<bldg:BuildingFurniture gml:id='f1'><bldg:lod4Geometry>"
        f"{surfaces(polygon(table))}</bldg:lod4Geometry></bldg:BuildingFurniture>"
        "</bldg:interiorFurniture></bldg:Room></bldg:interiorRoom></bldg:Building>"
        "</cityObjectMember><cityObjectMember><dem:ReliefFeature gml:id='t1'><dem:lod>2</dem:lod>"
        "<dem:reliefComponent><dem:TINRelief><dem:lod>2</dem:lod><dem:tin>"
        "<gml:TriangulatedSurface><gml:trianglePatches><gml:Triangle><gml:exterior>"
        f"<gml:LinearRing><gml:posList>{triangle}</gml:posList></gml:LinearRing>"
        "</gml:exterior></gml:Triangle></gml:trianglePatches></gml:TriangulatedSurface>"
        "</dem:tin></dem:TINRelief></dem:reliefComponent></dem:ReliefFeature>"
        "</cityObjectMember></CityModel>"
    ).encode()


def _citygml_implicit() -> bytes:
    """Two CityGML 2.0 trees of one implicit geometry: the first holds the crown (a triangle)
    turned and scaled by its matrix, the second links to it from its own reference point."""

    def tree(gml_id: str, geometry: str, matrix: str, point: str) -> str:
        return (
            f"<cityObjectMember><veg:SolitaryVegetationObject gml:id='{gml_id}'>"
            "<veg:lod2ImplicitRepresentation><ImplicitGeometry>"
            f"<transformationMatrix>{matrix}</transformationMatrix>{geometry}"
            f"<referencePoint><gml:Point><gml:pos>{point}</gml:pos></gml:Point></referencePoint>"
            "</ImplicitGeometry></veg:lod2ImplicitRepresentation>"
            "</veg:SolitaryVegetationObject></cityObjectMember>"
        )

    crown = (
        "<relativeGMLGeometry><gml:MultiSurface gml:id='crown'><gml:surfaceMember><gml:Polygon>"
        "<gml:exterior><gml:LinearRing><gml:posList>0 0 0 2 0 0 1 0 3 0 0 0</gml:posList>"
        "</gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember></gml:MultiSurface>"
        "</relativeGMLGeometry>"
    )
    link = "<relativeGMLGeometry xlink:href='#crown'/>"
    turned = "0 -2 0 0 2 0 0 0 0 0 2 0.5 0 0 0 1"
    return (
        "<?xml version='1.0' encoding='UTF-8'?>"
        "<CityModel xmlns='http://www.opengis.net/citygml/2.0' "
        "xmlns:veg='http://www.opengis.net/citygml/vegetation/2.0' "
        "xmlns:xlink='http://www.w3.org/1999/xlink' xmlns:gml='http://www.opengis.net/gml'>"
        + tree("t1", crown, turned, "100 200 10")
        + tree("t2", link, "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1", "110 200 10")
        + "</CityModel>"
    ).encode()


def _citygml_structures() -> bytes:
    """What the hostile CityGML cases grow, at a size that reads: a building without an id
    whose parts (without ids) nest three deep, generic attribute sets nested three deep, a
    description split by a comment, composites nested three deep and a chain of three links
    (:mod:`.hostile_citygml`); the mutations vary the depths, ids and coordinates."""
    description = "<gml:description>a<!-- note -->b</gml:description>"
    return gml.document(
        gml.building(description + gml.attribute_sets(3) + gml.parts(3), gml_id=""),
        gml.building(gml.composites(3), "composites"),
        gml.building(gml.links(3), "links"),
    )


def _zipped(name: str, data: bytes) -> bytes:
    """A zip holding ``data`` as ``name``."""
    import io
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr(zipfile.ZipInfo(name, (2020, 1, 1, 0, 0, 0)), data)
    return buffer.getvalue()


def reader_suffixes() -> list[str]:
    """Every suffix the registry reads, each once (in registry order)."""
    suffixes = [s for f in formats() if f.read is not None for s in f.suffixes]
    return list(dict.fromkeys(suffixes))


def seeds_for(suffix: str) -> tuple[bytes, ...]:
    """Seeds of ``suffix``: generated ones, else the samples of that suffix, else every
    generated seed (a reader registered without seeds still meets mislabelled files)."""
    if suffix in generated():
        return generated()[suffix]
    found = tuple(p.read_bytes() for p in sorted(SAMPLES.glob(f"*{suffix}")) if p.is_file())
    return found or tuple(seed for group in generated().values() for seed in group)


def gzipped(data: bytes) -> bytes:
    """``data`` as a ``.gz`` (deterministic: no time stamp)."""
    return gzip.compress(data, mtime=0)
