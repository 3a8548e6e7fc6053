"""What the command line prints while it works: bars on a terminal, plain lines elsewhere,
and how -v, -q and -qq change that."""

from __future__ import annotations

import io
import json
import re
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from lodconvert import tasks
from lodconvert.cli import console
from lodconvert.cli.console import Console

from .conftest import SAMPLE
from .test_cli import run

FAST = ("--resolution", "24,12,6")


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_a_bar_with_count_rate_and_time_left(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(console, "BAR_SECONDS", 0.0)
    stream = Terminal()
    out = Console(stream=stream)
    for done in range(1, 51):
        out.step("converting", done, 100)
    out.summary("wrote x.glb")
    text = stream.getvalue()
    assert "converting" in text and "50/100" in text
    assert "obj/s" in text and "<" in text  # rate, and tqdm's elapsed<remaining
    assert text.rstrip().endswith("wrote x.glb")


def test_a_log_gets_plain_lines_per_stage(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(console, "LINE_SECONDS", 0.0)
    stream = io.StringIO()
    out = Console(stream=stream)
    for done in range(1, 4):
        out.step("converting", done, 3)
    out.step("checking", 1, 1)
    out.summary("done")
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("converting: 1/3 (")
    assert any(line.startswith("converting: 3/3") for line in lines)
    assert any(line.endswith("/s)") for line in lines) and "\r" not in stream.getvalue()
    assert lines[-1] == "done"


@pytest.mark.parametrize(
    ("flags", "summary", "object_lines"),
    [
        ((), True, True),
        (("-q",), True, False),
        (("-qq",), False, False),
        (("--silent",), False, False),
    ],
)
def test_quiet_levels(
    tmp_path: Path, flags: tuple[str, ...], summary: bool, object_lines: bool
) -> None:
    result = run(SAMPLE, "-o", tmp_path / "k.glb", *FAST, *flags)
    assert result.returncode == 0, result.stderr
    lines = result.stderr.splitlines()
    assert any(line.startswith("wrote ") for line in lines) == summary
    assert any(line.startswith("torus_knot: LOD4") for line in lines) == object_lines
    if not summary:
        assert result.stderr == ""


def test_errors_show_even_when_silent(tmp_path: Path) -> None:
    result = run(tmp_path / "missing.ply", "-o", tmp_path / "k.glb", "-qq")
    assert result.returncode == 1 and "missing.ply" in result.stderr


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> Callable[[float], None]:
    """Set the console's clock to a given time (seconds)."""
    now = [0.0]
    monkeypatch.setattr(console.time, "perf_counter", lambda: now[0])

    def at(seconds: float) -> None:
        now[0] = seconds

    return at


def test_a_stage_line_says_the_time_its_count_was_reached(clock: Callable[[float], None]) -> None:
    """The stage starts at 0 s, its two objects are done at 1 s and 2 s; the line printed when
    the next stage starts at 9 s says 2.0 s, not 9.0."""
    stream = io.StringIO()
    out = Console(stream=stream)
    for at, done in ((0.0, 0), (1.0, 1), (2.0, 2)):
        clock(at)
        out.step("converting", done, 2)
    clock(9.0)
    out.summary("done")
    assert stream.getvalue().splitlines() == ["converting: 2/2 (2.0 s, 1/s)", "done"]


def test_a_stage_whose_last_line_said_its_count_prints_it_once(
    clock: Callable[[float], None],
) -> None:
    """The last objects, done 6 s in, get the periodic line; the stage's end adds none."""
    stream = io.StringIO()
    out = Console(stream=stream)
    for at, done in ((0.0, 0), (1.0, 3), (6.0, 6)):
        clock(at)
        out.step("converting", done, 6)
    clock(8.0)
    out.step("checking", 0, 1)
    clock(8.5)
    out.step("checking", 1, 1)
    out.summary("done")
    lines = stream.getvalue().splitlines()
    assert lines == ["converting: 6/6 (6.0 s, 1/s)", "checking: 1/1 (0.5 s)", "done"]


def test_the_converting_line_counts_the_time_spent_baking(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A run whose one object takes at least 0.5 s to bake says so on its progress line, as
    its report's execute time does (it said 0.0 s: the stage started as its object ended)."""
    baked = tasks.BakeTask.run

    def slow(self: tasks.BakeTask, *args: object, **kwargs: object) -> tasks.BakeResult:
        time.sleep(0.5)
        return baked(self, *args, **kwargs)

    monkeypatch.setattr(tasks.BakeTask, "run", slow)
    report = tmp_path / "report.json"
    result = run(SAMPLE, "-o", tmp_path / "k.glb", *FAST, "--workers", "1", "--report", report)
    assert result.returncode == 0, result.stderr
    (line,) = [line for line in result.stderr.splitlines() if line.startswith("converting:")]
    seconds = float(re.fullmatch(r"converting: 1/1 \((\d+\.\d) s\)", line).group(1))
    execute = json.loads(report.read_text())["timings"]["execute"]
    assert seconds >= max(0.5, round(execute, 1)), (line, execute)
