"""Resumable tilesets: a run killed with SIGKILL leaves its staging folder, and the next
identical command keeps the tiles already written there (each checked against its recorded
hash), writes the rest and ends byte-identical to a run never interrupted; changed options or
a changed input start over."""

from __future__ import annotations

import gc
import os
import shutil
import signal
import subprocess
import sys
import weakref
from pathlib import Path
from typing import Any

import pytest

from lodconvert.io.tiles import records, task
from tests.test_cli import run
from tests.test_tiles import FAST, convert, inputs

ROOT = Path(__file__).resolve().parents[1]
SAID = tuple(flag for flag in FAST if flag != "-q")
HOLD = """
import sys
from lodconvert.io.tiles import records
from lodconvert.cli import main
real, written = records.TileRecords.written, []
def write(self, name, result):
    if len(written) == int(sys.argv[1]):
        print("held", flush=True)
        sys.stdin.read()  # the test kills this process here
    written.append(name)
    return real(self, name, result)
records.TileRecords.written = write
if __name__ == "__main__":
    sys.exit(main(sys.argv[2:]))
"""
"""The command line, holding before it writes its tile number ``argv[1]`` (wherever that
tile was made) until it is killed."""


def glbs(tileset: dict[str, bytes]) -> int:
    """How many tiles the files of a tileset hold."""
    return sum(name.endswith(".glb") for name in tileset)


def files(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` by its relative path."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}  # fmt: skip


def staged(out: Path) -> list[Path]:
    """The staged folders beside the output folder ``out``."""
    return sorted(out.parent.glob(f".{out.name}.*.tmp"))


def killed(source: Path, out: Path, tiles: int, *flags: str) -> Path:
    """The staging folder of a run of ``source`` into ``out/tileset.json`` killed with SIGKILL
    once ``tiles`` tiles are staged."""
    command = [sys.executable, "-c", HOLD, str(tiles), str(source), "-o", str(out / "tileset.json"),
               "--crs", "EPSG:7415", *FAST, *flags]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with subprocess.Popen(
        command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env
    ) as process:
        assert process.stdout is not None and process.stderr is not None
        while (line := process.stdout.readline()) not in (b"held\n", b""):
            pass
        assert line, process.stderr.read().decode()
        process.send_signal(signal.SIGKILL)
        process.wait()
    assert not out.exists()
    [folder] = staged(out)
    assert len(list((folder / "tiles").glob("*.glb"))) == tiles
    return folder


def resumed(source: Path, out: Path, *flags: str) -> str:
    """The ``-v`` messages of a run of ``source`` into ``out/tileset.json``, which succeeds."""
    result = run(source, "-o", out / "tileset.json", "--crs", "EPSG:7415", *SAID, *flags, "-v")
    assert result.returncode == 0, result.stderr
    assert staged(out) == []
    return result.stderr


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """The files of multi_lod's tileset, written by a run never interrupted."""
    return files(convert("multi_lod", tmp_path_factory.mktemp("clean")).parent)


def test_a_killed_run_resumes_and_ends_byte_identical(
    tmp_path: Path, clean: dict[str, bytes]
) -> None:
    [source] = inputs("multi_lod")
    out = tmp_path / "out"
    killed(source, out, 1)
    said = resumed(source, out, "--workers", "2")  # the worker count is no option of the key
    assert f"1 of {glbs(clean)} tiles kept from an interrupted run" in said
    assert files(out) == clean


def test_a_run_whose_cells_made_their_tiles_in_workers_resumes_byte_identical(
    tmp_path: Path, clean: dict[str, bytes]
) -> None:
    """With workers, a coarsest cell's tiles are made where it is baked and come back with
    it: a run killed after writing the first keeps it, found by the key that came back."""
    [source] = inputs("multi_lod")
    out = tmp_path / "out"
    killed(source, out, 1, "--workers", "2")
    said = resumed(source, out)
    assert f"1 of {glbs(clean)} tiles kept from an interrupted run" in said
    assert files(out) == clean


@pytest.mark.parametrize("change", ["option", "input"])
def test_changed_options_or_input_start_over(tmp_path: Path, change: str) -> None:
    source = tmp_path / "city.json"
    shutil.copyfile(inputs("multi_lod")[0], source)
    out = tmp_path / "out"
    first = killed(source, out, 1)
    flags: tuple[str, ...] = ()
    if change == "option":
        flags = ("--sse", "8")
    else:
        os.utime(source, ns=(source.stat().st_mtime_ns + 10**9,) * 2)
    said = resumed(source, out, *flags)
    assert "interrupted run" not in said
    assert not first.exists()
    assert (out / "tileset.json").exists()


def test_a_damaged_staged_tile_is_written_again(tmp_path: Path, clean: dict[str, bytes]) -> None:
    [source] = inputs("multi_lod")
    out = tmp_path / "out"
    folder = killed(source, out, 1)
    [tile] = (folder / "tiles").glob("*.glb")
    data = tile.read_bytes()
    tile.write_bytes(data[: len(data) // 2])  # as a run killed while writing it leaves it
    said = resumed(source, out)
    assert f"0 of {glbs(clean)} tiles kept from an interrupted run" in said
    assert files(out) == clean


def test_a_tile_an_interrupted_run_wrote_that_this_one_does_not_is_removed(
    tmp_path: Path, clean: dict[str, bytes]
) -> None:
    [source] = inputs("multi_lod")
    out = tmp_path / "out"
    folder = killed(source, out, 1)
    [tile] = (folder / "tiles").glob("*.glb")
    (folder / "tiles" / "cell9_9_9.glb").write_bytes(tile.read_bytes())  # no tile of this tree
    with (folder / ".resume" / "written").open("a") as journal:
        journal.write("tiles/cell9_9_9.glb\n")  # as a run of another tree would have said
    resumed(source, out)
    assert files(out) == clean


def test_a_resumed_run_holds_no_kept_tiles_geometry(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A resumed run lets go of each kept tile's content at once: by the first tile it makes,
    none of the ten kept before it is alive (a 1000× city resumed held all of them)."""
    [source] = inputs("multi_lod")
    out = tmp_path / "out"
    killed(source, out, 10, "--hlod", "20")  # ten of its 20 tiles, two per cell
    kept_tasks: list[weakref.ref[task.TileTask]] = []
    alive: list[int] = []
    real_kept, real_run = records.TileRecords.kept, task.TileTask.run

    def kept(self: records.TileRecords, name: str, key: Any) -> task.TileResult | None:
        found = real_kept(self, name, key)
        if found is not None:
            kept_tasks.append(weakref.ref(key.__self__))  # the task whose key it is
        return found

    def made(self: task.TileTask, *args: Any) -> task.TileResult:
        if not alive:
            gc.collect()
            alive.append(sum(ref() is not None for ref in kept_tasks))
        return real_run(self, *args)

    monkeypatch.setattr(records.TileRecords, "kept", kept)
    monkeypatch.setattr(task.TileTask, "run", made)
    said = resumed(source, out, "--hlod", "20")
    assert "10 of 20 tiles kept from an interrupted run" in said
    assert len(kept_tasks) == 10 and alive == [0]
