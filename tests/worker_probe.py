"""A task for worker processes that tells what they imported: its module imports nothing else
(the test modules import trimesh, and trimesh scipy), so that taking it in changes nothing."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any


class Imported:
    """A task whose result is the names of the modules its worker process has imported."""

    def run(self, backend: Any = None, progress: Any = None) -> list[str]:
        return sorted(sys.modules)

    def failed(self, reason: str) -> list[str]:
        return []


def imported_by_workers(monkeypatch: Any, source: Path, output: Path) -> list[str]:
    """The modules a worker of a 2-worker conversion of ``source`` into ``output`` had imported
    when the run ended (what this function imports, only the calling process imports)."""
    from lodconvert import pipeline
    from lodconvert.pipeline import RunOptions, convert
    from lodconvert.tasks import PoolExecutor

    imported: list[str] = []

    class Probed(PoolExecutor):
        def close(self) -> None:
            if self._workers:
                imported.extend(next(self.results([Imported()])))
            super().close()

    monkeypatch.setattr(pipeline, "PoolExecutor", Probed)
    convert(source, output, RunOptions(workers=2))
    return imported
