"""The per-object records of a run's report, kept compact, and the report written as JSON.

A city of tens of thousands of objects gives as many records; as Python dictionaries each
would hold a few kilobytes for the whole run. :class:`Records` keeps each as its compact JSON
text and decodes it when read, and :func:`report_text` writes a report holding one without
building all its records at once.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator, Sequence
from typing import Any, overload


class Records(Sequence[dict[str, Any]]):
    """JSON-able records in the order added, each stored as compact JSON text; reading one
    gives a fresh dictionary."""

    def __init__(self, records: Iterable[dict[str, Any]] = ()) -> None:
        self._texts: list[bytes] = []
        self.extend(records)

    def append(self, record: dict[str, Any]) -> None:
        """Add ``record`` (later changes to it are not seen)."""
        self._texts.append(json.dumps(record, separators=(",", ":")).encode())

    def extend(self, records: Iterable[dict[str, Any]]) -> None:
        """Add each of ``records``."""
        for record in records:
            self.append(record)

    def __len__(self) -> int:
        return len(self._texts)

    @overload
    def __getitem__(self, index: int) -> dict[str, Any]: ...

    @overload
    def __getitem__(self, index: slice) -> list[dict[str, Any]]: ...

    def __getitem__(self, index: int | slice) -> dict[str, Any] | list[dict[str, Any]]:
        if isinstance(index, slice):
            return [json.loads(text) for text in self._texts[index]]
        return json.loads(self._texts[index])

    def __iter__(self) -> Iterator[dict[str, Any]]:
        for text in self._texts:
            yield json.loads(text)


def report_text(report: dict[str, Any]) -> Iterator[str]:
    """``report`` as JSON text indented by two spaces (as ``json.dumps(report, indent=2)``
    writes it, and a newline at the end), in pieces: a :class:`Records` value one record at a
    time."""
    yield "{"
    for n, (key, value) in enumerate(report.items()):
        yield ("," if n else "") + f"\n  {json.dumps(key)}: "
        if isinstance(value, Records):
            yield "[" if value else "[]"
            for i, record in enumerate(value):
                yield ("," if i else "") + "\n    " + _indented(record, 4)
            yield "\n  ]" if value else ""
        else:
            yield _indented(value, 2)
    yield "\n}\n"


def _indented(value: Any, depth: int) -> str:
    """``value`` as indented JSON whose lines after the first start ``depth`` spaces in."""
    return json.dumps(value, indent=2).replace("\n", "\n" + " " * depth)
