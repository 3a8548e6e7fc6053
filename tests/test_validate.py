"""``lodconvert validate`` and the converter's check: our outputs pass; each broken rule gives
its one-line finding; bad input gives findings, exit status 1 and no traceback; an output that
fails is never renamed into place."""

from __future__ import annotations

import codecs
import concurrent.futures
import dataclasses
import json
import re
import struct
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions
from lodconvert.cli import main
from lodconvert.errors import LodConvertError
from lodconvert.io import OutputInfo, gltf, streamed
from lodconvert.io.findings import Findings
from lodconvert.io.gltf.check import MAX_JSON_DEPTH, check_gltf
from lodconvert.io.x3d import write_x3d
from lodconvert.io.x3d.check import check_x3d
from lodconvert.model import LodChain, Node
from lodconvert.plans import bake_chain
from lodconvert.validate import Finding, errors_of, validate_file

from .conftest import SAMPLE, X3D_SCHEMAS, require, surface_of
from .test_cli import assert_one_line_error, run

INFO = OutputInfo(generator="lodconvert tests", source="torus.ply")
WRITERS = {".x3d": write_x3d, ".glb": gltf.write_glb, ".gltf": gltf.write_gltf}


@pytest.fixture(scope="module")
def chains() -> list[LodChain]:
    """A plain and a culled chain of a small torus."""
    torus = surface_of(trimesh.creation.torus(major_radius=1.0, minor_radius=0.3))
    options = ChainOptions(resolutions=(24, 12, 6))
    plain = bake_chain(Node("torus", torus), options, NumpyBackend())
    culled = bake_chain(Node("culled", torus), replace(options, cull=1.5), NumpyBackend())
    return [plain, culled]


def _write(chains: list[LodChain], path: Path) -> Path:
    with path.open("wb") as handle:
        WRITERS[path.suffix](iter(chains), handle, INFO)
    return path


@pytest.fixture
def x3d(chains: list[LodChain], tmp_path: Path) -> Path:
    return _write(chains, tmp_path / "torus.x3d")


@pytest.fixture
def glb(chains: list[LodChain], tmp_path: Path) -> Path:
    return _write(chains, tmp_path / "torus.glb")


def _codes(findings: list[Finding]) -> set[str]:
    return {f.code for f in findings}


# --- our outputs pass ---------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".x3d", ".glb", ".gltf"])
def test_written_files_have_no_findings(
    chains: list[LodChain], tmp_path: Path, suffix: str
) -> None:
    assert validate_file(_write(chains, tmp_path / f"torus{suffix}")) == []


def test_x3d_passes_the_official_schema(x3d: Path) -> None:
    require((X3D_SCHEMAS / "x3d-4.0.xsd").exists(), f"{X3D_SCHEMAS} is absent")
    assert validate_file(x3d, x3d_schema=X3D_SCHEMAS) == []
    assert validate_file(x3d, x3d_schema=X3D_SCHEMAS / "x3d-4.0.xsd") == []


def test_finding_is_one_line() -> None:
    finding = Finding("model.glb", "error", "MSFT_LOD_ID_RANGE", "node 3 (x_LOD4) id 12 is out")
    assert str(finding) == "model.glb: error MSFT_LOD_ID_RANGE: node 3 (x_LOD4) id 12 is out"


# --- X3D rules ----------------------------------------------------------------------------------


def _edit(path: Path, pattern: str, replacement: str, count: int = 1) -> Path:
    text, n = re.subn(pattern, replacement, path.read_text(), count=count)
    assert n, f"{pattern!r} not found"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("pattern", "replacement", "code"),
    [
        (r'range="(\S+) ', r'range="', "LOD_CHILDREN"),  # one range fewer
        (r'range="(\S+) (\S+)', r'range="\2 \1', "LOD_RANGE"),  # not increasing
        (r'range="', 'range="-1 ', "LOD_CHILDREN"),
        (r"(<PointSet>\s*<Color color=\")", r"\g<1>0 0 0 ", "POINTSET_COLOR_COUNT"),
        (r"(<PointSet>)", r'\1<Normal vector="0 0 1"/>', "POINTSET_NORMAL"),
        (r'(<PointSet>.*?<Coordinate point=")', r"\g<1>1 2 ", "NUMBERS"),  # not whole points
        (r'(<IndexedTriangleSet solid="false" index=")', r"\g<1>100000 0 1 ", "INDEX_RANGE"),
        (r'(<IndexedTriangleSet solid="false" index=")', r"\g<1>1.5 0 1 ", "NUMBERS"),
        (r'(<IndexedTriangleSet solid="false" index=")', r"\g<1>0x1 0 1 ", "NUMBERS"),
        (r'(<IndexedTriangleSet solid="false" index=")', r"\g<1>1e1 0 1 ", "NUMBERS"),
        (
            r'(<IndexedTriangleSet solid="false" index=")',
            r"\g<1>99999999999999999999 0 1 ",
            "NUMBERS",
        ),
        (r'(<IndexedTriangleSet solid="false" index=")', r"\g<1>0 1 ", "NUMBERS"),  # rows of 3
        (r'(<Coordinate point=")', r"\g<1>1 2 x ", "NUMBERS"),
        (r'<component name="Navigation" level="2"/>', "", "X3D_COMPONENT"),
        (r'<component name="Shape" level="5"/>', "", "X3D_COMPONENT"),
    ],
)
def test_broken_x3d_rules_are_found(x3d: Path, pattern: str, replacement: str, code: str) -> None:
    text = x3d.read_text()
    broken, n = re.subn(pattern, replacement, text, count=1, flags=re.S)
    assert n == 1
    x3d.write_text(broken)
    findings = validate_file(x3d)
    assert code in _codes(errors_of(findings)), findings
    assert all("\n" not in str(f) for f in findings)


def test_schema_finds_what_structure_checks_allow(x3d: Path) -> None:
    require((X3D_SCHEMAS / "x3d-4.0.xsd").exists(), f"{X3D_SCHEMAS} is absent")
    _edit(x3d, r'pointSizeScaleFactor="[^"]*"', 'pointSizeScaleFactor="0.5"')
    assert validate_file(x3d) == []
    findings = validate_file(x3d, x3d_schema=X3D_SCHEMAS)
    assert _codes(findings) == {"XSD"}
    assert "pointSizeScaleFactor" in findings[0].message


def test_unloadable_schema_is_an_error(x3d: Path, tmp_path: Path) -> None:
    with pytest.raises(LodConvertError, match="cannot load the schema"):
        validate_file(x3d, x3d_schema=tmp_path / "none.xsd")


@pytest.mark.parametrize(
    ("text", "code"),
    [
        ("<html><body/></html>", "X3D_ROOT"),
        ("<X3D version='4.0'><Scene><Group></Scene></X3D>", "XML_SYNTAX"),
        ("<X3D version='4.0'><head/></X3D>", "X3D_SCENE"),
        ("not xml at all", "XML_SYNTAX"),
        ("", "EMPTY"),
        (
            "<X3D version='4.0'><Scene><LOD range='5'><Group/><Group/></LOD></Scene></X3D>",
            "NO_LOD_CHAIN",
        ),
    ],
)
def test_bad_x3d_input_gives_findings(tmp_path: Path, text: str, code: str) -> None:
    path = tmp_path / "bad.x3d"
    path.write_text(text)
    assert code in _codes(errors_of(validate_file(path)))


def test_truncated_x3d_is_not_well_formed(x3d: Path) -> None:
    data = x3d.read_bytes()
    x3d.write_bytes(data[: len(data) // 2])
    (finding,) = validate_file(x3d)
    assert finding.code == "XML_SYNTAX" and "line" in finding.message


def test_x3d_without_a_chain_is_an_error(x3d: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Valid X3D whose LODs lack lodconvert's MetadataSet is not one of our outputs."""
    _edit(x3d, '<MetadataSet name="lodconvert"', '<MetadataSet name="other"', count=0)
    assert main(["validate", str(x3d)]) == 1
    assert capsys.readouterr().out.splitlines() == [
        f"{x3d}: error NO_LOD_CHAIN: no lodconvert LOD chain: no LOD inside a Transform holding "
        "MetadataSet name='lodconvert'",
        f"{x3d}: 1 error(s)",
    ]


def test_other_profiles_and_versions(x3d: Path) -> None:
    _edit(x3d, 'profile="Interchange"', 'profile="Full"')
    _edit(x3d, '<component name="[^"]*" level="[^"]*"/>', "", count=3)
    assert validate_file(x3d) == []
    _edit(x3d, 'version="4.0"', 'version="3.3"')
    assert [f.code for f in validate_file(x3d)] == ["X3D_VERSION"]
    assert errors_of(validate_file(x3d)) == []


# --- glTF rules ---------------------------------------------------------------------------------


def _split(path: Path) -> tuple[dict[str, Any], bytes]:
    data = path.read_bytes()
    (json_length,) = struct.unpack_from("<I", data, 12)
    return json.loads(data[20 : 20 + json_length]), data[28 + json_length :]


def _join(path: Path, doc: dict[str, Any], blob: bytes) -> Path:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text
    chunks += struct.pack("<I4s", len(blob), b"BIN\x00") + blob
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)
    return path


def _lod_node(doc: dict[str, Any]) -> dict[str, Any]:
    return next(n for n in doc["nodes"] if "MSFT_lod" in n.get("extensions", {}))


def _ids(doc: dict[str, Any]) -> list[int]:
    return _lod_node(doc)["extensions"]["MSFT_lod"]["ids"]


def _coverage(doc: dict[str, Any]) -> list[float]:
    return _lod_node(doc)["extras"]["MSFT_screencoverage"]


def _position(doc: dict[str, Any]) -> dict[str, Any]:
    mesh = doc["meshes"][doc["nodes"][_ids(doc)[0]]["mesh"]]
    return doc["accessors"][mesh["primitives"][0]["attributes"]["POSITION"]]


def _view(doc: dict[str, Any]) -> dict[str, Any]:
    return doc["bufferViews"][_position(doc)["bufferView"]]


def _extras(doc: dict[str, Any]) -> dict[str, Any]:
    return _lod_node(doc)["extras"]["lodconvert"]


def _set(item: dict[str, Any], key: str, value: Any) -> None:
    item[key] = value


GLTF_BREAKS: list[tuple[str, Callable[[dict[str, Any]], None], str]] = [
    ("id out of range", lambda d: _ids(d).append(len(d["nodes"]) + 3), "MSFT_LOD_ID_RANGE"),
    ("id twice", lambda d: _ids(d).append(_ids(d)[0]), "MSFT_LOD_ID_DUPLICATE"),
    ("id a root", lambda d: d["scenes"][0]["nodes"].append(_ids(d)[0]), "MSFT_LOD_SCENE_ROOT"),
    ("id a child", lambda d: d["nodes"][0]["children"].append(_ids(d)[1]), "MSFT_LOD_CHILD"),
    ("coverage rising", lambda d: _coverage(d).__setitem__(1, 9.0), "MSFT_LOD_COVERAGE"),
    ("coverage count", lambda d: _coverage(d).pop(), "MSFT_LOD_COVERAGE"),
    ("not used", lambda d: d["extensionsUsed"].remove("MSFT_lod"), "MSFT_LOD_NOT_USED"),
    ("extras levels", lambda d: _extras(d)["levels"].pop(), "LODCONVERT_LEVELS"),
    ("extras cutoffs", lambda d: _extras(d)["cutoffs"].reverse(), "LODCONVERT_CUTOFFS"),
    ("position max", lambda d: _position(d)["max"].__setitem__(0, 99.0), "ACCESSOR_MIN_MAX"),
    ("position min missing", lambda d: _position(d).pop("min"), "ACCESSOR_MIN_MAX"),
    ("accessor past its view", lambda d: _set(_position(d), "count", 10**6), "ACCESSOR_BOUNDS"),
    (
        "view past the buffer",
        lambda d: _set(d["bufferViews"][-1], "byteLength", 10**8),
        "BUFFER_VIEW_BOUNDS",
    ),
    (
        "buffer past the chunk",
        lambda d: _set(d["buffers"][0], "byteLength", 10**8),
        "BUFFER_LENGTH",
    ),
    ("bad reference", lambda d: d["nodes"][0]["children"].append(999), "REFERENCE"),
    ("attribute counts", lambda d: _set(d["accessors"][1], "count", 1), "PRIMITIVE_COUNT"),
    ("asset version", lambda d: _set(d["asset"], "version", "1.0"), "ASSET_VERSION"),
    ("nodes not objects", lambda d: _set(d, "nodes", [1, 2]), "GLTF_STRUCTURE"),
    ("MSFT_lod removed", lambda d: _lod_node(d)["extensions"].clear(), "LODCONVERT_LEVELS"),
    ("buffer uri in a GLB", lambda d: _set(d["buffers"][0], "uri", "a.bin"), "GLB_BIN_BUFFER"),
    ("view without length", lambda d: d["bufferViews"][0].pop("byteLength"), "BUFFER_VIEW"),
    ("view stride of 6", lambda d: _set(_view(d), "byteStride", 6), "BUFFER_VIEW_STRIDE"),
    ("stride below an element", lambda d: _set(_view(d), "byteStride", 4), "ACCESSOR_STRIDE"),
    ("negative accessor offset", lambda d: _set(_position(d), "byteOffset", -12), "ACCESSOR"),
    ("count true", lambda d: _set(_position(d), "count", True), "ACCESSOR"),
]


@pytest.mark.parametrize(("what", "edit", "code"), GLTF_BREAKS, ids=[b[0] for b in GLTF_BREAKS])
def test_broken_gltf_rules_are_found(
    glb: Path, what: str, edit: Callable[[dict[str, Any]], None], code: str
) -> None:
    doc, blob = _split(glb)
    edit(doc)
    findings = validate_file(_join(glb, doc, blob))
    assert code in _codes(errors_of(findings)), findings
    assert all("\n" not in str(f) for f in findings)


def test_index_outside_the_vertices_is_found(glb: Path) -> None:
    doc, blob = _split(glb)
    primitive = doc["meshes"][0]["primitives"][0]
    accessor = doc["accessors"][primitive["indices"]]
    view = doc["bufferViews"][accessor["bufferView"]]
    dtype = {5123: "<u2", 5125: "<u4"}[accessor["componentType"]]
    data = bytearray(blob)
    start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
    data[start : start + np.dtype(dtype).itemsize] = np.array([60000], dtype=dtype).tobytes()
    findings = validate_file(_join(glb, doc, bytes(data)))
    assert _codes(findings) == {"INDEX_RANGE"}, findings


def test_msft_lod_required_is_a_warning(glb: Path) -> None:
    doc, blob = _split(glb)
    doc["extensionsRequired"] = ["MSFT_lod"]
    findings = validate_file(_join(glb, doc, blob))
    assert [(f.severity, f.code) for f in findings] == [("warning", "MSFT_LOD_REQUIRED")]


def test_message_names_node_and_id(glb: Path) -> None:
    doc, blob = _split(glb)
    _ids(doc)[1] = 12
    (finding,) = validate_file(_join(glb, doc, blob))
    assert str(finding) == (
        f"{glb}: error MSFT_LOD_ID_RANGE: node 1 (torus_LOD4) MSFT_lod id 12 is outside "
        f"nodes ({len(doc['nodes'])})"
    )


@pytest.mark.parametrize(
    ("cut", "code"),
    [(lambda d: d[: len(d) // 2], "GLB_LENGTH"), (lambda d: d[:10], "GLB_HEADER")],
)
def test_truncated_glb_is_found(glb: Path, cut: Callable[[bytes], bytes], code: str) -> None:
    glb.write_bytes(cut(glb.read_bytes()))
    (finding,) = validate_file(glb)
    assert finding.code == code and "truncated" in finding.message


def test_gltf_that_is_not_json(tmp_path: Path) -> None:
    path = tmp_path / "bad.gltf"
    path.write_text("{nope")
    assert _codes(validate_file(path)) == {"GLTF_JSON_SYNTAX"}


def test_unknown_and_missing_files(tmp_path: Path) -> None:
    assert _codes(validate_file(tmp_path / "a.ply")) == {"FORMAT"}
    assert _codes(validate_file(tmp_path / "a.glb")) == {"READ"}
    assert _codes(validate_file(SAMPLE, kind=".x3d")) == {"XML_SYNTAX"}


def test_gltf_without_a_chain_is_an_error(glb: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A valid glTF with no node carrying MSFT_lod or extras.lodconvert is not our output."""
    doc, blob = _split(glb)
    for node in doc["nodes"]:
        node.pop("extensions", None)
        node.pop("extras", None)
    doc["extensionsUsed"].remove("MSFT_lod")
    _join(glb, doc, blob)
    assert main(["validate", str(glb)]) == 1
    assert capsys.readouterr().out.splitlines() == [
        f"{glb}: error NO_LOD_CHAIN: no lodconvert LOD chain: no node has MSFT_lod or "
        "extras.lodconvert levels",
        f"{glb}: 1 error(s)",
    ]


# --- GLB framing, JSON text and bounded work ----------------------------------------------------


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack("<I4s", len(data), kind) + data


def _glb_bytes(*chunks: bytes, version: int = 2, length: int | None = None) -> bytes:
    """A GLB header (``length``: as declared, default the true one) and ``chunks``."""
    body = b"".join(chunks)
    declared = 12 + len(body) if length is None else length
    return struct.pack("<4sII", b"glTF", version, declared) + body


def _spaced(text: bytes) -> bytes:
    """JSON chunk data padded with spaces, as GLB requires."""
    return text + b" " * (-len(text) % 4)


def _zero_padded(text: bytes) -> bytes:
    text = text.rstrip(b" ")
    return text + b"\x00" * (4 - len(text) % 4)


J, B = b"JSON", b"BIN\x00"
DEEP = b"[" * 100_000 + b"]" * 100_000
Make = Callable[[bytes, bytes], bytes]
"""Bytes of a bad file from a good GLB's JSON chunk data and BIN chunk data."""

BAD_FILES: list[tuple[str, str, Make, str, str]] = [
    ("random bytes", ".glb", lambda j, b: bytes(range(7, 250)), "GLB_MAGIC", "not a GLB file"),
    ("text", ".glb", lambda j, b: b"solid cube\nfacet\n", "GLB_MAGIC", "b'soli', not 'glTF'"),
    ("glTF JSON", ".glb", lambda j, b: j, "GLB_MAGIC", "looks like glTF JSON: name it .gltf"),
    ("short header", ".glb", lambda j, b: b"glTF\x02\x00", "GLB_HEADER", "6 bytes, less than"),
    (
        "version 1",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, j), version=1),
        "GLB_VERSION",
        "GLB version 1",
    ),
    (
        "declared longer",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, b"{}  "), length=1234),
        "GLB_LENGTH",
        "truncated GLB: declared length 1234 but the file has 24 bytes",
    ),
    (
        "bytes after the end",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, j), _chunk(B, b)) + b"\x00" * 8,
        "GLB_LENGTH",
        "(8 after the declared end)",
    ),
    (
        "chunk past the end",
        ".glb",
        lambda j, b: _glb_bytes(struct.pack("<I4s", len(j) + 400, J) + j),
        "GLB_CHUNK_LENGTH",
        "chunk 0 (JSON) at byte 12 declares",
    ),
    (
        "half a chunk header",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, j), _chunk(B, b), b"\x00" * 4),
        "GLB_CHUNK_HEADER",
        "4 bytes left, less than a chunk header",
    ),
    (
        "chunk not aligned",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, j + b"  "), _chunk(B, b)),
        "GLB_CHUNK_ALIGNMENT",
        "not a multiple of 4",
    ),
    ("no chunks", ".glb", lambda j, b: _glb_bytes(), "GLB_JSON_CHUNK", "no chunks"),
    (
        "BIN first",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(B, b), _chunk(J, j)),
        "GLB_JSON_CHUNK",
        "the first chunk is BIN, not JSON",
    ),
    (
        "two BIN chunks",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, j), _chunk(B, b), _chunk(B, b)),
        "GLB_CHUNK_ORDER",
        "only the second chunk may be BIN",
    ),
    (
        "JSON chunk not UTF-8",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, _spaced(b'{"a": "\xff"}'))),
        "GLTF_JSON_ENCODING",
        "the GLB JSON chunk is not UTF-8 text: byte 0xff at offset 7",
    ),
    (
        "JSON chunk with a BOM",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, _spaced(codecs.BOM_UTF8 + j)), _chunk(B, b)),
        "GLTF_JSON_ENCODING",
        "byte order mark",
    ),
    (
        "JSON chunk padded with zeros",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, _zero_padded(j)), _chunk(B, b)),
        "GLB_JSON_PADDING",
        "padding must be spaces",
    ),
    (
        "JSON chunk not JSON",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, _spaced(b'{"asset": '))),
        "GLTF_JSON_SYNTAX",
        "the GLB JSON chunk is not JSON: Expecting value at line 1 column 13",
    ),
    (
        "JSON chunk nested deep",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, DEEP)),
        "GLTF_JSON_DEPTH",
        f"over {MAX_JSON_DEPTH} deep",
    ),
    (
        "JSON chunk an array",
        ".glb",
        lambda j, b: _glb_bytes(_chunk(J, b"[]  ")),
        "GLTF_STRUCTURE",
        "holds a JSON list, not an object",
    ),
    ("not JSON", ".gltf", lambda j, b: b"{nope", "GLTF_JSON_SYNTAX", "line 1 column 2"),
    (
        "PNG",
        ".gltf",
        lambda j, b: b"\x89PNG\r\n\x1a\n",
        "GLTF_JSON_ENCODING",
        "the glTF file is not UTF-8 text: byte 0x89 at offset 0",
    ),
    (
        "UTF-16",
        ".gltf",
        lambda j, b: j.decode().encode("utf-16"),
        "GLTF_JSON_ENCODING",
        "not UTF-8",
    ),
    (
        "a GLB",
        ".gltf",
        lambda j, b: _glb_bytes(_chunk(J, j), _chunk(B, b)),
        "GLTF_JSON_SYNTAX",
        "binary glTF (GLB), not JSON: name it .glb",
    ),
    ("nested deep", ".gltf", lambda j, b: DEEP, "GLTF_JSON_DEPTH", "the glTF file nests"),
    (
        "NaN",
        ".gltf",
        lambda j, b: b'{"asset": {"version": NaN}}',
        "GLTF_JSON_SYNTAX",
        "NaN is not a JSON value",
    ),
    (
        "external buffer",
        ".gltf",
        lambda j, b: b'{"buffers": [{"byteLength": 4, "uri": "a.bin"}]}',
        "GLTF_BUFFER_URI",
        "not embedded",
    ),
    (
        "bad base64",
        ".gltf",
        lambda j, b: b'{"buffers": [{"byteLength": 4, "uri": "data:,@@@"}]}',
        "GLTF_BUFFER_URI",
        "not valid base64",
    ),
]


@pytest.mark.parametrize(
    ("what", "suffix", "make", "code", "words"), BAD_FILES, ids=[b[0] for b in BAD_FILES]
)
def test_bad_gltf_files_say_what_is_wrong(
    glb: Path,
    capsys: pytest.CaptureFixture[str],
    what: str,
    suffix: str,
    make: Make,
    code: str,
    words: str,
) -> None:
    """Garbage, broken GLB framing and bad JSON give a finding in a user's terms (no codec or
    parser jargon, no traceback) on the first line the command prints."""
    doc, blob = _split(glb)
    path = glb.with_name(f"bad{suffix}")
    path.write_bytes(make(_spaced(json.dumps(doc).encode()), blob))
    assert main(["validate", str(path)]) == 1
    out = capsys.readouterr().out
    first = out.splitlines()[0]
    assert first.startswith(f"{path}: error {code}: "), out
    assert words in first, first
    assert "codec" not in out and "Traceback" not in out


def test_chunk_alignment_alone(glb: Path) -> None:
    """An unpadded JSON chunk is its own finding; the file is read on."""
    doc, blob = _split(glb)
    glb.write_bytes(
        _glb_bytes(_chunk(J, _spaced(json.dumps(doc).encode()) + b"  "), _chunk(B, blob))
    )
    assert _codes(validate_file(glb)) == {"GLB_CHUNK_ALIGNMENT"}


HANG_GUARD_S = 300.0
"""Far beyond any machine's time for the bounded work (well under a second) and far below the
hours the unbounded work takes: a guard against a hang, not a speed requirement."""


def _bounded(check: Any, *args: Any) -> Any:
    """``check(*args)``, failing only if it has not finished after :data:`HANG_GUARD_S`; the
    time taken is printed as a measurement."""
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=1)
    start = time.perf_counter()
    future = pool.submit(check, *args)
    try:
        result = future.result(timeout=HANG_GUARD_S)
    except concurrent.futures.TimeoutError:
        pytest.fail(f"still running after {HANG_GUARD_S:.0f} s: the work is not bounded")
    finally:
        pool.shutdown(wait=False)
    print(f"{check.__name__}: {time.perf_counter() - start:.3f} s")
    return result


@pytest.mark.parametrize(("stride", "code"), [(None, "ACCESSOR_BOUNDS"), (0, "BUFFER_VIEW_STRIDE")])
def test_huge_accessor_is_found_without_reading_it(
    glb: Path, stride: int | None, code: str
) -> None:
    """An accessor claiming 2^33 rows is compared with its view, never allocated or iterated
    (a zero stride would make it fit in a few bytes)."""
    doc, blob = _split(glb)
    _position(doc)["count"] = 2**33
    if stride is not None:
        _view(doc)["byteStride"] = stride
    _join(glb, doc, blob)
    findings = _bounded(validate_file, glb)
    assert code in _codes(errors_of(findings)), findings


def test_shared_accessor_data_is_read_a_bounded_number_of_times(glb: Path) -> None:
    """Primitives that re-use the same accessors read them at most a few times the buffer's
    size in all; the rest is left unchecked with a warning."""
    doc, blob = _split(glb)
    doc["meshes"][0]["primitives"] *= 200
    findings = validate_file(_join(glb, doc, blob))
    assert [(f.severity, f.code) for f in findings] == [("warning", "ACCESSOR_DATA_UNCHECKED")]


def test_many_msft_lod_ids_are_checked_in_linear_time(glb: Path) -> None:
    """100,000 repeated MSFT_lod ids are counted once each, not compared pairwise."""
    doc, blob = _split(glb)
    _lod_node(doc)["extensions"]["MSFT_lod"]["ids"] = [_ids(doc)[0]] * 100_000
    _join(glb, doc, blob)
    findings = _bounded(validate_file, glb)
    assert "MSFT_LOD_ID_DUPLICATE" in _codes(findings)


def test_unreadable_files_are_findings(tmp_path: Path) -> None:
    """A file that vanishes (or cannot be read) after the existence check is a finding."""
    for check, name in ((check_gltf, "gone.glb"), (check_x3d, "gone.x3d")):
        findings = Findings(tmp_path / name)
        check(tmp_path / name, findings, None)
        assert [(f.code, f.message) for f in findings.items] == [
            ("READ", "cannot read: No such file or directory")
        ]


def test_command_goes_on_after_bad_files(
    glb: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    deep = tmp_path / "deep.glb"
    deep.write_bytes(_glb_bytes(_chunk(J, DEEP)))
    garbage = tmp_path / "garbage.glb"
    garbage.write_bytes(b"\x00\xff" * 50)
    assert main(["validate", str(deep), str(garbage), str(glb)]) == 1
    assert [line.split(": ")[1] for line in capsys.readouterr().out.splitlines()] == [
        "error GLTF_JSON_DEPTH",
        "1 error(s)",
        "error GLB_MAGIC",
        "1 error(s)",
        "valid",
    ]


# --- command line -------------------------------------------------------------------------------


def test_command_passes_valid_files(x3d: Path, glb: Path) -> None:
    result = run("validate", x3d, glb)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [f"{x3d}: valid", f"{glb}: valid"]


def test_command_with_schema(x3d: Path) -> None:
    require((X3D_SCHEMAS / "x3d-4.0.xsd").exists(), f"{X3D_SCHEMAS} is absent")
    assert run("validate", x3d, "--x3d-schema", X3D_SCHEMAS).returncode == 0
    _edit(x3d, r'pointSizeScaleFactor="[^"]*"', 'pointSizeScaleFactor="0.5"')
    result = run("validate", "-q", x3d, "--x3d-schema", X3D_SCHEMAS)
    assert result.returncode == 1 and result.stdout.startswith(f"{x3d}: error XSD: line ")


def test_command_on_bad_input(glb: Path, tmp_path: Path) -> None:
    html = tmp_path / "page.x3d"
    html.write_text("<html><body/></html>")
    truncated = tmp_path / "truncated.glb"
    truncated.write_bytes(glb.read_bytes()[:1000])
    doc, blob = _split(glb)
    _ids(doc)[0] = 99
    bad_ids = _join(tmp_path / "ids.glb", doc, blob)
    for path, code in (
        (html, "X3D_ROOT"),
        (truncated, "GLB_LENGTH"),
        (bad_ids, "MSFT_LOD_ID_RANGE"),
    ):
        result = run("validate", "-q", path)
        assert result.returncode == 1, result.stderr
        assert result.stdout.splitlines() == [
            line for line in result.stdout.splitlines() if line.startswith(f"{path}: error ")
        ]
        assert code in result.stdout and "Traceback" not in result.stdout + result.stderr


def test_command_with_unloadable_schema(x3d: Path, tmp_path: Path) -> None:
    result = run("validate", x3d, "--x3d-schema", tmp_path / "no.xsd")
    assert_one_line_error(result, 1, "cannot load the schema")


# --- the converter's check ----------------------------------------------------------------------


def test_converter_refuses_an_invalid_output(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "knot.glb"
    out.write_bytes(b"previous output")
    real = gltf.write_glb

    def truncating(chains, handle, info, **options) -> None:
        real(chains, handle, info, **options)
        handle.truncate(handle.tell() - 8)

    writer = streamed({".glb": truncating})
    monkeypatch.setattr(gltf, "FORMAT", dataclasses.replace(gltf.FORMAT, write=writer))
    result = run(SAMPLE, "-o", out, "--resolution", "24,12,6", "--quiet")
    assert_one_line_error(result, 1, str(out), "output fails validation", "GLB_LENGTH")
    assert out.read_bytes() == b"previous output"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["knot.glb"]  # no temporary left


def test_converter_reports_validation_time(tmp_path: Path) -> None:
    report = tmp_path / "report.json"
    result = run(SAMPLE, "-o", tmp_path / "knot.x3d", "--resolution", "24,12,6", "--report", report)
    assert result.returncode == 0, result.stderr
    assert json.loads(report.read_text())["timings"]["validate"] >= 0
