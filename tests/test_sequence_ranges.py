"""CityJSONSeq files read by workers from byte ranges (:mod:`lodconvert.io.cityjson.ranges`):
the nodes, skipped lines and their numbers of one process, whatever the ranges' size, with
the main process reading the first feature alone; a worker that cannot open the file."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import pytest

from lodconvert.io import read_scene, spread
from lodconvert.io.cityjson import ranges
from lodconvert.io.cityjson.parallel import LinesResult, SequenceReading
from lodconvert.io.geometry_checks import tally_of
from lodconvert.io.reopened import NewlinesTask
from lodconvert.limits import Limits

from .test_cityjson import _features, multi_lod
from .test_parallel_reading import _parked_facts
from .test_range_reading import _InProcess


def _awkward(folder: Path) -> Path:
    """Ten buildings a line after the header, with blank lines, a line of spaces, carriage
    returns, leading white space, a line that is no feature and one past the line limit of
    :func:`_limits`."""
    document = json.loads(multi_lod().read_text())
    header = {key: document[key] for key in ("type", "version", "transform")}
    features = [json.dumps(feature).encode() for feature in _features(document)]
    lines = [json.dumps({**header, "CityObjects": {}, "vertices": []}).encode(), b""]
    lines += [features[0], b"   ", b"\t" + features[1] + b"\r", features[2], b"", b""]
    lines += [b'{"type": "CityJSONFeature", "CityObjects": 3}', features[3]]
    lines += [b'{"type": "CityJSONFeature", "x": "' + b"x" * 30_000 + b'"}']
    lines += [b"  " + f for f in features[4:]]
    path = folder / "awkward.city.jsonl"
    path.write_bytes(b"\n".join(lines))  # no line break after the last
    return path


def _limits() -> Limits:
    return Limits(sequence_line_bytes=20_000)


def _counted_here(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count the lines of each run the main process reads."""
    parsed: list[int] = []
    original = SequenceReading.read_here

    def counted(self: SequenceReading, run: Any) -> Any:
        parsed.append(len(run))
        return original(self, run)

    monkeypatch.setattr(SequenceReading, "read_here", counted)
    return parsed


@pytest.mark.parametrize(("size", "block"), [(1, 7), (61, 1 << 22), (997, 64), (1 << 20, 5)])
def test_ranges_of_any_size_read_the_sequence_one_process_reads(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, size: int, block: int
) -> None:
    """Ranges of ``size`` bytes and line breaks counted in blocks of ``block``: the nodes of
    one process in its order, the same lines skipped with the same numbers, and the main
    process reads the first feature alone."""
    path = _awkward(tmp_path)
    one = read_scene(path, limits=_limits())
    monkeypatch.setattr(spread.Sizer, "wanted", lambda self: size)
    monkeypatch.setattr(ranges, "COUNT_BYTES", block)
    parsed = _counted_here(monkeypatch)
    executor = _InProcess()
    two, told = _by_limits(executor, path)
    assert two == _parked_facts(one) and len(two) == 10
    assert told == []
    assert parsed == [1]  # the first feature
    skipped = [entry["id"] for entry in executor.skipped]
    assert skipped == [entry["id"] for entry in tally_of(one).skipped] == ["line 9", "line 11"]
    counts = [task for task in executor.tasks if isinstance(task, NewlinesTask)]
    assert len(counts) == -(-path.stat().st_size // block)
    read = [r for r in executor.results_kept if isinstance(r, LinesResult)]
    assert sum(len(result.nodes) for result in read) == 9


def _by_limits(executor: _InProcess, path: Path) -> tuple[list[Any], list[str]]:
    """The facts of ``path`` read through ``executor`` under :func:`_limits` (its skipped lines
    kept on ``executor.skipped``), and what ``-v`` heard."""
    from lodconvert.bake import get_backend
    from lodconvert.context import RunContext

    told: list[str] = []
    context = RunContext(executor, get_backend("numpy"), progress=told.append)  # type: ignore[arg-type]
    scene = read_scene(path, context=context, limits=_limits())
    facts = _parked_facts(scene)
    executor.skipped = tally_of(scene).skipped  # type: ignore[attr-defined]
    return facts, told


def _elsewhere(kind: type, first: int = 0) -> Any:
    """Point tasks of ``kind`` at a file that is not there, from the ``first`` of them on."""
    seen = [0]

    def change(number: int, task: Any) -> Any:
        if not isinstance(task, kind):
            return task
        seen[0] += 1
        if seen[0] <= first:
            return task
        return dataclasses.replace(task, path=task.path + ".elsewhere")

    return change


def test_workers_that_cannot_count_the_file_are_sent_its_lines(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Workers on machines without the file: they cannot count its lines, so its lines are
    sent as bytes, and ``-v`` says so once."""
    path = _awkward(tmp_path)
    one = _parked_facts(read_scene(path, limits=_limits()))
    monkeypatch.setattr(spread.Sizer, "wanted", lambda self: 300)
    executor = _InProcess(_elsewhere(NewlinesTask))
    two, told = _by_limits(executor, path)
    assert two == one
    assert len(told) == 1 and "a worker cannot open it" in told[0]
    assert told[0].endswith("its lines are sent as bytes")
    assert not any(isinstance(task, ranges.RangeLinesTask) for task in executor.tasks)


def test_a_range_a_worker_cannot_open_is_read_here(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A worker that cannot open the file for a later range: the main process reads that
    range itself (``-v`` says so once), and the nodes are those of one process."""
    path = _awkward(tmp_path)
    one = _parked_facts(read_scene(path, limits=_limits()))
    monkeypatch.setattr(spread.Sizer, "wanted", lambda self: 300)
    parsed = _counted_here(monkeypatch)
    executor = _InProcess(_elsewhere(ranges.RangeLinesTask, first=2))
    two, told = _by_limits(executor, path)
    assert two == one
    assert len(told) == 1 and told[0].endswith("the main process reads its range")
    assert len(parsed) > 1


def test_a_link_in_place_of_the_file_is_not_followed(tmp_path: Path) -> None:
    """A worker opens the input's real path without following a link there: a link put in
    its place after the main process read it is refused."""
    path = _awkward(tmp_path)
    task = NewlinesTask(str(tmp_path / "link.jsonl"), (0, 0), b"", 0, 10)
    (tmp_path / "link.jsonl").symlink_to(path)
    assert task.run().unreachable is not None


def test_a_sequence_with_templates_is_read_here_and_said_once(tmp_path: Path) -> None:
    """A file with geometry templates is read in the main process (instances share one mesh
    per template): ``-v`` says so once, no range is sent, and the nodes are those of one
    process."""
    document = json.loads(multi_lod().read_text())
    header = {key: document[key] for key in ("type", "version", "transform")}
    cube = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    templates = {
        "templates": [{"type": "Solid", "lod": "2", "boundaries": [[[q] for q in quads]]}],
        "vertices-templates": cube,
    }
    lines = [json.dumps({**header, "geometry-templates": templates, "CityObjects": {}})]
    lines += [json.dumps(feature) for feature in _features(document)]
    path = tmp_path / "templates.city.jsonl"
    path.write_text("\n".join(lines) + "\n")
    one = _parked_facts(read_scene(path, limits=_limits()))
    executor = _InProcess()
    two, told = _by_limits(executor, path)
    assert two == one and len(one) == 10
    assert told == [f"{path}: geometry templates are read in the main process"]
    assert executor.tasks == []
