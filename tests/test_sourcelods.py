"""City objects' own LoDs as levels, in their CityGML slots, and the LOD1 prism derived from the
footprint where a source has no LoD1."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions, bake_chain
from lodconvert.model import Mesh, Node, Surface
from lodconvert.ranges import cutoff
from lodconvert.sourcelods import lod_rank, prism, source_levels


def block(width: float, depth: float, height: float, x: float = 0.0, y: float = 0.0) -> Mesh:
    """A box standing on z = 0."""
    box = trimesh.creation.box((width, depth, height))
    box.apply_translation((x, y, height / 2))
    return Mesh([Surface(np.asarray(box.vertices, float), np.asarray(box.faces, np.int64))])


def l_shaped(height: float) -> Mesh:
    """Two boxes making an L (20 × 10 and 10 × 10 beside it): 300 m² of footprint."""
    a, b = block(20, 10, height, 10, 5), block(10, 10, height, 5, 15)
    return Mesh([*a.parts, *b.parts])


def surfaces_area(mesh: Mesh, facing: float) -> float:
    """Area of the faces whose unit normal has a z component of ``facing``."""
    tri = mesh.triangles
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1) / 2
    nz = cross[:, 2] / np.maximum(2 * area, 1e-12)
    return float(area[np.isclose(nz, facing, atol=1e-6)].sum())


@pytest.mark.parametrize(
    ("label", "rank"), [("lod2", (2, 0)), ("LOD4", (4, 0)), ("1.3", (1, 3)), ("2", (2, 0))]
)
def test_lod_labels_name_their_slot(label: str, rank: tuple[int, int]) -> None:
    assert lod_rank(label) == rank
    assert lod_rank("roof edge") is None


def test_the_highest_label_of_a_slot_wins() -> None:
    low, high, top = block(10, 10, 8), block(10, 10, 9), block(10, 10, 10)
    chosen = source_levels({"1.2": low, "1.3": high, "2.2": top})
    assert {slot: label for slot, (label, _) in chosen.items()} == {1: "1.3", 2: "2.2"}


def test_a_lod2_building_shows_its_lod2_up_to_the_lod1_slot_and_a_prism_beyond() -> None:
    house = l_shaped(9.0)
    node = Node("b", house, "Building", {"measuredHeight": 12.0}, lods={"lod2": house})
    chain = bake_chain(node, ChainOptions(gamma=20.0), NumpyBackend())
    assert [(lv.name, lv.kind) for lv in chain.levels] == [("LOD2", "source"), ("LOD1", "prism")]
    assert chain.xs == [1.0]
    assert chain.cutoffs == [pytest.approx(cutoff(chain.alpha, 3.0, 20.0, 1.0))]
    shape = chain.levels[1].mesh.translated(chain.origin)
    assert surfaces_area(shape, 1.0) == pytest.approx(300.0)  # the L, not its convex hull
    assert surfaces_area(shape, -1.0) == pytest.approx(300.0)
    assert shape.bounds[0, 2] == pytest.approx(0.0)
    assert shape.bounds[1, 2] == pytest.approx(12.0)  # measuredHeight


def test_a_source_lod1_wins_over_a_prism_and_finer_slots_keep_their_place() -> None:
    lod4, lod2, lod1 = block(10, 10, 10), block(10, 10, 10), block(10, 10, 9)
    node = Node("b", lod4, "Building", lods={"lod4": lod4, "lod2": lod2, "lod1": lod1})
    chain = bake_chain(node, ChainOptions(), NumpyBackend())
    names = [(lv.name, lv.kind) for lv in chain.levels]
    assert names[0] == ("LOD4", "source") and names[-1] == ("LOD1", "source")
    assert ("LOD2", "source") in names
    assert "LOD3" in chain.dropped  # a box: no point level pays
    assert chain.xs == [0.66, 1.0]


def test_no_footprint_means_no_prism() -> None:
    wall = Mesh([Surface(np.array([[0, 0, 0], [5, 0, 0], [5, 0, 3.0]]), np.array([[0, 1, 2]]))])
    assert prism({"lod2": wall}, wall, {}) is None
    chain = bake_chain(Node("w", wall, lods={"lod2": wall}), ChainOptions(), NumpyBackend())
    assert [lv.name for lv in chain.levels] == ["LOD2"] and "LOD1" in chain.dropped


def test_plot_radii_come_from_the_neighbours_spacing() -> None:
    from lodconvert.model import Scene
    from lodconvert.pipeline import object_ranges
    from lodconvert.plots import MAX_RADIUS

    houses = [block(8, 8, 6, x, 0.0) for x in (0.0, 20.0, 50.0)]
    far = block(8, 8, 6, 5000.0, 0.0)
    nodes = [Node(f"b{i}", m, "Building", lods={"lod2": m}) for i, m in enumerate([*houses, far])]
    rows = object_ranges(Scene("city", nodes), ChainOptions())
    assert [row["gamma"] for row in rows] == [10.0, 10.0, 15.0, MAX_RADIUS]
    fixed = object_ranges(Scene("city", nodes), ChainOptions(gamma=20.0))
    assert {row["gamma"] for row in fixed} == {20.0}
    mesh = object_ranges(Scene("mesh", [Node("m", block(8, 8, 6))]), ChainOptions())
    assert mesh[0]["gamma"] == 10.0  # objects of a mesh file keep the default


def test_inputs_merge_the_lods_of_one_city_object() -> None:
    from lodconvert.model import Scene
    from lodconvert.pipeline import merged

    lod1, lod2, lod3 = block(10, 10, 8), block(10, 10, 9), block(10, 10, 10)
    scenes = [
        Scene("a.gml", [Node("house", lod1, "Building", {"name": "a"}, lods={"lod1": lod1})]),
        Scene("b.gml", [Node("house", lod3, "Building", {"name": "b"}, lods={"lod3": lod3})]),
        Scene("c.gml", [Node("house", lod2, "Building", lods={"lod2": lod2}), Node("m", lod1)]),
        Scene("d.ply", [Node("m", lod2)]),
    ]
    scene = merged(scenes)
    house, *meshes = list(scene.nodes)
    assert sorted(house.lods) == ["lod1", "lod2", "lod3"]
    assert house.geometry is lod3 and house.attributes == {"name": "a"}
    assert [n.id for n in meshes] == ["m", "m"]  # meshes are never merged: both stay
    chain = bake_chain(house, ChainOptions(), NumpyBackend())
    assert [(lv.name, lv.kind) for lv in chain.levels] == [
        ("LOD3", "source"),
        ("LOD2", "source"),
        ("LOD1", "source"),
    ]
