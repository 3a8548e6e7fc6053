"""Hostile and degenerate input through the real command line: each case ends with exit 0 or
one line naming the file and the problem, no traceback, and no output or temporary file left;
what memory it takes is measured in a child process. The cases are :data:`tests.fuzz.cases.CASES`
(``docs/hostile_input.md`` lists them), plus what the fuzzing found."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from lodconvert.io import read_scene
from lodconvert.io.geometry_checks import kept_faces, tally_of

from .conftest import ROOT
from .fuzz.cases import CASES, TRIANGLE, Case
from .fuzz.worker import run_cli
from .test_cli import assert_one_line_error, run

GB = 1 << 30


def assert_nothing_left(folder: Path, before: set[Path]) -> None:
    """No file appeared in ``folder`` but the inputs ``before``."""
    assert set(folder.iterdir()) == before


SLOW_CASES = ("members.gml.gz",)
"""Cases of several seconds: the slow tier's."""


@pytest.mark.parametrize(
    "case",
    [pytest.param(c, marks=pytest.mark.slow) if c.name in SLOW_CASES else c for c in CASES],
    ids=[c.name for c in CASES],
)
def test_hostile_case(tmp_path: Path, case: Case) -> None:
    src = case.write(tmp_path)
    out = tmp_path / "out.x3d"
    result = run(src, "-o", out, *case.args)
    if case.code:
        # an input error names the file; a usage error names the option
        named = (src.name,) if case.code == 1 else ()
        assert_one_line_error(result, case.code, *named, *case.words)
        assert_nothing_left(tmp_path, {src})
    else:
        assert result.returncode == 0, result.stderr
        for word in case.words:
            assert word in result.stderr
        assert out.exists() and not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*"))


@pytest.mark.parametrize("name", ["repeated.obj", "zeros.ply.gz", "bomb.ply.gz"])
def test_peak_memory_in_a_child(tmp_path: Path, name: str) -> None:
    (case,) = [c for c in CASES if c.name == name]
    src = case.write(tmp_path)
    result = run_cli(src, "-o", tmp_path / "out.glb", *case.args, budget=2 * GB)
    assert result.code == case.code, result.stderr
    # the 1 GB of zeros is never inflated whole: refused after its first MiB, or at the limit
    assert result.peak_bytes < (2 * GB if case.code == 0 else 600 << 20), result.peak_bytes


def test_dropped_faces_are_counted_in_the_report(tmp_path: Path) -> None:
    src = tmp_path / "parts.obj"
    square = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 0\n"
    src.write_text(f"{square}o a\nf 1 2 3\nf 1 3 4\nf 1 3 5\nf 2 2 3\no b\nf 1 1 1\n")
    report = tmp_path / "r.json"
    result = run(src, "-o", tmp_path / "out.glb", "--report", report)
    assert result.returncode == 0, result.stderr
    data = json.loads(report.read_text())
    jsonschema.validate(data, json.loads((ROOT / "schemas/report.schema.json").read_text()))
    assert data["totals"]["dropped_faces"] == 3
    assert [(o["id"], o["dropped_faces"]) for o in data["objects"]] == [("parts", 2)]
    assert [s["id"] for s in data["skipped"]] == ["b"]
    assert "b: all its 1 faces have no area" in result.stderr


def test_the_reader_keeps_faces_with_area_only(tmp_path: Path) -> None:
    src = tmp_path / "t.obj"
    src.write_text(TRIANGLE + "v 2 0 0\nf 1 2 3\nf 1 2 4\nf 3 3 1\n")
    scene = read_scene(src)
    (node,) = scene.with_geometry()
    assert node.geometry.faces.tolist() == [[0, 1, 2]]
    tally = tally_of(scene)
    assert tally is not None and tally.dropped_faces == 2 and tally.vertices == 4


def test_slivers_are_kept_and_exact_lines_dropped() -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1e-9, 0], [0.1, 0.2, 0.3], [0.3, 0.6, 0.9]])
    kept, dropped = kept_faces(v, [[0, 1, 2], [0, 3, 4]], "t")
    assert kept.tolist() == [[0, 1, 2]] and dropped == 1


def test_an_instance_placed_out_of_range_is_refused(tmp_path: Path) -> None:
    import trimesh

    scene = trimesh.Scene()
    box = trimesh.creation.box()
    far = np.eye(4)
    far[:3, 3] = (1e20, 0, 0)
    scene.add_geometry(box, node_name="near", geom_name="box")
    scene.add_geometry(box, node_name="far", geom_name="box", transform=far)
    src = tmp_path / "placed.glb"
    scene.export(src)
    assert_one_line_error(run(src, "-o", tmp_path / "o.x3d"), 1, "placed.glb", "far", "1e+20")


def test_fuzz_found_a_non_ascii_digit_in_a_ply_count(tmp_path: Path) -> None:
    # str.isdigit() accepts "1²", which int() refuses: a ValueError escaped the reader
    src = tmp_path / "count.ply"
    src.write_bytes(
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        b"property float z\nelement face 1\xb2\nproperty list uchar int vertex_indices\n"
        b"end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    assert_one_line_error(run(src, "-o", tmp_path / "o.x3d"), 1, "count.ply", "PLY")
    assert_nothing_left(tmp_path, {src})


def test_strict_turns_a_skipped_object_into_a_failure(tmp_path: Path) -> None:
    source = tmp_path / "two.obj"
    source.write_text(TRIANGLE + "o good\nf 1 2 3\no bad\nf 1 1 2\n")
    out = tmp_path / "out.glb"
    result = run(source, "-o", out)
    assert result.returncode == 0 and "1 skipped" in result.stderr.splitlines()[-1]
    out.unlink()
    result = run(source, "-o", out, "--strict")
    assert_one_line_error(result, 1, "two.obj", "object bad: ", "--strict")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["two.obj"]
