"""The CityJSON reader triangulates a batch of objects at a time: what it gives must not depend
on the batch (one object at a time gives the same arrays, to the last bit), polygons must come
out as :func:`~lodconvert.polygons.triangulate` makes them one by one, a broken object must cost
only itself, and CityJSONSeq must still be read a batch of features at a time."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from lodconvert.io import read_scene
from lodconvert.io.cityjson import document as cityjson_document
from lodconvert.io.cityjson import geometry
from lodconvert.io.geometry_checks import faces_with_area, tally_of
from lodconvert.polygons import DegenerateRing, triangulate

from .test_cityjson import delft, multi_lod, write_json

SCALE = 0.001
TRANSLATE = [84_000.0, 447_000.0, 0.0]


def _ring(rng: np.random.Generator, centre: np.ndarray, axes: np.ndarray, radius: float) -> list:
    """A star-shaped ring of 3 to 9 points on the plane of ``axes`` around ``centre``."""
    count = int(rng.integers(3, 10))
    angles = np.sort(rng.uniform(0, 2 * np.pi, count))
    radii = radius * rng.uniform(0.5, 1.0, count)
    flat = np.column_stack([np.cos(angles), np.sin(angles)]) * radii[:, None]
    return list(centre + flat @ axes)


def polygon_city(seed: int = 7, objects: int = 150) -> dict:
    """A CityJSON document of buildings whose MultiSurfaces hold every kind of polygon the
    reader meets: triangles, closed triangles, quads and star-shaped rings on tilted planes,
    holes (some without area), closed rings, repeated points, collinear and empty polygons,
    with semantics and materials."""
    rng = np.random.default_rng(seed)
    vertices: list[list[int]] = []

    def add(points: list) -> list[int]:
        start = len(vertices)
        vertices.extend(np.rint((np.asarray(points) - TRANSLATE) / SCALE).astype(int).tolist())
        return list(range(start, start + len(points)))

    city_objects = {}
    for k in range(objects):
        surfaces, values, materials = [], [], []
        base = np.array([84_000.0 + 30 * (k % 20), 447_000.0 + 30 * (k // 20), 0.0])
        for _ in range(int(rng.integers(1, 12))):
            q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            axes, centre = q[:2], base + rng.uniform(0, 20, 3)
            kind = rng.choice(["star", "holed", "triangle", "closed", "repeat", "line", "empty"])
            outer = add(_ring(rng, centre, axes, 5.0))
            if kind == "triangle":
                rings = [outer[:3]]
            elif kind == "holed":
                rings = [outer, add(_ring(rng, centre, axes, 1.0))]
                if rng.random() < 0.5:  # a hole without area
                    rings.append(add([centre, centre + axes[0], centre + 2 * axes[0]]))
            elif kind == "closed":
                rings = [outer + outer[:1]]
            elif kind == "repeat":
                rings = [outer[:2] + outer[1:]]
            elif kind == "line":
                rings = [add([centre, centre + axes[0], centre + 2 * axes[0]])]
            elif kind == "empty":
                rings = [[]]
            else:
                rings = [outer]
            surfaces.append(rings)
            values.append(int(rng.integers(0, 3)))
            materials.append(int(rng.integers(0, 2)) if rng.random() < 0.3 else None)
        geometry = {
            "type": "MultiSurface",
            "lod": "2",
            "boundaries": surfaces,
            "semantics": {
                "surfaces": [{"type": "RoofSurface"}, {"type": "WallSurface"}, {"type": "Door"}],
                "values": values,
            },
            "material": {"theme": {"values": materials}},
        }
        city_objects[f"b{k}"] = {"type": "Building", "geometry": [geometry]}
    return {
        "type": "CityJSON",
        "version": "2.0",
        "transform": {"scale": [SCALE] * 3, "translate": TRANSLATE},
        "metadata": {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/7415"},
        "appearance": {"materials": [{"diffuseColor": [1, 0, 0]}, {"diffuseColor": [0, 0, 1]}]},
        "CityObjects": city_objects,
        "vertices": vertices,
    }


def _read(path: Path) -> tuple[list, dict]:
    """Every node of a file (id, type, children, each LoD's parts: vertices, faces, colour)
    and its tally."""
    scene = read_scene(path)
    nodes = [
        (
            n.id,
            n.type,
            [c.id for c in n.children],
            {
                label: [(p.vertices, p.faces, p.base_color) for p in mesh.parts]
                for label, mesh in n.lods.items()
            },
        )
        for n in scene.walk()
    ]
    tally = tally_of(scene)
    assert tally is not None
    facts = {
        "vertices": tally.vertices,
        "faces": tally.faces,
        "dropped": tally.dropped_faces,
        "by_object": list(tally.dropped_by_object.items()),
        "skipped": tally.skipped,
    }
    return nodes, facts


def _assert_same(got: tuple[list, dict], expected: tuple[list, dict]) -> None:
    assert got[1] == expected[1]
    assert len(got[0]) == len(expected[0])
    for (*head, lods), (*head_expected, lods_expected) in zip(got[0], expected[0], strict=True):
        assert head == head_expected
        assert list(lods) == list(lods_expected)
        for label, parts in lods.items():
            assert len(parts) == len(lods_expected[label])
            for part, part_expected in zip(parts, lods_expected[label], strict=True):
                for array, array_expected in zip(part, part_expected, strict=True):
                    assert array.dtype == array_expected.dtype
                    assert np.array_equal(array, array_expected)


@pytest.fixture
def polygons_file(tmp_path: Path) -> Path:
    return write_json(tmp_path / "polygons.city.json", polygon_city())


@pytest.mark.parametrize("which", ["delft", "multi_lod", "polygons"])
def test_batches_give_what_one_object_at_a_time_gives(
    which: str, polygons_file: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = {"delft": delft, "multi_lod": multi_lod}.get(which, lambda: polygons_file)()
    batched = _read(path)
    for size in (1, 5):
        monkeypatch.setattr(cityjson_document, "BATCH", size)
        _assert_same(_read(path), batched)


def test_polygons_are_triangulated_as_triangulate_makes_them(tmp_path: Path) -> None:
    """Each polygon alone in an object: its triangles, corner by corner, are those of
    :func:`triangulate` with area (a lone ring of three indices is taken as it is)."""
    document = polygon_city(seed=11)
    vertices = np.asarray(document["vertices"]) * SCALE + TRANSLATE
    single = {}
    for key, obj in document["CityObjects"].items():
        for n, rings in enumerate(obj["geometry"][0]["boundaries"]):
            geometry = {"type": "MultiSurface", "lod": "2", "boundaries": [rings]}
            single[f"{key}-{n}"] = {"type": "Building", "geometry": [geometry]}
    path = write_json(tmp_path / "single.city.json", {**document, "CityObjects": single})
    nodes = {n.id: n for n in read_scene(path).walk()}
    degenerate = 0
    for key, obj in single.items():
        (rings,) = obj["geometry"][0]["boundaries"]
        if len(rings) == 1 and len(rings[0]) == 3:
            points, faces = vertices[rings[0]], np.array([[0, 1, 2]])
        else:
            try:
                points, faces = triangulate([vertices[ring] for ring in rings])
            except DegenerateRing:
                assert key not in nodes
                degenerate += 1
                continue
        expected = points[faces[faces_with_area(points, faces)]]
        if not len(expected):  # no triangle with area: the object is left out
            assert key not in nodes
            continue
        mesh = nodes[key].geometry
        assert np.array_equal(mesh.vertices[mesh.faces], expected), key
    assert 0 < degenerate < len(single) // 2


def test_a_broken_object_costs_only_itself(tmp_path: Path) -> None:
    document = polygon_city(seed=3, objects=40)
    objects = document["CityObjects"]
    good = _read(write_json(tmp_path / "good.city.json", document))
    broken = dict(objects)
    keys = list(objects)
    bad_index = json.loads(json.dumps(objects[keys[10]]))
    ring = next(ring for rings in bad_index["geometry"][0]["boundaries"] for ring in rings if ring)
    ring[0] = 10**9
    malformed = {"type": "Building", "geometry": [{"type": "Solid", "boundaries": [["x"]]}]}
    broken = {
        **{k: objects[k] for k in keys[:10]},
        "bad-index": bad_index,
        **{k: objects[k] for k in keys[10:20]},
        "malformed": malformed,
        "not-an-object": 7,
        **{k: objects[k] for k in keys[20:]},
    }
    got = _read(write_json(tmp_path / "broken.city.json", {**document, "CityObjects": broken}))
    assert [s["id"] for s in got[1]["skipped"]] == ["bad-index", "malformed", "not-an-object"]
    assert "index 1000000000" in got[1]["skipped"][0]["reason"]
    assert "malformed Solid boundaries" in got[1]["skipped"][1]["reason"]
    got[1]["skipped"] = []
    _assert_same(got, good)


def test_a_sequence_is_read_a_batch_of_features_at_a_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    document = polygon_city(seed=5, objects=60)
    header = {k: v for k, v in document.items() if k not in ("CityObjects", "vertices")}
    lines = [json.dumps({**header, "CityObjects": {}, "vertices": []})]
    for n, (key, obj) in enumerate(document["CityObjects"].items()):
        feature = {
            "type": "CityJSONFeature",
            "id": key,
            "CityObjects": {key: obj},
            "vertices": document["vertices"],
        }
        lines.append(json.dumps(feature))
        if n == 25:
            lines.append("[not a feature")
    path = tmp_path / "polygons.city.jsonl"
    path.write_text("\n".join(lines) + "\n")
    monkeypatch.setattr(cityjson_document, "BATCH", 8)
    parsed: list[str] = []
    real_parsed = cityjson_document.parsed

    def counting(text: str, where: str):
        parsed.append(where)
        return real_parsed(text, where)

    monkeypatch.setattr(cityjson_document, "parsed", counting)
    scene = read_scene(path)
    first = next(iter(scene.nodes))
    assert first.id == "b0" and len(parsed) == 1 + 8  # the header, then one batch
    sequence = _read(path)
    document_read = _read(write_json(tmp_path / "polygons.city.json", document))
    skipped = [s["id"] for s in sequence[1].pop("skipped")]
    expected = [s["id"] for s in document_read[1].pop("skipped")]
    before = [key for key in expected if int(key[1:]) <= 25]
    assert skipped == [*before, "line 28", *expected[len(before) :]]
    _assert_same(sequence, document_read)


@pytest.mark.parametrize("batch", [1, 64])
def test_a_sequence_counts_every_mesh_once_as_its_nodes_are_freed(
    batch: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Nodes handed on and freed must not hide the meshes read after them from the limits
    (their ids are taken again); a template's mesh, shared by its instances, counts once."""
    monkeypatch.setattr(cityjson_document, "BATCH", batch)
    document = polygon_city(seed=9, objects=120)
    cube = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    templates = {
        "templates": [{"type": "Solid", "lod": "2", "boundaries": [[[q] for q in quads]]}],
        "vertices-templates": cube,
    }
    header = {k: v for k, v in document.items() if k not in ("CityObjects", "vertices")}
    lines = [json.dumps({**header, "geometry-templates": templates, "vertices": []})]
    for n, (key, obj) in enumerate(document["CityObjects"].items()):
        objects = {key: obj}
        if n % 10 == 0:
            tree = {"type": "GeometryInstance", "template": 0, "boundaries": [0]}
            objects[f"tree{n}"] = {"type": "SolitaryVegetationObject", "geometry": [tree]}
        feature = {
            "type": "CityJSONFeature",
            "CityObjects": objects,
            "vertices": document["vertices"],
        }
        lines.append(json.dumps(feature))
    path = tmp_path / "trees.city.jsonl"
    path.write_text("\n".join(lines) + "\n")
    scene = read_scene(path)
    vertices = faces = 0
    template_meshes = set()
    for node in scene.walk():  # each node dropped once seen
        for mesh in node.lods.values():
            if node.type == "SolitaryVegetationObject":
                if template_meshes:
                    continue
                template_meshes.add(id(mesh))
            vertices += mesh.vertex_count
            faces += mesh.face_count
    tally = tally_of(scene)
    assert tally is not None and (tally.vertices, tally.faces) == (vertices, faces)


def test_rings_are_lists_of_whole_numbers() -> None:
    index, lengths, counts = geometry._rings([[[0, 1, 2, 3]], [[0, 1, 2], [3, 4, 5, 6]], [], [[]]])
    assert index.dtype == np.int64 and index.tolist() == [0, 1, 2, 3, 0, 1, 2, 3, 4, 5, 6]
    assert (lengths, counts) == ([4, 3, 4, 0], [1, 2, 0, 1])


@pytest.mark.parametrize(
    ("surfaces", "words"),
    [
        ([[[0.0, 1, 2]]], "an index is number 0.0, not a whole number"),
        ([[[16.5, 1, 2]]], "an index is number 16.5, not a whole number"),
        ([[[0, 1, True]]], "an index is boolean true, not a whole number"),
        ([[[0, 1, "3"]]], 'an index is string "3", not a whole number'),
        ([[[[0], [1], [2]]], [[0, 1, 2]]], "an index is array [0], not a whole number"),
        ([["0123"]], 'a ring is string "0123", not a list of indices'),
        ([[5]], "a ring is number 5, not a list of indices"),
        ([[{"a": 1}]], 'a ring is object {"a": 1}, not a list of indices'),
        ([{"a": [0, 1, 2]}], "a surface is object"),
        ([None, [[0, 1, 2]]], "a surface is null, not a list of rings"),
        ([[None]], "a ring is null"),
        ([[[float("nan"), 1, 2]]], "an index is number NaN"),
    ],
)
def test_rings_refuse_what_is_not_a_whole_number(surfaces: list, words: str) -> None:
    """16.5 was truncated, ``"3"`` and ``true`` taken as indices, an extra level flattened."""
    with pytest.raises(ValueError, match=re.escape(words)):
        geometry._rings(surfaces)


def test_an_index_beyond_int64_is_refused() -> None:
    with pytest.raises(OverflowError):
        geometry._rings([[[2**70, 1, 2]]])
