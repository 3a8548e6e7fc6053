"""The :class:`Finding` of a check and the collector the formats' checks report into."""

from __future__ import annotations

from collections.abc import Iterable
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


def errors_of(findings: Iterable[Finding]) -> list[Finding]:
    """The findings of severity error."""
    return [f for f in findings if f.severity == ERROR]


def failure_of(findings: Iterable[Finding]) -> str | None:
    """The line a conversion fails with for the first error of ``findings`` (and how many
    more), if any."""
    errors = errors_of(findings)
    if not errors:
        return None
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"output fails validation: {errors[0].code}: {errors[0].message}{more}"
