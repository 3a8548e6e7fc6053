"""Hostile CityJSON, CityJSONSeq and padded mesh files: memory measured in a child process
(``RLIMIT_AS``, peak RSS against a small run's), time compared between n and 4n bytes, and
what a user sees of objects the reader leaves out. The one-line errors are cases of
:data:`tests.fuzz.cases.CASES`."""

from __future__ import annotations

import gzip
import json
import time
from pathlib import Path

import pytest

from lodconvert.errors import InputError
from lodconvert.io import read_scene
from lodconvert.io.cityjson import sequence as sequence_module
from lodconvert.io.geometry_checks import tally_of
from lodconvert.limits import Limits

from .fuzz.cases import CASES, SQUARE, city, city_object, sequence, zeros_gz
from .fuzz.seeds import _cityjson
from .fuzz.worker import run_cli
from .test_cli import run

MB = 1 << 20
GB = 1 << 30
SQUARE_XY = ((0, 0), (1, 0), (1, 1), (0, 1))


def _case(name: str, folder: Path) -> Path:
    (case,) = [c for c in CASES if c.name == name]
    return case.write(folder)


@pytest.fixture(scope="module")
def small_peak(tmp_path_factory: pytest.TempPathFactory) -> int:
    """Peak RSS of a run that reads a 1 KB CityJSON file and refuses it."""
    src = _case("appearance.city.json", tmp_path_factory.mktemp("small"))
    result = run_cli(src, "-o", src.with_suffix(".glb"))
    assert result.code == 1, result.stderr
    return result.peak_bytes


def test_a_small_cityjson_file_converts_under_a_2gib_address_space(tmp_path: Path) -> None:
    # the reader allocated a buffer of the 2 GiB limit (+ 1) before reading a byte
    src = tmp_path / "house.city.json"
    src.write_bytes(_cityjson()[0])
    result = run_cli(src, "-o", tmp_path / "house.glb", budget=2 * GB)
    assert result.code == 0, result.stderr
    assert (tmp_path / "house.glb").exists()


@pytest.mark.parametrize("bad", [None, float("nan"), "x"])
def test_vertices_take_the_memory_of_an_array(tmp_path: Path, small_peak: int, bad) -> None:
    # as JSON lists of Python numbers, 1M vertices took some 235 MB; as float64, 24 MB (and
    # so they do with a row that is not three numbers among them)
    vertices = [[k % 1000, k * 7 % 1000, k % 800] for k in range(1_000_000)]
    if bad is not None:
        vertices[500_000] = [bad, 0, 0]
    src = tmp_path / "many.city.json"
    src.write_bytes(city({"a": city_object()}, SQUARE + vertices))
    result = run_cli(src, "-o", tmp_path / "many.glb", budget=4 * GB)
    assert result.code == 0, result.stderr
    assert result.peak_bytes - small_peak < 120 * MB, (result.peak_bytes, small_peak)


def test_a_gz_past_the_limit_is_refused_holding_a_chunk(tmp_path: Path, small_peak: int):
    """A CityJSON ``.gz`` past the limit is counted before any of it is kept: the refusal's
    peak grows neither with the limit nor with the file (it held up to the limit: 4× the
    limit raised the peak by 3× it; past the default 2 GiB it peaked at 2.19 GB)."""

    def peak(inflated: int, limit: str) -> int:
        src = tmp_path / "bomb.city.json.gz"
        src.write_bytes(zeros_gz(inflated, b'{"type": "CityJSON", "x": "', b"x"))
        result = run_cli(src, "-o", tmp_path / "bomb.glb", "--limit", f"decompressed_bytes={limit}")
        assert result.code == 1 and "inflates past the limit" in result.stderr, result.stderr
        assert not (tmp_path / "bomb.glb").exists()
        return result.peak_bytes

    low, high = peak(160 * MB, "32M"), peak(160 * MB, "128M")
    assert high - low < 16 * MB, (low, high)
    assert high - small_peak < 24 * MB, (high, small_peak)
    assert peak(512 * MB, "128M") - high < 16 * MB, high


def _feature_line(name: str) -> bytes:
    """The line of a feature of one object, ``name``, without its line break."""
    return sequence({"CityObjects": {name: city_object()}, "vertices": SQUARE}).splitlines()[1]


def test_a_long_sequence_line_is_skipped_without_being_held(tmp_path: Path, small_peak: int):
    """A feature line of 256 MiB (in a ``.gz``) over a 4 MiB limit: that line reported by its
    number and passed over as it streams, the features after it converted (the run failed:
    "has a line longer than the limit"), the peak some 4 MiB above a small run's."""
    src = tmp_path / "long.city.jsonl.gz"
    head = sequence() + _feature_line("a") + b'\n{"type": "CityJSONFeature", "x": "'
    after = gzip.compress(b'"}\n' + _feature_line("b") + b"\n", mtime=0)
    src.write_bytes(zeros_gz(256 * MB, head, b"x") + after)
    result = run_cli(src, "-o", tmp_path / "long.glb", "--limit", "sequence_line_bytes=4M")
    assert result.code == 0, result.stderr
    assert (
        f"lodconvert: warning: {src}: object line 3: is longer than the limit of 4,194,304 bytes "
        "(sequence_line_bytes; raise it with --limit sequence_line_bytes=N) — skipped"
    ) in result.stderr.splitlines()
    assert "(2 object(s), 1 skipped," in result.stderr
    assert result.peak_bytes - small_peak < 32 * MB, (result.peak_bytes, small_peak)


@pytest.mark.parametrize("chunk", [1, 5, 64, 1 << 16])
def test_long_lines_are_passed_over_wherever_reads_cut_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, chunk: int
) -> None:
    """Lines over the limit (alone, in a row, first in a read, last in the file without a line
    break) come as ``None`` under their numbers; the others as they are."""
    monkeypatch.setattr(sequence_module, "CHUNK", chunk)
    lines = [b"short", b"x" * 40, b"", b"y" * 21, b"z" * 20, b"  ok ", b"", b"w" * 100]
    path = tmp_path / "lines.city.jsonl"
    path.write_bytes(b"\n".join(lines))
    read = list(sequence_module.sequence_lines(path, Limits(sequence_line_bytes=20)))
    assert read == [
        (1, b"short"), (2, None), (4, None), (5, b"z" * 20), (6, b"ok "), (8, None),
    ]  # fmt: skip


def _read_seconds(path: Path) -> float:
    """CPU seconds of reading ``path`` here (not wall time: a loaded machine slows the wall
    clock, not this process's work)."""
    start = time.process_time()
    scene = read_scene(path)
    assert list(scene.nodes) == []
    return time.process_time() - start


def test_blank_lines_of_a_sequence_take_time_linear_in_their_bytes(tmp_path: Path) -> None:
    seconds = []
    for n in (16, 64):
        src = tmp_path / f"blank{n}.city.jsonl.gz"
        src.write_bytes(zeros_gz(n * MB, sequence(), b"\n"))
        seconds.append(min(_read_seconds(src) for _ in range(3)))
    assert seconds[1] < 8 * seconds[0], seconds


def test_a_ply_gz_padded_with_newlines_converts_in_little_memory(tmp_path: Path) -> None:
    # trimesh made a numpy array of every line of an ASCII PLY: 64 MiB of newlines took 11 GB
    result = run_cli(_case("blank.ply.gz", tmp_path), "-o", tmp_path / "out.glb", budget=1 * GB)
    assert result.code == 0, result.stderr
    assert result.peak_bytes < 400 * MB, result.peak_bytes


def test_an_obj_gz_of_spaces_is_not_held_inflated(tmp_path: Path, small_peak: int) -> None:
    result = run_cli(_case("spaces.obj.gz", tmp_path), "-o", tmp_path / "out.glb")
    assert result.code == 1 and "no vertex" in result.stderr, result.stderr
    assert result.peak_bytes - small_peak < 64 * MB, (result.peak_bytes, small_peak)


def test_a_ply_followed_by_blank_lines_converts(tmp_path: Path) -> None:
    src = tmp_path / "blank.ply"
    src.write_bytes(
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        b"end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n" + b"\n" * (16 * MB)
    )
    result = run_cli(src, "-o", tmp_path / "out.glb", budget=1 * GB)
    assert result.code == 0, result.stderr
    assert result.peak_bytes < 400 * MB, result.peak_bytes


def test_coordinates_that_are_not_finite_skip_their_buildings_without_warnings(
    tmp_path: Path,
) -> None:
    src = _case("nan.city.json", tmp_path)
    report = tmp_path / "report.json"
    result = run_cli(src, "-o", tmp_path / "out.glb", "--report", report)
    assert result.code == 0, result.stderr
    assert "Warning" not in result.stderr, result.stderr
    skipped = {s["id"]: s["reason"] for s in json.loads(report.read_text())["skipped"]}
    assert sorted(skipped) == ["big", "inf", "nan"]
    assert "uses vertex 4, whose coordinates are unreadable or not finite" in skipped["nan"]
    assert "uses vertex 6" in skipped["big"]
    assert "1 skipped" not in result.stderr and "3 skipped" in result.stderr


def test_a_latitude_beyond_90_in_the_first_object_skips_it_alone(tmp_path: Path) -> None:
    """Three squares in EPSG:4979, the first with a latitude of 200: that one skipped, the
    local frame centred on the points within range (centred on all, at 126°, the run failed:
    "not latitude and longitude")."""
    squares = [
        [[52 + dy * 1e-4, 13 + k * 1e-3 + dx * 1e-4, 0] for dx, dy in SQUARE_XY] for k in (0, 1, 2)
    ]
    squares[0][2][0] = 200
    objects = {f"b{k}": city_object([[[4 * k + i for i in range(4)]]]) for k in range(3)}
    src = tmp_path / "geo.city.json"
    geographic = {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/4979"}
    src.write_bytes(city(objects, [p for square in squares for p in square], metadata=geographic))
    scene = read_scene(src)
    assert [node.id for node in scene.nodes] == ["b1", "b2"]
    assert [entry["id"] for entry in tally_of(scene).skipped] == ["b0"]


def test_unreadable_vertex_rows_skip_the_buildings_using_them(tmp_path: Path) -> None:
    vertices = [*SQUARE, [0, "1", 2], [0, 1], [True, 0, 0], [10**400, 0, 0]]
    objects = {"good": city_object()} | {
        f"bad{k}": city_object([[[0, 1, 2, k]]]) for k in range(4, 8)
    }
    src = tmp_path / "rows.city.json"
    src.write_text(city(objects, vertices).decode())
    report = tmp_path / "report.json"
    result = run(src, "-o", tmp_path / "out.glb", "--report", report)
    assert result.returncode == 0, result.stderr
    data = json.loads(report.read_text())
    assert [o["id"] for o in data["objects"]] == ["good"]
    assert [s["id"] for s in data["skipped"]] == ["bad4", "bad5", "bad6", "bad7"]
    assert "--strict" not in result.stderr
    strict = run(src, "-o", tmp_path / "strict.glb", "--strict")
    assert strict.returncode == 1 and "bad4" in strict.stderr


def test_a_deep_chain_is_cut_and_a_cycle_kept(tmp_path: Path) -> None:
    report = tmp_path / "chain.json"
    result = run(_case("chain.city.json", tmp_path), "-o", tmp_path / "c.glb", "--report", report)
    assert result.returncode == 0, result.stderr
    (skipped,) = json.loads(report.read_text())["skipped"]
    assert skipped["id"] == "o33"
    assert "nested more than 32 levels deep" in skipped["reason"]
    assert "566 object(s) below it" in skipped["reason"]
    report = tmp_path / "cycle.json"
    result = run(_case("cycle.city.json", tmp_path), "-o", tmp_path / "y.glb", "--report", report)
    assert result.returncode == 0, result.stderr
    assert sorted(o["id"] for o in json.loads(report.read_text())["objects"]) == ["a", "b"]


def test_a_plain_file_over_the_limit_is_refused_by_its_size(tmp_path: Path) -> None:
    src = tmp_path / "house.city.json"
    src.write_bytes(_cityjson()[0])
    with pytest.raises(InputError, match="is larger than the limit of 100 bytes"):
        read_scene(src, limits=Limits(decompressed_bytes=100))
