"""What the command line prints while it works: bars on a terminal, plain lines elsewhere,
and how -v, -q and -qq change that."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

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
