"""Fidelity measures (EGL/llvmpipe): properties a user of the metric relies on, files read back,
geometric error, contact sheets, and the fidelity of the defaults (inset points, qem levels)."""

from __future__ import annotations

import itertools
import json
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

import lodconvert
from lodconvert.analysis.contact_sheet import SHEET_COLORS, contact_sheet
from lodconvert.analysis.evaluate import (
    Protocol,
    ReferenceRenders,
    evaluate_chain,
    evaluate_object,
    geometric_errors,
    level_window,
    match_references,
    sample_spacing,
    sample_surface,
    silhouette_scores,
)
from lodconvert.analysis.render import fibonacci_directions, point_pixel_size
from lodconvert.analysis.silhouette import SilhouetteRenderer
from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions, outward_sign
from lodconvert.errors import InputError, LodConvertError
from lodconvert.io import read_chains
from lodconvert.model import LodChain, Node, PointCloud, Surface
from lodconvert.plan import level_cost
from lodconvert.plans import bake_chain
from lodconvert.ranges import cutoff

from .conftest import degenerate_meshes, require, surface_of

pytestmark = pytest.mark.gl

SIZE = 256
VIEWS = 16


@pytest.fixture(scope="module")
def renderer() -> Iterator[SilhouetteRenderer]:
    """One 256×256 renderer for the module; skips (or fails under LODCONVERT_REQUIRE_GL=1)
    when no EGL context can be made."""
    try:
        r = SilhouetteRenderer(SIZE)
    except LodConvertError as exc:
        require(False, str(exc), env="LODCONVERT_REQUIRE_GL")
    yield r
    r.release()


@pytest.fixture(scope="module")
def torus_chain() -> LodChain:
    """The default chain (mesh + 3 point levels) of a torus of diagonal ≈ 3.7."""
    mesh = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    return bake_chain(Node("torus", surface_of(mesh)), ChainOptions(), NumpyBackend())


def evaluate(chain: LodChain, renderer: SilhouetteRenderer, **kwargs: object) -> list:
    return evaluate_chain(None, chain, views=VIEWS, renderer=renderer, **kwargs)


def test_fibonacci_directions_are_unit_and_spread() -> None:
    for n in (16, 64, 256):
        d = fibonacci_directions(n)
        assert d.shape == (n, 3)
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
        cos = np.clip(d @ d.T, -1.0, 1.0)
        np.fill_diagonal(cos, -1.0)
        # Each direction owns about 4π/n steradians: neighbours are about √(4π/n) apart.
        assert np.arccos(cos.max()) > 0.8 * np.sqrt(4 * np.pi / n)
        assert np.linalg.norm(d.mean(axis=0)) < 0.01
    np.testing.assert_array_equal(fibonacci_directions(64), fibonacci_directions(64))


def test_scores_count_pixels() -> None:
    ref = np.array([[1, 1, 0, 0]], dtype=bool)
    lod = np.array([[1, 0, 1, 0]], dtype=bool)
    s = silhouette_scores(ref, lod)
    assert (s["tp"], s["fp"], s["fn"]) == (1, 1, 1)
    assert s["precision"] == s["recall"] == s["f"] == 0.5
    assert silhouette_scores(ref, ref)["f"] == 1.0
    assert silhouette_scores(ref, np.zeros_like(ref))["f"] == 0.0


def test_point_size_follows_the_declaration() -> None:
    assert point_pixel_size(2.0, 10.0, 10.0) == 2.0
    assert point_pixel_size(2.0, 10.0, 5.0) == 4.0  # twice as close, twice as wide
    assert point_pixel_size(2.0, 10.0, 5.0, view_scale=0.5) == 2.0
    assert point_pixel_size(2.0, 10.0, 100.0) == 1.0  # never below one pixel
    assert point_pixel_size(2.0, 10.0, 0.01, max_size=64.0) == 64.0


def test_mesh_against_itself_scores_one(torus_chain: LodChain, renderer: SilhouetteRenderer):
    mesh_row = evaluate(torus_chain, renderer)[0]
    assert mesh_row.kind == "mesh"
    assert [s.f for s in mesh_row.scores] == [1.0, 1.0, 1.0]
    assert all(s.fn == 0 and s.fp == 0 and s.tp > 0 for s in mesh_row.scores)


def test_point_levels_follow_the_silhouette(torus_chain: LodChain, renderer: SilhouetteRenderer):
    rows = evaluate(torus_chain, renderer, at_design_distance=True)
    assert [r.name for r in rows] == [lv.name for lv in torus_chain.levels]
    for row, level in zip(rows[1:], torus_chain.levels[1:], strict=True):
        assert row.mean_f > 0.8
        assert row.at_design is not None
        assert row.at_design.distance == level.design_distance
        # LOD1 switches in at 30 diagonals, where the torus is about 10 pixels wide: every
        # silhouette pixel a point touches counts, so precision falls but recall stays.
        assert row.at_design.f > 0.6 and row.at_design.recall > 0.95
        assert [s.diagonals for s in row.scores] == pytest.approx([4, 8, 16])


def test_empty_point_cloud_scores_zero(torus_chain: LodChain, renderer: SilhouetteRenderer):
    empty = PointCloud(np.zeros((0, 3)), np.zeros((0, 4), np.uint8), np.zeros((0, 3), np.float32))
    levels = [torus_chain.levels[0], replace(torus_chain.levels[1], points=empty)]
    row = evaluate(replace(torus_chain, levels=levels), renderer)[1]
    assert row.count == 0
    assert all(s.f == 0.0 and s.tp == 0 and s.fn > 0 for s in row.scores)


def test_shifted_mesh_scores_clearly_lower(torus_chain: LodChain, renderer: SilhouetteRenderer):
    mesh = torus_chain.levels[0].mesh
    shift = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0) * 0.1 * torus_chain.alpha
    directions = fibonacci_directions(VIEWS)
    distance = 4 * torus_chain.alpha
    original = renderer.mesh(mesh.vertices, mesh.faces)
    shifted = renderer.mesh(mesh.vertices + shift, mesh.faces)
    ref = renderer.render(original, torus_chain.center, distance, directions)
    moved = renderer.render(shifted, torus_chain.center, distance, directions)
    original.release()
    shifted.release()
    assert silhouette_scores(ref, moved)["f"] < 0.9


@pytest.mark.parametrize("name", ["torus", "bunny"])
def test_one_pixel_points_score_lower_than_declared_sizes_near(
    name: str, torus_chain: LodChain, renderer: SilhouetteRenderer, request: pytest.FixtureRequest
) -> None:
    if name == "torus":
        chain = torus_chain
    else:
        chain = bake_chain(request.getfixturevalue("bunny"), ChainOptions(), NumpyBackend())
    declared = evaluate(chain, renderer, distances_in_diagonals=(4,))[1:]
    one_px = evaluate(chain, renderer, distances_in_diagonals=(4,), pixel_size=1.0)[1:]
    # Coarse levels seen this close have gaps between 1-pixel points; declared sizes close them.
    for d, o in zip(declared, one_px, strict=True):
        assert d.scores[0].recall >= o.scores[0].recall
    assert np.mean([d.mean_f for d in declared]) > np.mean([o.mean_f for o in one_px]) + 0.05
    assert declared[-1].scores[0].pixel_size > 1.0


# --- level ranges -------------------------------------------------------------------------------


def test_level_windows_follow_the_cutoffs(torus_chain: LodChain) -> None:
    a, b, g = torus_chain.alpha, torus_chain.beta, torus_chain.gamma
    windows = [level_window(torus_chain, i) for i in range(len(torus_chain.levels))]
    # each point level first shows at its switch-in cutoff, which it was designed for
    assert [near for near, _ in windows[1:]] == pytest.approx(torus_chain.cutoffs)
    assert [near for near, _ in windows[1:]] == pytest.approx(
        [lv.design_distance for lv in torus_chain.levels[1:]]
    )
    # middles at the mean exponent; the open last range is one step (0.34) wide
    expected = [cutoff(a, b, g, x) for x in (0.165, 0.495, 0.83, 1.17)]
    assert [middle for _, middle in windows] == pytest.approx(expected)
    assert windows[0][0] == pytest.approx(a * b)
    culled = bake_chain(
        Node("t", torus_chain.levels[0].mesh), ChainOptions(cull=2.0), NumpyBackend()
    )
    assert level_window(culled, 3)[1] == pytest.approx(cutoff(a, b, g, 1.5))


# --- inset points and qem levels: what the defaults rest on -------------------------------------


def test_points_sit_half_a_pitch_inside_whatever_the_winding() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=4)
    outward = Surface(sphere.vertices, sphere.faces.astype(np.int64))
    inward = Surface(sphere.vertices, sphere.faces[:, ::-1].astype(np.int64))
    assert (outward_sign(outward), outward_sign(inward)) == (1.0, -1.0)
    for surface in (outward, inward):
        chain = bake_chain(Node("s", surface), ChainOptions(), NumpyBackend())
        for level in chain.levels[1:]:
            radius = np.linalg.norm(level.points.positions, axis=1)
            # on the sphere (within the faceting) less half a pitch
            assert np.median(radius) == pytest.approx(1.0 - 0.5 * level.spacing, abs=0.01)
    flat = Surface(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.0]]), np.array([[0, 1, 2]]))
    assert outward_sign(flat) == 0.0
    chain = bake_chain(Node("f", flat), ChainOptions(keep_mesh=False), NumpyBackend())
    assert np.all(chain.levels[0].points.positions[:, 2] == 0.0)  # no inside: left in place


def test_inset_points_follow_the_outline_better(
    torus_chain: LodChain, renderer: SilhouetteRenderer
) -> None:
    mesh = torus_chain.levels[0].mesh
    same = tuple(lv.params.resolution for lv in torus_chain.levels[1:])
    options = ChainOptions(inset=0.0, resolutions=same)
    on_surface = bake_chain(Node("torus", mesh), options, NumpyBackend())
    inset, plain = evaluate(torus_chain, renderer)[1:], evaluate(on_surface, renderer)[1:]
    for a, b in zip(inset, plain, strict=True):
        assert a.count == b.count
        assert a.mean_f > b.mean_f  # squares no longer spill half a point past the outline
        assert np.mean([s.precision for s in a.scores]) > np.mean([s.precision for s in b.scores])


def test_qem_levels_are_decimated_meshes_of_the_point_counts(
    torus_chain: LodChain, renderer: SilhouetteRenderer
) -> None:
    mesh = torus_chain.levels[0].mesh
    options = ChainOptions(level_kinds=("pcd", "qem", "qem"))
    chain = bake_chain(Node("torus", mesh), options, NumpyBackend())
    assert [lv.kind for lv in chain.levels] == ["mesh", "pcd", "qem", "qem"]
    costs = [level_cost(lv) for lv in chain.levels]
    assert all(b < a for a, b in itertools.pairwise(costs)), costs
    pairs = zip(itertools.pairwise(chain.levels[1:]), torus_chain.levels[2:], strict=True)
    for (before, qem), pcd in pairs:
        # decimated to the point count, or below the draw cost of the level before
        target = min(pcd.count, level_cost(before))
        assert 0.8 * target <= qem.count <= target
        assert qem.design_distance == pcd.design_distance
    scores = evaluate(chain, renderer)
    assert all(row.mean_f > 0.97 for row in scores[2:])


@pytest.mark.parametrize(
    "mesh", [*degenerate_meshes(), pytest.param(trimesh.creation.box().subdivide(), id="box")]
)
def test_qem_levels_that_cannot_be_lighter_stay_points(mesh: trimesh.Trimesh) -> None:
    warnings: list[str] = []
    options = ChainOptions(level_kinds=("qem",))
    obj = Node("thing", surface_of(mesh))
    chain = bake_chain(obj, options, NumpyBackend(), warn=warnings.append)
    counts = [lv.count for lv in chain.levels]
    assert all(b < a for a, b in itertools.pairwise(counts)) and counts[-1] >= 1, counts
    for level in chain.levels[1:]:
        assert level.kind == "pcd" or len(level.mesh.faces) > 0
    kept = [lv for lv in chain.levels[1:] if lv.kind == "pcd"]
    assert len([w for w in warnings if "kept as points" in w]) == len(kept)


# --- geometric error ----------------------------------------------------------------------------


def test_surface_samples_are_uniform_and_repeatable() -> None:
    box = trimesh.creation.box(extents=(1.0, 2.0, 4.0))
    surface = Surface(box.vertices, box.faces.astype(np.int64))
    points = sample_surface(surface, 20_000)
    np.testing.assert_array_equal(points, sample_surface(surface, 20_000))
    # area-weighted: the two 2×4 faces at x = ±0.5 hold 16/28 of the area
    on_x = np.isclose(np.abs(points[:, 0]), 0.5).mean()
    assert on_x == pytest.approx(16 / 28, abs=0.02)
    assert sample_spacing(surface, 20_000) == pytest.approx(np.sqrt(28 / 20_000))


def test_geometric_error_of_identical_shifted_and_empty_levels(torus_chain: LodChain) -> None:
    mesh = torus_chain.levels[0].mesh
    shift = 0.03 * torus_chain.alpha
    shifted = PointCloud(
        sample_surface(mesh, 50_000, seed=1) + np.array([shift, 0.0, 0.0]),
        np.zeros((50_000, 4), np.uint8),
        np.zeros((50_000, 3), np.float32),
    )
    empty = PointCloud(np.zeros((0, 3)), np.zeros((0, 4), np.uint8), np.zeros((0, 3), np.float32))
    levels = [
        torus_chain.levels[0],
        replace(torus_chain.levels[1], points=shifted),
        replace(torus_chain.levels[2], points=empty),
    ]
    chain = replace(torus_chain, levels=levels)
    itself, moved, none = geometric_errors(mesh, chain, 50_000)
    assert itself.chamfer == pytest.approx(0.0, abs=1e-12)
    # the surface moved sideways: points lie |n_x| · shift from it, 0.5 · shift on average
    assert 0.4 * 0.03 < moved.chamfer < 0.6 * 0.03
    assert moved.hausdorff == pytest.approx(0.03, rel=0.1)  # where the normal is along x
    assert none.chamfer is None and none.hausdorff is None
    pitches = [e.chamfer for e in geometric_errors(mesh, torus_chain, 50_000)[1:]]
    assert pitches == sorted(pitches)  # coarser levels lie farther from the surface


# --- files read back ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def written(torus_chain: LodChain, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The torus chain written as .glb and .x3d."""
    folder = tmp_path_factory.mktemp("written")
    paths = {suffix: folder / f"torus{suffix}" for suffix in (".glb", ".x3d")}
    for path in paths.values():
        lodconvert.write([torus_chain], path, source="torus")
    return paths


@pytest.mark.parametrize("suffix", [".glb", ".x3d"])
def test_files_read_back_score_as_the_chain_baked(
    suffix: str, written: dict[str, Path], torus_chain: LodChain, renderer: SilhouetteRenderer
) -> None:
    (chain,) = read_chains(written[suffix])
    assert chain.object_id == torus_chain.object_id
    assert chain.alpha == torus_chain.alpha and chain.cutoffs == torus_chain.cutoffs
    assert chain.xs == torus_chain.xs and np.array_equal(chain.origin, torus_chain.origin)
    for got, baked in zip(chain.levels, torus_chain.levels, strict=True):
        assert (got.name, got.kind, got.count) == (baked.name, baked.kind, baked.count)
        assert got.params == baked.params and got.design_distance == baked.design_distance
    read, baked = evaluate(chain, renderer), evaluate(torus_chain, renderer)
    for a, b in zip(read, baked, strict=True):
        assert [s.pixel_size for s in a.scores] == [s.pixel_size for s in b.scores]
        assert a.mean_f == pytest.approx(b.mean_f, abs=2e-3)


def test_files_lodconvert_did_not_write_are_refused(tmp_path: Path) -> None:
    plain = tmp_path / "plain.glb"
    trimesh.creation.box().export(plain)
    foreign = tmp_path / "foreign.x3d"
    foreign.write_text("<X3D><Scene><Shape><Box/></Shape></Scene></X3D>")
    for path, words in (
        (plain, "not a glTF written by lodconvert"),
        (foreign, "not an X3D file written by lodconvert"),
        (tmp_path / "mesh.ply", "is not a file lodconvert writes"),
    ):
        with pytest.raises(InputError, match=words):
            read_chains(path)


def test_references_are_matched_by_id_and_bounds(
    torus_chain: LodChain, written: dict[str, Path]
) -> None:
    (chain,) = read_chains(written[".glb"])
    source = torus_chain.levels[0].mesh.parts[0]
    right = Node("anything", replace(source, vertices=source.vertices + chain.origin))
    (surface,) = match_references([right], [chain], "ref.ply", "out.glb")
    np.testing.assert_allclose(surface.vertices, source.vertices)
    bigger = Node("torus", replace(source, vertices=source.vertices * 1.1))
    with pytest.raises(InputError, match=r"does not match out\.glb"):
        match_references([bigger], [chain], "ref.ply", "out.glb")
    with pytest.raises(InputError, match="no object 'torus'"):
        match_references([right, replace(right, id="other")], [chain], "ref.ply", "out.glb")


def test_object_report_is_json_ready(torus_chain: LodChain, renderer: SilhouetteRenderer) -> None:
    source = torus_chain.levels[0].mesh.parts[0]
    protocol = Protocol(views=4, size=SIZE, distances=(4.0,), samples=5_000, range_size=SIZE)
    references = ReferenceRenders(renderer, source, torus_chain.center, protocol.views)
    report = evaluate_object(references, torus_chain, protocol, range_references=references)
    references.release()
    record = json.loads(json.dumps(report.to_json()))
    assert record["mean_point_f"] == pytest.approx(report.mean_point_f)
    lod3 = record["levels"][1]
    assert lod3["fraction"] == pytest.approx(lod3["scores"]["count"] / len(source.vertices))
    assert set(lod3["scores"]["in_range"]) == {"near", "middle", "near_1px", "middle_1px"}
    assert lod3["error"]["chamfer"] > 0


# --- contact sheet ------------------------------------------------------------------------------


def test_contact_sheet_colours_the_differences(
    torus_chain: LodChain, renderer: SilhouetteRenderer
) -> None:
    shifted = replace(
        torus_chain.levels[1],
        points=replace(
            torus_chain.levels[1].points,
            positions=torus_chain.levels[1].points.positions
            + np.array([0.1 * torus_chain.alpha, 0.0, 0.0]),
        ),
    )
    chain = replace(torus_chain, levels=[*torus_chain.levels[:1], shifted])
    sheet = contact_sheet(renderer, torus_chain.levels[0].mesh, chain, views=2, tile=100)
    assert sheet.size == (3 * 100, sheet.height) and sheet.height > 2 * 100
    pixels = np.asarray(sheet)
    columns = [pixels[60:, c * 100 : (c + 1) * 100].reshape(-1, 3) for c in range(3)]

    def has(column: np.ndarray, name: str) -> bool:
        return bool(np.all(column == SHEET_COLORS[name], axis=1).any())

    assert has(columns[0], "both") and not has(columns[0], "level only")
    assert not has(columns[1], "level only") and not has(columns[1], "source only")  # LOD4
    assert has(columns[2], "level only") and has(columns[2], "source only")
