"""What the readers that read a city in worker processes share: how many bytes of input a task
holds (sized for the executor's ``task_seconds`` of reading, as measured so far) and how what a
worker counted is added to the file's tally. The tasks themselves hold bytes only (no path, so
that a worker needs no shared file system): :mod:`.citygml.parallel`,
:mod:`.cityjson.parallel`."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

from .geometry_checks import InputTally

TASK_SECONDS = 0.1
"""CPU seconds of reading a task is sized for unless the executor says otherwise (CPU, not
wall: a busy machine does not make tasks smaller)."""
MIN_BYTES, MAX_BYTES = 1 << 20, 1 << 24
"""Bytes of input a task holds at least (but for the last) and at most: a task reads its
objects together (a CityGML run of one member reads 2.4× slower than one of 64)."""

Results = Callable[[Iterable[Any]], Iterator[Any]]
"""An executor's ``results``: tasks in, their results out, in order."""


def quiet(_: str) -> None:
    """Discard a message."""


class Sizer:
    """The bytes (or other units: objects) a task should hold for ``seconds`` of reading, from
    the seconds one took to read so far, between ``least`` and ``most``."""

    def __init__(self, least: int = MIN_BYTES, most: int = MAX_BYTES) -> None:
        self.least, self.most = least, most
        self.seconds = TASK_SECONDS
        self.seconds_per_byte = 0.0

    @property
    def timed(self) -> bool:
        return self.seconds_per_byte > 0

    def took(self, seconds: float, size: int) -> None:
        """Reading ``size`` bytes took ``seconds``."""
        self.seconds_per_byte = seconds / size

    def wanted(self) -> int:
        """The bytes a task should hold (1 until reading has been timed)."""
        if not self.seconds_per_byte:
            return 1
        return int(min(self.most, max(self.least, self.seconds / self.seconds_per_byte)))


def add_tally(tally: InputTally, part: InputTally) -> None:
    """Add what a worker's reading counted (``part``) to the file's ``tally``; the file's
    limits are checked against the sum (:class:`~lodconvert.errors.InputError`)."""
    tally.count(part.vertices, part.faces)
    tally.dropped_faces += part.dropped_faces
    tally.dropped_by_object.update(part.dropped_by_object)
    tally.skipped.extend(part.skipped)
