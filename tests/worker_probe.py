"""A task for worker processes that tells what they imported: its module imports nothing else
(the test modules import trimesh, and trimesh scipy), so that taking it in changes nothing."""

from __future__ import annotations

import sys
from typing import Any


class Imported:
    """A task whose result is the names of the modules its worker process has imported."""

    def run(self, backend: Any = None, progress: Any = None) -> list[str]:
        return sorted(sys.modules)

    def failed(self, reason: str) -> list[str]:
        return []
