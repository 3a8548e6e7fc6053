"""A ``.zip`` input is read by the one city model file it holds — CityGML, CityJSON (as
cityjson.org ships its datasets) or CityJSONSeq — within the same limits, and refused in one
line when it holds none or several."""

from __future__ import annotations

import gzip
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from lodconvert.errors import InputError
from lodconvert.io import read_scene
from lodconvert.io.archive import inflated_size
from lodconvert.limits import Limits

from .conftest import SHARED, shared_data
from .test_cityjson import _features
from .test_cli import assert_one_line_error, run

DELFT = SHARED / "data" / "cityjson" / "delft.city.json"
MULTI_LOD = SHARED / "data" / "cityjson" / "multi_lod_10bldg.city.json"


def zipped(path: Path, members: dict[str, bytes]) -> Path:
    """A zip at ``path`` holding ``members`` (name → bytes), deflated."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(zipfile.ZipInfo(name), data, zipfile.ZIP_DEFLATED)
    return path


def sequence() -> bytes:
    """The ten multi-LoD buildings as a CityJSONSeq: a header line, one feature a line."""
    document = json.loads(shared_data(MULTI_LOD).read_text())
    header = {
        "type": "CityJSON",
        "version": "2.0",
        "transform": document["transform"],
        "CityObjects": {},
        "vertices": [],
    }
    lines = [json.dumps(header), *(json.dumps(f) for f in _features(document))]
    return ("\n".join(lines) + "\n").encode()


def same_nodes(got: Path, expected: Path) -> None:
    """``got`` reads into the nodes of ``expected``: the same ids, LoDs and vertices."""
    want = {node.id: node for node in read_scene(expected).walk()}
    have = {node.id: node for node in read_scene(got).walk()}
    assert list(have) == list(want)
    for key, node in have.items():
        assert set(node.lods) == set(want[key].lods)
        assert np.array_equal(node.geometry.vertices, want[key].geometry.vertices)


def test_a_city_json_in_a_zip_reads_and_converts_as_the_file(tmp_path: Path) -> None:
    data = shared_data(DELFT).read_bytes()
    path = zipped(tmp_path / "delft.zip", {"3-20-DELFSHAVEN/delft.city.json": data})
    same_nodes(path, DELFT)
    result = run(path, "-o", tmp_path / "delft.glb", "--backend", "numpy", "-q")
    assert result.returncode == 0, result.stderr
    assert "570 object(s)" in result.stderr
    ranges = run("ranges", path, "--json")
    assert ranges.returncode == 0 and len(json.loads(ranges.stdout)) == 570


def test_a_cityjsonseq_in_a_zip_reads_as_the_plain_sequence(tmp_path: Path) -> None:
    plain = tmp_path / "ten.city.jsonl"
    plain.write_bytes(sequence())
    path = zipped(tmp_path / "ten.zip", {"ten.city.jsonl": plain.read_bytes(), "README": b"hi"})
    same_nodes(path, plain)
    assert not isinstance(read_scene(path).nodes, list)  # still streamed line by line


def test_files_beside_the_city_model_folders_and_macos_forks_are_ignored(tmp_path: Path) -> None:
    data = shared_data(MULTI_LOD).read_bytes()
    members = {
        "LICENSE.txt": b"CC BY 4.0",
        "__MACOSX/._ten.city.json": b"\0",
        "ten.city.json": data,
        "tiles/": b"",
        "": b"a member without a name",
    }
    same_nodes(zipped(tmp_path / "ten.zip", members), MULTI_LOD)


@pytest.mark.parametrize(
    ("members", "words"),
    [
        ({"README.md": b"# data"}, ["holds 0 city model files", "exactly one"]),
        (
            {"a.city.json": b"{}", "b.gml": b"<x/>"},
            ["holds 2 city model files", "'a.city.json', 'b.gml'"],
        ),
        (
            {"a.city.json": b"{}", "b.city.json": b"{}", "c.city.jsonl": b"{}", "d.xml": b""},
            ["holds 4 city model files", "'a.city.json', 'b.city.json', 'c.city.jsonl'"],
        ),
    ],
    ids=["none", "two-kinds", "four"],
)
def test_a_zip_without_exactly_one_city_model_is_refused_in_one_line(
    tmp_path: Path, members: dict[str, bytes], words: list[str]
) -> None:
    path = zipped(tmp_path / "city.zip", members)
    out = tmp_path / "out.glb"
    assert_one_line_error(run(path, "-o", out), 1, "city.zip", *words)
    assert not out.exists()


def test_a_cityjson_member_past_the_inflation_limit_is_refused(tmp_path: Path) -> None:
    path = zipped(tmp_path / "delft.zip", {"delft.city.json": shared_data(DELFT).read_bytes()})
    with pytest.raises(InputError, match="inflates past the limit of 100,000 bytes"):
        read_scene(path, limits=Limits(decompressed_bytes=100_000))
    # a member that declares a smaller size than it inflates to is read no further than that
    data = bytearray(path.read_bytes())
    size = len(DELFT.read_bytes()).to_bytes(4, "little")
    for at in (data.index(b"PK\x03\x04") + 22, data.index(b"PK\x01\x02") + 24):
        assert data[at : at + 4] == size
        data[at : at + 4] = (1000).to_bytes(4, "little")
    path.write_bytes(bytes(data))
    result = run(path, "-o", tmp_path / "out.glb", "--limit", "decompressed_bytes=100000")
    assert_one_line_error(result, 1, "delft.zip", "cannot be read", "CRC")


def test_a_corrupt_cityjsonseq_member_is_a_one_line_error(tmp_path: Path) -> None:
    path = zipped(tmp_path / "ten.zip", {"ten.city.jsonl": sequence()})
    data = bytearray(path.read_bytes())
    middle = data.index(b"PK\x01\x02") // 2  # inside the deflated member
    data[middle : middle + 64] = bytes(64)
    path.write_bytes(bytes(data))
    result = run(path, "-o", tmp_path / "out.glb")
    assert_one_line_error(result, 1, "ten.zip")
    assert not (tmp_path / "out.glb").exists()


def test_inputs_are_sized_as_they_inflate_for_the_default_workers(tmp_path: Path) -> None:
    """The default ``--workers`` counts what a compressed city holds, not its compressed bytes
    (TUM Munich's zip is 0.9 MB and holds 12 MB of CityGML)."""
    text = b"<CityModel>" + b" " * 100_000 + b"</CityModel>"
    plain = tmp_path / "city.gml"
    plain.write_bytes(text)
    packed = zipped(tmp_path / "city.zip", {"readme.txt": b"licence", "city.gml": text})
    squeezed = tmp_path / "city.gml.gz"
    squeezed.write_bytes(gzip.compress(text))
    assert packed.stat().st_size < len(text) // 10
    assert [inflated_size(p) for p in (plain, packed, squeezed)] == [len(text)] * 3
    assert inflated_size(tmp_path / "absent.zip") == 0
    assert inflated_size(zipped(tmp_path / "none.zip", {"a.txt": b"x"})) == 0
