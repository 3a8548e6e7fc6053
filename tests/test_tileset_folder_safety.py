"""A tileset's folders cannot be turned against the user: a run killed with SIGKILL leaves its
staged folder, something is planted in it or in the committed folder (a link out of it, a hard
link, a file of the user's), and the next run either refuses in one line or works around it,
without ever writing, reading or deleting through a link, and without touching a canary file
(and a canary folder) outside the output."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.test_cli import assert_one_line_error, run
from tests.test_tiles import FAST, inputs
from tests.test_tiles_resume import SAID, killed, staged

CANARY = b"the user's own file\n"


@pytest.fixture
def source() -> Path:
    [path] = inputs("multi_lod")
    return path


@pytest.fixture
def outside(tmp_path: Path) -> Path:
    """A folder of the user's beside the output, with a canary file in it."""
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "canary.txt").write_bytes(CANARY)
    return folder


def again(source: Path, out: Path) -> object:
    """The same run of ``source`` into ``out/tileset.json`` as the killed one."""
    return run(source, "-o", out / "tileset.json", "--crs", "EPSG:7415", *SAID)


def untouched(outside: Path) -> None:
    """The user's folder holds its canary as it was, and nothing else."""
    assert sorted(p.name for p in outside.iterdir()) == ["canary.txt"]
    assert (outside / "canary.txt").read_bytes() == CANARY


def _link_file(folder: Path, outside: Path) -> str:
    (folder / "tileset.json").unlink(missing_ok=True)
    (folder / "tileset.json").symlink_to(outside / "canary.txt")
    return "tileset.json"


def _link_tile(folder: Path, outside: Path) -> str:
    [tile] = (folder / "tiles").glob("*.glb")
    tile.unlink()
    tile.symlink_to(outside / "canary.txt")
    return f"tiles/{tile.name}"


def _link_record(folder: Path, outside: Path) -> str:
    record = folder / ".resume" / "tiles.jsonl"
    record.unlink()
    record.symlink_to(outside / "canary.txt")
    return ".resume/tiles.jsonl"


def _link_tiles_folder(folder: Path, outside: Path) -> str:
    for tile in (folder / "tiles").iterdir():
        tile.unlink()
    (folder / "tiles").rmdir()
    (folder / "tiles").symlink_to(outside, target_is_directory=True)
    return "tiles"


def _hard_link_tile(folder: Path, outside: Path) -> str:
    [tile] = (folder / "tiles").glob("*.glb")
    tile.unlink()
    os.link(outside / "canary.txt", tile)
    return f"tiles/{tile.name}"


def _user_file(folder: Path, outside: Path) -> str:
    (folder / "tiles" / "notes.doc").write_bytes(CANARY)
    return "tiles/notes.doc"


TAMPERED: dict[str, Callable[[Path, Path], str]] = {
    "tileset.json a link": _link_file,
    "a tile a link": _link_tile,
    "a resume record a link": _link_record,
    "tiles/ a link to a folder": _link_tiles_folder,
    "a tile a hard link": _hard_link_tile,
    "a file no run wrote": _user_file,
}


@pytest.mark.parametrize("tamper", TAMPERED.values(), ids=TAMPERED.keys())
def test_a_tampered_staged_folder_is_refused_and_nothing_outside_is_touched(
    tmp_path: Path, source: Path, outside: Path, tamper: Callable[[Path, Path], str]
) -> None:
    out = tmp_path / "out"
    folder = killed(source, out, 1)
    planted = tamper(folder, outside)
    result = again(source, out)
    assert_one_line_error(result, 1, str(out), folder.name, repr(planted), "remove that folder")
    untouched(outside)
    assert not out.exists()
    assert os.path.lexists(folder / planted)  # what was planted is left for the user to see


def test_a_staged_folder_that_is_a_link_is_neither_followed_nor_removed(
    tmp_path: Path, source: Path, outside: Path
) -> None:
    out = tmp_path / "out"
    folder = killed(source, out, 1)
    name = folder.name
    os.rename(folder, tmp_path / "moved")
    (tmp_path / name).symlink_to(outside, target_is_directory=True)
    result = again(source, out)
    assert result.returncode == 0, result.stderr
    untouched(outside)
    assert (tmp_path / name).is_symlink()
    assert (out / "tileset.json").is_file() and not (out / "tileset.json").is_symlink()


def test_a_dead_runs_staged_folder_holding_a_link_is_left_alone(
    tmp_path: Path, source: Path, outside: Path
) -> None:
    """Another key's staged folder (a changed option) is removed only when it holds nothing
    but what its runs wrote."""
    out = tmp_path / "out"
    folder = killed(source, out, 1)
    planted = _link_tile(folder, outside)
    result = run(source, "-o", out / "tileset.json", "--crs", "EPSG:7415", *SAID, "--sse", "8")
    assert result.returncode == 0, result.stderr
    untouched(outside)
    assert (folder / planted).is_symlink()
    assert staged(out) == [folder]


def tileset(tmp_path: Path, source: Path) -> Path:
    """A tileset folder lodconvert wrote."""
    out = tmp_path / "out"
    result = run(source, "-o", out / "tileset.json", "--crs", "EPSG:7415", *FAST)
    assert result.returncode == 0, result.stderr
    return out


def test_a_rerun_replaces_its_own_tileset(tmp_path: Path, source: Path) -> None:
    out = tileset(tmp_path, source)
    first = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    out2 = tileset(tmp_path, source)
    assert out2 == out
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == first


def test_a_user_file_added_to_a_tileset_is_named_and_kept(tmp_path: Path, source: Path) -> None:
    out = tileset(tmp_path, source)
    (out / "tiles" / "important.doc").write_bytes(CANARY)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    result = again(source, out)
    assert_one_line_error(result, 1, "'tiles/important.doc'", "not written by lodconvert")
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_a_forged_generator_does_not_make_a_folder_ours(tmp_path: Path, source: Path) -> None:
    out = tmp_path / "out"
    (out / "tiles").mkdir(parents=True)
    (out / "tileset.json").write_text(json.dumps({"asset": {"generator": "lodconvert-fake"}}))
    (out / "tiles" / "important.doc").write_bytes(CANARY)
    result = again(source, out)
    assert_one_line_error(result, 1, "not a tileset lodconvert wrote")
    assert (out / "tiles" / "important.doc").read_bytes() == CANARY


def test_a_damaged_tileset_of_ours_is_said_to_be_ours_and_damaged(
    tmp_path: Path, source: Path
) -> None:
    out = tileset(tmp_path, source)
    text = (out / "tileset.json").read_bytes()
    (out / "tileset.json").write_bytes(text[: len(text) // 2])
    result = again(source, out)
    assert_one_line_error(result, 1, "a tileset lodconvert wrote", "tileset.json", "damaged")
    assert "not a tileset" not in result.stderr
    assert (out / "tileset.json").read_bytes() == text[: len(text) // 2]


def test_a_committed_tileset_json_made_a_link_is_refused(
    tmp_path: Path, source: Path, outside: Path
) -> None:
    out = tileset(tmp_path, source)
    (out / "tileset.json").unlink()
    (out / "tileset.json").symlink_to(outside / "canary.txt")
    result = again(source, out)
    assert_one_line_error(result, 1, "'tileset.json'", "a link")
    untouched(outside)


def test_the_viewer_page_joins_the_list_of_the_tileset_files(tmp_path: Path, source: Path) -> None:
    """``lodconvert view`` writes its page inside the folder and names it in the manifest, so
    that the next run replaces the folder, page included."""
    out = tileset(tmp_path, source)
    result = run("view", out / "tileset.json", "-q")
    assert result.returncode == 0, result.stderr
    assert (out / "tileset.json.html").is_file()
    out = tileset(tmp_path, source)
    assert not (out / "tileset.json.html").exists()
