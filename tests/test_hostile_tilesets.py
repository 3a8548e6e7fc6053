"""Hostile 3D Tiles tilesets given to ``lodconvert validate`` and ``lodconvert view``: a tileset
JSON over ``tileset_json_bytes`` is refused before it is read, JSON nested 100,000 deep and
external tilesets in a cycle are one line naming the file (no RecursionError, no traceback),
and a content URI that leads out of the tileset's folder (a symbolic link, ``../``, an absolute
path, a URL) is an error naming the tile, never read through."""

from __future__ import annotations

import contextlib
import json
import os
import struct
import sys
import tracemalloc
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from lodconvert.errors import InputError
from lodconvert.limits import Limits
from lodconvert.validate import errors_of, validate_file
from lodconvert.viewer import render_page
from tests.test_cli import assert_one_line_error, run

BOX = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]


def tile(
    uri: str | None = None, children: list[dict] | None = None, error: float = 1.0, **more: Any
) -> dict:
    """A tile (a leaf without content needs no geometric error of 0) refining by
    replacement."""
    out: dict[str, Any] = {"boundingVolume": {"box": BOX}, "geometricError": error}
    out["refine"] = "REPLACE"
    if uri is not None:
        out["content"] = {"uri": uri}
    if children:
        out["children"] = children
    return {**out, **more}


def tileset(root: dict) -> dict:
    """A tileset JSON that reads as one lodconvert wrote (what ``view`` asks of it)."""
    extras = {"sse": 16.0, "view": {"height_px": 1080, "fov_y_deg": 45.0}}
    asset = {"version": "1.1", "generator": "lodconvert test", "extras": {"lodconvert": extras}}
    return {"asset": asset, "geometricError": root.get("geometricError", 1.0), "root": root}


def write(path: Path, root: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(tileset(root)))
    return path


def validated(path: Path, *options: str) -> list[str]:
    """The finding lines of ``lodconvert validate`` on ``path``, which must fail in no other
    way than by reporting errors."""
    result = run("validate", "-q", *options, path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert result.stderr == "", result.stderr
    assert "Traceback" not in result.stdout and "RecursionError" not in result.stdout
    return result.stdout.strip().splitlines()


def viewed(path: Path, *words: str, options: tuple[str, ...] = ()) -> None:
    """``lodconvert view`` refuses ``path`` in one line holding ``words``, writing no page."""
    result = run("view", *options, path)
    assert_one_line_error(result, 1, *words)
    assert "RecursionError" not in result.stderr
    assert not list(path.parent.glob("*.html"))


# -- a tileset JSON over the limit ------------------------------------------------------------


def test_a_tileset_json_over_its_byte_limit_is_one_line_naming_the_file(tmp_path: Path) -> None:
    path = tmp_path / "out" / "tileset.json"
    write(path, tile())
    with path.open("a") as handle:
        handle.write(" " * 4096)  # white space: as cheap to parse as it is to write
    limit = ("--limit", "tileset_json_bytes=1K")
    (line,) = validated(path, *limit)
    assert "error JSON" in line and "tileset.json" in line, line
    assert "over the limit of 1,024" in line and "tileset_json_bytes" in line, line
    viewed(path, str(path), "over the limit of 1,024", "tileset_json_bytes", options=limit)
    assert run("validate", "-q", path).returncode == 0  # the default limit is far larger


def test_a_large_tileset_json_is_refused_before_it_is_read(tmp_path: Path) -> None:
    path = tmp_path / "out" / "tileset.json"
    path.parent.mkdir()
    with path.open("wb") as handle:  # 64 MiB, over the default 16 MiB, and sparse: no disk
        handle.truncate(64 << 20)
    tracemalloc.start()
    try:
        findings = validate_file(path)
        with pytest.raises(InputError, match="over the limit of 16,777,216"):
            render_page(path, path.with_suffix(".json.html"))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert [f.code for f in findings] == ["JSON"], findings
    assert "67,108,864 bytes" in findings[0].message, findings
    assert peak < 4 << 20, f"{peak:,} bytes traced"
    limits = Limits(tileset_json_bytes=1 << 10)  # lowered: the message says so
    assert "over the limit of 1,024" in validate_file(path, limits=limits)[0].message


# -- nesting and cycles -------------------------------------------------------------------------

DEEP = 100_000


@pytest.mark.parametrize(
    "text",
    [
        pytest.param('{"root":' + '{"children":[' * DEEP + "]}" * DEEP + "}", id="tiles"),
        pytest.param("[" * DEEP + "]" * DEEP, id="arrays"),
    ],
)
def test_json_nested_100000_deep_is_one_line_naming_the_file(tmp_path: Path, text: str) -> None:
    path = tmp_path / "deep" / "tileset.json"
    path.parent.mkdir()
    path.write_text(text)
    (line,) = validated(path)
    assert "error JSON" in line and "tileset.json: nests arrays and objects over" in line, line
    viewed(path, str(path), "nests arrays and objects over")


def test_external_tilesets_in_a_cycle_are_one_line_naming_the_files(tmp_path: Path) -> None:
    a = write(tmp_path / "a.json", tile("b.json"))
    write(tmp_path / "b.json", tile("a.json"))
    (line,) = validated(a)
    assert "error CYCLE: b.json root: content uri 'a.json' leads back to a.json" in line, line
    viewed(a, "b.json: root: content uri 'a.json' leads back to a.json", "cycle")


def test_a_tileset_that_refers_to_itself_is_a_cycle(tmp_path: Path) -> None:
    path = write(tmp_path / "tileset.json", tile(children=[tile("./tileset.json", error=0.5)]))
    (line,) = validated(path)
    assert "error CYCLE: root/0: content uri './tileset.json' leads back" in line, line
    viewed(path, str(path), "root/0", "cycle")


def test_an_external_tileset_named_twice_is_read_once(tmp_path: Path) -> None:
    # each file naming the next twice: 2^20 visits if each name were followed
    for index in range(20):
        name, error = f"t{index + 1}.json", 0.5**index
        children = [tile(name, error=error / 2), tile(name, error=error / 2)]
        write(tmp_path / f"t{index}.json", tile(children=children, error=error))
    write(tmp_path / "t20.json", tile(error=0.5**20))
    lines = validated(tmp_path / "t0.json")
    assert len(lines) == 20, lines
    assert "error URI: root/1: content uri 't1.json' names t1.json, an external tileset" in lines[0]
    assert "t19.json root/1: content uri 't20.json'" in lines[-1], lines[-1]
    viewed(tmp_path / "t0.json", "root/1", "t1.json", "already")


def test_a_long_chain_of_external_tilesets_is_walked_without_recursion(tmp_path: Path) -> None:
    count = 2 * sys.getrecursionlimit()
    for index in range(count):
        write(tmp_path / "tiles" / f"{index}.json", tile(f"{index + 1}.json"))
    write(tmp_path / "tiles" / f"{count}.json", tile())
    top = write(tmp_path / "tileset.json", tile("tiles/0.json"))
    result = run("validate", top)
    assert (result.returncode, result.stderr) == (0, ""), result.stdout + result.stderr
    assert run("view", top).returncode == 0


# -- content out of the folder ------------------------------------------------------------------


@pytest.fixture
def outside(tmp_path: Path) -> Path:
    """A file outside the tileset's folder (``tmp_path/set``) that must not be read."""
    path = tmp_path / "secret.glb"
    path.write_bytes(b"glTF secret")
    return path


@contextlib.contextmanager
def opened() -> Iterator[list[str]]:
    """The files opened while the block runs (an audit hook, silent afterwards)."""
    seen: list[str] = []
    active = [True]

    def hook(event: str, args: tuple) -> None:
        if active[0] and event == "open" and isinstance(args[0], str | bytes | os.PathLike):
            seen.append(os.path.realpath(os.fsdecode(args[0])))

    sys.addaudithook(hook)
    try:
        yield seen
    finally:
        active[0] = False


def _linked_file(folder: Path, outside: Path) -> dict:
    (folder / "tiles").mkdir()
    (folder / "tiles" / "a.glb").symlink_to(outside)
    return tile(children=[tile("tiles/a.glb", error=0.0)])


def _linked_folder(folder: Path, outside: Path) -> dict:
    (folder / "tiles").symlink_to(outside.parent)
    return tile(children=[tile("tiles/secret.glb", error=0.0)])


def _external(folder: Path, outside: Path) -> dict:
    write(outside.parent / "other.json", tile(error=0.0))
    return tile(children=[tile("../other.json", error=0.0)])


CASES: dict[str, Callable[[Path, Path], dict]] = {
    "a link out of the folder": _linked_file,
    "a link to a folder outside": _linked_folder,
    "../": lambda folder, outside: tile(children=[tile("../secret.glb", error=0.0)]),
    "%2e%2e/": lambda folder, outside: tile(children=[tile("%2e%2e/secret.glb", error=0.0)]),
    "an absolute path": lambda folder, outside: tile(children=[tile(str(outside), error=0.0)]),
    "a URL": lambda folder, outside: tile(children=[tile(outside.as_uri(), error=0.0)]),
    "a tile without a box": lambda folder, outside: tile(
        children=[{"geometricError": 0.0, "content": {"uri": "../secret.glb"}}]
    ),
    "3D Tiles 1.1 contents": lambda folder, outside: tile(
        children=[tile(error=0.0, contents=[{"uri": "../secret.glb"}])]
    ),
    "an external tileset outside": _external,
}


@pytest.mark.parametrize("case", list(CASES))
def test_content_out_of_the_folder_is_an_error_naming_the_tile_never_read(
    tmp_path: Path, case: str
) -> None:
    outside = tmp_path / "secret.glb"
    outside.write_bytes(b"glTF secret")
    folder = tmp_path / "set"
    folder.mkdir()
    path = write(folder / "tileset.json", CASES[case](folder, outside))
    with opened() as seen:
        findings = errors_of(validate_file(path))
        with pytest.raises(InputError) as refused:
            render_page(path, folder / "tileset.json.html")
    uri = [f for f in findings if f.code == "URI"]
    assert len(uri) == 1 and uri[0].message.startswith("root/0: content uri "), findings
    assert "leads outside the tileset's folder" in uri[0].message or (
        "is not a relative path" in uri[0].message
    ), uri[0].message
    assert str(refused.value) == f"{path}: {uri[0].message}"
    inside = str(folder.resolve()) + os.sep
    strays = [name for name in seen if name.startswith(str(tmp_path.resolve()))]
    assert all(name.startswith(inside) for name in strays), strays


def test_a_tile_whose_glb_json_nests_100000_deep_is_an_error_naming_the_tile(
    tmp_path: Path,
) -> None:
    text = b'{"asset":{"version":"2.0"},"extras":' + b"[" * DEEP + b"]" * DEEP + b"}"
    text += b" " * (-len(text) % 4)
    glb = struct.pack("<4sII", b"glTF", 2, 20 + len(text)) + struct.pack("<I4s", len(text), b"JSON")
    path = write(tmp_path / "set" / "tileset.json", tile(children=[tile("a.glb", error=0.0)]))
    (path.parent / "a.glb").write_bytes(glb + text)
    (line,) = validated(path)
    assert "error CONTENT: root/0: a.glb cannot be read" in line and "over 256 deep" in line, line
