"""What the readers that read a city in worker processes share: how many bytes of input a task
holds (sized for the executor's ``task_seconds`` of reading, as measured so far) and how what a
worker counted is added to the file's tally. The tasks hold bytes (no path, so that a worker
needs no shared file system): :mod:`.citygml.parallel`, :mod:`.cityjson.parallel`; a plain
CityGML file is read from byte ranges of it instead (:mod:`.citygml.ranges`)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from typing import Any, Generic, TypeVar

from ..errors import InputError
from .geometry_checks import InputTally

TASK_SECONDS = 0.1
"""CPU seconds of reading a task is sized for unless the executor says otherwise (CPU, not
wall: a busy machine does not make tasks smaller)."""
MIN_BYTES, MAX_BYTES = 1 << 20, 1 << 24
"""Bytes of input a task holds at least (but for the last) and at most: a task reads its
objects together (a CityGML run of one member reads 2.4× slower than one of 64)."""

Run = TypeVar("Run")
Task = TypeVar("Task")
Item = TypeVar("Item")
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
    for text in part.warnings:
        tally.warn(text)


class Spread(ABC, Generic[Run, Task]):
    """The spread-reading algorithm, written once for every reader that reads a city in
    worker processes: the file's runs (:func:`runs`) are read here until the CRS is settled
    and reading is timed, the rest as tasks on the executor's ``results`` (given by
    :meth:`use`; without one, here too), taken back in order. A worker's nodes are merged into
    the file's state; a run whose workers died is read here; a worker's error is the one
    reading the file in one process gives. A format supplies how to read a run here, make its
    task, merge a result and find that error (docs/architecture.md)."""

    def __init__(self, sizer: Sizer | None = None) -> None:
        self.results: Results | None = None
        self.progress: Callable[[str], None] = quiet
        self.sizer = sizer or Sizer()

    def use(
        self, results: Results, progress: Callable[[str], None], seconds: float = TASK_SECONDS
    ) -> None:
        """Read what is left by ``results`` (an executor's), in tasks of about ``seconds`` of
        reading; ``progress`` hears where runs are read here instead, and why a file is read
        here whole (:meth:`read_here_only`)."""
        why = self.read_here_only()
        if why is not None:
            progress(why)
            return
        self.results, self.progress, self.sizer.seconds = results, progress, seconds

    def read_here_only(self) -> str | None:
        """Why the whole file is read in this process, if it is."""
        return None

    def spread(self, runs: Iterator[Run]) -> Iterator[Any]:
        """What reading each of ``runs`` gives, in order."""
        for run in runs:
            yield from self.read_here(run)
            if self.settled():
                break
        if self.results is None:
            for run in runs:
                yield from self.read_here(run)
            return
        sent: deque[tuple[Run, Task]] = deque()

        def tasks() -> Iterator[Task]:
            for run in runs:
                task = self.task(run)
                sent.append((run, task))
                yield task

        for result in self.results(tasks()):
            run, task = sent.popleft()
            yield from self._taken(run, task, result)

    def _taken(self, run: Run, task: Task, result: Any) -> Iterator[Any]:
        """What ``result`` (of ``task``, made of ``run``) gives: a worker's nodes, or ``run``
        read here where its workers died or the format says so (:meth:`read_instead`)."""
        if result.error is not None:
            raise self.one_process_error(InputError(result.error))
        if result.died is not None:
            self.progress(self.died(result.died))
        if self.read_instead(task, result) or result.died is not None:
            yield from self.read_here(run)
            return
        if result.nodes:
            self.sizer.took(result.seconds, self.size(run))
        try:
            self.merge(result)
        except InputError as exc:
            raise self.one_process_error(exc) from None
        yield from self.given(run, result)

    @abstractmethod
    def read_here(self, run: Run) -> Iterator[Any]:
        """What reading ``run`` in this process gives (timed by the sizer)."""

    def settled(self) -> bool:
        """Whether what was read here so far settles the CRS (and timed reading)."""
        return self.sizer.timed

    @abstractmethod
    def task(self, run: Run) -> Task:
        """The task that reads ``run`` in a worker."""

    @abstractmethod
    def size(self, run: Run) -> int:
        """The size of ``run`` in the sizer's units."""

    @abstractmethod
    def merge(self, result: Any) -> None:
        """Add what a worker counted to the file's state."""

    def given(self, run: Run, result: Any) -> Iterator[Any]:
        """What a worker's ``result`` of ``run`` gives: its nodes."""
        yield from result.nodes

    def read_instead(self, task: Task, result: Any) -> bool:
        """Whether ``task`` is read here although a worker read it."""
        return False

    @abstractmethod
    def died(self, how: str) -> str:
        """What ``-v`` tells of a run read here because its workers died (``how``)."""

    @abstractmethod
    def one_process_error(self, error: InputError) -> InputError:
        """The error reading the file in one process gives (``error`` if none)."""


def runs(items: Iterable[Item], size: Callable[[Item], int], sizer: Sizer) -> Iterator[list[Item]]:
    """``items`` in runs of about the sizer's wanted size, as measured so far (one item until
    reading is timed)."""
    run: list[Item] = []
    total = 0
    for item in items:
        run.append(item)
        total += size(item)
        if total >= sizer.wanted():
            yield run
            run, total = [], 0
    if run:
        yield run
