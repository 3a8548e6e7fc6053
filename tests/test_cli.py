"""The command line as a user runs it: exit codes, one-line errors, no partial output."""

from __future__ import annotations

import contextlib
import gzip
import io
import json
import re
import subprocess
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import trimesh

from lodconvert.cli import command_parser, main
from lodconvert.cli.commands import COMMANDS, MAIN_COMMAND

from .conftest import ROOT, SAMPLE, degenerate_meshes


def run(*args: str | Path) -> subprocess.CompletedProcess[str]:
    """Run the command line in this process (as the console script would) and capture it."""
    out, err = io.StringIO(), io.StringIO()
    argv = [str(a) for a in args]
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse's --help/--version/usage errors
            code = int(exc.code or 0)
    return subprocess.CompletedProcess(argv, code, out.getvalue(), err.getvalue())


def assert_one_line_error(result: subprocess.CompletedProcess[str], code: int, *words: str) -> None:
    assert result.returncode == code, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0], lines[0]


@pytest.fixture
def work(tmp_path: Path) -> Path:
    return tmp_path


def write_obj(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_sample_converts_to_x3d_and_glb_with_a_valid_report(work: Path) -> None:
    schema = json.loads((ROOT / "schemas" / "report.schema.json").read_text())
    for suffix in ("x3d", "glb"):
        out, report = work / f"knot.{suffix}", work / f"knot-{suffix}.json"
        result = run(SAMPLE, "-o", out, "--report", report, "--backend", "numpy")
        assert result.returncode == 0, result.stderr
        assert out.stat().st_size > 10_000
        data = json.loads(report.read_text())
        jsonschema.validate(data, schema)
        (obj,) = data["objects"]
        assert [lv["name"] for lv in obj["levels"]] == ["LOD4", "LOD3", "LOD2", "LOD1"]
        assert "wrote" in result.stderr


def test_same_input_and_options_give_identical_bytes(work: Path) -> None:
    for suffix in ("x3d", "glb", "gltf"):
        a, b = work / f"a.{suffix}", work / f"b.{suffix}"
        for out in (a, b):
            assert run(SAMPLE, "-o", out, "-q", "--plot-radius", "20").returncode == 0
        assert a.read_bytes() == b.read_bytes()


def test_python_m_lodconvert_runs_the_command_line(work: Path) -> None:
    version = subprocess.run(
        [sys.executable, "-m", "lodconvert", "--version"], capture_output=True, text=True
    )
    assert version.returncode == 0 and version.stdout.startswith("lodconvert ")
    missing = subprocess.run(
        [sys.executable, "-m", "lodconvert", str(work / "no.ply"), "-o", str(work / "o.glb")],
        capture_output=True,
        text=True,
    )
    assert_one_line_error(missing, 1, "no.ply", "no such file")


def test_ranges_command_prints_cutoffs() -> None:
    result = run("ranges", SAMPLE, "--plot-radius", "20", "--json")
    assert result.returncode == 0, result.stderr
    (row,) = json.loads(result.stdout)
    mesh = trimesh.load(SAMPLE, process=False)
    alpha = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    assert row["alpha"] == pytest.approx(alpha)
    assert row["cutoffs"] == pytest.approx([alpha * 3 * 20**x for x in (0.33, 0.66, 1.0)])
    table = run("ranges", SAMPLE)
    assert table.returncode == 0 and "torus_knot" in table.stdout


@pytest.mark.parametrize(
    ("name", "content", "words"),
    [
        ("missing.obj", None, ["missing.obj", "no such file"]),
        ("model.xyz", "v 0 0 0\n", ["model.xyz", "unknown input format"]),
        ("empty.obj", "", ["empty.obj", "empty"]),
        ("nan.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", ["nan.obj", "NaN"]),
        ("inf.obj", "v 0 0 0\nv 1 inf 0\nv 0 1 0\nf 1 2 3\n", ["inf.obj", "NaN or infinite"]),
        ("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", ["points.obj", "no faces"]),
    ],
)
def test_bad_input_is_one_line_exit_1_and_no_output(
    work: Path, name: str, content: str | None, words: list[str]
) -> None:
    src = work / name
    if content is not None:
        src.write_text(content)
    out = work / "out.x3d"
    assert_one_line_error(run(src, "-o", out), 1, *words)
    assert not out.exists()
    assert list(work.glob("*.tmp")) == [] and list(work.glob(".out*")) == []


def test_truncated_files_are_reported(work: Path) -> None:
    data = SAMPLE.read_bytes()
    cut = work / "cut.ply"
    cut.write_bytes(data[: len(data) // 2])
    out = work / "out.glb"
    assert_one_line_error(run(cut, "-o", out), 1, "cut.ply")
    gz = work / "cut.ply.gz"
    gz.write_bytes(gzip.compress(data)[:5000])
    assert_one_line_error(run(gz, "-o", out), 1, "cut.ply.gz")
    assert not out.exists()


def test_unknown_output_format(work: Path) -> None:
    assert_one_line_error(run(SAMPLE, "-o", work / "out.fbx"), 2, "out.fbx", "unknown output")


def test_existing_output_survives_a_failed_run(work: Path) -> None:
    out = work / "keep.x3d"
    out.write_text("previous result")
    bad = write_obj(work / "bad.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n")
    assert run(bad, "-o", out).returncode == 1
    assert out.read_text() == "previous result"


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--plot-radius", "1"], ["greater than 1"]),
        (["--plot-radius", "0.5"], ["greater than 1"]),
        (["--x", "0.66,0.33,1"], ["increasing"]),
        (["--x", "0.33,0.33,1"], ["increasing"]),
        (["--resolution", "0,32,16"], ["--resolution", "positive"]),
        (["--resolution", "64,-32,16"], ["--resolution", "positive"]),
        (["--resolution", "64,32"], ["--resolution", "3 values"]),
        (["--cull", "0.5"], ["--cull"]),
        (["--levels", "7"], ["--levels"]),
        (["--filter", "box"], ["--filter"]),
    ],
)
def test_bad_options_are_usage_errors(work: Path, args: list[str], words: list[str]) -> None:
    out = work / "out.x3d"
    assert_one_line_error(run(SAMPLE, "-o", out, *args), 2, *words)
    assert not out.exists()


def test_a_scheduler_without_dask_says_the_install_that_works_from_a_clone(
    work: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """lodconvert is on no package index: the missing dask extra is installed from the clone."""
    monkeypatch.setitem(sys.modules, "lodconvert.dask_executor", None)  # its import fails
    out = work / "out.x3d"
    result = run(SAMPLE, "-o", out, "--scheduler", "tcp://127.0.0.1:8786")
    assert_one_line_error(result, 2, "--scheduler needs dask.distributed", "pip install '.[dask]'")
    assert "lodconvert[dask]" not in result.stderr
    assert not out.exists()


def test_debug_shows_the_traceback(work: Path) -> None:
    result = run(work / "missing.ply", "-o", work / "o.x3d", "--debug")
    assert result.returncode == 1 and "Traceback" in result.stderr


@pytest.mark.parametrize("mesh", degenerate_meshes())
def test_degenerate_meshes_convert(work: Path, mesh: trimesh.Trimesh) -> None:
    src = work / "thing.obj"
    mesh.export(src)
    for suffix in ("x3d", "glb"):
        out = work / f"thing.{suffix}"
        result = run(src, "-o", out)
        assert result.returncode == 0, result.stderr
        assert out.stat().st_size > 0


def test_several_objects_stay_several_and_a_broken_one_is_skipped(work: Path) -> None:
    scene = trimesh.Scene()
    box = trimesh.creation.box(extents=(1, 2, 3))
    scene.add_geometry(box, node_name="near", geom_name="box")
    far = np.eye(4)
    far[:3, 3] = (300000.0, 5000000.0, 50.0)
    scene.add_geometry(
        trimesh.creation.icosphere(3), node_name="far", geom_name="ball", transform=far
    )
    flat = trimesh.Trimesh([[1, 1, 1]] * 3, [[0, 1, 2]], process=False)
    scene.add_geometry(flat, node_name="broken", geom_name="flat")
    src = work / "city.glb"
    scene.export(src)
    report = work / "r.json"
    result = run(src, "-o", work / "city.x3d", "--report", report)
    assert result.returncode == 0, result.stderr
    assert "broken" in result.stderr and "skipped" in result.stderr
    data = json.loads(report.read_text())
    ids = {o["id"]: o for o in data["objects"]}
    assert set(ids) == {"near", "far"}
    assert ids["far"]["origin"] == pytest.approx([300000.0, 5000000.0, 50.0])
    assert [s["id"] for s in data["skipped"]] == ["broken"]


OPTIONS_PAGE = ROOT / "docs" / "options.md"
"""Where the options of every command are listed (linked from the README)."""


def _readme_options_table() -> str:
    section = OPTIONS_PAGE.read_text(encoding="utf-8").split("\n# Options\n", 1)[-1]
    return "\n".join(line for line in section.split("\n\n")[1].splitlines() if line.startswith("|"))


def test_the_options_page_lists_every_option_of_the_main_command() -> None:
    table = _readme_options_table()
    first_cells = "\n".join(row.split(" | ")[0] for row in table.splitlines())
    listed_flags = set(re.findall(r"(?<![\w-])--?[a-z][a-z0-9-]*", first_cells))
    flags = {s for a in command_parser(MAIN_COMMAND)._actions for s in a.option_strings}
    assert {"--crs", "--strict", "--limit"} <= flags
    assert sorted(flags - listed_flags) == []


@pytest.mark.parametrize("name", sorted(set(COMMANDS) - {MAIN_COMMAND}))
def test_the_options_page_lists_every_option_of_each_other_command(name: str) -> None:
    """Each other command's row names every option of its own (those it shares with the main
    command are in the options table; -h, -q, -v and --debug are every command's)."""
    page = OPTIONS_PAGE.read_text(encoding="utf-8")
    (row,) = [line for line in page.splitlines() if line.startswith(f"| `lodconvert {name} ")]
    listed = set(re.findall(r"(?<![\w-])--?[a-z][a-z0-9-]*", row))
    shared = {s for a in command_parser(MAIN_COMMAND)._actions for s in a.option_strings}
    flags = {s for a in command_parser(name)._actions for s in a.option_strings} - shared
    assert sorted(flags - listed - {"-h", "--help", "-q", "--quiet", "-v", "--verbose"}) == []
