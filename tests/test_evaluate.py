"""Silhouette F-measure (EGL/llvmpipe): properties a user of the metric relies on."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions, bake_chain
from lodconvert.errors import LodConvertError
from lodconvert.evaluate import (
    SilhouetteRenderer,
    evaluate_chain,
    fibonacci_directions,
    point_pixel_size,
    silhouette_scores,
)
from lodconvert.scene import LodChain, PointCloud, SceneObject

from .conftest import require, surface_of

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
    return bake_chain(SceneObject("torus", surface_of(mesh)), ChainOptions(), NumpyBackend())


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
