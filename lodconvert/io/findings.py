"""The :class:`Finding` of a check and the collector the formats' checks report into."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

ERROR, WARNING = "error", "warning"


@dataclass(frozen=True)
class Finding:
    """One problem found in a file: an ``error`` (the file is broken or breaks lodconvert's
    rules) or a ``warning`` (legal, but not what lodconvert writes). ``str()`` is one line."""

    path: str
    severity: str
    code: str
    message: str

    def __str__(self) -> str:
        return f"{self.path}: {self.severity} {self.code}: {self.message}"


class Findings:
    """The findings of one file, in the order they were found."""

    def __init__(self, path: Path) -> None:
        self.path = str(path)
        self.items: list[Finding] = []

    def error(self, code: str, message: str) -> None:
        """Record an error."""
        self.items.append(Finding(self.path, ERROR, code, message))

    def warning(self, code: str, message: str) -> None:
        """Record a warning."""
        self.items.append(Finding(self.path, WARNING, code, message))
