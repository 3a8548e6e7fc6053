"""``lodconvert bench``: grid layout, level selection, and the LOD grid against the original."""

from __future__ import annotations

import contextlib
import io
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from lodconvert import convert
from lodconvert.analysis.bench import (
    BenchSettings,
    GridRenderer,
    frustum_planes,
    grid_points,
    grid_view,
    level_kind,
    read_object,
    run_bench,
    select_levels,
    spheres_in_frustum,
)
from lodconvert.analysis.render import look_at, perspective
from lodconvert.cli import main
from lodconvert.errors import InputError
from lodconvert.plan import POINT_COST

from .conftest import SAMPLE, gl_renderer

SMALL = "4,9,25"


def cli(*args: str | Path) -> tuple[int, str, str]:
    """Run the command line in this process: exit code, stdout, stderr."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:
            code = int(exc.code or 0)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def knot(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The bundled sample converted with the default chain to .glb and .x3d, and with
    --no-mesh (a point-cloud finest level) to .glb."""
    folder = tmp_path_factory.mktemp("bench")
    files = {"glb": folder / "knot.glb", "x3d": folder / "knot.x3d"}
    for path in files.values():
        convert(SAMPLE, path, backend="numpy")
    files["points"] = folder / "knot-points.glb"
    assert cli(SAMPLE, "-o", files["points"], "--no-mesh", "-q")[0] == 0
    return files


@pytest.fixture(scope="module")
def renderer() -> Iterator[GridRenderer]:
    """One renderer for the module; skips (or fails under LODCONVERT_REQUIRE_GL=1) without an
    EGL context."""
    yield from gl_renderer(GridRenderer)


def test_grid_is_a_centred_square_lattice_going_away_from_the_camera() -> None:
    points = grid_points(9, 2.0)
    assert points.shape == (9, 2)
    assert sorted(set(points[:, 0])) == [-2.0, 0.0, 2.0]
    assert sorted(set(points[:, 1])) == [0.0, 2.0, 4.0]


def test_levels_switch_at_the_cutoffs_as_x3d_lod_does() -> None:
    d = np.array([0.0, 0.99, 1.0, 2.5, 3.0, 99.0])
    np.testing.assert_array_equal(select_levels(d, [1.0, 3.0]), [0, 0, 1, 1, 2, 2])


def test_frustum_culling_drops_spheres_behind_and_beside_the_camera() -> None:
    planes = frustum_planes(
        perspective(45.0, 1.0, 0.1, 100.0) @ look_at(np.zeros(3), np.array([0.0, 1.0, 0.0]))
    )
    centers = np.array([[0, 10, 0], [0, -10, 0], [30, 10, 0], [4.5, 10, 0], [0, 200, 0]], float)
    np.testing.assert_array_equal(
        spheres_in_frustum(centers, 1.0, planes), [True, False, False, True, False]
    )


def test_x3d_and_glb_give_the_same_chain_and_level_mix(knot: dict[str, Path]) -> None:
    glb_object, x3d_object = read_object(knot["glb"]), read_object(knot["x3d"])
    glb, x3d = glb_object.chain, x3d_object.chain
    assert [lv.name for lv in glb.levels] == [lv.name for lv in x3d.levels]
    assert [lv.count for lv in glb.levels] == [lv.count for lv in x3d.levels]
    assert [level_kind(lv) for lv in x3d.levels] == ["mesh", "pcd", "pcd", "pcd"]
    np.testing.assert_allclose(glb.cutoffs, x3d.cutoffs, rtol=1e-12)
    np.testing.assert_allclose(glb.alpha, x3d.alpha, rtol=1e-12)
    for a, b in zip(glb.levels[1:], x3d.levels[1:], strict=True):
        assert a.params.point_size == pytest.approx(b.params.point_size)
        assert a.design_distance == pytest.approx(b.design_distance)
    np.testing.assert_allclose(glb.origin + glb.center, x3d.origin + x3d.center, atol=1e-6)
    assert glb_object.reference is glb.levels[0] and x3d_object.reference is x3d.levels[0]
    for chain in (glb, x3d):
        view = grid_view(chain, 6561)
        assert set(np.unique(view.levels[view.visible])) == {0, 1, 2, 3}
        assert 0 < view.visible.sum() < 6561


def test_a_point_cloud_finest_level_needs_the_reference_mesh(knot: dict[str, Path]) -> None:
    with pytest.raises(InputError, match="--reference"):
        read_object(knot["points"])
    target = read_object(knot["points"], reference=SAMPLE)
    assert level_kind(target.chain.levels[0]) == "pcd"
    assert level_kind(target.reference) == "mesh"
    assert target.reference.count == read_object(knot["glb"]).chain.levels[0].count


@pytest.mark.gl
@pytest.mark.usefixtures("renderer")
def test_lod_grid_costs_less_to_draw_than_the_original_at_every_n(
    knot: dict[str, Path],
) -> None:
    code, out, err = cli("bench", knot["glb"], "--instances", SMALL, "--frames", "1", "--json")
    assert code == 0, err
    report = json.loads(out)
    assert report["object"] == "torus_knot"
    assert report["renderer"]
    assert report["settings"]["instances"] == [4, 9, 25]
    counts = {lv["name"]: lv["count"] for lv in report["levels"]}
    # Draw cost in mesh-vertex units: a point costs POINT_COST (the planner's cost model).
    costs = {
        lv["name"]: lv["count"] * (POINT_COST if lv["kind"] == "pcd" else 1.0)
        for lv in report["levels"]
    }
    assert [row["instances"] for row in report["rows"]] == [4, 9, 25]
    for row in report["rows"]:
        lod, original = row["lod"], row["original"]
        lod_cost = sum(n * costs[k] for k, n in lod["level_instances"].items())
        assert lod_cost < original["submitted"], row
        assert sum(n > 0 for n in lod["level_instances"].values()) > 1, row
        assert lod["submitted"] == sum(n * counts[k] for k, n in lod["level_instances"].items())
        assert lod["drawn"] == original["drawn"] == row["instances"]
        assert original["submitted"] == original["drawn"] * report["reference"]["count"]
        for grid in (lod, original):
            assert grid["status"] == "ok"
            assert len(grid["frame_seconds"]) == 1
            assert grid["median_s"] > 0 and grid["fps"] == pytest.approx(1 / grid["median_s"])
        assert row["speedup"] == pytest.approx(original["median_s"] / lod["median_s"])


@pytest.mark.gl
@pytest.mark.usefixtures("renderer")
def test_bench_prints_a_table_per_n_for_x3d(knot: dict[str, Path]) -> None:
    code, out, err = cli("bench", knot["x3d"], "--instances", "4,9", "--frames", "1", "-q")
    assert code == 0, err
    lines = out.strip().splitlines()
    assert "torus_knot" in lines[0] and "cutoffs" in lines[0]
    assert "frustum culling" in lines[1]
    assert "LOD submitted" in lines[2] and "speed-up" in lines[2]
    assert [line.split()[0] for line in lines[3:]] == ["4", "9"]
    assert all(line.rstrip().endswith("×") for line in lines[3:])


@pytest.mark.gl
def test_a_frame_over_budget_is_reported_and_larger_grids_skipped(
    knot: dict[str, Path], renderer: GridRenderer
) -> None:
    target = read_object(knot["glb"])
    settings = BenchSettings(instances=(4, 9), frames=1, warmup=0, budget_s=1e-9)
    first, second = run_bench(target, settings, renderer)
    assert first.lod.timing.status == first.original.timing.status == "over budget"
    assert second.lod.timing.status == second.original.timing.status == "skipped"
    assert first.speedup is None and first.lod.timing.median_s is None
    costs = {
        lv.name: lv.count * (POINT_COST if lv.is_points else 1.0) for lv in target.chain.levels
    }
    lod_cost = sum(n * costs[name] for name, n in second.lod.level_instances.items())
    assert lod_cost < second.original.submitted  # counted, not timed
    run_bench(target, BenchSettings(instances=(9,), frames=1, warmup=0), renderer)
    image = renderer.read_image()
    sky = np.all(image == image[0, 0], axis=2)
    assert 0.01 < 1 - sky.mean() < 0.9  # the instances cover part of the frame


def test_no_gl_context_is_one_line_naming_the_packages(
    knot: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    moderngl = pytest.importorskip("moderngl")

    def fail(**_: object) -> None:
        raise RuntimeError("eglGetDisplay failed\n(no EGL display)")

    monkeypatch.setattr(moderngl, "create_standalone_context", fail)
    code, out, err = cli("bench", knot["glb"], "--instances", "4")
    assert code == 1 and not out
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "render benchmark unavailable" in lines[0]
    assert "apt-get install" in lines[0] and "libegl1" in lines[0]


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--instances", "4,10"], ["perfect squares", "10"]),
        (["--frames", "0"], ["--frames"]),
        (["--budget", "-1"], ["--budget"]),
    ],
)
def test_bad_options_are_one_line_usage_errors(
    knot: dict[str, Path], args: list[str], words: list[str]
) -> None:
    code, _, err = cli("bench", knot["glb"], *args)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and all(w in lines[0] for w in words), err


def test_bad_files_are_one_line_errors(knot: dict[str, Path], tmp_path: Path) -> None:
    for path, words in [
        (tmp_path / "missing.glb", ["missing.glb"]),
        (SAMPLE, [".ply"]),
        (knot["glb"], ["no object", "nope"]),
    ]:
        extra = ["--object", "nope"] if path == knot["glb"] else []
        code, _, err = cli("bench", path, "--instances", "4", "--frames", "1", *extra)
        lines = err.strip().splitlines()
        assert code == 1 and len(lines) == 1 and all(w in lines[0] for w in words), err
