"""Every output of a run is checked before any work and committed together or not at all."""

from __future__ import annotations

import errno
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import lodconvert
from lodconvert import spool
from lodconvert.errors import InputError
from lodconvert.sinks import Outputs

from .conftest import ROOT, SAMPLE, shared_data
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


@pytest.mark.parametrize("name", ["x.x3d", "tileset.json", "report"])
def test_an_output_through_a_link_loop_is_one_line_naming_it(tmp_path: Path, name: str) -> None:
    """A folder that is a link to itself (``ln -s out out``): the output (or the report) named
    in one line, nothing written (a tileset's was a ``RuntimeError``)."""
    loop = tmp_path / "out"
    loop.symlink_to(loop)
    output, more = loop / name, ()
    if name == "report":
        output, more = tmp_path / "x.glb", ("--report", loop / "r.json")
    written = str(more[-1] if more else output)
    assert_one_line_error(run(SAMPLE, "-o", output, *more, *FAST), 1, written, "link loop")
    assert _files(tmp_path) == ["out"]


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
    listed = [".lodconvert-manifest.json", "0", "0/1.bin"]
    assert sorted(str(p.relative_to(old)) for p in old.rglob("*")) == listed
    with pytest.raises(InputError, match="is a file"):
        Outputs().directory(old / "0" / "1.bin")


def test_a_replaced_directory_loses_only_the_files_its_manifest_lists(tmp_path: Path) -> None:
    old = tmp_path / "tiles"
    with Outputs() as outputs, outputs.directory(old).file("0/1.bin") as handle:
        handle.write(b"x")
    (old / "0" / "mine.txt").write_text("the user's")  # added after the run
    with Outputs() as outputs, outputs.directory(old).file("2.bin") as handle:
        handle.write(b"y")
    assert sorted(str(p.relative_to(old)) for p in old.rglob("*")) == [
        ".lodconvert-manifest.json",
        "2.bin",
    ]
    [kept] = tmp_path.glob(".tiles.*.tmp.old/0/mine.txt")
    assert kept.read_text() == "the user's"


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


@pytest.mark.parametrize("target", ["/proc/out.x3d", "/sys/out.glb", "/proc/self/fd/out.x3d"])
def test_an_output_in_proc_or_sys_is_one_line(target: str) -> None:
    if not Path(target).parent.is_dir():
        pytest.skip(f"no {Path(target).parent} here")
    result = run(SAMPLE, "-o", target, *FAST)
    assert_one_line_error(result, 1, target, "cannot write here")
    assert not Path(target).exists()


def _in_a_small_tmpfs(
    folder: Path, command: str, size: str = "256k"
) -> subprocess.CompletedProcess[str]:
    """``command`` run by sh with a tmpfs of ``size`` mounted on ``folder``, in a mount
    namespace of its own (so the mount goes with it), or skip where namespaces or tmpfs are
    refused."""
    unshare = shutil.which("unshare")
    if unshare is None:
        pytest.skip("no unshare(1)")
    mount = f"mount -t tmpfs -o size={size} tmpfs {shlex.quote(str(folder))} || exit 99; "
    script = mount + command
    done = subprocess.run(
        [unshare, "-rm", "sh", "-c", script], capture_output=True, text=True, timeout=300
    )
    if done.returncode == 99 or "unshare failed" in done.stderr:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    return done


@pytest.mark.parametrize("suffix", [".x3d", ".glb"])
def test_a_full_disk_is_one_line_naming_the_output_and_leaves_nothing(
    tmp_path: Path, suffix: str
) -> None:
    small = tmp_path / "small"
    small.mkdir()
    out, report = small / f"out{suffix}", small / "report.json"
    convert = shlex.join(
        [sys.executable, "-m", "lodconvert", str(SAMPLE), "-o", str(out), "--report", str(report)]
    )
    done = _in_a_small_tmpfs(small, f"{convert}; echo exit=$?; ls -A {shlex.quote(str(small))}")
    lines = done.stderr.strip().splitlines()
    assert lines == [f"lodconvert: error: {out}: cannot write: No space left on device"], done
    assert done.stdout.split() == ["exit=1"]  # and the tmpfs holds no file


def test_a_full_disk_under_a_tileset_names_the_output_not_its_staged_folder(
    tmp_path: Path,
) -> None:
    city = ROOT.parent / "shared" / "data" / "cityjson" / "multi_lod_10bldg.city.json"
    shared_data(city)
    small = tmp_path / "small"
    small.mkdir()
    out = small / "out" / "tileset.json"
    convert = shlex.join(
        [sys.executable, "-m", "lodconvert", str(city), "-o", str(out), "--crs", "EPSG:7415"]
    )
    done = _in_a_small_tmpfs(
        small, f"{convert}; echo exit=$?; ls -A {shlex.quote(str(small))}", size="64k"
    )
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(f"lodconvert: error: {small}/out/"), line
    assert line.endswith(": cannot write: No space left on device") and ".tmp" not in line, line
    assert done.stdout.split() == ["exit=1"]  # and the tmpfs holds no file


def test_a_full_temporary_folder_is_one_line_naming_it_and_leaves_nothing(tmp_path: Path) -> None:
    city = ROOT.parent / "shared" / "data" / "cityjson" / "multi_lod_10bldg.city.json"
    if not city.exists():
        pytest.skip(f"{city} is absent (shared test data not checked out)")
    small, out = tmp_path / "small", tmp_path / "out" / "city.glb"
    small.mkdir()
    out.parent.mkdir()
    # its objects wait on disk, as a city's do past the spool's memory
    parked = "import sys; from lodconvert import spool, cli; spool.SPOOL_MEMORY = 0; "
    parked += "sys.exit(cli.main())"
    convert = shlex.join([sys.executable, "-c", parked, str(city), "-o", str(out), "-qq"])
    done = _in_a_small_tmpfs(small, f"TMPDIR={shlex.quote(str(small))} {convert}", size="16k")
    assert done.returncode == 1, done
    lines = done.stderr.strip().splitlines()
    assert lines == [
        f"lodconvert: error: temporary folder {small}: cannot write: No space left on device"
    ]
    assert _files(out.parent) == []


def test_a_full_temporary_folder_while_objects_wait_on_disk_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def full(*args: object, **kwargs: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(spool.pickle, "dump", full)
    monkeypatch.setattr(spool, "SPOOL_MEMORY", 0)  # as for a city past it
    city = ROOT.parent / "shared" / "data" / "cityjson" / "multi_lod_10bldg.city.json"
    if not city.exists():
        pytest.skip(f"{city} is absent (shared test data not checked out)")
    result = run(city, "-o", tmp_path / "city.glb", "-qq")
    assert_one_line_error(result, 1, "temporary folder", "No space left on device")
    assert _files(tmp_path) == []
