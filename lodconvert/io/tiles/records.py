"""What a tileset's main process records of the tiles it writes, to resume an interrupted run
(docs/outputs.md): beside each tile's file, its task's key (:meth:`~.task.TileTask.key`), the
file's SHA-256, frame and box, appended as one JSON line to :data:`RECORDS` in the staged
folder once the file is whole. A resumed run takes a tile's last record instead of running its
task where the key is the task's and the file has the recorded hash, both written by a run of
that folder (its journal); a file a killed run left half-written has no record yet, or another
hash, and is made again, and a line it left half-written is no record.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable

import numpy as np

from ...sinks import RESUME, DirectorySink
from .task import TILES, TileResult

RECORDS = f"{RESUME}/tiles.jsonl"
"""Where the records are appended, inside the staged folder."""
FILE_BYTES = 1 << 40
"""Largest tile file or records file read back (both were written by a run of the folder)."""


class TileRecords:
    """The tiles written through ``sink`` (a staged tileset folder) and their records; in a
    resumed run, the records an interrupted run left there (the last of each tile's)."""

    def __init__(self, sink: DirectorySink) -> None:
        self.sink = sink
        data = sink.read(RECORDS, FILE_BYTES) or b""  # none unless a run of the folder wrote it
        self.found: dict[str, bytes] = {}
        for line in data.splitlines():
            name = _name(line)
            if name is not None:
                self.found[name] = line
        self.torn = bool(data) and not data.endswith(b"\n")
        """Whether the records end in a line a killed run left half-written."""

    def kept(self, name: str, key: str | Callable[[], str]) -> TileResult | None:
        """What an interrupted run recorded of the tile ``name``, where its file is whole and
        was made of the same (its task's ``key``, or what finds it, called only where a record
        is); ``None`` otherwise."""
        record = self.found.get(name)
        if record is None:
            return None
        data = self.sink.read(f"{TILES}/{name}", FILE_BYTES)
        if data is None:
            return None
        return _kept(record, data, key() if callable(key) else key)

    def written(self, name: str, result: TileResult) -> TileResult:
        """Write the tile ``name``'s file (``result``'s GLB), then its record; a failed write
        is one line naming the file."""
        assert result.data is not None and result.key is not None
        with self.sink.file(f"{TILES}/{name}") as handle:
            handle.write(result.data)
        frame, box = _placed(result)
        sha256 = hashlib.sha256(result.data).hexdigest()
        text = {"name": name, "key": result.key, "sha256": sha256}
        text |= {"frame": frame.tolist(), "box": box.tolist()}
        line = b"\n" if self.torn else b""
        with self.sink.appended(RECORDS) as handle:
            handle.write(line + json.dumps(text).encode() + b"\n")
        self.torn = False
        return TileResult(frame, box)


def _name(line: bytes) -> str | None:
    """The tile a record line names; ``None`` for a line that is no record."""
    try:
        name = json.loads(line)["name"]
    except (ValueError, KeyError, TypeError):
        return None
    return name if isinstance(name, str) else None


def _placed(result: TileResult) -> tuple[np.ndarray, np.ndarray]:
    assert result.frame is not None and result.box is not None
    return result.frame, result.box


def _kept(record: bytes, data: bytes, key: str) -> TileResult | None:
    """The result ``record`` holds for the tile file of bytes ``data`` when its key is ``key``
    and the file is whole (its recorded hash); ``None`` otherwise."""
    try:
        found = json.loads(record)
        if found["key"] != key or hashlib.sha256(data).hexdigest() != found["sha256"]:
            return None
        frame, box = np.array(found["frame"], dtype=np.float64), np.array(found["box"])
    except (ValueError, KeyError, TypeError):
        return None
    if frame.shape != (4, 4) or box.shape != (2, 3):
        return None
    return TileResult(frame, box.astype(np.float64), reused=True)
