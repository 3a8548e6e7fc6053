"""A CityJSONSeq file read by worker processes: the main process reads the lines (inflated and
held to the limits there) and the first feature itself (its vertices centre a geographic CRS's
frame), then ships runs of lines as bytes with the header (:class:`LinesTask`); each worker
reads its lines as one process reads them and gives back the nodes and what it counted
(:class:`LinesResult`), which the main process takes in order. A file with geometry templates
is read in the main process (its instances share one mesh per template); a run a worker
cannot read is read by the one-process reader from the start, so that the error is the one it
gives."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import closing
from dataclasses import dataclass
from typing import Any

from ...errors import InputError
from ...limits import Limits
from ...model import Node
from ..crs import Crs
from ..geometry_checks import InputTally
from ..spread import Results, Sizer, add_tally
from .source import Context, context_of

Lines = list[tuple[int, bytes]]
"""Lines of a file, each with its number."""
ReadLines = Callable[[Iterator[tuple[int, bytes]], dict[str, Any], Context, Any], Iterator[Node]]
"""How one process reads lines into nodes: ``read(lines, header, ctx, types)``."""


@dataclass(frozen=True)
class LinesResult:
    """The nodes of a run of lines and what reading them counted, or why it could not."""

    nodes: tuple[Node, ...] = ()
    tally: InputTally | None = None
    error: str | None = None
    seconds: float = 0.0


@dataclass(frozen=True)
class LinesTask:
    """A run of a CityJSONSeq file's lines to read against its ``header`` in ``declared``
    (the main process's CRS, its frame settled), by ``read``."""

    lines: Lines
    header: dict[str, Any]
    declared: Crs | None
    source: str
    limits: Limits
    types: frozenset[str] | None
    palette: Any
    read: ReadLines

    def run(self, backend: Any = None, progress: Any = None) -> LinesResult:
        """Read the lines (``backend`` and ``progress`` are not used)."""
        start = time.perf_counter()
        tally = InputTally(self.source, self.limits)
        try:
            ctx = context_of(self.header, tally, self.declared, self.palette)
            nodes = tuple(self.read(_each(self.lines), self.header, ctx, self.types))
        except InputError as exc:
            return LinesResult(error=str(exc))
        return LinesResult(nodes, tally, seconds=time.perf_counter() - start)

    def failed(self, reason: str) -> LinesResult:
        """The result of a run no worker could read, for ``reason``."""
        return LinesResult(error=reason)


class SequenceReading:
    """The nodes of a CityJSONSeq file's ``lines`` (after its header) read as
    :class:`LinesTask` on an executor once one is given (:meth:`use`), until then and without
    one in this process by ``read``; ``again`` reads the whole file in one process."""

    def __init__(
        self,
        lines: Iterator[tuple[int, bytes]],
        header: dict[str, Any],
        ctx: Context,
        types: frozenset[str] | None,
        read: ReadLines,
        again: Callable[[], Iterator[Node]],
    ) -> None:
        self.lines, self.header, self.ctx, self.types = lines, header, ctx, types
        self.read, self.again = read, again
        self.results: Results | None = None
        self.sizer = Sizer()

    def use(self, results: Results, progress: Callable[[str], None]) -> None:
        """Read the rest of the file by ``results`` (an executor's); a file with geometry
        templates is read here (``progress`` hears so)."""
        if self.ctx.templates:
            progress(f"{self.ctx.tally.source}: geometry templates are read in the main process")
            return
        self.results = results

    def nodes(self) -> Iterator[Node]:
        """The file's nodes, in line order."""
        with closing(self.lines):
            runs = self._runs()
            for run in runs:
                yield from self._read_here(run)
                declared = self.ctx.declared
                settled = declared is None or declared.geographic is None or declared.frame
                if settled and self.sizer.timed:
                    break
            if self.results is None:
                for run in runs:
                    yield from self._read_here(run)
                return
            sent: deque[LinesTask] = deque()
            for result in self.results(self._tasks(runs, sent)):
                task = sent.popleft()
                if result.error is not None:
                    raise self._one_process_error(InputError(result.error))
                if result.nodes:
                    self.sizer.took(result.seconds, sum(len(line) for _, line in task.lines))
                assert result.tally is not None
                try:
                    add_tally(self.ctx.tally, result.tally)
                except InputError as exc:
                    raise self._one_process_error(exc) from None
                yield from result.nodes

    def _runs(self) -> Iterator[Lines]:
        """Runs of lines of about :data:`~..spread.TASK_SECONDS` of reading as measured so
        far (of one line until then)."""
        run: Lines = []
        size = 0
        for number, line in self.lines:
            run.append((number, line))
            size += len(line)
            if size >= self.sizer.wanted():
                yield run
                run, size = [], 0
        if run:
            yield run

    def _read_here(self, run: Lines) -> Iterator[Node]:
        """The nodes of ``run``, read in this process."""
        start = time.perf_counter()
        nodes = list(self.read(_each(run), self.header, self.ctx, self.types))
        if nodes:
            self.sizer.took(time.perf_counter() - start, sum(len(line) for _, line in run))
        yield from nodes

    def _tasks(self, runs: Iterator[Lines], sent: deque[LinesTask]) -> Iterator[LinesTask]:
        """A task of each run (noted in ``sent``)."""
        tally = self.ctx.tally
        for run in runs:
            task = LinesTask(
                run, self.header, self.ctx.declared, tally.source, tally.limits, self.types,
                self.ctx.palette, self.read,
            )  # fmt: skip
            sent.append(task)
            yield task

    def _one_process_error(self, error: InputError) -> InputError:
        """The error reading the file in one process gives (``error`` if none)."""
        try:
            for _ in self.again():
                pass
        except InputError as exc:
            return exc
        return error


def _each(lines: Lines) -> Iterator[tuple[int, bytes]]:
    """``lines`` as the generator the reader takes (and closes)."""
    yield from lines
