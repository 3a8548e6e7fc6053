"""``lodconvert validate`` and the converter's check: our outputs pass; each broken rule gives
its one-line finding; bad input gives findings, exit status 1 and no traceback; an output that
fails is never renamed into place."""

from __future__ import annotations

import json
import re
import struct
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions, bake_chain
from lodconvert.errors import LodConvertError
from lodconvert.io import WRITERS, OutputInfo, writer_for
from lodconvert.model import LodChain, Node
from lodconvert.validate import Finding, errors_of, validate_file

from .conftest import SAMPLE, X3D_SCHEMAS, require, surface_of
from .test_cli import assert_one_line_error, run

INFO = OutputInfo(generator="lodconvert tests", source="torus.ply")


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
        writer_for(path)(iter(chains), handle, INFO)
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
    [(lambda d: d[: len(d) // 2], "GLTF_FORMAT"), (lambda d: d[:10], "GLTF_FORMAT")],
)
def test_truncated_glb_is_found(glb: Path, cut: Callable[[bytes], bytes], code: str) -> None:
    glb.write_bytes(cut(glb.read_bytes()))
    (finding,) = validate_file(glb)
    assert finding.code == code and "truncated" in finding.message


def test_gltf_that_is_not_json(tmp_path: Path) -> None:
    path = tmp_path / "bad.gltf"
    path.write_text("{nope")
    assert _codes(validate_file(path)) == {"GLTF_FORMAT"}


def test_unknown_and_missing_files(tmp_path: Path) -> None:
    assert _codes(validate_file(tmp_path / "a.ply")) == {"FORMAT"}
    assert _codes(validate_file(tmp_path / "a.glb")) == {"READ"}
    assert _codes(validate_file(SAMPLE, kind=".x3d")) == {"XML_SYNTAX"}


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
        (truncated, "GLTF_FORMAT"),
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
    real = writer_for(out)

    def truncating(chains, handle, info) -> None:
        real(chains, handle, info)
        handle.truncate(handle.tell() - 8)

    monkeypatch.setitem(WRITERS, ".glb", truncating)
    result = run(SAMPLE, "-o", out, "--resolution", "24,12,6")
    assert_one_line_error(result, 1, str(out), "output fails validation", "GLTF_FORMAT")
    assert out.read_bytes() == b"previous output"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["knot.glb"]  # no temporary left


def test_converter_reports_validation_time(tmp_path: Path) -> None:
    report = tmp_path / "report.json"
    result = run(SAMPLE, "-o", tmp_path / "knot.x3d", "--resolution", "24,12,6", "--report", report)
    assert result.returncode == 0, result.stderr
    assert json.loads(report.read_text())["timings"]["validate"] >= 0
