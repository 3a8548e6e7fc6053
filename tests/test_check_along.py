"""An X3D output checked while it is written (worker processes bake meanwhile): the check reads
the staged file as it grows, refuses a broken output as the check of the finished file does,
and stops with a failed write, leaving nothing."""

from __future__ import annotations

import dataclasses
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from lodconvert.errors import InputError
from lodconvert.io import streamed, x3d
from lodconvert.validate.along import Abandoned, GrowingFile

from .conftest import SHARED, shared_data
from .test_cli import assert_one_line_error, run

KIT = SHARED / "data" / "citygml" / "kit_testcases_lod2_100bldg_v3.gml"


def _write_slowly(path: Path, pieces: list[bytes], done: GrowingFile) -> threading.Thread:
    def write() -> None:
        with path.open("wb") as handle:
            for piece in pieces:
                handle.write(piece)
                handle.flush()
                time.sleep(0.01)
        done.finished()

    thread = threading.Thread(target=write)
    thread.start()
    return thread


def test_a_growing_file_is_read_whole_as_it_is_written(tmp_path: Path) -> None:
    path = tmp_path / "out.x3d"
    path.write_bytes(b"")
    pieces = [bytes([i]) * (i * 1000 + 1) for i in range(20)]
    growing = GrowingFile(path)
    writer = _write_slowly(path, pieces, growing)
    read = bytearray()
    while data := growing.read(4096):
        read += data
    writer.join()
    growing.close()
    assert bytes(read) == b"".join(pieces)


def test_a_file_whose_writing_failed_stops_its_reader(tmp_path: Path) -> None:
    path = tmp_path / "out.x3d"
    path.write_bytes(b"<X3D")
    growing = GrowingFile(path)
    assert growing.read(100) == b"<X3D"
    threading.Timer(0.05, growing.abandon).start()
    with pytest.raises(Abandoned):
        growing.read(100)
    growing.close()


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
    assert not [t for t in threading.enumerate() if t.name == "lodconvert-check"]


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
    assert not [t for t in threading.enumerate() if t.name == "lodconvert-check"]
