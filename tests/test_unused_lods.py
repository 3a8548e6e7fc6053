"""Source LoDs that no level is made from are named in the report, with why: the lower labels
of a slot (CityJSON LoD 1.2 beside 1.3), a LoD 0 beside a source LoD 1, every other LoD where
the options bake from the finest geometry."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import trimesh

from lodconvert import convert
from lodconvert.chain import ChainOptions
from lodconvert.model import Mesh, Surface
from lodconvert.model.lods import unused_levels

from .conftest import ROOT, SHARED, shared_data
from .test_cli import run

MULTI_LOD = SHARED / "data" / "cityjson" / "multi_lod_10bldg.city.json"
SIG3D = SHARED / "data" / "citygml" / "sig3d_house_lod0-4"


def block(height: float) -> Mesh:
    """A 10 × 10 m box standing on z = 0."""
    box = trimesh.creation.box((10, 10, height))
    box.apply_translation((0, 0, height / 2))
    return Mesh([Surface(np.asarray(box.vertices, float), np.asarray(box.faces, np.int64))])


def objects_of(tmp_path: Path, inputs: list[Path], options: ChainOptions) -> list[dict]:
    """The report's objects of converting ``inputs``, the report checked against its schema."""
    report = tmp_path / "report.json"
    convert(inputs, tmp_path / "out.glb", options, backend="numpy", report_path=report)
    data = json.loads(report.read_text())
    jsonschema.validate(data, json.loads((ROOT / "schemas/report.schema.json").read_text()))
    return data["objects"]


def test_each_label_left_out_of_a_slot_says_which_took_it() -> None:
    empty = Mesh([Surface(np.zeros((0, 3)), np.zeros((0, 3), np.int64))])
    lods = {"1.2": block(8), "1.3": block(9), "1.1": block(7), "2.2": block(10)}
    lods |= {"5": block(11), "roof edge": block(1), "2.0": empty}
    assert unused_levels(lods) == {
        "1.2": "slot LOD1 taken by LoD 1.3",
        "1.1": "slot LOD1 taken by LoD 1.3",
        "5": "names no LoD 0–4",
        "roof edge": "names no LoD 0–4",
        "2.0": "has no faces",
    }


def test_the_report_names_lod_1_2_beside_the_lod_1_3_that_fills_lod1(tmp_path: Path) -> None:
    objects = objects_of(tmp_path, [shared_data(MULTI_LOD)], ChainOptions())
    assert len(objects) == 10
    for obj in objects:
        assert obj["unused"] == {"1.2": "slot LOD1 taken by LoD 1.3"}
        assert [level["name"] for level in obj["levels"]] == ["LOD2", "LOD1"]


def test_the_summary_counts_the_unused_lods(tmp_path: Path) -> None:
    report = tmp_path / "report.json"
    result = run(
        shared_data(MULTI_LOD), "-o", tmp_path / "out.glb", "--backend", "numpy",
        "--levels", "3", "--report", report,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert (
        "10 object(s) have source LoDs that no level is made from: LoD 1.2 (10), LoD 1.3 (10)"
        in result.stderr
    )
    # the totals, counted as the objects were recorded, are those of the objects' records
    data = json.loads(report.read_text())
    objects, totals = data["objects"], data["totals"]
    fewer = [len(obj["levels"]) for obj in objects if obj["dropped"]]
    assert totals["fewer_levels"] == len(fewer)
    assert totals["levels_kept"] == {str(n): fewer.count(n) for n in sorted(set(fewer))}
    assert totals["with_unused_lods"] == 10 and totals["unused_lods"] == {"1.2": 10, "1.3": 10}
    points = sum(lv["count"] for obj in objects for lv in obj["levels"] if lv["kind"] == "pcd")
    assert totals["points"] == points
    assert totals["levels_kept"] == {"1": 10}  # each keeps its LOD2 alone here
    assert "10 object(s) keep fewer levels (10 with 1 level(s))" in result.stderr


def test_with_three_levels_every_lod_but_the_finest_is_unused(tmp_path: Path) -> None:
    objects = objects_of(tmp_path, [shared_data(MULTI_LOD)], ChainOptions(levels=3))
    for obj in objects:
        assert obj["unused"] == {
            "1.2": "slot LOD1 taken by LoD 1.3",
            "1.3": "--levels 3: every level is made from the finest geometry",
        }


def test_the_sig3d_house_names_its_footprint_where_its_own_lod1_fills_the_slot(
    tmp_path: Path,
) -> None:
    files = sorted(shared_data(SIG3D).glob("*.gml"))
    objects = objects_of(tmp_path, files, ChainOptions())
    house = next(obj for obj in objects if len(obj["levels"]) == 4)
    assert house["unused"] == {"lod0": "LOD1 is the source's lod1, not a prism of this footprint"}
    lod0_only = objects_of(tmp_path, [files[0]], ChainOptions())  # Building_LOD0: the prism
    assert next(o for o in lod0_only if o["id"] == house["id"])["unused"] == {}
