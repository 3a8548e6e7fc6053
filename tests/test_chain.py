"""LOD chains: levels, default parameters, switching distances, degenerate objects."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions
from lodconvert.errors import InputError, UsageError
from lodconvert.model import Node, Surface
from lodconvert.plan import level_cost
from lodconvert.plans import bake_chain
from lodconvert.ranges import projected_px

from .conftest import degenerate_meshes, surface_of


def chain_of(obj: Node, **options):
    return bake_chain(obj, ChainOptions(**options), NumpyBackend())


def test_default_chain_is_mesh_then_three_point_levels(bunny: Node) -> None:
    chain = chain_of(bunny)
    assert [lv.name for lv in chain.levels] == ["LOD4", "LOD3", "LOD2", "LOD1"]
    assert [lv.kind for lv in chain.levels] == ["mesh", "pcd", "pcd", "pcd"]
    counts = [lv.count for lv in chain.levels]
    assert counts[0] == len(bunny.geometry.vertices)
    assert all(b < a for a, b in itertools.pairwise(counts)), counts


def test_cutoffs_follow_alpha_beta_gamma(bunny: Node) -> None:
    chain = chain_of(bunny, gamma=20.0)
    lo, hi = bunny.geometry.bounds
    alpha = float(np.linalg.norm(hi - lo))
    assert chain.alpha == pytest.approx(alpha)
    expected = [alpha * 3.0 * 20.0**x for x in (0.33, 0.66, 1.0)]
    assert chain.cutoffs == pytest.approx(expected)
    assert np.allclose(chain.origin, (lo + hi) / 2)


def test_default_resolution_keeps_spacing_within_budget(bunny: Node) -> None:
    opts = ChainOptions()
    chain = chain_of(bunny)
    for level in chain.levels[1:]:
        # the pitch seen from where the level first shows stays within the pixel budget ...
        spacing_px = projected_px(level.spacing, level.design_distance, opts.view)
        assert spacing_px <= opts.spacing_px + 1e-9
        # ... and the point size covers the pitch there
        assert level.params.point_size >= max(1.0, spacing_px) - 1e-9
    # coarser levels are designed for farther distances
    assert [lv.design_distance for lv in chain.levels[1:]] == pytest.approx(chain.cutoffs)


def test_explicit_parameters_are_used(bunny: Node) -> None:
    chain = chain_of(bunny, resolutions=(40, 20, 10), slices=(20, 10, 5), point_sizes=(3, 4, 5))
    params = [lv.params for lv in chain.levels[1:]]
    assert [p.resolution for p in params] == [40, 20, 10]
    assert [p.slices for p in params] == [20, 10, 5]
    assert [p.point_size for p in params] == [3, 4, 5]


def test_a_level_heavier_than_the_one_before_is_lowered(torus: Node) -> None:
    warnings: list[str] = []
    chain = bake_chain(
        torus, ChainOptions(resolutions=(64, 20, 10)), NumpyBackend(), warn=warnings.append
    )
    assert level_cost(chain.levels[1]) < level_cost(chain.levels[0])  # 1,536 torus vertices
    assert chain.levels[1].params.resolution < 64
    assert any("LOD3" in w and "64" in w for w in warnings)


def test_no_mesh_bakes_every_level(torus: Node) -> None:
    chain = chain_of(torus, keep_mesh=False)
    assert [lv.kind for lv in chain.levels] == ["pcd"] * 4
    counts = [lv.count for lv in chain.levels]
    assert all(b < a for a, b in itertools.pairwise(counts))


def test_levels_and_exponents(torus: Node) -> None:
    chain = chain_of(torus, levels=3)
    assert [lv.name for lv in chain.levels] == ["LOD4", "LOD3", "LOD2"]
    assert chain.xs == [0.5, 1.0]
    with pytest.raises(UsageError, match="exponents"):
        chain_of(torus, levels=3, xs=(0.3, 0.6, 1.0))


def test_cull_adds_a_last_cutoff(torus: Node) -> None:
    chain = chain_of(torus, cull=1.5)
    assert chain.culled
    assert len(chain.cutoffs) == len(chain.levels)
    assert chain.cutoffs[-1] == pytest.approx(chain.alpha * 3 * 10**1.5)
    with pytest.raises(UsageError, match="cull must be greater than the last exponent"):
        chain_of(torus, cull=0.9)


def test_far_from_origin_levels_stay_small(torus: Node) -> None:
    offset = np.array([500000.0, 5400000.0, 100.0])
    moved = Node("far", Surface(torus.geometry.vertices + offset, torus.geometry.faces))
    chain = chain_of(moved)
    assert np.allclose(chain.origin, offset, atol=1e-6)
    near = chain_of(torus)
    for a, b in zip(chain.levels[1:], near.levels[1:], strict=True):
        assert np.abs(a.points.positions).max() < 2.0
        assert a.count == b.count


@pytest.mark.parametrize("mesh", degenerate_meshes())
def test_degenerate_but_valid_objects_convert(mesh: trimesh.Trimesh) -> None:
    warnings: list[str] = []
    chain = bake_chain(
        Node("thing", surface_of(mesh)), ChainOptions(), NumpyBackend(), warn=warnings.append
    )
    # A few triangles: no point level is both cheaper and faithful, the mesh stays on, quietly.
    assert [(lv.name, lv.kind) for lv in chain.levels] == [("LOD4", "mesh")]
    assert chain.cutoffs == [] and list(chain.dropped) == ["LOD3", "LOD2", "LOD1"]
    assert warnings == []
    points_only = bake_chain(
        Node("thing", surface_of(mesh)), ChainOptions(keep_mesh=False), NumpyBackend()
    )
    counts = [lv.count for lv in points_only.levels]
    assert counts[0] >= 1 and all(b < a for a, b in itertools.pairwise(counts))
    assert len(points_only.cutoffs) == len(points_only.levels) - 1


def test_bad_geometry_is_an_input_error() -> None:
    nan = Surface(np.array([[0, 0, 0], [1, np.nan, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    with pytest.raises(InputError, match="NaN"):
        chain_of(Node("bad", nan))
    empty = Surface(np.zeros((3, 3)), np.zeros((0, 3), dtype=np.int64))
    with pytest.raises(InputError, match="no faces"):
        chain_of(Node("empty", empty))


def test_a_moved_mesh_keeps_its_bounds_exact() -> None:
    from lodconvert.model import Mesh

    rng = np.random.default_rng(7)
    parts = [Surface(rng.random((9, 3)) * 40 + 4.4e6, rng.integers(0, 9, (5, 3))) for _ in range(3)]
    mesh = Mesh(parts)
    offset = -mesh.bounds.mean(axis=0)
    moved = mesh.translated(offset)  # the bounds come along from the mesh
    fresh = Mesh([Surface(p.vertices + offset, p.faces) for p in parts])
    np.testing.assert_array_equal(moved.bounds, fresh.bounds)
    np.testing.assert_array_equal(moved.parts[0].bounds, fresh.parts[0].bounds)


def test_a_packed_chain_comes_back_whole_after_pickling(bunny: Node) -> None:
    """A chain a worker sends packed (each level's geometry pickled where it was baked) is,
    once unpacked on the other side, the chain it baked: the same levels, geometry, placement
    and facts; tables derived from its mesh in between (a block footprint) come along, and
    the costly ones derived before packing are found again where needed, not carried."""
    import pickle

    chain = chain_of(bunny)
    chain.transform = np.eye(4)
    finest = chain.levels[0].mesh
    assert finest is not None and finest.triangles is not None  # a costly derived table
    packed = pickle.loads(pickle.dumps(chain.packed(), protocol=5))
    assert all(level.mesh is None and level.points is None for level in packed.levels)
    assert [lv.count for lv in packed.levels] == [lv.count for lv in chain.levels]
    assert [lv.faces for lv in packed.levels] == [lv.faces for lv in chain.levels]
    packed.levels[0].keep_derived({"block-footprint-3": "found"})
    back = pickle.loads(pickle.dumps(packed, protocol=5)).unpacked()
    for array in ("origin", "center", "transform"):
        assert np.array_equal(getattr(back, array), getattr(chain, array))
        assert getattr(back, array).dtype == np.float64
    assert (back.cutoffs, back.metadata, back.xs) == (chain.cutoffs, chain.metadata, chain.xs)
    mesh = back.levels[0].mesh
    assert mesh is not None and np.array_equal(mesh.vertices, finest.vertices)
    assert mesh._derived.get("block-footprint-3") == "found"
    assert "triangles" not in mesh._derived and "bounds" in mesh._derived
    for before, after in zip(chain.levels[1:], back.levels[1:], strict=True):
        assert before.points is not None and after.points is not None
        assert np.array_equal(before.points.positions, after.points.positions)
        assert np.array_equal(before.points.colors, after.points.colors)
