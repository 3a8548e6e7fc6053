"""``lodconvert evaluate REF OUT`` as a user runs it, and ``--level-kind`` on the converter:
table, JSON and contact sheet; one-line errors for foreign files, mismatched sources, bad
options and a machine without GL; the default chain's fidelity on the Stanford scans (slow)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import trimesh
from PIL import Image

from lodconvert.analysis.contact_sheet import SHEET_VIEWS
from lodconvert.analysis.silhouette import SilhouetteRenderer
from lodconvert.errors import LodConvertError
from lodconvert.plan import POINT_COST

from .conftest import SAMPLE, require, stanford
from .test_cli import assert_one_line_error, run

pytestmark = pytest.mark.gl

QUICK = ("--views", "8", "--size", "128", "--range-size", "128", "--samples", "20000")


@pytest.fixture(scope="module", autouse=True)
def gl_context() -> None:
    """Skip the module (or fail under LODCONVERT_REQUIRE_GL=1) without an EGL context."""
    try:
        SilhouetteRenderer(16).release()
    except LodConvertError as exc:
        require(False, str(exc), env="LODCONVERT_REQUIRE_GL")


@pytest.fixture(scope="module")
def outputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The bundled sample converted to .glb and .x3d, and with --level-kind qem."""
    folder = tmp_path_factory.mktemp("evaluate")
    paths = {
        "glb": folder / "knot.glb",
        "x3d": folder / "knot.x3d",
        "qem": folder / "knot-qem.glb",
    }
    for key, path in paths.items():
        extra = ("--level-kind", "pcd,qem,qem") if key == "qem" else ()
        result = run(SAMPLE, "-o", path, "-q", "--backend", "numpy", *extra)
        assert result.returncode == 0, result.stderr
    return paths


@pytest.mark.parametrize("kind", ["glb", "x3d"])
def test_table_json_and_contact_sheet(kind: str, outputs: dict[str, Path], tmp_path: Path):
    report, sheet = tmp_path / "report.json", tmp_path / "sheet.png"
    result = run(
        "evaluate", SAMPLE, outputs[kind], *QUICK, "--json", report, "--contact-sheet", sheet
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert "128 x 128 px" in lines[0] and "8 Fibonacci views" in lines[0]
    for name in ("LOD4", "LOD3", "LOD2", "LOD1"):
        assert any(line.startswith(name) for line in lines), result.stdout
    assert "mean F of the point levels at 4, 8, 16 α" in lines[-1]

    data = json.loads(report.read_text())
    assert data["protocol"] == {
        "views": 8,
        "size": 128,
        "fov_y_deg": 45.0,
        "distances": [4.0, 8.0, 16.0],
        "samples": 20000,
        "range_size": 128,
    }
    assert data["gl_renderer"]
    (obj,) = data["objects"]
    levels = obj["levels"]
    assert [lv["scores"]["name"] for lv in levels] == ["LOD4", "LOD3", "LOD2", "LOD1"]
    assert all(s["f"] == pytest.approx(1.0, abs=1e-3) for s in levels[0]["scores"]["scores"])
    costs = [
        lv["scores"]["count"] * (POINT_COST if lv["scores"]["kind"] == "pcd" else 1.0)
        for lv in levels
    ]
    assert costs == sorted(costs, reverse=True)
    assert all(0 < lv["fraction"] < 1 / POINT_COST for lv in levels)
    # a thin knot, 128 px wide at most: far from perfect, far from empty
    assert all(0.5 < s["f"] <= 1 for lv in levels for s in lv["scores"]["scores"])
    assert obj["mean_point_f"] > 0.7
    assert levels[1]["scores"]["in_range"]["near_1px"]["f"] > 0.5

    image = Image.open(sheet)
    assert image.width == 5 * 240  # the source and four levels
    assert image.height > SHEET_VIEWS * 240


def test_level_kind_qem_writes_meshes_that_score_higher(outputs: dict[str, Path], tmp_path):
    scores = {}
    for key in ("glb", "qem"):
        path = tmp_path / f"{key}.json"
        result = run("evaluate", SAMPLE, outputs[key], *QUICK, "--json", path, "-q")
        assert result.returncode == 0 and result.stdout == "", result.stderr
        scores[key] = json.loads(path.read_text())["objects"][0]["levels"]
    kinds = [lv["scores"]["kind"] for lv in scores["qem"]]
    assert kinds == ["mesh", "pcd", "qem", "qem"]
    for qem, pcd in zip(scores["qem"][2:], scores["glb"][2:], strict=True):
        assert qem["scores"]["count"] <= pcd["scores"]["count"]
        assert qem["error"]["chamfer"] < pcd["error"]["chamfer"]


def test_level_kind_usage_errors(tmp_path: Path) -> None:
    out = tmp_path / "x.glb"
    result = run(SAMPLE, "-o", out, "--level-kind", "pcd,mesh,pcd")
    assert_one_line_error(result, 2, "--level-kind", "'mesh'")
    result = run(SAMPLE, "-o", out, "--level-kind", "qem,qem")
    assert_one_line_error(result, 2, "--level-kind", "3")
    assert not out.exists()


def test_file_lodconvert_did_not_write_is_an_error(tmp_path: Path) -> None:
    plain = tmp_path / "plain.glb"
    trimesh.creation.box().export(plain)
    assert_one_line_error(run("evaluate", SAMPLE, plain), 1, "plain.glb", "not a glTF written")
    foreign = tmp_path / "foreign.x3d"
    foreign.write_text("<X3D><Scene/></X3D>")
    assert_one_line_error(run("evaluate", SAMPLE, foreign), 1, "foreign.x3d", "not an X3D")
    assert_one_line_error(run("evaluate", SAMPLE, SAMPLE), 1, "is not a file lodconvert writes")
    missing = tmp_path / "missing.glb"
    assert_one_line_error(run("evaluate", SAMPLE, missing), 1, "missing.glb")


def test_reference_that_does_not_match_is_an_error(outputs: dict[str, Path], tmp_path: Path):
    other = tmp_path / "box.ply"
    trimesh.creation.box().export(other)
    result = run("evaluate", other, outputs["glb"], *QUICK)
    assert_one_line_error(result, 1, "box.ply", "does not match", "converted from")


def test_bad_protocol_is_a_usage_error(outputs: dict[str, Path]) -> None:
    for option, value in (("--views", "0"), ("--size", "4"), ("--distances", "4,-1")):
        result = run("evaluate", SAMPLE, outputs["glb"], option, value)
        assert_one_line_error(result, 2, option)


def test_no_gl_context_names_the_packages(outputs: dict[str, Path], monkeypatch) -> None:
    import moderngl

    def unavailable(**_: object) -> None:
        raise RuntimeError("eglGetDisplay failed")

    monkeypatch.setattr(moderngl, "create_standalone_context", unavailable)
    result = run("evaluate", SAMPLE, outputs["glb"], *QUICK)
    assert_one_line_error(result, 1, "eglGetDisplay failed", "apt-get install", "libegl1")


@pytest.mark.slow
@pytest.mark.parametrize(
    "name",
    [
        "bunny_bun_zipper.ply",
        "dragon_vrip_res2.ply.gz",
        "happy_buddha_100k.obj.gz",
        "dragon_vrip.ply.gz",
    ],
)
def test_default_chain_meets_the_fidelity_target(name: str, tmp_path: Path) -> None:
    """The issue's target: mean F of the point levels over 4, 8 and 16 α ≥ 0.95 with the
    default chain and the declared sizes (here on 16 of the protocol's 64 views)."""
    source, out, report = stanford(name), tmp_path / "out.glb", tmp_path / "report.json"
    assert run(source, "-o", out, "-q", "--backend", "numpy").returncode == 0
    options = ("--views", "16", "--range-size", "512", "--samples", "200000")
    result = run("evaluate", source, out, *options, "--json", report, "-q")
    assert result.returncode == 0, result.stderr
    (obj,) = json.loads(report.read_text())["objects"]
    assert obj["mean_point_f"] >= 0.95
    first_points = obj["levels"][1]
    assert first_points["fraction"] < 0.5  # well below the source's vertex count


def test_deeply_nested_gltf_json_is_one_line_error(tmp_path: Path) -> None:
    # json.loads raised RecursionError, which escaped as a raw Python error
    deep = tmp_path / "deep.gltf"
    lodconvert = '{"asset": {"version": "2.0", "extras": {"lodconvert": {}}}, "x": '
    deep.write_text(lodconvert + "[" * 100_000 + "]" * 100_000 + "}")
    assert_one_line_error(run("evaluate", SAMPLE, deep), 1, "deep.gltf", "nested too deeply")
