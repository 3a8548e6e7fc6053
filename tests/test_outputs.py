"""Every output of a run is checked before any work and committed together or not at all."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import lodconvert
from lodconvert.errors import InputError
from lodconvert.sinks import Outputs

from .conftest import SAMPLE
from .test_cli import assert_one_line_error, run

FAST = ("--resolution", "24,12,6")


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize(
    ("make", "words", "code"),
    [
        (lambda d: d / "missing" / "out.glb", ["out.glb", "no folder"], 1),
        (lambda d: (d / "dir.glb").mkdir() or d / "dir.glb", ["dir.glb", "is a directory"], 1),
        (lambda d: d / "out.fbx", ["out.fbx", "unknown output format"], 2),
    ],
    ids=["missing-folder", "a-directory", "unknown-suffix"],
)
def test_output_problems_are_found_before_any_work(tmp_path: Path, make, words, code) -> None:
    out = make(tmp_path)
    before = _files(tmp_path)
    assert_one_line_error(run(SAMPLE, "-o", out, *FAST), code, *words)
    assert _files(tmp_path) == before


def test_an_unwritable_folder_is_refused(tmp_path: Path) -> None:
    if os.geteuid() == 0:
        pytest.skip("root writes everywhere")
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    assert_one_line_error(run(SAMPLE, "-o", locked / "o.glb", *FAST), 1, "not writable")


def test_the_input_is_never_an_output(tmp_path: Path) -> None:
    copy = tmp_path / "knot.x3d"
    run(SAMPLE, "-o", copy, *FAST)
    data = copy.read_bytes()
    link = tmp_path / "same.x3d"
    link.symlink_to(copy)
    for output in (copy, link):
        assert_one_line_error(run("view", copy, "-o", output), 1, "input of this run")
    assert copy.read_bytes() == data
    glb = tmp_path / "knot.glb"
    run(SAMPLE, "-o", glb, *FAST)
    before = glb.read_bytes()
    assert_one_line_error(run(glb, "-o", glb, *FAST), 1, "input of this run")
    assert glb.read_bytes() == before
    report = tmp_path / "r.json"
    result = run(SAMPLE, "-o", tmp_path / "k.glb", "--report", SAMPLE, *FAST)
    assert_one_line_error(result, 1, "input of this run")
    assert not report.exists() and not (tmp_path / "k.glb").exists()


def test_a_report_that_cannot_be_written_leaves_no_model(tmp_path: Path) -> None:
    out = tmp_path / "r.glb"
    result = run(SAMPLE, "-o", out, "--report", tmp_path / "nodir" / "r.json", *FAST)
    assert_one_line_error(result, 1, "r.json", "no folder")
    assert _files(tmp_path) == []


def test_report_and_output_may_not_be_one_file(tmp_path: Path) -> None:
    out = tmp_path / "same.glb"
    assert_one_line_error(run(SAMPLE, "-o", out, "--report", out, *FAST), 1, "written twice")
    assert _files(tmp_path) == []


def test_a_failed_step_after_staging_removes_every_staged_file(tmp_path: Path) -> None:
    (tmp_path / "b.txt").write_text("previous")
    with pytest.raises(RuntimeError), Outputs() as outputs:
        outputs.file(tmp_path / "a.txt").write_bytes(b"new a")
        outputs.file(tmp_path / "b.txt").write_bytes(b"new b")
        with outputs.directory(tmp_path / "tiles").file("0/0.bin") as handle:
            handle.write(b"tile")
        raise RuntimeError("a later step failed")
    assert _files(tmp_path) == ["b.txt"]
    assert (tmp_path / "b.txt").read_text() == "previous"


def test_a_commit_puts_back_what_it_replaced_when_a_rename_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for name in ("a.txt", "b.txt"):
        (tmp_path / name).write_text(f"old {name}")
    outputs = Outputs()
    outputs.file(tmp_path / "a.txt").write_bytes(b"new a")
    outputs.file(tmp_path / "b.txt").write_bytes(b"new b")
    real = os.replace

    def failing(src: str | Path, dst: str | Path) -> None:
        if Path(dst).name == "b.txt" and str(src).endswith(".tmp.txt"):  # b's staged file
            raise OSError("disk full")
        real(src, dst)

    monkeypatch.setattr(os, "replace", failing)
    with pytest.raises(OSError, match="disk full"):
        outputs.commit()
    monkeypatch.setattr(os, "replace", real)
    assert _files(tmp_path) == ["a.txt", "b.txt"]
    assert [(tmp_path / n).read_text() for n in ("a.txt", "b.txt")] == ["old a.txt", "old b.txt"]


def test_a_directory_output_replaces_the_old_one_whole(tmp_path: Path) -> None:
    old = tmp_path / "tiles"
    (old / "stale").mkdir(parents=True)
    with Outputs() as outputs, outputs.directory(old).file("0/1.bin") as handle:
        handle.write(b"x")
    assert sorted(str(p.relative_to(old)) for p in old.rglob("*")) == ["0", "0/1.bin"]
    with pytest.raises(InputError, match="is a file"):
        Outputs().directory(old / "0" / "1.bin")


def test_library_convert_runs_again_and_write_checks_like_the_cli(tmp_path: Path) -> None:
    options = lodconvert.ChainOptions(resolutions=(24, 12, 6))
    first = lodconvert.convert(SAMPLE, tmp_path / "a.glb", options)
    second = lodconvert.convert(SAMPLE, tmp_path / "b.x3d", options)
    assert first["totals"]["objects"] == second["totals"]["objects"] == 1
    chains = [lodconvert.bake(node, options) for node in lodconvert.read(SAMPLE).with_geometry()]
    with pytest.raises(InputError, match="no folder"):
        lodconvert.write(chains, tmp_path / "nowhere" / "c.glb")
    lodconvert.write(chains, tmp_path / "c.glb")
    assert _files(tmp_path) == ["a.glb", "b.x3d", "c.glb"]


def test_a_command_name_is_a_command_even_when_a_file_has_that_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("ranges").write_bytes(SAMPLE.read_bytes())
    result = run("ranges", SAMPLE)
    assert result.returncode == 0 and "torus_knot" in result.stdout
    result = run("./ranges", "-o", "x.glb")
    assert result.returncode == 1 and "unknown input format" in result.stderr
