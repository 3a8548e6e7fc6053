"""Objects' ids and attributes that no output could hold as they are (characters XML cannot
hold, lone surrogates, huge strings, deep nesting, many long values) are bounded and cleaned
once (:mod:`lodconvert.model.safe_text`): the conversion writes every object, the X3D reads with
libxml2's default limits, ids read back as the report gives them, and the report says what was
cut per object."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
from lxml import etree

from lodconvert.io import read_chains
from lodconvert.model import Node
from lodconvert.model.safe_text import (
    MAX_DEPTH,
    MAX_OBJECT_CHARS,
    MAX_TEXT_CHARS,
    object_text,
    xml_text,
)
from lodconvert.spool import NodeSpool

from .conftest import ROOT
from .test_citygml import sample
from .test_cityjson import multi_lod
from .test_cli import run

BIG = 11_000_000
"""Characters of one attribute: over libxml2's 10 MB attribute value limit."""
TRICKY_ID = "a\"b\\c&<>'\td é😀"
"""An id that XML and X3D's MFString escape, written and read back as it is."""


def _nested(depth: int) -> dict:
    value: dict | str = "leaf"
    for _ in range(depth):
        value = {"n": value}
    assert isinstance(value, dict)
    return value


@pytest.fixture(scope="module")
def hostile_city(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    """The 10-building CityJSON sample with one hostile object after another: an id with
    U+0001, a lone surrogate in a name, an 11 MB description, a value nested 600 deep, and 40
    values of 64 Ki double quotes (each 9 bytes in X3D: 23 MB in one attribute value), 1.5
    million empty strings (16 bytes each in X3D); and an id that needs escaping but no cut."""
    data = json.loads(multi_lod().read_text(encoding="utf-8"))
    objects = data["CityObjects"]
    keys = list(objects)
    objects["bad\x01id"] = objects.pop(keys[0])
    objects[keys[1]].setdefault("attributes", {})["name"] = "a\ud800b"
    objects[keys[2]].setdefault("attributes", {})["description"] = "x" * BIG
    objects[keys[3]].setdefault("attributes", {})["deep"] = _nested(600)
    objects[keys[4]].setdefault("attributes", {}).update(
        {f"q{i}": '"' * MAX_TEXT_CHARS for i in range(40)}
    )
    objects[keys[6]].setdefault("attributes", {})["empties"] = [""] * 1_500_000
    objects[TRICKY_ID] = objects.pop(keys[5])
    path = tmp_path_factory.mktemp("hostile") / "hostile.city.json"
    path.write_text(json.dumps(data), encoding="utf-8", errors="surrogatepass")
    return path, ["bad\\u0001id", *keys[1:5], keys[6]]


@pytest.mark.parametrize("suffix", [".x3d", ".glb"])
def test_hostile_ids_and_attributes_convert_read_back_and_are_reported(
    hostile_city: tuple[Path, list[str]], tmp_path: Path, suffix: str
) -> None:
    source, ids = hostile_city
    out, report_path = tmp_path / f"city{suffix}", tmp_path / "report.json"
    result = run(source, "-o", out, "--report", report_path, "-q")
    assert result.returncode == 0, result.stderr
    report = json.loads(report_path.read_text())
    schema = json.loads((ROOT / "schemas" / "report.schema.json").read_text())
    jsonschema.validate(report, schema)
    records = {record["id"]: record for record in report["objects"]}
    assert len(records) == 10 and set(ids) <= set(records)
    cut = {i: " | ".join(records[i].get("cut", [])) for i in ids}
    assert "id written as \\uXXXX" in cut[ids[0]]
    assert "written as \\uXXXX (first in 'name')" in cut[ids[1]]
    assert f"first 'description': {BIG:,} characters" in cut[ids[2]]
    assert f"nested over {MAX_DEPTH} levels deep written as JSON text" in cut[ids[3]]
    assert "left out beyond" in cut[ids[4]] and "left out beyond" in cut[ids[5]]
    assert sum(bool(record.get("cut")) for record in records.values()) == 6

    chains = {chain.object_id: chain for chain in read_chains(out, geometry=False)}
    assert set(chains) == set(records) and TRICKY_ID in chains  # ids read back as reported
    assert chains[ids[0]].metadata["id"] == "bad\\u0001id"
    assert chains[ids[1]].metadata["name"] == "a\\ud800b"
    assert chains[ids[2]].metadata["description"] == "x" * MAX_TEXT_CHARS
    deep = chains[ids[3]].metadata["deep"]
    for _ in range(MAX_DEPTH - 1):
        deep = deep["n"]
    assert json.loads(deep["n"]) == _nested(600 - MAX_DEPTH)
    assert sum(len(v) for k, v in chains[ids[4]].metadata.items() if k[0] == "q") < MAX_OBJECT_CHARS
    if suffix == ".x3d":  # libxml2's default limits read it (no huge_tree)
        assert etree.parse(str(out), etree.XMLParser(huge_tree=False)).getroot().tag == "X3D"


def test_a_citygml_attribute_over_libxml2s_limit_is_cut_and_the_x3d_reads(tmp_path: Path) -> None:
    text = sample("potsdam_lod1_v1.gml").read_text(encoding="utf-8")
    first = text.index("<gen:stringAttribute ")
    value = "y" * BIG
    big = f'<gen:stringAttribute name="big"><gen:value>{value}</gen:value></gen:stringAttribute>'
    source = tmp_path / "big.gml"
    source.write_text(text[:first] + big + text[first:], encoding="utf-8")
    out, report = tmp_path / "city.x3d", tmp_path / "report.json"
    result = run(source, "-o", out, "--report", report, "-q")
    assert result.returncode == 0, result.stderr
    cut = [record["cut"] for record in json.loads(report.read_text())["objects"] if "cut" in record]
    assert len(cut) == 1 and f"first 'generic.big': {BIG:,} characters" in cut[0][0]
    assert etree.parse(str(out), etree.XMLParser(huge_tree=False)).getroot().tag == "X3D"


def test_bounded_text_is_bounded_again_without_change() -> None:
    attributes = {"id": "a\x01", "s": "x" * (MAX_TEXT_CHARS + 1), "d": _nested(40), "n": 1.5}
    first = object_text("a\ud800", attributes)
    assert first.id == "a\\ud800" and len(first.cut) == 4
    again = object_text(first.id, first.attributes)
    assert (again.id, again.attributes, again.cut) == (first.id, first.attributes, ())
    assert xml_text("tab\tand line\nkept") == "tab\tand line\nkept"


def test_a_node_parked_on_disk_keeps_its_text_bounded_and_what_was_cut() -> None:
    node = Node("deep", attributes={"deep": _nested(5000)})
    node.children.append(Node("part", type="BuildingPart", attributes={"x": "\x02"}))
    with NodeSpool() as spool:
        spool.add(node)
        parked = spool.get(0)
    text = parked.written()
    assert isinstance(text.attributes["parts"][0]["x"], str)
    assert [line.split(" (")[0] for line in text.cut] == [
        "1 character(s) XML cannot hold written as \\uXXXX",
        f"1 value(s) nested over {MAX_DEPTH} levels deep written as JSON text",
    ]
