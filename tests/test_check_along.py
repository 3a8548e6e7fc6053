"""An X3D output checked while it is written (worker processes bake meanwhile): the check, a
process of its own, reads the staged file as it grows, refuses a broken output as the check of
the finished file does, and stops with a failed write or a killed main process, leaving
nothing; a killed check ends the run in one line, and a killed resource tracker is started
again."""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from lodconvert.errors import InputError
from lodconvert.io import streamed, x3d
from lodconvert.io.findings import Findings
from lodconvert.io.x3d import check
from lodconvert.validate import errors_of
from lodconvert.validate.along import Abandoned, CheckAlong, GrowingFile

from .conftest import SHARED, shared_data
from .test_cli import assert_one_line_error, run

KIT = SHARED / "data" / "citygml" / "kit_testcases_lod2_100bldg_v3.gml"


def _write_slowly(path: Path, pieces: list[bytes], done: threading.Event) -> threading.Thread:
    def write() -> None:
        with path.open("wb") as handle:
            for piece in pieces:
                handle.write(piece)
                handle.flush()
                time.sleep(0.01)
        done.set()

    thread = threading.Thread(target=write)
    thread.start()
    return thread


def test_a_growing_file_is_read_whole_as_it_is_written(tmp_path: Path) -> None:
    path = tmp_path / "out.x3d"
    path.write_bytes(b"")
    pieces = [bytes([i]) * (i * 1000 + 1) for i in range(20)]
    finished = threading.Event()
    growing = GrowingFile(path, finished, lambda: False)
    writer = _write_slowly(path, pieces, finished)
    read = bytearray()
    while data := growing.read(4096):
        read += data
    writer.join()
    growing.close()
    assert bytes(read) == b"".join(pieces)


def test_a_file_whose_writing_failed_stops_its_reader(tmp_path: Path) -> None:
    path = tmp_path / "out.x3d"
    path.write_bytes(b"<X3D")
    abandoned = threading.Event()
    growing = GrowingFile(path, threading.Event(), abandoned.is_set)
    assert growing.read(100) == b"<X3D"
    threading.Timer(0.05, abandoned.set).start()
    with pytest.raises(Abandoned):
        growing.read(100)
    growing.close()


def _checks_running() -> list[multiprocessing.process.BaseProcess]:
    return [p for p in multiprocessing.active_children() if p.name == "lodconvert-check"]


_KILLED_WRITER = """
import os, signal, sys
from pathlib import Path
from lodconvert.validate.along import CheckAlong
path = Path(sys.argv[1])
path.write_bytes(b"<X3D")
with CheckAlong(path, path) as along:
    print(along.process.pid, flush=True)
    os.kill(os.getpid(), signal.SIGKILL)
"""


def test_the_check_ends_with_a_killed_main_process(tmp_path: Path) -> None:
    """A main process killed mid-write (SIGKILL: nothing of it runs on) leaves no check
    waiting for the rest of its file."""
    psutil = pytest.importorskip("psutil")
    killed = subprocess.run(
        [sys.executable, "-c", _KILLED_WRITER, str(tmp_path / "out.x3d")],
        capture_output=True, text=True, env={**os.environ, "PYTHONPATH": os.getcwd()},
    )  # fmt: skip
    assert killed.returncode == -9, killed.stderr
    check = int(killed.stdout.split()[0])
    while _running(psutil, check):  # it must end by itself (a hang here is the failure)
        time.sleep(0.05)


def _running(psutil: Any, pid: int) -> bool:
    """Whether process ``pid`` runs (not ended, nor ended and waiting to be reaped)."""
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def test_a_check_runs_in_a_process_of_its_own(tmp_path: Path) -> None:
    path = tmp_path / "out.x3d"
    path.write_bytes(b"<X3D")
    with CheckAlong(path, path) as along:
        assert along.process.pid != os.getpid()
        assert _checks_running()
    assert not _checks_running()


def _x3d_writer(monkeypatch: pytest.MonkeyPatch, write: Any) -> None:
    """``write(real, chains, handle, info, **options)`` as the X3D writer."""
    real = x3d.write_x3d

    def writer(*args: Any, **options: Any) -> None:
        write(real, *args, **options)

    monkeypatch.setattr(
        x3d, "FORMAT", dataclasses.replace(x3d.FORMAT, write=streamed({".x3d": writer}))
    )


class _Unclosed:
    """A binary stream that leaves out the document's last end tag."""

    def __init__(self, handle: Any) -> None:
        self.handle = handle

    def write(self, data: bytes) -> int:
        return self.handle.write(data.replace(b"</X3D>", b""))


def test_a_broken_x3d_written_beside_workers_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Checked while written, as after: one line naming the output, the previous output kept,
    nothing left beside it, no check left running."""
    _x3d_writer(
        monkeypatch,
        lambda real, chains, handle, info, **o: real(chains, _Unclosed(handle), info, **o),
    )
    out = tmp_path / "kit.x3d"
    out.write_bytes(b"previous output")
    result = run(shared_data(KIT), "-o", out, "--workers", "2", "-q")
    assert_one_line_error(result, 1, str(out), "output fails validation", "XML_SYNTAX")
    assert out.read_bytes() == b"previous output"
    assert [p.name for p in tmp_path.iterdir()] == ["kit.x3d"]
    assert not _checks_running()


def test_a_write_that_fails_beside_workers_stops_the_check(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A writer that fails half way: its error, nothing written, no check left waiting for the
    rest of the file."""

    def failing(real: Any, chains: Any, handle: Any, info: Any, **options: Any) -> None:
        handle.write(b'<?xml version="1.0" encoding="UTF-8"?>\n<X3D version="4.0">')
        handle.flush()
        raise InputError("cannot be written", "kit")

    _x3d_writer(monkeypatch, failing)
    out = tmp_path / "kit.x3d"
    result = run(shared_data(KIT), "-o", out, "--workers", "2", "-q")
    assert_one_line_error(result, 1, "cannot be written")
    assert list(tmp_path.iterdir()) == []
    assert not _checks_running()


def test_a_city_is_checked_holding_one_object_at_a_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A city's objects sit in the scene frame's Transform, not in the Scene: the check frees
    each once checked there too, so that its memory does not grow with the city (100× TUM
    Munich's check grew to 572 MB while it kept them)."""
    out = tmp_path / "kit.x3d"
    result = run(shared_data(KIT), "-o", out, "--workers", "1", "-q")
    assert result.returncode == 0, result.stderr
    held: list[int] = []  # elements of the document's tree, every 100 events
    iterparse = check.etree.iterparse

    def counted(*args: Any, **options: Any) -> Any:
        root = None
        for i, (event, element) in enumerate(iterparse(*args, **options)):
            root = element if root is None else root
            if i % 100 == 0:
                held.append(sum(1 for _ in root.iter()))
            yield event, element

    monkeypatch.setattr(check.etree, "iterparse", counted)
    findings = Findings(out)
    check.check_x3d(out, findings, None)
    assert errors_of(findings.items) == []
    document = check.etree.parse(out)
    objects = document.findall("Scene/Transform/Transform")
    assert len(objects) > 50 and len(held) > 20
    # what lxml parsed ahead of the events it gave (a read's worth) and the skeleton; keeping
    # the objects, it held 2,220 of the file's 3,337 elements by the end
    assert max(held) < sum(1 for _ in document.iter()) / 4


_KILLS_ITS_CHECK = """
import dataclasses, multiprocessing, os, signal, sys, time
from pathlib import Path
from lodconvert.cli import main
from lodconvert.io import streamed, x3d

out = Path(sys.argv[sys.argv.index("-o") + 1])


def read_to_the_end(check):
    # whether the check has read the staged output as far as it is written
    for fd in Path(f"/proc/{check.pid}/fd").iterdir():
        target = Path(os.readlink(fd))
        if target.parent == out.parent and target.name.startswith(f".{out.name}."):
            info = Path(f"/proc/{check.pid}/fdinfo/{fd.name}").read_text()
            return int(info.split()[1]) == target.stat().st_size
    return False


class KillsTheCheck:
    # the staged output: once its first piece is written, the check is killed as it waits
    # for more (its writing goes on)
    def __init__(self, handle):
        self.handle, self.killed = handle, False

    def write(self, data):
        written = self.handle.write(data)
        if not self.killed:
            self.handle.flush()
            children = multiprocessing.active_children()
            (check,) = [p for p in children if p.name == "lodconvert-check"]
            while not read_to_the_end(check):
                time.sleep(0.01)
            os.kill(check.pid, signal.SIGKILL)
            check.join()
            self.killed = True
        return written


def write(chains, handle, info, **options):
    x3d.write_x3d(chains, KillsTheCheck(handle), info, **options)


x3d.FORMAT = dataclasses.replace(x3d.FORMAT, write=streamed({".x3d": write}))
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
def test_a_check_killed_while_the_output_is_written_ends_the_run_in_one_line(
    tmp_path: Path,
) -> None:
    """The check's process killed (SIGKILL, as the out-of-memory killer ends one) while it waits
    for more of the file: the run ends with one line naming the output and nothing written (it
    waited for the dead check forever)."""
    out = tmp_path / "out" / "kit.x3d"
    out.parent.mkdir()
    killed = subprocess.run(
        [sys.executable, "-c", _KILLS_ITS_CHECK, str(shared_data(KIT)), "-o", str(out),
         "--workers", "2", "-q"],
        capture_output=True, text=True, env={**os.environ, "PYTHONPATH": os.getcwd()},
        timeout=300,  # a safety net: the run waited for its dead check forever
    )  # fmt: skip
    assert_one_line_error(killed, 1, str(out), "signal SIGKILL")
    assert list(out.parent.iterdir()) == []


_KILLS_THE_TRACKER = """
import os, signal, sys, time
from multiprocessing import resource_tracker
from pathlib import Path
from lodconvert.cli import main
from lodconvert.validate.along import CheckAlong

start = CheckAlong.__enter__


def enter(self):
    # multiprocessing's resource tracker killed just before the check's process starts
    tracker = resource_tracker._resource_tracker._pid
    os.kill(tracker, signal.SIGKILL)
    while Path(f"/proc/{tracker}/stat").read_text().split()[2] != "Z":
        time.sleep(0.01)
    return start(self)


CheckAlong.__enter__ = enter
sys.exit(main(sys.argv[1:]))
"""


def test_a_killed_resource_tracker_is_started_again_without_a_word(tmp_path: Path) -> None:
    """The process that starting worker processes starts, killed: the next process start (the
    check's) starts another, and the run goes on; multiprocessing's warning that resources
    might leak is not shown, as lodconvert gives it none to look after."""
    out = tmp_path / "kit.x3d"
    done = subprocess.run(
        [sys.executable, "-c", _KILLS_THE_TRACKER, str(shared_data(KIT)), "-o", str(out),
         "--workers", "2", "-q"],
        capture_output=True, text=True, env={**os.environ, "PYTHONPATH": os.getcwd()},
        timeout=300,
    )  # fmt: skip
    lines = done.stderr.splitlines()
    assert done.returncode == 0 and len(lines) == 1, done.stderr
    assert lines[0].startswith(f"wrote {out} (100 object(s)")
    assert [p.name for p in tmp_path.iterdir()] == ["kit.x3d"]
