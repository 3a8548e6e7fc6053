"""A plain CityJSONSeq file read by workers from byte ranges of it, so that the main process
reads its header and first feature only (docs/cluster.md).

Workers first count the file's line breaks in blocks of :data:`COUNT_BYTES`
(:class:`~..reopened.NewlinesTask`), so that each range's lines are numbered as one process
numbers them. Each worker is then sent a range of offsets (:class:`RangeLinesTask`); it opens
the file itself (the same file: its size, modification time and first bytes are checked),
takes the lines that start in its range (the first after the first line break before or at
its start; the last may run past its end) and reads them as a run of lines sent as bytes is
read (:class:`~.parallel.LinesTask`). Lines resynchronise on a line break, so every range is
read where it falls. The main process reads the first feature itself (its vertices centre a
geographic CRS's frame, and it times reading), and a range whose worker cannot open the file;
where no worker can count the file, its lines are sent as bytes
(:class:`~.parallel.SequenceReading`). ``.gz`` and ``.zip`` files are always sent as bytes.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO, Any

from ...errors import InputError
from ...limits import Limits
from ...model import Node, PackedNode
from ..reopened import (
    COUNT_CHUNK,
    Changed,
    identity_of,
    newlines,
    newlines_by_workers,
    opened,
    opened_or_why,
)
from ..spread import TASK_SECONDS, Results, Spread
from .parallel import Lines, LinesResult, LinesTask, SequenceReading
from .sequence import stream_lines

COUNT_BYTES = 1 << 22
"""Bytes of the file whose line breaks one worker counts (and the most a range's worker counts
again to number its first line)."""
HEAD_BYTES = 1024
"""Bytes of the file's start that a worker checks it by."""


@dataclass(frozen=True)
class LineRange:
    """The lines that start in ``start``–``stop`` (``exact``: one starts at ``start``); the
    line holding offset ``counted_from`` (at or before ``start``) is line ``number``."""

    start: int
    stop: int
    exact: bool
    counted_from: int
    number: int


def range_lines(handle: IO[bytes], span: LineRange, limits: Limits) -> Lines:
    """The lines of ``span`` in ``handle``, numbered, as :func:`.sequence.sequence_lines`
    gives them."""
    start = span.start if span.exact else _line_start(handle, span.start)
    first = span.number + newlines(handle, span.counted_from, start)
    handle.seek(start)
    found: Lines = []
    for number, line, at in stream_lines(handle, limits, first, start):
        if at >= span.stop:
            break
        found.append((number, line))
    return found


def _line_start(handle: IO[bytes], start: int) -> int:
    """The first offset at or after ``start`` (> 0) where a line starts (the file's end
    where none does)."""
    at = start - 1
    handle.seek(at)
    while chunk := handle.read(COUNT_CHUNK):
        found = chunk.find(b"\n")
        if found >= 0:
            return at + found + 1
        at += len(chunk)
    return at


@dataclass(frozen=True)
class RangeLinesTask:
    """The lines of ``span`` of the file at ``path`` (``identity``: its size and modification
    time; ``head``: its first bytes), read as ``reading`` (a :class:`~.parallel.LinesTask`
    without lines) reads its lines."""

    path: str
    identity: tuple[int, int]
    head: bytes
    span: LineRange
    reading: LinesTask

    def run(self, backend: Any = None, progress: Any = None) -> LinesResult:
        """Read the range (``backend`` and ``progress`` are not used)."""
        handle = opened_or_why(self.path, self.identity, self.head)
        if isinstance(handle, str):
            return LinesResult(unreachable=handle)
        with handle:
            lines = range_lines(handle, self.span, self.reading.limits)
        return replace(self.reading, lines=lines).run()

    def failed(self, reason: str) -> LinesResult:
        """The result of a range no worker could read, for ``reason``."""
        return LinesResult(died=reason)


class SequenceRanges(Spread[LineRange, RangeLinesTask]):
    """The nodes of the plain CityJSONSeq file ``path`` read from byte ranges by an
    executor's workers (see the module's docstring), in line order; read as ``lines``
    (:class:`~.parallel.SequenceReading`, which this shares its state with) reads them where
    there is no executor, the file is read here whole, or no worker can count it."""

    def __init__(self, path: Path, lines: SequenceReading) -> None:
        super().__init__(lines.sizer)
        self.lines = lines
        self.path = path
        self.where = os.path.realpath(path)
        self.identity = (0, 0)
        self.head = b""
        self.told = False

    def use(
        self, results: Results, progress: Callable[[str], None], seconds: float = TASK_SECONDS
    ) -> None:
        super().use(results, progress, seconds)
        if self.results is not None:  # not a file read here whole (said once, above)
            self.lines.use(results, progress, seconds)

    def read_here_only(self) -> str | None:
        return self.lines.read_here_only()

    def nodes(self) -> Iterator[Node | PackedNode]:
        """The file's nodes, in line order."""
        if self.results is None:
            yield from self.lines.nodes()
            return
        self.identity = identity_of(self.path)
        with self._opened() as handle:
            self.head = handle.read(HEAD_BYTES)
            handle.seek(0)
            lines = stream_lines(handle, self.lines.ctx.tally.limits)
            next(lines, None)  # the header
            first = next(lines, None)
            lines.close()
        counted = newlines_by_workers(
            self.where, self.identity, self.head, self.results, COUNT_BYTES
        )
        if isinstance(counted, str):
            self.progress(self._unopened(counted, "its lines are sent as bytes"))
            yield from self.lines.nodes()
            return
        self.lines.lines.close()  # the lines this process read, past the header: not needed
        if first is not None:
            number, _, at = first
            yield from self.spread(self._ranges(LineRange(at, at + 1, True, at, number), counted))

    def _ranges(self, first: LineRange, counted: list[int]) -> Iterator[LineRange]:
        """``first``, then ranges of the size the sizer wants to the file's end (``counted``:
        the line breaks before each block of :data:`COUNT_BYTES`)."""
        yield first
        start, size = first.stop, self.identity[0]
        while start < size:
            stop = min(size, start + self.sizer.wanted())
            block = start // COUNT_BYTES
            yield LineRange(start, stop, False, block * COUNT_BYTES, 1 + counted[block])
            start = stop

    def _opened(self) -> IO[bytes]:
        """The file, checked to be the one this reading began with (:class:`InputError`
        where it is not, or cannot be opened)."""
        try:
            return opened(self.where, self.identity, self.head)
        except (OSError, Changed) as exc:
            raise InputError(f"cannot be read ({exc})", self.lines.ctx.tally.source) from None

    def read_here(self, run: LineRange) -> Iterator[Node]:
        """The nodes of the lines of ``run``, read in this process."""
        with self._opened() as handle:
            lines = range_lines(handle, run, self.lines.ctx.tally.limits)
        yield from self.lines.read_here(lines)

    def settled(self) -> bool:
        return self.lines.settled()

    def task(self, run: LineRange) -> RangeLinesTask:
        return RangeLinesTask(self.where, self.identity, self.head, run, self.lines.task([]))

    def size(self, run: LineRange) -> int:
        return run.stop - run.start

    def merge(self, result: LinesResult) -> None:
        self.lines.merge(result)

    def read_instead(self, task: RangeLinesTask, result: LinesResult) -> bool:
        """A range whose worker cannot open the file is read here (``-v`` says so once)."""
        if result.unreachable is None:
            return False
        if not self.told:
            self.progress(self._unopened(result.unreachable, "the main process reads its range"))
            self.told = True
        return True

    def died(self, how: str) -> str:
        return self.lines.died(how)

    def one_process_error(self, error: InputError) -> InputError:
        return self.lines.one_process_error(error)

    def _unopened(self, reason: str, instead: str) -> str:
        """What ``-v`` tells where a worker could not open the file for ``reason``."""
        source = self.lines.ctx.tally.source
        return f"{source}: a worker cannot open it at {self.where} ({reason}); {instead}"
