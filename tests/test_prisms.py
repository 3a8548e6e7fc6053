"""The LOD1 prism's shape, height and colours, and the rule that keeps it only where it pays
and looks like the building."""

from __future__ import annotations

import gc
import time

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions
from lodconvert.city.prisms import LOW_F, MORE_TRIANGLES, prism
from lodconvert.model import Mesh, Node, Surface
from lodconvert.plans import bake_chain

from .test_lods import block
from .test_plan import gabled_house


def house_of(mesh: trimesh.Trimesh) -> Mesh:
    return Mesh([Surface(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))])


@pytest.mark.parametrize("inward", [False, True])
def test_the_top_stands_at_the_60th_percentile_of_the_roof_not_its_ridge(inward: bool) -> None:
    """Seen from above, a gabled roof's height grows evenly from the eaves (6 m) to the ridge
    (10 m): 60 % of it lies below 8.4 m, whichever way the house's faces are wound."""
    house = house_of(gabled_house(10, 8, 6, 10))
    if inward:
        house = Mesh([Surface(house.vertices, house.faces[:, ::-1].copy())])
    shape = prism({"lod2": house}, house, {"measuredHeight": 10.0})
    assert shape is not None
    assert shape.bounds[:, 2] == pytest.approx([0.0, 8.4])


def test_the_top_takes_the_roofs_colour_and_the_walls_the_walls() -> None:
    """The source's materials: a red roof over white walls gives a red top over white walls
    (the floor's dark grey nowhere)."""
    red, white, dark = ([r, g, b, 255] for r, g, b in ((170, 40, 30), (250, 250, 250), (9, 9, 9)))
    box = block(10, 8, 6).single
    normals = box.face_normals(np.arange(len(box.faces)))
    parts = [
        Surface(box.vertices, box.faces[facing], base_color=np.array(color, np.uint8))
        for facing, color in (
            (normals[:, 2] > 0.5, red),
            (np.abs(normals[:, 2]) < 0.5, white),
            (normals[:, 2] < -0.5, dark),
        )
    ]
    house = Mesh(parts)
    shape = prism({"lod2": house}, house, {})
    assert shape is not None
    faces = np.arange(shape.face_count)
    colors = shape.colors_at(faces, shape.triangles.mean(axis=1)).tolist()
    up = shape.face_normals(faces)[:, 2]
    assert len(shape.parts) == 1  # one draw call
    assert {tuple(c) for c, z in zip(colors, up, strict=True) if z > 0.99} == {tuple(red)}
    assert {tuple(c) for c, z in zip(colors, up, strict=True) if abs(z) < 0.01} == {tuple(white)}
    assert (np.abs(up) > 0.99).sum() == 2  # the top's two triangles, no floor


def test_colours_inside_faces_are_interpolated_from_their_corners_times_the_base() -> None:
    """A prism's faces each have one colour at every point; a face whose corners differ shades
    from one to the next; both are modulated by the base colour and rounded to bytes."""
    vertices = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [4, 4, 0]], float)
    corners = np.array(
        [[200, 10, 10, 255], [200, 10, 10, 255], [200, 10, 10, 255], [0, 0, 255, 255]]
    )
    surface = Surface(
        vertices,
        np.array([[0, 1, 2], [1, 3, 2]]),
        vertex_colors=corners.astype(np.uint8),
        base_color=np.array([255, 128, 255, 255], np.uint8),
    )
    points = np.array([[1.0, 1.0, 0.0], [3.0, 2.0, 0.0], [4.0, 4.0, 0.0]])
    colors = surface.colors_at(np.array([0, 1, 1]), points).tolist()
    # (3, 2) on the second face: half from (4, 0), a quarter each from (4, 4) and (0, 4)
    assert colors == [[200, 5, 10, 255], [150, 4, 71, 255], [0, 0, 255, 255]]


def notched(depth: float) -> Mesh:
    """A 20 × 10 × 6 block with a notch ``depth`` deep and 2 m wide in its long south side."""
    a, b, c = (
        block(9, 10, 6, 4.5, 5),
        block(2, 10 - depth, 6, 10, 5 + depth / 2),
        block(9, 10, 6, 15.5, 5),
    )
    return Mesh([*a.parts, *b.parts, *c.parts])


def test_the_footprint_is_simplified_within_the_tolerance_topology_kept() -> None:
    house = notched(0.2)
    exact = prism({"lod2": house}, house, {})
    simple = prism({"lod2": house}, house, {}, tolerance=0.5)
    assert exact is not None and simple is not None
    assert walls(exact) == 2 * 8  # the notch's four corners kept
    assert walls(simple) == 2 * 4 and simple.face_count == 2 * 4 + 2  # a rectangle
    deep = prism({"lod2": notched(2.0)}, notched(2.0), {}, tolerance=0.5)
    assert deep is not None and walls(deep) == 2 * 8


def test_simplifying_many_footprint_polygons_takes_time_linear_in_them() -> None:
    """10,000 one-metre squares two metres apart simplified within 1.5 m (more than a square)
    cost about 4× what 2,500 cost (16× as one multipolygon, whose topology GEOS kept by
    checking every ring against all the others: a building of 100,000 parts spent minutes
    there); a polygon whose box meets another's is still simplified with it, topology kept."""
    import shapely

    from lodconvert.city.prisms import simplified_polygons

    def seconds(count: int) -> float:
        side = int(count**0.5) + 1
        squares = [
            shapely.box(2 * (i % side), 2 * (i // side), 2 * (i % side) + 1, 2 * (i // side) + 1)
            for i in range(count)
        ]
        outline = shapely.MultiPolygon(squares)
        gc.disable()  # the collector's passes cost what the rest of the test process holds
        try:
            start = time.process_time()
            simplified_polygons(outline, 1.5)
            return time.process_time() - start
        finally:
            gc.enable()

    seconds(2_500)  # warm up
    assert seconds(10_000) < 8 * seconds(2_500)
    comb = shapely.Polygon([(0, 0), (10, 0), (10, 3), (9.6, 3), (9.6, 0.4), (0, 0.4)])
    inside = shapely.box(1, 1, 9, 2.9)
    kept = simplified_polygons(shapely.MultiPolygon([comb, inside]), 0.5)
    assert len(kept) == 2 and not kept[0].intersects(kept[1])


def walls(shape: Mesh) -> int:
    """The wall triangles of ``shape``."""
    return int((np.abs(shape.face_normals(np.arange(shape.face_count))[:, 2]) < 0.01).sum())


def test_a_prism_with_as_many_triangles_as_the_lod2_is_left_out() -> None:
    """A pyramid's 4 triangles against a triangular prism's 7: the pyramid stays on."""
    pyramid = house_of(trimesh.Trimesh([(0, 0, 0), (10, 0, 0), (0, 10, 0), (3, 3, 8)],
                                       [(0, 2, 1), (0, 1, 3), (1, 2, 3), (2, 0, 3)]))  # fmt: skip
    chain = bake_chain(Node("p", pyramid, "Building", lods={"lod2": pyramid}), ChainOptions(),
                       NumpyBackend())  # fmt: skip
    assert [lv.name for lv in chain.levels] == ["LOD2"] and chain.cutoffs == []
    assert chain.dropped["LOD1"].startswith(f"{MORE_TRIANGLES} LOD2")
    assert "the prism has 7 triangles, LOD2 4" in chain.dropped["LOD1"]


def test_a_prism_that_loses_the_tower_is_left_out() -> None:
    """A 30 m tower on a 20 × 20 × 3 m podium: nine tenths of the roof lie at 3 m, and a 3 m
    block would not look like it where it switches in."""
    podium, tower = block(20, 20, 3), block(4, 4, 30)
    house = Mesh([*podium.parts, *tower.parts])
    chain = bake_chain(Node("t", house, "Building", lods={"lod2": house}), ChainOptions(),
                       NumpyBackend())  # fmt: skip
    assert [lv.name for lv in chain.levels] == ["LOD2"]
    assert chain.dropped["LOD1"].startswith(LOW_F) and "below 0.95" in chain.dropped["LOD1"]


def test_a_kept_prism_reports_its_silhouette_f() -> None:
    from lodconvert.report import chain_record

    house = house_of(gabled_house(10, 8, 6, 7))
    chain = bake_chain(Node("h", house, "Building", lods={"lod2": house}), ChainOptions(),
                       NumpyBackend())  # fmt: skip
    (prism_level,) = [lv for lv in chain_record(chain)["levels"] if lv["kind"] == "prism"]
    assert 0.95 <= prism_level["silhouette_f"] <= 1.0
    assert prism_level["faces"] == 10  # top 2, walls 8: no floor


def test_footprint_groups_are_the_connected_components_scipy_finds() -> None:
    """The groups of a footprint's triangles whose boxes meet (unioned group by group) are
    numbered as scipy's ``connected_components`` numbers them, on graphs with self-loops as
    shapely's tree gives them: isolated nodes, chains, stars and cycles."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from lodconvert.components import components

    rng = np.random.default_rng(7)
    for _ in range(300):
        n = int(rng.integers(1, 40))
        edges = rng.integers(0, n, (2, int(rng.integers(0, 2 * n))))
        pairs = np.concatenate([edges, np.stack([np.arange(n)] * 2)], axis=1)
        graph = coo_matrix((np.ones(pairs.shape[1]), pairs), shape=(n, n))
        _, expected = connected_components(graph, directed=False)
        assert components(pairs, n).tolist() == expected.tolist()


def _sampled_percentile(heights: np.ndarray, weights: np.ndarray, share: float) -> float:
    """The percentile of :func:`~lodconvert.city.roof_heights.area_percentile` by brute force: each
    triangle cut into 200² equal ones, each weighing its share of the area at its centre's
    height (off the exact one by at most a 200th of the heights' range)."""
    k = 200
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    up = (i + j <= k - 1).ravel()
    down = (i + j <= k - 2).ravel()
    u = np.concatenate([(i.ravel()[up] + 1 / 3), (i.ravel()[down] + 2 / 3)]) / k
    v = np.concatenate([(j.ravel()[up] + 1 / 3), (j.ravel()[down] + 2 / 3)]) / k
    h = (
        heights[:, :1]
        + u * (heights[:, 1:2] - heights[:, :1])
        + v * (heights[:, 2:] - heights[:, :1])
    )
    order = np.argsort(h.ravel())
    below = np.cumsum(np.repeat(weights / (k * k), h.shape[1])[order])
    return float(h.ravel()[order][np.searchsorted(below, share * weights.sum())])


def test_the_roofs_percentile_is_the_area_weighted_one_in_closed_form() -> None:
    """The height below which a share of the roof's area lies, heights varying linearly across
    each triangle, matches a brute-force count over finely cut triangles, on random triangles;
    where the area steps up at a flat triangle's height it is that height exactly."""
    from lodconvert.city.roof_heights import area_percentile

    rng = np.random.default_rng(3)
    for _ in range(40):
        m = int(rng.integers(1, 6))
        heights = rng.normal(0, 5, (m, 3))
        heights[rng.random(m) < 0.3] = rng.normal()  # some flat ones
        weights = rng.random(m) + 0.01
        share = float(rng.random())
        expected = _sampled_percentile(heights, weights, share)
        spread = heights.max() - heights.min()
        assert area_percentile(heights, weights, share) == pytest.approx(expected, abs=spread / 100)
    flat = np.array([[3.0, 3.0, 3.0], [5.0, 5.0, 5.0]])
    assert area_percentile(flat, np.array([0.7, 0.3]), 0.6) == 3.0
    assert area_percentile(flat, np.array([0.5, 0.5]), 0.6) == 5.0
    assert area_percentile(np.array([[0.0, 0.0, 4.0]]), np.array([1.0]), 0.75) == 2.0
