"""A plain CityGML file read by workers from byte ranges of it: the main process reads its
prolog only, a worker finds its first member by its start tag, and where that guess is wrong
(a start tag in a comment, CDATA or nested), where a worker cannot open the file, or where the
file changed, the city read is still the city one process reads."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import zipfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import pytest

from lodconvert.bake import get_backend
from lodconvert.context import RunContext
from lodconvert.io import read_scene, spread
from lodconvert.io.citygml import members as members_module
from lodconvert.io.citygml import ranges
from lodconvert.io.citygml.appearance import MARKS
from lodconvert.io.citygml.members import member_after
from lodconvert.io.citygml.parallel import SpreadReading
from lodconvert.io.citygml.ranges import (
    MarksResult,
    MarksTask,
    RangeResult,
    RangeTask,
    marks_by_workers,
)
from lodconvert.limits import DEFAULT_LIMITS
from lodconvert.semantics import DEFAULT_PALETTE

from .conftest import SHARED, shared_data
from .test_citygml import box, building
from .test_parallel_reading import _city, _parked_facts, _read, _town, _tricky
from .test_workers import TUM, _lodconvert, _untimed


def _misleading() -> str:
    """A town whose comments, CDATA and a nested empty member hold member start tags."""
    fake = "<!-- <cityObjectMember> <gml:featureMember> -->"
    nested = building("n", box(600.0)).replace(
        "<bldg:Building", "<cityObjectMember/><bldg:Building", 1
    )
    cdata = building("c", box(640.0)).replace(
        "<bldg:lod2MultiSurface>",
        '<gen:stringAttribute xmlns:gen="http://www.opengis.net/citygml/generics/2.0" '
        'name="n"><gen:value><![CDATA[<cityObjectMember>]]></gen:value></gen:stringAttribute>'
        "<bldg:lod2MultiSurface>",
        1,
    )
    towns = [building(f"b{i}", box(20.0 * i)) for i in range(8)]
    return _city(towns[0], fake, *towns[1:4], nested, fake, _tricky(), cdata, *towns[4:], fake)


class _InProcess:
    """An executor that runs each task here (pickled and unpickled, as a worker takes it),
    after ``change`` (task number, task → task), keeping the tasks and results."""

    task_seconds = spread.TASK_SECONDS

    def __init__(self, change: Any = None) -> None:
        self.change = change or (lambda number, task: task)
        self.tasks: list[Any] = []
        self.results_kept: list[Any] = []

    def results(self, tasks: Iterable[Any]) -> Iterator[Any]:
        for task in tasks:
            task = self.change(len(self.tasks), task)
            self.tasks.append(task)
            result = task.run()
            self.results_kept.append(result)
            yield result


def _read_here(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count the runs of members the main process parses (one entry per run)."""
    parsed: list[int] = []
    original = SpreadReading.read_here

    def counted(self: SpreadReading, run: list[bytes]) -> Iterator[Any]:
        parsed.append(len(run))
        return original(self, run)

    monkeypatch.setattr(SpreadReading, "read_here", counted)
    return parsed


def _by(executor: _InProcess, path: Path) -> tuple[list[Any], list[str]]:
    told: list[str] = []
    context = RunContext(executor, get_backend("numpy"), progress=told.append)  # type: ignore[arg-type]
    return _parked_facts(read_scene(path, context=context)), told


@pytest.mark.parametrize("size", [1, 97, 331, 4096])
def test_ranges_of_any_size_read_the_city_one_process_reads(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, size: int
) -> None:
    """Ranges of ``size`` bytes over a town whose comments, CDATA and a nested member hold
    member start tags: the same nodes in the same order, also where a worker took such a tag
    for a member's start (the main process reads from where the range before ended)."""
    path = tmp_path / "misleading.gml"
    path.write_text(_misleading())
    _, one, _, _ = _read(path, spread=False)
    monkeypatch.setattr(spread.Sizer, "wanted", lambda self: size)
    executor = _InProcess()
    two, told = _by(executor, path)
    assert two == one and len(one) == 11
    assert told == []
    ranged = [r for r in executor.results_kept if not isinstance(r, MarksResult)]
    assert all(isinstance(result, RangeResult) for result in ranged)
    text = path.read_bytes()
    in_comments = {
        at
        for tag in (b"<cityObjectMember>", b"<gml:featureMember>")
        for at in range(len(text))
        if text.startswith(tag, at) and text.rfind(b"<!--", 0, at) > text.rfind(b"-->", 0, at)
    }
    assert len(in_comments) == 6
    guessed = {result.first for result in ranged} & in_comments
    if size == 1:  # a range starts at every offset: the middle comment's tags were guessed
        assert len(guessed) == 2  # (and refused: the nodes are the same)


def test_a_clean_city_is_parsed_by_workers_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ranges of 300 bytes over buildings alone: every range's first member is the one the
    range before ended at, and the main process parses none."""
    path = tmp_path / "clean.gml"
    path.write_text(_city(*(building(f"b{i}", box(20.0 * i)) for i in range(12))))
    _, one, _, _ = _read(path, spread=False)
    monkeypatch.setattr(spread.Sizer, "wanted", lambda self: 300)
    parsed = _read_here(monkeypatch)
    executor = _InProcess()
    two, told = _by(executor, path)
    assert two == one and len(one) == 12
    assert parsed == [] and told == []
    assert len(executor.tasks) >= 12
    ranged = [r for r in executor.results_kept if isinstance(r, RangeResult)]
    assert sum(len(result.read.nodes) for result in ranged) == 12


def _moved(number: int, task: Any, first: int = 0) -> Any:
    """``task`` pointed at a file that is not there, from task ``first`` on."""
    if number < first or not isinstance(task, RangeTask):
        return task
    return dataclasses.replace(task, path=task.path + ".elsewhere")


@pytest.mark.parametrize("first", [0, 2])
def test_a_worker_that_cannot_open_the_file_is_sent_its_members(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, first: int
) -> None:
    """Workers on machines without the file: where the first range cannot be opened, the
    members are sent as bytes (``-v`` says so); where a later one cannot, the main process
    reads that range. Either way the city read is the one process's."""
    path = tmp_path / "town.gml"
    path.write_text(_town())
    _, one, _, _ = _read(path, spread=False)
    monkeypatch.setattr(spread.Sizer, "wanted", lambda self: 400)
    executor = _InProcess(lambda number, task: _moved(number, task, first))
    two, told = _by(executor, path)
    assert two == one
    missing = f"a worker cannot open it at {path.resolve()} (No such file or directory)"
    if first == 0:
        assert told[0] == f"{path}: {missing}; its members are sent as bytes"
        assert any(not isinstance(task, RangeTask) for task in executor.tasks)
    else:
        assert told[0] == f"{path}: {missing}; the main process reads its range"
        assert all(isinstance(task, (MarksTask, RangeTask)) for task in executor.tasks)


def test_a_file_changed_after_its_prolog_was_read_is_not_read_from_ranges(
    tmp_path: Path,
) -> None:
    """A worker opens the file the main process read or none: a link (the main process sends
    the input's real path), another size, time or start is refused before anything of it is
    read."""
    path = tmp_path / "town.gml"
    path.write_text(_town())
    status = os.stat(path)
    prolog = path.read_bytes()[:200]
    task = RangeTask(
        str(path), (status.st_size, status.st_mtime_ns), prolog, b"</CityModel>", 200, 400,
        False, str(path), DEFAULT_LIMITS, None, DEFAULT_PALETTE, None,
    )  # fmt: skip
    assert task.run().unreachable is None
    link = tmp_path / "link.gml"
    link.symlink_to(path)
    assert "symbolic links" in str(dataclasses.replace(task, path=str(link)).run().unreachable)
    for changed in (
        dataclasses.replace(task, identity=(status.st_size + 1, status.st_mtime_ns)),
        dataclasses.replace(task, identity=(status.st_size, status.st_mtime_ns + 1)),
        dataclasses.replace(task, prolog=b"<" + prolog[1:].upper()),
    ):
        reason = changed.run().unreachable
        assert reason is not None and "not the file the main process read" in reason


@pytest.mark.parametrize("chunk", [7, 1 << 20])
def test_a_member_start_tag_is_found_from_any_offset(
    monkeypatch: pytest.MonkeyPatch, chunk: int
) -> None:
    monkeypatch.setattr(members_module, "CHUNK", chunk)
    text = b"<a><cityObjectMemberX/> <core:cityObjectMember> <featureMember/><gml:member\n>"
    found = [member_after(io.BytesIO(text[at:]), at) for at in range(len(text) + 1)]
    starts = [text.index(b"<core:"), text.index(b"<featureMember/>"), text.index(b"<gml:member")]
    assert found[0] == starts[0] and found[starts[0]] == starts[0]
    assert found[starts[0] + 1] == starts[1] and found[starts[1] + 1] == starts[2]
    assert found[starts[2] + 1] is None and found[len(text)] is None


@pytest.mark.parametrize("bytes_", [5, 11, 1 << 26])
def test_workers_find_the_marks_of_appearances_across_their_ranges(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, bytes_: int
) -> None:
    """Ranges of ``bytes_`` bytes: a mark that straddles two is found, one absent is not, and
    a worker that cannot open the file leaves the looking to this process."""
    monkeypatch.setattr(ranges, "MARK_BYTES", bytes_)
    path = tmp_path / "marks.gml"
    path.write_bytes(b"<CityModel><app:appearanceMember><app:Appearance/>" + b"x" * 40)
    executor = _InProcess()
    assert marks_by_workers(path, executor.results, MARKS) == set(MARKS)
    assert len(executor.tasks) == -(-path.stat().st_size // bytes_)
    plain = tmp_path / "plain.gml"
    plain.write_bytes(b"<CityModel><cityObjectMember/>" + b"Appearanc" * 9)
    assert marks_by_workers(plain, _InProcess().results, MARKS) == set()
    away = _InProcess(lambda number, task: dataclasses.replace(task, path=task.path + ".x"))
    assert marks_by_workers(path, away.results, MARKS) is None


def test_a_textured_city_read_from_ranges_is_the_city_one_process_reads(tmp_path: Path) -> None:
    """PLATEAU's textured building with two worker processes: they find its appearances
    (which are then read in this process), the same nodes and textures as in one process."""
    source = shared_data(SHARED / "data/citygml/plateau_53394517_bldg_lod012_v2.gml")
    _, one, _, _ = _read(source, spread=False)
    _, two, results, _ = _read(source, spread=True)
    assert two == one and one
    assert [r.found for r in results if isinstance(r, MarksResult)] == [frozenset(MARKS)]


@pytest.mark.slow
def test_tum_munich_unzipped_is_converted_from_ranges_into_the_bytes_of_one_process(
    tmp_path: Path,
) -> None:
    """TUM Munich's 12 MB of CityGML as a plain file: ranges of at least 1 MiB over two
    workers give the X3D and report of one process, byte for byte."""
    with zipfile.ZipFile(shared_data(TUM)) as archive:
        name = next(n for n in archive.namelist() if n.endswith(".gml"))
        path = tmp_path / "tum.gml"
        path.write_bytes(archive.read(name))
    outputs = []
    for workers in (1, 2):
        out, report = tmp_path / f"w{workers}.x3d", tmp_path / f"w{workers}.json"
        run = _lodconvert(path, "-o", out, "--report", report, "--workers", workers, "-v")
        assert run.returncode == 0, run.stderr
        outputs.append((out.read_bytes(), _untimed(json.loads(report.read_text()))))
        assert "main process" not in run.stderr  # nothing read there instead
    assert outputs[1] == outputs[0]
