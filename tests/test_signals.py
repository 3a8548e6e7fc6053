"""Interrupted runs: SIGTERM and Ctrl-C (SIGINT) while a conversion is under way end it with
exit 143 / 130 and one line, and leave no output and no staged file behind."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest
import trimesh


@pytest.mark.parametrize(
    ("sig", "code", "word"),
    [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")],
)
def test_an_interrupted_run_leaves_nothing(
    tmp_path: Path, sig: signal.Signals, code: int, word: str
) -> None:
    source = tmp_path / "sphere.ply"
    trimesh.creation.icosphere(subdivisions=5).export(source)
    out = tmp_path / "out" / "sphere.glb"
    out.parent.mkdir()
    command = [sys.executable, "-m", "lodconvert", str(source), "-o", str(out), "-v"]
    # a slow bake (seconds a level), so that the signal arrives while the run is under way
    command += ["--resolution", "1024,512,256", "--no-mesh", "--levels", "3"]
    with subprocess.Popen(command, stderr=subprocess.PIPE, text=True) as run:
        assert run.stderr is not None
        seen = []
        while not any("baking" in line for line in seen[-1:]):  # the state: a level is baking
            line = run.stderr.readline()
            assert line, "".join(seen)  # the run ended before baking
            seen.append(line)
        assert any(out.parent.iterdir())  # its staged output exists
        run.send_signal(sig)
        stderr = "".join(seen) + run.stderr.read()
        assert run.wait() == code, stderr
    lines = stderr.strip().splitlines()
    assert lines[-1] == f"lodconvert: {word}" and "Traceback" not in stderr, stderr
    assert list(out.parent.iterdir()) == []
