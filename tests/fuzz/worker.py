"""Child processes that contain what a hostile input may do: a crash, a hang or a blow-up of
memory ends the child, not the test run.

:class:`Worker` keeps one child that reads case after case (a suffix and the file's bytes) and
answers a verdict for each; :func:`run_cli` runs the command line once in a child and measures
its peak memory. Both children run under an address-space limit (``RLIMIT_AS``) and with one
BLAS thread.
"""

from __future__ import annotations

import json
import os
import pickle
import resource
import select
import struct
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
MEMORY_BUDGET = 2 << 30
"""Address space a child may take (``RLIMIT_AS``)."""
CASE_SECONDS = 60.0
"""A case still running after this long is a hang: far beyond the milliseconds a small input
takes, so that only a real hang (not a loaded machine) trips it."""
_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _limit_memory(budget: int) -> None:
    """Cap this process's address space at ``budget`` bytes."""
    resource.setrlimit(resource.RLIMIT_AS, (budget, budget))


def child_env() -> dict[str, str]:
    """The environment of a child: this one, one BLAS thread, the project on the path."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, **_ENV, "PYTHONPATH": path}


@dataclass
class Verdict:
    """What one case did: ``ok`` (read, or refused with lodconvert's own error), else
    ``problem`` (``exception``, ``hang``, ``crash``, ``memory``) and ``detail``."""

    ok: bool
    problem: str = ""
    detail: str = ""


class Worker:
    """A child process that reads fuzz cases with every registered reader, one at a time."""

    def __init__(self, budget: int = MEMORY_BUDGET, case_seconds: float = CASE_SECONDS) -> None:
        self.budget, self.case_seconds = budget, case_seconds
        self.process: subprocess.Popen[bytes] | None = None

    def _start(self) -> subprocess.Popen[bytes]:
        if self.process is None or self.process.poll() is not None:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "tests.fuzz.worker", str(self.budget)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                cwd=ROOT,
                env=child_env(),
            )
        return self.process

    def close(self) -> None:
        """End the child."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.process = None

    def read(self, suffix: str, data: bytes) -> Verdict:
        """Have the child read ``data`` as a file of ``suffix`` (a new child after a case that
        ended the last one)."""
        process = self._start()
        assert process.stdin is not None and process.stdout is not None
        case = pickle.dumps((suffix, data))
        try:
            process.stdin.write(struct.pack("<Q", len(case)) + case)
            process.stdin.flush()
        except BrokenPipeError:
            return self._ended("crash")
        ready, _, _ = select.select([process.stdout], [], [], self.case_seconds)
        if not ready:
            self.close()
            return Verdict(False, "hang", f"no answer within {self.case_seconds:.0f} s")
        line = process.stdout.readline()
        if not line:
            return self._ended("crash")
        answer = json.loads(line)
        return Verdict(answer["ok"], answer.get("problem", ""), answer.get("detail", ""))

    def _ended(self, problem: str) -> Verdict:
        assert self.process is not None
        code = self.process.wait()
        self.process = None
        return Verdict(False, problem, f"the child ended with exit status {code}")


def _contract(scene: Any) -> None:
    """What every reader promises of the nodes it yields (after its boundary checks)."""
    import numpy as np

    from lodconvert.io.geometry_checks import MAX_MAGNITUDE

    for node in scene.with_geometry():
        for part in node.geometry.parts:
            v, f = part.vertices, part.faces
            assert v.ndim == 2 and v.shape[1] == 3 and np.isfinite(v).all(), "bad vertices"
            assert np.abs(v).max(initial=0) <= MAX_MAGNITUDE, "coordinates too large"
            assert f.ndim == 2 and f.shape[1] == 3 and len(f), "bad faces"
            assert f.min() >= 0 and f.max() < len(v), "face index out of range"
        node.geometry.bounds  # noqa: B018 (derived tables must build)


def _serve(budget: int) -> None:
    """The child's loop: read a case from stdin, answer a JSON verdict line on stdout."""
    _limit_memory(budget)
    from lodconvert.errors import LodConvertError, UsageError
    from lodconvert.io import read_scene
    from lodconvert.limits import MIB, Limits

    limits = Limits(decompressed_bytes=256 * MIB)
    source, sink = sys.stdin.buffer, sys.stdout
    with tempfile.TemporaryDirectory() as folder:
        while header := source.read(8):
            suffix, data = pickle.loads(source.read(struct.unpack("<Q", header)[0]))
            path = Path(folder) / f"case{suffix}"
            path.write_bytes(data)
            try:
                _contract(read_scene(path, limits=limits))
                answer: dict[str, Any] = {"ok": True}
            except (LodConvertError, UsageError):
                answer = {"ok": True}
            except MemoryError:
                answer = {"ok": False, "problem": "memory", "detail": traceback.format_exc()}
            except Exception:
                answer = {"ok": False, "problem": "exception", "detail": traceback.format_exc()}
            sink.write(json.dumps(answer) + "\n")
            sink.flush()


@dataclass
class CliRun:
    """A command-line run in a child: exit code, stderr, peak RSS (bytes) and wall time."""

    code: int
    stderr: str
    peak_bytes: int
    seconds: float


PEAK_FILE = "LODCONVERT_PEAK_FILE"
"""Environment variable naming the file a ``--cli`` child writes its peak memory to."""


def run_cli(*args: str | Path, budget: int = MEMORY_BUDGET, timeout: float = 600) -> CliRun:
    """Run ``lodconvert ARGS`` in a child under ``budget`` bytes of address space; its peak
    RSS is that child's alone (``wait4``). A run past ``timeout`` seconds is killed."""
    start = time.perf_counter()
    with tempfile.TemporaryFile() as err, tempfile.NamedTemporaryFile("r") as peak:
        process = subprocess.Popen(
            [sys.executable, "-m", "tests.fuzz.worker", str(budget), "--cli", *map(str, args)],
            stdout=subprocess.DEVNULL,
            stderr=err,
            cwd=ROOT,
            env={**child_env(), PEAK_FILE: peak.name},
        )
        timer = threading.Timer(timeout, process.kill)
        timer.start()
        _, status, usage = os.wait4(process.pid, 0)
        timer.cancel()
        process.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        text = err.read().decode()
        # The child's own high-water mark; wait4's ru_maxrss also counts the parent's memory
        # copied into the child before it exec'd python (large when pytest has grown).
        reported = peak.read().strip()
    peak_bytes = int(reported) if reported else usage.ru_maxrss * 1024
    return CliRun(process.returncode, text, peak_bytes, time.perf_counter() - start)


def _own_peak_bytes() -> int:
    """This process's peak resident memory since it exec'd (``VmHWM``), in bytes."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    return 0


if __name__ == "__main__":
    if sys.argv[2:3] == ["--cli"]:
        _limit_memory(int(sys.argv[1]))
        from lodconvert.cli import main

        try:
            code = main(sys.argv[3:])
        finally:
            if os.environ.get(PEAK_FILE):
                Path(os.environ[PEAK_FILE]).write_text(str(_own_peak_bytes()))
        sys.exit(code)
    _serve(int(sys.argv[1]))
