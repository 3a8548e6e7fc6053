"""City objects' own LoDs as levels, in their CityGML slots, and the LOD1 prism derived from the
footprint where a source has no LoD1."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions
from lodconvert.city.prisms import footprint, prism
from lodconvert.model import Mesh, Node, Surface
from lodconvert.model.lods import lod_rank, source_levels
from lodconvert.plans import bake_chain
from lodconvert.polygons import triangulate
from lodconvert.ranges import cutoff


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


def enclosed_volume(mesh: Mesh) -> float:
    """Signed volume its faces enclose: positive when they face outward. Measured about a point
    of its lowest plane, so that a prism's missing floor (which lies there) adds nothing."""
    tri = mesh.triangles - mesh.bounds[0]
    return float(np.einsum("ij,ij->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))) / 6


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
    assert surfaces_area(shape, -1.0) == 0.0  # no floor: never seen from above the ground
    assert shape.bounds[0, 2] == pytest.approx(0.0)
    assert shape.bounds[1, 2] == pytest.approx(9.0)  # its roof, not measuredHeight
    assert enclosed_volume(shape) == pytest.approx(300.0 * 9.0)  # faces outward, as the source's
    assert enclosed_volume(house) > 0
    assert closed_and_wound_alike(with_floor(shape))


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


def with_floor(shape: Mesh) -> Mesh:
    """A prism closed by its top faces turned over at its base."""
    surface = shape.single
    assert surface is not None  # one part: one draw call
    up = surface.face_normals(np.arange(len(surface.faces)))[:, 2] > 0.5
    floor = surface.vertices.copy()
    floor[:, 2] = shape.bounds[0, 2]
    return Mesh([surface, Surface(floor, surface.faces[up][:, ::-1])])


def closed_and_wound_alike(mesh: Mesh) -> bool:
    """Whether every edge of ``mesh`` (by its corners' coordinates) is run once each way as
    often as the other: no gap, and all faces wound alike."""
    edges: dict[tuple[tuple[float, ...], tuple[float, ...]], int] = {}
    for corners in mesh.triangles.tolist():
        for a, b in itertools.pairwise([*map(tuple, corners), tuple(corners[0])]):
            edges[a, b] = edges.get((a, b), 0) + 1
    return all(edges.get((b, a)) == count for (a, b), count in edges.items())


def with_slivers(slivers: list[list[tuple[float, float, float]]]) -> Mesh:
    """The 10 × 8 × 6 block on the origin and steep triangles with the corners of ``slivers``
    facing down, as leaning walls' do: slivers seen from above."""
    parts = list(block(10, 8, 6).parts)
    for corners in slivers:
        sliver = np.array(corners, dtype=float)
        (ax, ay), (bx, by), (cx, cy) = sliver[:, :2]
        if (bx - ax) * (cy - ay) - (by - ay) * (cx - ax) > 0:
            sliver = sliver[::-1].copy()
        parts.append(Surface(sliver, np.array([[0, 1, 2]])))
    return Mesh(parts)


INSIDE = [(-5, -4, 0), (5, -4, 0), (0, -3.99, 6)]
ALONG = [(5, -4, 0), (5, 4, 0), (5.01, 0, 6)]
ACROSS = [(-5, 4, 0), (0, 4.01, 6), (5, 3.99, 6)]


@pytest.mark.parametrize(
    "slivers",
    [
        [INSIDE],  # inside the ground: it adds nothing
        [ALONG],  # outside, along an edge of the ground: it merges with it
        [INSIDE, ALONG],
        [INSIDE, ACROSS],  # across an edge of the ground
    ],
)
def test_the_slivers_of_steep_faces_join_the_footprint_exactly(
    slivers: list[list[tuple[float, float, float]]],
) -> None:
    import shapely

    house = with_slivers(slivers)
    seen = [shapely.Polygon(np.array(corners)[:, :2]) for corners in slivers]
    outline = shapely.union_all([shapely.box(-5, -4, 5, 4), *seen])
    shape = prism({"lod2": house}, house, {})
    assert shape is not None and closed_and_wound_alike(with_floor(shape))
    assert surfaces_area(shape, -1.0) == 0.0
    assert surfaces_area(shape, 1.0) == pytest.approx(outline.area, rel=1e-12)
    assert shape.bounds[:, :2] == pytest.approx(np.reshape(outline.bounds, (2, 2)))


def test_a_footprint_with_a_courtyard_keeps_it() -> None:
    square = [(0, 0, 0), (10, 0, 0), (10, 10, 0), (0, 10, 0)]
    yard = [(3, 3, 0), (6, 3, 0), (6, 6, 0), (3, 6, 0)]
    points, faces = triangulate([np.array(square, float), np.array(yard, float)])
    ground = Mesh([Surface(points, faces)])
    house = block(10, 10, 5, 5, 5)
    (polygon,) = footprint({"lod0": ground, "lod2": house}, house).polygons
    assert len(polygon.interiors) == 1  # the yard is a hole
    shape = prism({"lod0": ground, "lod2": house}, house, {})
    assert shape is not None and closed_and_wound_alike(with_floor(shape))
    assert surfaces_area(shape, 1.0) == pytest.approx(91.0)
    assert surfaces_area(shape, 0.0) == pytest.approx(4 * 10 * 5 + 4 * 3 * 5)  # walls
    assert enclosed_volume(shape) == pytest.approx(91.0 * 5)


def test_plot_radii_come_from_the_neighbours_spacing() -> None:
    from lodconvert.bakery import object_ranges
    from lodconvert.city.plots import MAX_RADIUS
    from lodconvert.model import Scene

    houses = [block(8, 8, 6, x, 0.0) for x in (0.0, 20.0, 50.0)]
    far = block(8, 8, 6, 5000.0, 0.0)
    nodes = [Node(f"b{i}", m, "Building", lods={"lod2": m}) for i, m in enumerate([*houses, far])]
    rows = object_ranges(Scene("city", nodes), ChainOptions())
    assert [row["gamma"] for row in rows] == [10.0, 10.0, 15.0, MAX_RADIUS]
    fixed = object_ranges(Scene("city", nodes), ChainOptions(gamma=20.0))
    assert {row["gamma"] for row in fixed} == {20.0}
    mesh = object_ranges(Scene("mesh", [Node("m", block(8, 8, 6))]), ChainOptions())
    assert mesh[0]["gamma"] == 10.0  # objects of a mesh file keep the default


def test_nearest_distances_are_those_a_kd_tree_gives() -> None:
    """Each centre's distance to its nearest neighbour, bit for bit as scipy's ``cKDTree``
    gives it (so plot radii, and the cutoffs written, stay as they were): georeferenced
    coordinates, ties, and centres that coincide (0)."""
    from scipy.spatial import cKDTree

    from lodconvert.city.plots import nearest_distances

    rng = np.random.default_rng(3)
    for n in (2, 3, 50, 2000):
        spread = rng.random((n, 2)) * 900 + [691_000.0, 5_336_000.0]
        grid = np.round(rng.random((n, 2)) * 20, 1)  # many ties and coinciding centres
        for centres in (spread, grid, np.array([[1.0, 2.0]] * n)):
            expected = cKDTree(centres).query(centres, k=2)[0][:, 1]
            assert np.array_equal(nearest_distances(centres), expected)


def test_inputs_merge_the_lods_of_one_city_object() -> None:
    from lodconvert.inputs import merged
    from lodconvert.model import Scene

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


def test_every_prism_of_a_real_district_pays_looks_alike_and_faces_outward() -> None:
    """On TUM Munich no kept prism draws as many triangles as the LoD2 it replaces, each
    has silhouette F ≥ 0.95 where it switches in, and beyond the last cutoff the district
    draws at least 30 % fewer triangles than its LoD2; the prisms enclose their volume with
    outward faces, as the buildings do (viewers light and cull them by their winding)."""
    from lodconvert.bake import get_backend
    from lodconvert.bakery import iter_chains
    from lodconvert.city.prisms import MIN_PRISM_F
    from lodconvert.context import RunContext
    from lodconvert.io import read_scene

    from .test_citygml import sample

    chains = list(
        iter_chains(
            read_scene(sample("tum_munich_lod2_v2.zip")),
            ChainOptions(),
            RunContext.here(get_backend("numpy")),
        )
    )
    assert len(chains) == 290
    kept = [(chain.levels[0].mesh, chain.levels[-1]) for chain in chains if len(chain.levels) > 1]
    assert [lv.kind for _, lv in kept] == ["prism"] * len(kept) and len(kept) > 200
    assert all(lv.mesh.face_count < lod2.face_count for lod2, lv in kept)
    assert all(lv.silhouette_f >= MIN_PRISM_F for _, lv in kept)
    assert all("LOD1" in chain.dropped for chain in chains if len(chain.levels) == 1)
    finest = sum(chain.levels[0].mesh.face_count for chain in chains)
    beyond = sum(chain.levels[-1].mesh.face_count for chain in chains)
    assert beyond <= 0.7 * finest
    assert all(enclosed_volume(lv.mesh) > 0 for _, lv in kept)
    sources = [chain.levels[0].mesh for chain in chains]
    assert sum(enclosed_volume(mesh) > 0 for mesh in sources) > 0.95 * len(sources)
