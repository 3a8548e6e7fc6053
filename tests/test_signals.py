"""Interrupted runs: SIGTERM and Ctrl-C (SIGINT) while a conversion is under way end it with
exit 143 / 130 and one line, and leave no output and no staged file behind. A run killed outright
(SIGKILL) leaves its staged file, which the next run to the same output removes; a live run's
staged file is never removed."""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import trimesh

from .conftest import SAMPLE


def _slow_run(source: Path, out: Path) -> list[str]:
    """A command line converting ``source`` with a slow bake (seconds a level), so that a
    signal arrives while the run is under way."""
    return [
        *(sys.executable, "-m", "lodconvert", str(source), "-o", str(out), "-v"),
        *("--resolution", "1024,512,256", "--no-mesh", "--levels", "3"),
    ]


@contextlib.contextmanager
def _baking(command: list[str]) -> Iterator[tuple[subprocess.Popen[str], list[str]]]:
    """The run of ``command`` once it bakes a level, with the lines it printed so far."""
    with subprocess.Popen(command, stderr=subprocess.PIPE, text=True) as run:
        assert run.stderr is not None
        seen: list[str] = []
        while not any("baking" in line for line in seen[-1:]):  # the state: a level is baking
            line = run.stderr.readline()
            assert line, "".join(seen)  # the run ended before baking
            seen.append(line)
        yield run, seen


def _sphere(tmp_path: Path) -> tuple[Path, Path]:
    source = tmp_path / "sphere.ply"
    trimesh.creation.icosphere(subdivisions=5).export(source)
    out = tmp_path / "out" / "sphere.glb"
    out.parent.mkdir()
    return source, out


@pytest.mark.parametrize(
    ("sig", "code", "word"),
    [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")],
)
def test_an_interrupted_run_leaves_nothing(
    tmp_path: Path, sig: signal.Signals, code: int, word: str
) -> None:
    source, out = _sphere(tmp_path)
    command = _slow_run(source, out)
    with _baking(command) as (run, seen):
        assert any(out.parent.iterdir())  # its staged output exists
        run.send_signal(sig)
        stderr = "".join(seen) + run.stderr.read()
        assert run.wait() == code, stderr
    lines = stderr.strip().splitlines()
    assert lines[-1] == f"lodconvert: {word}" and "Traceback" not in stderr, stderr
    assert list(out.parent.iterdir()) == []


def _convert_sample(out: Path) -> None:
    command = [sys.executable, "-m", "lodconvert", str(SAMPLE), "-o", str(out), "-q"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr


def test_the_staged_file_of_a_killed_run_is_removed_by_the_next_run(tmp_path: Path) -> None:
    source, out = _sphere(tmp_path)
    with _baking(_slow_run(source, out)) as (run, _):
        run.send_signal(signal.SIGKILL)  # as the out-of-memory killer ends a run
        assert run.wait() == -signal.SIGKILL
    left = list(out.parent.iterdir())
    assert len(left) == 1 and left[0].name.startswith(".sphere.glb.")
    _convert_sample(out)
    assert list(out.parent.iterdir()) == [out]


def test_the_staged_file_of_a_live_run_is_left_to_it(tmp_path: Path) -> None:
    source, out = _sphere(tmp_path)
    with _baking(_slow_run(source, out)) as (run, seen):
        staged = list(out.parent.iterdir())
        _convert_sample(out)  # the same output, while the first run still bakes
        assert sorted(out.parent.iterdir()) == sorted([out, *staged])
        run.send_signal(signal.SIGTERM)
        assert run.wait() == 143, "".join(seen)
    assert list(out.parent.iterdir()) == [out]
