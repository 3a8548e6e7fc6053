"""The hostile inputs that the regression tests (``tests/test_hostile_input.py``) run and
``docs/hostile_input.md`` lists (``benchmarks/robustness.py``): each a file, the options of
the run, the exit code and words of the one-line message expected."""

from __future__ import annotations

import gzip
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from . import hostile_citygml as gml

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"


def _ply(vertices: str, faces: str, face_count: int | None = None) -> bytes:
    """An ASCII PLY of ``vertices`` and ``faces`` lines (header counts from them, or
    ``face_count`` faces declared)."""
    nv, nf = len(vertices.splitlines()), len(faces.splitlines())
    header = (
        "ply\nformat ascii 1.0\n"
        f"element vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {nf if face_count is None else face_count}\n"
        "property list uchar int vertex_indices\nend_header\n"
    )
    return (header + vertices + faces).encode()


def zeros_gz(inflated: int, head: bytes = b"", fill: bytes = b"\0") -> bytes:
    """A ``.gz`` of ``head`` followed by ``fill`` bytes (zeros), ``inflated`` bytes in all
    (MiB of them are one gzip member, repeated: never held inflated)."""
    mib = gzip.compress(fill * (1 << 20), mtime=0)
    whole, rest = divmod(inflated - len(head), 1 << 20)
    tail = gzip.compress(fill * rest, mtime=0) if rest else b""
    return gzip.compress(head, mtime=0) + mib * whole + tail


def _binary_ply_head(vertices: int) -> bytes:
    """A binary PLY header declaring ``vertices`` float vertices and no faces."""
    return (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 0\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()


def grid_obj(side: int) -> bytes:
    """An OBJ of a ``side`` × ``side`` vertex grid, two triangles per cell."""
    lines = [f"v {i % side} {i // side} 0" for i in range(side * side)]
    for y in range(side - 1):
        for x in range(side - 1):
            a = y * side + x + 1
            lines += [f"f {a} {a + 1} {a + side}", f"f {a + 1} {a + side + 1} {a + side}"]
    return ("\n".join(lines) + "\n").encode()


SQUARE = [[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]]
_RD = {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/7415"}


def city_object(boundaries: object = None, kind: str = "MultiSurface") -> dict:
    """A Building with one LoD 1 geometry of ``kind`` and ``boundaries`` (by default a
    MultiSurface of one square)."""
    if boundaries is None:
        boundaries = [[[0, 1, 2, 3]]]
    return {"type": "Building", "geometry": [{"type": kind, "lod": "1", "boundaries": boundaries}]}


def city(objects: dict, vertices: object = SQUARE, **extra: object) -> bytes:
    """A CityJSON 2.0 document of ``objects`` over ``vertices`` (no transform, in the Dutch
    national CRS)."""
    document = {"type": "CityJSON", "version": "2.0", "metadata": _RD, "CityObjects": objects}
    document |= extra
    return json.dumps({**document, "vertices": vertices}).encode()


def sequence(*features: dict, header: dict | None = None) -> bytes:
    """A CityJSONSeq file: a header line, then one line per feature."""
    head = {"type": "CityJSON", "version": "2.0", "metadata": _RD, "CityObjects": {}}
    head["vertices"] = []
    lines = [head | (header or {})] + [{"type": "CityJSONFeature", **f} for f in features]
    return "".join(json.dumps(line) + "\n" for line in lines).encode()


def _chain(depth: int) -> bytes:
    """Buildings each the child of the one before, ``depth`` deep; the first has a surface."""
    objects = {f"o{k}": {"type": "Building", "children": [f"o{k + 1}"]} for k in range(depth)}
    objects[f"o{depth - 1}"].pop("children")
    objects["o0"] = {**city_object(), "children": ["o1"]}
    return city(objects)


def _nested(depth: int) -> object:
    """A JSON value ``depth`` objects deep."""
    value: object = 1
    for _ in range(depth):
        value = {"a": value}
    return value


def _instance(template: dict, point: object = 0) -> bytes:
    """A tree placed as an instance of ``template`` at vertex ``point``."""
    instance = {"type": "GeometryInstance", "template": 0, "boundaries": [point]}
    instance["transformationMatrix"] = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    templates = {"templates": [template], "vertices-templates": SQUARE}
    tree = {"type": "SolitaryVegetationObject", "geometry": [instance]}
    return city({"tree": tree}, **{"geometry-templates": templates})


_TEMPLATE = {"type": "MultiSurface", "lod": "2", "boundaries": [[[0, 1, 2, 3]]]}
_SHIFTED = [[x + 20, y, z] for x, y, z in SQUARE]


@dataclass(frozen=True)
class Case:
    """One hostile input: what it is, its file name and content, the run's extra options,
    the expected exit code and words of the message (exit 0: words of the summary)."""

    what: str
    name: str
    content: Callable[[], bytes]
    args: tuple[str, ...] = ()
    code: int = 1
    words: tuple[str, ...] = ()

    def write(self, folder: Path) -> Path:
        """The case's input file in ``folder``."""
        path = folder / self.name
        path.write_bytes(self.content())
        return path


CASES = (
    Case(
        "one triangle repeated 10,000 times (80 KB OBJ)",
        "repeated.obj",
        lambda: (TRIANGLE + "f 1 2 3\n" * 10_000).encode(),
        code=0,
        words=("wrote",),
    ),
    Case(
        "OBJ face index past the last vertex",
        "past.obj",
        lambda: (TRIANGLE + "f 1 2 9\n").encode(),
        words=("out of bounds",),
    ),
    Case(
        "OBJ negative (relative) index before the first vertex",
        "negative.obj",
        lambda: (TRIANGLE + "f -1 -2 -5\n").encode(),
        words=("out of bounds",),
    ),
    Case(
        "PLY face index past the last vertex",
        "past.ply",
        lambda: _ply("0 0 0\n1 0 0\n0 1 0\n", "3 0 1 7\n"),
        words=("do not exist", "index 7"),
    ),
    Case(
        "PLY negative face index",
        "negative.ply",
        lambda: _ply("0 0 0\n1 0 0\n0 1 0\n", "3 0 1 -1\n"),
        words=("do not exist", "index -1"),
    ),
    Case(
        "only faces without area (collinear corners, a repeated index)",
        "flat.obj",
        lambda: b"v 0 0 0\nv 1 1 1\nv 2 2 2\nf 1 2 3\nf 1 1 2\n",
        words=("no face with area", "2 faces"),
    ),
    Case(
        "a good object and one whose faces all lack area",
        "two.obj",
        lambda: (TRIANGLE + "o good\nf 1 2 3\no bad\nf 1 1 2\nf 2 2 3\n").encode(),
        code=0,
        words=("bad", "skipped", "2 faces have no area"),
    ),
    Case(
        "2-D OBJ vertices",
        "flat2d.obj",
        lambda: b"v 0 0\nv 1 0\nv 0 1\nf 1 2 3\n",
        words=("2-D vertices",),
    ),
    Case(
        "NaN coordinate",
        "nan.obj",
        lambda: b"v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n",
        words=("NaN or infinite",),
    ),
    Case(
        "infinite coordinate (PLY)",
        "inf.ply",
        lambda: _ply("0 0 0\n1 inf 0\n0 1 0\n", "3 0 1 2\n"),
        words=("NaN or infinite",),
    ),
    Case(
        "coordinates of 1e20",
        "big.obj",
        lambda: b"v 0 0 0\nv 1e20 0 0\nv 0 1e20 0\nf 1 2 3\n",
        words=("1e+20", "at most 1e+15"),
    ),
    Case(
        "coordinates of 1e308",
        "huge.obj",
        lambda: b"v 0 0 0\nv 1e308 0 0\nv 0 1e308 0\nf 1 2 3\n",
        words=("1e+308", "at most 1e+15"),
    ),
    Case(
        "an object 1e-4 across at 1e12 from the origin",
        "far.obj",
        lambda: b"v 1e12 0 0\nv 1e12 1e-4 0\nv 1e12 0 1e-4\nf 1 2 3\n",
        words=("spans only", "significant digits"),
    ),
    Case(
        "an object 1e-12 across",
        "speck.obj",
        lambda: b"v 0 0 0\nv 1e-12 0 0\nv 0 1e-12 0\nf 1 2 3\n",
        words=("spans only 1e-12",),
    ),
    Case(
        "a 1 MB .ply.gz of zeros (inflates to 1 GB)",
        "zeros.ply.gz",
        lambda: zeros_gz(1 << 30),
        words=("cannot be read as PLY", "no 'ply' header"),
    ),
    Case(
        "a PLY header and 1 GB of zeros in a 1 MB .gz, over --limit decompressed_bytes=64M",
        "bomb.ply.gz",
        lambda: zeros_gz(1 << 30, _binary_ply_head(10**8)),
        args=("--limit", "decompressed_bytes=64M"),
        words=("inflates past the limit of 67,108,864 bytes", "decompressed_bytes="),
    ),
    Case(
        "a truncated .gz",
        "cut.obj.gz",
        lambda: gzip.compress(grid_obj(20), mtime=0)[:300],
        words=("truncated",),
    ),
    Case(
        "ASCII PLY declaring 10^9 faces and holding one",
        "truncated.ply",
        lambda: _ply("0 0 0\n1 0 0\n0 1 0\n", "3 0 1 2\n", face_count=10**9),
        words=("truncated", "1,000,000,000 face"),
    ),
    Case(
        "binary PLY declaring 10^8 vertices and holding one",
        "truncated_binary.ply",
        lambda: _binary_ply_head(10**8) + bytes(12),
        words=("truncated", "100,000,000 vertex"),
    ),
    Case(
        "OFF declaring 10^9 faces and holding one",
        "truncated.off",
        lambda: b"OFF\n3 1000000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        words=("truncated", "1,000,000,000 face"),
    ),
    Case(
        "10,000 vertices, over --limit vertices=1000",
        "grid.obj",
        lambda: grid_obj(100),
        args=("--limit", "vertices=1000"),
        words=("10,000 vertices", "limit of 1,000", "--limit vertices="),
    ),
    Case(
        "a PLY declaring 10,000 faces, over --limit faces=1000",
        "faces.ply",
        lambda: _ply("0 0 0\n1 0 0\n0 1 0\n", "3 0 1 2\n" * 10_000),
        args=("--limit", "faces=1000"),
        words=("declares 10,000 faces", "--limit faces="),
    ),
    Case(
        "a CityJSON children chain 600 deep",
        "chain.city.json",
        lambda: _chain(600),
        code=0,
        words=("1 skipped",),
    ),
    Case(
        "a CityJSON children/parents cycle of two buildings",
        "cycle.city.json",
        lambda: city(
            {
                "a": {**city_object(), "children": ["b"]},
                "b": {**city_object([[[4, 5, 6, 7]]]), "children": ["a"]},
            },
            SQUARE + _SHIFTED,
        ),
        code=0,
        words=("wrote",),
    ),
    Case(
        "CityJSON appearance that is not an object",
        "appearance.city.json",
        lambda: city({"a": city_object()}, appearance=[1]),
        words=("'appearance'", "not an object"),
    ),
    Case(
        "CityJSON geometry-templates that is not an object",
        "templates.city.json",
        lambda: city({"a": city_object()}, **{"geometry-templates": "x"}),
        words=("'geometry-templates'", "not an object"),
    ),
    Case(
        'CityJSON "vertices": 5',
        "vertices.city.json",
        lambda: city({"a": city_object()}, 5),
        words=("vertices that are not a list",),
    ),
    Case(
        'CityJSONSeq feature with "vertices": 5 beside a good one',
        "vertices.city.jsonl",
        lambda: sequence(
            {"CityObjects": {"a": city_object()}, "vertices": 5},
            {"CityObjects": {"b": city_object()}, "vertices": SQUARE},
        ),
        code=0,
        words=("1 skipped",),
    ),
    Case(
        'CityJSONSeq header with "vertices": 5',
        "header.city.jsonl",
        lambda: sequence(
            {"CityObjects": {"a": city_object()}, "vertices": SQUARE}, header={"vertices": 5}
        ),
        words=("vertices that are not a list",),
    ),
    Case(
        "CityJSON instance whose reference point is 2**63",
        "point.city.json",
        lambda: _instance(_TEMPLATE, 2**63),
        words=("tree", "reference point number 9223372036854775808"),
    ),
    Case(
        "CityJSON instance whose reference point is -1",
        "minus.city.json",
        lambda: _instance(_TEMPLATE, -1),
        words=("tree", "reference point number -1", "not one of the 4 vertices"),
    ),
    Case(
        "CityJSON template that is itself a GeometryInstance",
        "nested.city.json",
        lambda: _instance({"type": "GeometryInstance", "template": 0, "boundaries": [0]}),
        words=("tree", "uses template 0", '"GeometryInstance"'),
    ),
    Case(
        "CityJSON Solid with one list level too many",
        "solid.city.json",
        lambda: city({"a": city_object([[[[[0, 1, 2, 3]]]]], "Solid")}),
        words=("a: has malformed Solid boundaries", "not a whole number"),
    ),
    *(
        Case(
            f"CityJSON boundary index {shown}",
            f"index{n}.city.json",
            lambda index=index: city({"a": city_object([[[0, 1, 2, index]]])}),
            words=("a: has malformed MultiSurface boundaries", f"an index is {shown}"),
        )
        for n, (index, shown) in enumerate(
            [(16.5, "number 16.5"), ("16", 'string "16"'), (True, "boolean true")]
        )
    ),
    Case(
        "CityJSON vertices NaN, Infinity and 1e308 (scaled past float64) beside a good building",
        "nan.city.json",
        lambda: city(
            {
                "good": city_object(),
                "nan": city_object([[[0, 1, 2, 4]]]),
                "inf": city_object([[[0, 1, 2, 5]]]),
                "big": city_object([[[0, 1, 2, 6]]]),
            },
            [*SQUARE, [float("nan"), 0, 0], [float("inf"), 0, 0], [1e308, 0, 0]],
            transform={"scale": [10, 10, 10], "translate": [0, 0, 0]},
        ),
        code=0,
        words=("3 skipped",),
    ),
    Case(
        "a CityJSON .gz inflating to 64 MiB, over --limit decompressed_bytes=16M",
        "bomb.city.json.gz",
        lambda: zeros_gz(64 << 20, b'{"type": "CityJSON", "version": "2.0", "x": "', b"x"),
        args=("--limit", "decompressed_bytes=16M"),
        words=("inflates past the limit of 16,777,216 bytes", "decompressed_bytes="),
    ),
    Case(
        "a CityJSONSeq .gz of a header and 256 MiB of newlines, over --limit "
        "decompressed_bytes=16M",
        "newlines.city.jsonl.gz",
        lambda: zeros_gz(256 << 20, sequence(), b"\n"),
        args=("--limit", "decompressed_bytes=16M"),
        words=("inflates past the limit of 16,777,216 bytes",),
    ),
    Case(
        "a CityJSONSeq feature line of 2 MiB, over --limit sequence_line_bytes=1M",
        "long.city.jsonl",
        lambda: sequence(
            {"CityObjects": {"a": city_object()}, "vertices": SQUARE},
            {"CityObjects": {"b": city_object()}, "vertices": SQUARE, "x": "x" * (2 << 20)},
        ),
        args=("--limit", "sequence_line_bytes=1M"),
        code=0,
        words=("(1 object(s), 1 skipped,",),
    ),
    Case(
        "a CityJSONSeq header line of 2 MiB, over --limit sequence_line_bytes=1M",
        "longheader.city.jsonl",
        lambda: sequence(
            {"CityObjects": {"a": city_object()}, "vertices": SQUARE},
            header={"metadata": {"title": "x" * (2 << 20)}},
        ),
        args=("--limit", "sequence_line_bytes=1M"),
        words=("line 1", "longer than the limit"),
    ),
    Case(
        "a valid ASCII PLY followed by 64 MiB of newlines in a .ply.gz",
        "blank.ply.gz",
        lambda: zeros_gz(64 << 20, _ply("0 0 0\n1 0 0\n0 1 0\n", "3 0 1 2\n"), b"\n"),
        code=0,
        words=("wrote",),
    ),
    Case(
        "an .obj.gz of 256 MiB of spaces",
        "spaces.obj.gz",
        lambda: zeros_gz(256 << 20, fill=b" "),
        words=("no vertex ('v') or face ('f') lines",),
    ),
    Case(
        "CityGML: a generic attribute in genericAttributeSets nested 1,000 deep",
        "sets.gml",
        lambda: gml.nested_attribute_sets(1000),
        words=("deeper than the limit of 256", "--limit xml_depth="),
    ),
    Case(
        "CityGML: a BuildingPart of a BuildingPart… 500 deep",
        "parts.gml",
        lambda: gml.part_chain(500),
        words=("deeper than the limit of 256",),
    ),
    Case(
        "CityGML: BuildingParts nested 40 deep (within --limit xml_depth=2048)",
        "parts40.gml",
        lambda: gml.part_chain(40),
        args=("--limit", "xml_depth=2048"),
        words=("B1", "parts nested more than 32 deep"),
    ),
    Case(
        "CityGML: 500 nested CompositeSurfaces",
        "composites.gml",
        lambda: gml.nested_composites(500),
        words=("deeper than the limit of 256",),
    ),
    Case(
        "CityGML: a solid reaching its polygons through 1,500 chained xlink:hrefs",
        "links.gml",
        lambda: gml.link_chain(1500),
        code=0,
        words=("wrote",),
    ),
    *(
        Case(
            f"CityGML: a posList value {value} in one of two buildings",
            f"{name}.gml",
            lambda value=value: gml.with_coordinate(value),
            code=0,
            words=("bad", reason, "skipped"),
        )
        for name, value, reason in (
            ("nan", "nan", "NaN or infinite"),
            ("inf", "-inf", "NaN or infinite"),
            ("huge", "1e308", "1e+308"),
        )
    ),
    Case(
        "CityGML: a posList value NaN with --strict",
        "strict_nan.gml",
        lambda: gml.with_coordinate("nan"),
        args=("--strict",),
        words=("object bad", "NaN or infinite", "--strict"),
    ),
    Case(
        "CityGML: a 2 MB gml:description, over --limit xml_text_bytes=1M",
        "description.gml",
        lambda: gml.long_text(2 << 20),
        args=("--limit", "xml_text_bytes=1M"),
        words=("over the limit of 1,048,576 bytes", "--limit xml_text_bytes="),
    ),
    Case(
        "CityGML: a 2 MB gml:description in pieces between comments, over xml_text_bytes=1M",
        "commented.gml",
        lambda: gml.long_text(2 << 20, split_by="<!-- <a> -->"),
        args=("--limit", "xml_text_bytes=1M"),
        words=("over the limit of 1,048,576 bytes",),
    ),
    Case(
        "CityGML: a .gml.gz of empty members inflating to 64 MiB, over decompressed_bytes=8M",
        "members.gml.gz",
        lambda: gml.empty_members_gz(64 << 20),
        args=("--limit", "decompressed_bytes=8M"),
        words=("inflates past the limit of 8,388,608 bytes",),
    ),
    Case(
        "CityJSON: an id with U+0001 and an attribute with a lone surrogate",
        "text.city.json",
        lambda: city({"a\x01b": {**city_object(), "attributes": {"name": "x\ud800y"}}}),
        code=0,
        words=("wrote",),
    ),
    Case(
        "CityJSON: a 12 MB attribute (past libxml2's 10 MB attribute limit)",
        "long.city.json",
        lambda: city({"a": {**city_object(), "attributes": {"note": "x" * (12 << 20)}}}),
        code=0,
        words=("wrote",),
    ),
    Case(
        "CityJSON: an attribute nested 600 deep",
        "deep.city.json",
        lambda: city({"a": {**city_object(), "attributes": {"deep": _nested(600)}}}),
        code=0,
        words=("wrote",),
    ),
    *(
        Case(
            f"option {' '.join(args)}",
            "ok.obj",
            lambda: (TRIANGLE + "f 1 2 3\n").encode(),
            args=args,
            code=2,
            words=(args[0],),
        )
        for args in (
            ("--resolution", "inf,inf,inf"),
            ("--resolution", "nan,nan,nan"),
            ("--resolution", "1e400,1e400,1e400"),
            ("--x", "1e300,2e300,3e300"),
            ("--cull", "1e300"),
            ("--beta", "1e-320"),
            ("--beta", "1e308"),
            ("--plot-radius", "1e308"),
            ("--limit", "memory_bytes=-1"),
        )
    ),
)
"""Every hostile case, in the order the docs list them."""
