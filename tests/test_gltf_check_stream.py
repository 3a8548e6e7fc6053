"""The glTF check reads the JSON window by window: nesting depth counted as the regular
expression over the whole text counts it, the document read as ``json.loads`` reads it, a
large file checked in memory that does not grow with it, and broken files given the same
findings whether their arrays are read whole or element by element."""

from __future__ import annotations

import json
import random
import re
import struct
import tracemalloc
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from lodconvert.io import OutputInfo
from lodconvert.io.findings import Findings
from lodconvert.io.gltf import check, elements, extrema, write_glb
from lodconvert.io.gltf.stream import (
    NotStreamed,
    Source,
    TooDeep,
    read_object,
    too_deep,
    utf8_error,
)
from lodconvert.model import Level, LodChain, Surface

INFO = OutputInfo(generator="lodconvert tests", source="check", crs="EPSG:25832")
_BRACKETS = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"|([\[{])|[\]}]')


def _too_deep_by_expression(text: str, limit: int) -> bool:
    """The depth rule as it reads over the whole decoded text."""
    depth = 0
    for match in _BRACKETS.finditer(text):
        if match.lastindex:
            depth += 1
            if depth > limit:
                return True
        elif text[match.start()] != '"':
            depth -= 1
    return False


def _source(raw: bytes) -> Source:
    return Source(raw, 0, len(raw), None)


def test_depth_is_counted_as_the_expression_counts_it() -> None:
    """Random text of quotes, backslashes, brackets and line breaks (mostly not JSON), counted
    in windows of a few bytes, as the expression counts the whole text."""
    rng = random.Random(7)
    alphabet = ['"', "\\", "[", "]", "{", "}", "\n", "a", "é", " "]
    weights = [3, 2, 3, 2, 2, 2, 1, 4, 1, 2]
    for _ in range(500):
        text = "".join(rng.choices(alphabet, weights, k=rng.randrange(60)))
        raw = text.encode()
        for limit in (0, 1, 3):
            expected = _too_deep_by_expression(text, limit)
            for window in (1, 3, 8, 64):
                assert too_deep(_source(raw), limit, window) == expected, (text, limit, window)


def test_first_byte_that_is_not_utf8() -> None:
    rng = random.Random(3)
    for _ in range(1000):
        raw = bytes(
            rng.choice([0x41, 0xC3, 0xA9, 0xE2, 0x82, 0xAC, 0xF0, 0x9F, 0xFF]) for _ in range(20)
        )
        try:
            raw.decode("utf-8")
            expected = None
        except UnicodeDecodeError as exc:
            expected = (exc.start, raw[exc.start])
        for window in (4, 5, 7, 64):
            assert utf8_error(_source(raw), window) == expected, (raw, window)


def _random_value(rng: random.Random, depth: int = 0) -> Any:
    pick = rng.random()
    if depth > 3 or pick < 0.3:
        return rng.choice([1, -2.5, 1.5e-7, 'q"é\\', True, None, 10**20, ""])
    if pick < 0.65:
        return [_random_value(rng, depth + 1) for _ in range(rng.randrange(5))]
    keys = ["a", "nodes", "bü", "accessors"]
    return {rng.choice(keys): _random_value(rng, depth + 1) for _ in range(rng.randrange(4))}


def _plain(doc: dict[str, Any]) -> dict[str, Any]:
    return {key: list(value) if hasattr(value, "starts") else value for key, value in doc.items()}


def test_document_reads_as_json_loads_reads_it() -> None:
    """Objects read in windows of a few bytes (numbers, strings and arrays cut anywhere) equal
    json.loads; a byte changed gives json.loads' object or NotStreamed where json.loads fails."""
    rng = random.Random(11)
    keys = ["nodes", "accessors", "asset", "buffers", "x"]
    for _ in range(600):
        doc = {key: _random_value(rng, 1) for key in rng.sample(keys, rng.randrange(5))}
        text = json.dumps(doc, indent=rng.choice([None, 1]), ensure_ascii=rng.random() < 0.5)
        raw = text.encode()
        for window in (1, 3, 7, 1000):
            read = read_object(_source(raw), {}, window)
            assert _plain(read) == doc
            for key, value in read.items():  # elements read again by their offsets
                if hasattr(value, "starts"):
                    assert [value[i] for i in range(len(value))] == doc[key] == value.whole()
        broken = bytearray(raw)
        broken[rng.randrange(len(broken))] = rng.choice(b'{}[],:" x')
        try:
            broken.decode("utf-8")
        except UnicodeDecodeError:
            continue  # the check reads only UTF-8 text
        try:
            expected: Any = json.loads(broken.decode("utf-8"))
        except ValueError:
            expected = None
        try:
            got: Any = _plain(read_object(_source(bytes(broken)), {}, rng.choice([2, 5, 1000])))
        except NotStreamed:
            got = None
        assert got == (expected if isinstance(expected, dict) else None), bytes(broken)


def test_a_document_nested_too_deep_is_found_as_it_is_read() -> None:
    """A JSON object read with a depth limit raises TooDeep exactly where too_deep says the
    text nests deeper than it: elements read in batches (ASCII text), one at a time (text
    that is not ASCII) and members read whole."""
    rng = random.Random(5)
    keys = ["nodes", "accessors", "asset", "buffers", "x"]
    raised = 0
    for _ in range(400):
        doc = {key: _random_value(rng, 1) for key in rng.sample(keys, rng.randrange(1, 5))}
        text = json.dumps(doc, indent=rng.choice([None, 1]), ensure_ascii=rng.random() < 0.5)
        raw = text.encode()
        for limit in range(7):
            expected = too_deep(_source(raw), limit)
            for window in (3, 1000):
                try:
                    read_object(_source(raw), {}, window, limit)
                    got = False
                except TooDeep:
                    got = True
                assert got == expected, (text, limit, window)
                raised += got
    assert raised > 100


# --- a large-ish file ---------------------------------------------------------------------------


def _chain(i: int) -> LodChain:
    box = trimesh.creation.box(extents=(10.0, 8.0, 6.0 + i % 7))
    surface = Surface(vertices=box.vertices, faces=box.faces.astype(np.int64))
    prism = Surface(vertices=box.vertices * 0.9, faces=box.faces.astype(np.int64))
    return LodChain(
        object_id=f"building_{i}_Straße",
        levels=[Level("LOD2", "source", mesh=surface), Level("LOD1", "prism", mesh=prism)],
        cutoffs=[300.0 + i],
        origin=np.array([691000.0 + 20 * i, 5336000.0, 520.0]),
        center=np.zeros(3),
        alpha=20.0,
        beta=3.0,
        gamma=4.0,
        xs=[1.0],
        metadata={"function": "1001", "address": f"Weg {i}"},
    )


def _chains(count: int) -> Iterator[LodChain]:
    return (_chain(i) for i in range(count))


def _write(path: Path, count: int) -> Path:
    with path.open("wb") as handle:
        write_glb(_chains(count), handle, INFO)
    return path


@pytest.fixture(scope="module")
def city(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2,400 buildings: a JSON chunk of some megabytes, many windows."""
    return _write(tmp_path_factory.mktemp("city") / "city.glb", 2400)


def _findings(path: Path) -> list[tuple[str, str, str]]:
    findings = Findings(path)
    check.check_gltf(path, findings, None)
    return [(f.severity, f.code, f.message) for f in findings.items]


def _json_size(path: Path) -> int:
    return struct.unpack_from("<I", path.read_bytes(), 12)[0]


def _traced_peak(path: Path) -> int:
    tracemalloc.start()
    try:
        assert _findings(path) == []
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_large_file_is_checked_in_bounded_memory(
    city: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A clean file passes the summary checks (never the checks that look element by
    element) and takes a fraction of the memory its parsed JSON would; checking four times
    the JSON takes less memory more than that JSON's size (the windows are the same; what
    grows is a few integers per element)."""
    calls = []
    monkeypatch.setattr(elements.ElementChecks, "run", lambda self: calls.append(self))
    monkeypatch.setattr(extrema, "_BLOCK", 1 << 16)  # both files read in whole blocks
    town = _write(tmp_path / "town.glb", 600)
    peak = _traced_peak(city)
    grown = peak - _traced_peak(town)
    more = _json_size(city) - _json_size(town)
    assert not calls
    assert more > 3 << 20
    assert grown < more, f"{grown / 2**20:.1f} MiB more for {more / 2**20:.1f} MiB of JSON"
    text = city.read_bytes()[20 : 20 + _json_size(city)]
    tracemalloc.start()
    try:
        json.loads(text)
        parsed = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < parsed / 2, f"{peak / 2**20:.1f} MiB, parsed JSON {parsed / 2**20:.1f} MiB"


def _edit_json(path: Path, out: Path, edit: Callable[[dict[str, Any]], None]) -> Path:
    data = path.read_bytes()
    size = _json_size(path)
    doc = json.loads(data[20 : 20 + size])
    edit(doc)
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text + data[20 + size :]
    out.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)
    return out


def _node(doc: dict[str, Any], k: int) -> dict[str, Any]:
    return [n for n in doc["nodes"] if "MSFT_lod" in n.get("extensions", {})][k]


def _position(doc: dict[str, Any], k: int) -> dict[str, Any]:
    return doc["accessors"][doc["meshes"][k]["primitives"][0]["attributes"]["POSITION"]]


EDITS: list[tuple[str, Callable[[dict[str, Any]], None]]] = [
    ("id out of range", lambda d: _node(d, 2300)["extensions"]["MSFT_lod"]["ids"].append(10**6)),
    (
        "id twice",
        lambda d: _node(d, 7)["extensions"]["MSFT_lod"]["ids"].append(
            _node(d, 7)["extensions"]["MSFT_lod"]["ids"][0]
        ),
    ),
    (
        "id a child",
        lambda d: d["nodes"][0]["children"].append(
            d["nodes"][1]["extensions"]["MSFT_lod"]["ids"][0]
        ),
    ),
    ("coverage rising", lambda d: _node(d, 1999)["extras"]["MSFT_screencoverage"].insert(0, 0.0)),
    ("position max", lambda d: _position(d, 4000)["max"].__setitem__(1, 99.0)),
    ("position min missing", lambda d: _position(d, 4001).pop("min")),
    (
        "index count",
        lambda d: d["accessors"][d["meshes"][5]["primitives"][0]["indices"]].__setitem__(
            "count", 35
        ),
    ),
    ("view past the buffer", lambda d: d["bufferViews"][-1].__setitem__("byteLength", 10**8)),
    ("count a float", lambda d: _position(d, 3).__setitem__("count", 24.0)),
    ("mesh reference", lambda d: d["nodes"][2000].__setitem__("mesh", 10**7)),
    ("nodes not objects", lambda d: d["nodes"].append(5)),
    ("required", lambda d: d.__setitem__("extensionsRequired", ["MSFT_lod"])),
]


@pytest.mark.slow
@pytest.mark.parametrize(("what", "edit"), EDITS, ids=[e[0] for e in EDITS])
def test_broken_large_file_findings_do_not_depend_on_how_it_is_read(
    city: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    what: str,
    edit: Callable[[dict[str, Any]], None],
) -> None:
    """The arrays read element by element (as a file too large to hold) give the findings of
    the arrays read whole, and there are some."""
    path = _edit_json(city, tmp_path / "broken.glb", edit)
    whole = _findings(path)
    monkeypatch.setattr(check, "IN_MEMORY", -1)
    assert _findings(path) == whole
    assert whole, what


def test_instances_share_meshes_and_pass(tmp_path: Path) -> None:
    """Chains placed by a matrix (one mesh for all) pass the summary checks too."""
    turned = trimesh.transformations.rotation_matrix(0.5, [0, 0, 1])
    base = _chain(0)
    chains = [replace(base, object_id=f"twin{i}", transform=turned) for i in range(3)]
    path = tmp_path / "twins.glb"
    with path.open("wb") as handle:
        write_glb(iter(chains), handle, INFO)
    assert _findings(path) == []


def test_untextured_primitives_of_one_colour_share_a_material(city: Path) -> None:
    data = city.read_bytes()
    doc = json.loads(data[20 : 20 + _json_size(city)])
    used = {p["material"] for mesh in doc["meshes"] for p in mesh["primitives"]}
    assert len(doc["materials"]) == 1 and used == {0}
