"""``lodconvert ranges`` prints what ``convert`` writes: the same levels, α, γ and cutoffs for
every object, planned by the same code without baking."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from lxml import etree

from lodconvert.io import read_scene

from .conftest import SAMPLE, SHARED, shared_data
from .test_cli import run

CITYGML = SHARED / "data" / "citygml"
CITYJSON = SHARED / "data" / "cityjson"


def plateau_lod0(folder: Path) -> Path:
    """The PLATEAU building with its LoD 1 and 2 taken out: its LoD 0 roof edge and its
    measuredHeight (31.7 m) are left, so that its chain is the prism alone."""
    tree = etree.parse(str(shared_data(CITYGML / "plateau_53394517_bldg_lod012_v2.gml")))
    for element in tree.iter("{*}lod1Solid", "{*}lod2Solid", "{*}lod2MultiSurface"):
        element.getparent().remove(element)
    path = folder / "plateau_lod0.gml"
    tree.write(str(path))
    return path


def inputs_of(name: str, folder: Path) -> list[Path]:
    """The input files of a test case."""
    if name == "sig3d-house":
        return sorted(shared_data(CITYGML / "sig3d_house_lod0-4").glob("*.gml"))
    if name == "plateau-lod0":
        return [plateau_lod0(folder)]
    if name == "mesh":
        return [SAMPLE]
    return [shared_data(CITYGML / name if name.endswith(".zip") else CITYJSON / name)]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "options"),
    [
        ("tum_munich_lod2_v2.zip", ()),
        ("delft.city.json", ()),
        ("sig3d-house", ()),
        ("plateau-lod0", ()),
        ("mesh", ()),
        ("mesh", ("--levels", "3", "--cull", "1.5")),
        ("tum_munich_lod2_v2.zip", ("--plot-radius", "20", "--x", "0.5,1,2")),
    ],
)
def test_ranges_prints_the_cutoffs_convert_writes(
    tmp_path: Path, name: str, options: tuple[str, ...]
) -> None:
    inputs = inputs_of(name, tmp_path)
    ranges = run("ranges", *inputs, "--json", *options)
    assert ranges.returncode == 0, ranges.stderr
    report = tmp_path / "report.json"
    out = tmp_path / "out.glb"
    converted = run(*inputs, "-o", out, "--report", report, "--backend", "numpy", "-qq", *options)
    assert converted.returncode == 0, converted.stderr
    planned = {row["id"]: row for row in json.loads(ranges.stdout)}
    written = {obj["id"]: obj for obj in json.loads(report.read_text())["objects"]}
    assert planned.keys() == written.keys()
    for key, obj in written.items():
        row = planned[key]
        assert row["cutoffs"] == obj["cutoffs"], key
        assert (row["alpha"], row["gamma"], row["xs"]) == (obj["alpha"], obj["gamma"], obj["xs"])
        assert [lv["name"] for lv in row["levels"]] == [lv["name"] for lv in obj["levels"]]
        assert (row["dropped"], row["unused"]) == (obj["dropped"], obj["unused"])


@pytest.mark.slow
def test_a_lod2_building_has_one_cutoff_and_a_lod0_prism_the_alpha_of_its_box(
    tmp_path: Path,
) -> None:
    rows, _ = run_json("ranges", shared_data(CITYGML / "tum_munich_lod2_v2.zip"))
    tum = next(row for row in rows if "LOD1" not in row["dropped"])  # one whose prism pays
    assert [lv["name"] for lv in tum["levels"]] == ["LOD2", "LOD1"]
    assert tum["xs"] == [1.0] and len(tum["cutoffs"]) == 1
    path = plateau_lod0(tmp_path)
    (prism,), _ = run_json("ranges", path)
    assert prism["levels"] == [{"name": "LOD1", "kind": "prism"}] and prism["cutoffs"] == []
    # α is the diagonal of the prism, 31.7 m high (measuredHeight), not of its flat roof edge
    (node,) = read_scene(path).nodes
    low, high = node.geometry.bounds
    flat = math.hypot(*(high - low)[:2])
    assert (high - low)[2] < 1.0 and prism["alpha"] == pytest.approx(math.hypot(flat, 31.7))


def test_points_still_to_bake_are_marked(tmp_path: Path) -> None:
    (row,), table = run_json("ranges", SAMPLE)
    assert [lv.get("to_bake", False) for lv in row["levels"]] == [False, True, True, True]
    assert "LOD4 LOD3* LOD2* LOD1*" in table.stdout and "* points convert bakes" in table.stdout


def test_the_table_keeps_its_columns_under_long_ids() -> None:
    """KIT's ids are 45 characters long: every value still stands under its heading."""
    (row, *_), table = run_json(
        "ranges", shared_data(CITYGML / "kit_testcases_lod2_100bldg_v3.gml")
    )
    heading, first = table.stdout.splitlines()[:2]
    assert first.startswith(row["id"] + " ")
    for name, value in (("alpha", f"{row['alpha']:.6g}"), ("gamma", f"{row['gamma']:g}")):
        assert first.index(value, len(row["id"])) + len(value) == heading.index(name) + len(name)
    assert first.index("LOD2") == heading.index("levels")


def run_json(*args: str | Path) -> tuple[list[dict], object]:
    """The rows of ``lodconvert ranges ... --json`` and the table run without ``--json``."""
    rows = run(*args, "--json")
    assert rows.returncode == 0, rows.stderr
    table = run(*args)
    assert table.returncode == 0, table.stderr
    return json.loads(rows.stdout), table


def test_a_broken_object_is_reported_and_the_others_listed(tmp_path: Path) -> None:
    document = json.loads(shared_data(CITYJSON / "multi_lod_10bldg.city.json").read_text())
    bad = list(document["CityObjects"])[3]
    document["CityObjects"][bad]["geometry"][1]["boundaries"][0][0][0][0] = 10**6
    path = tmp_path / "bad.city.json"
    path.write_text(json.dumps(document))
    result = run("ranges", path, "--json")
    assert result.returncode == 0, result.stderr
    assert [row["id"] for row in json.loads(result.stdout)] == [
        key for key in document["CityObjects"] if key != bad
    ]
    (warning,) = [w for w in result.stderr.splitlines() if "declares no CRS" not in w]
    assert bad in warning and "skipped" in warning


def test_instances_of_one_template_get_the_ranges_convert_gives_them(tmp_path: Path) -> None:
    """Convert bakes a template's geometry once, for its first instance (γ: that tree's plot
    radius), and every instance shows that chain; ranges says the same of each."""
    cube = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    template = {"type": "Solid", "lod": "2", "boundaries": [[[f] for f in faces]]}
    scale = [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1]
    instance = {"type": "GeometryInstance", "template": 0, "transformationMatrix": scale}
    trees = {
        f"t{i}": {"type": "SolitaryVegetationObject", "geometry": [{**instance, "boundaries": [i]}]}
        for i in range(3)
    }
    path = tmp_path / "trees.city.json"
    path.write_text(
        json.dumps(
            {
                "type": "CityJSON",
                "version": "2.0",
                "CityObjects": trees,
                "vertices": [[0, 0, 0], [6, 0, 0], [40, 0, 0]],
                "geometry-templates": {"templates": [template], "vertices-templates": cube},
            }
        )
    )
    ranges = run("ranges", path, "--json")
    assert ranges.returncode == 0, ranges.stderr
    report = tmp_path / "report.json"
    assert run(path, "-o", tmp_path / "trees.x3d", "--report", report, "-qq").returncode == 0
    written = [
        (o["id"], o["gamma"], o["cutoffs"]) for o in json.loads(report.read_text())["objects"]
    ]
    assert [(r["id"], r["gamma"], r["cutoffs"]) for r in json.loads(ranges.stdout)] == written
    assert {gamma for _, gamma, _ in written} == {3.0}  # the first tree's plot radius
