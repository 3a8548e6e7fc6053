"""A plain CityGML file read by workers from byte ranges of it, so that the main process reads
its prolog only (docs/cluster.md).

Each worker is sent a range of offsets (:class:`RangeTask`); it opens the file itself (the
same file: its size, modification time and prolog are checked), finds the first member start
tag at or after the range's start (:func:`.members.member_after`), scans the members from there
to the first one that starts at or after the range's end, and reads them as a run of members
sent as bytes is read (:func:`.parallel.read_members`). A start tag found that way may stand
in a comment or CDATA section; the main process takes the results in order and checks that
each range's first member starts where the scan of the range before it ended (a scan from the
document's first member onwards is never misled), and reads the range itself where it does
not. It also reads a range itself where a worker could not open the file, where the worker's
members hold implicit geometry, where ids would differ from those of one process, or where the
workers died, as for runs sent as bytes (:mod:`.parallel`). The first ranges are read one at a
time until the CRS is settled; when a worker cannot open the file at the first of them, the
members are sent as bytes instead (:class:`.parallel.SpreadReading`).
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from ...errors import InputError
from ...limits import Limits
from ...model import Node, PackedNode
from ...semantics import Palette
from ..crs import Crs
from ..reopened import Changed, FileSpan, identity_of, opened, opened_or_why
from ..spread import Results
from .members import Members, NotSplit, member_after
from .parallel import IMPLICIT, READ, ReadResult, SpreadReading, read_members
from .source import open_document
from .text_limit import TextLimit

MARK_BYTES = 1 << 26
"""Bytes of a file a worker looks through for given marks (:class:`MarksTask`)."""
_MARK_CHUNK = 1 << 22
"""Bytes a worker reads at a time while it looks for marks."""
COMPRESSED = (".gz", ".zip")
"""Suffixes of files whose offsets are not those of the document (read as bytes sent)."""


def by_ranges(path: Path) -> bool:
    """Whether the document ``path`` can be read by workers from ranges of its bytes."""
    return not path.name.lower().endswith(COMPRESSED)


@dataclass(frozen=True)
class Scan:
    """The members of a range of a document (as bytes, those the reader reads) and where its
    scan ended: at the root's end tag (``closed``) or at the member that starts the next range."""

    members: list[bytes]
    end: int
    closed: bool


def scan(handle: IO[bytes], start: int, stop: int, limits: Limits, source: str) -> Scan:
    """The members of the document ``handle`` holds from the member starting at ``start`` to
    the first member starting at or after ``stop``, every text held to ``limits`` as
    :func:`.source.open_document` holds it (:class:`InputError`); :class:`NotSplit` where the
    document ends in its root."""
    handle.seek(start)
    size = os.fstat(handle.fileno()).st_size
    stream = (
        TextLimit(handle, limits.xml_text_bytes, source) if size > limits.xml_text_bytes else handle
    )
    members = Members(stream, start, stop)
    kept = [member for name, member in members if name in READ]
    return Scan(kept, members.end, members.closed)


@dataclass(frozen=True)
class RangeResult:
    """What a worker read of a range: where its first member starts (None: no member starts
    after the range's start), where its scan ended, what reading its members gave (with the
    CRS after them); or that its members hold implicit geometry (``in_main``), or why the
    worker could not open the file (``unreachable``)."""

    read: ReadResult = field(default_factory=ReadResult)
    first: int | None = None
    end: int = -1
    closed: bool = False
    crs: Crs | None = None
    in_main: bool = False
    unreachable: str | None = None


@dataclass(frozen=True)
class RangeTask:
    """The members of the document at ``path`` (``identity``: its size and modification
    time) that start in ``start``–``stop`` (``exact``: a member starts at ``start``), to read
    inside its root (``prolog``, ``root_end``) with the document's CRS (None until settled);
    ``source`` names the file in messages."""

    path: str
    identity: tuple[int, int]
    prolog: bytes
    root_end: bytes
    start: int
    stop: int
    exact: bool
    source: str
    limits: Limits
    types: frozenset[str] | None
    palette: Palette
    crs: Crs | None

    def run(self, backend: Any = None, progress: Any = None) -> RangeResult:
        """Read the range (``backend`` and ``progress`` are not used)."""
        handle = opened_or_why(self.path, self.identity, self.prolog)
        if isinstance(handle, str):
            return RangeResult(unreachable=handle)
        with handle:
            handle.seek(self.start)
            first = self.start if self.exact else member_after(handle, self.start)
            if first is None:
                return RangeResult()
            try:
                found = scan(handle, first, self.stop, self.limits, self.source)
            except InputError as exc:
                return RangeResult(ReadResult(error=str(exc)), first)
            except NotSplit:
                return RangeResult(ReadResult(error="ends inside its root element"), first)
        if any(IMPLICIT in member for member in found.members):
            return RangeResult(first=first, end=found.end, closed=found.closed, in_main=True)
        read, crs = read_members(self, b"".join(found.members))
        return RangeResult(read, first, found.end, found.closed, crs)

    def failed(self, reason: str) -> RangeResult:
        """The result of a range no worker could read, for ``reason``."""
        return RangeResult(ReadResult(died=reason))


@dataclass(frozen=True)
class MarksResult:
    """Which marks a worker found in its range, or why it could not open the file."""

    found: frozenset[bytes] = frozenset()
    unreachable: str | None = None


@dataclass(frozen=True)
class MarksTask(FileSpan):
    """Which of ``marks`` start in the span."""

    marks: tuple[bytes, ...] = ()

    def run(self, backend: Any = None, progress: Any = None) -> MarksResult:
        """Look for the marks (``backend`` and ``progress`` are not used)."""
        handle = self.opened()
        if isinstance(handle, str):
            return MarksResult(unreachable=handle)
        with handle:
            longest = max(len(mark) for mark in self.marks)
            found: set[bytes] = set()
            last, at, end = b"", self.start, self.stop + longest - 1
            while at < end and len(found) < len(self.marks):
                chunk = handle.read(min(_MARK_CHUNK, end - at))
                if not chunk:
                    break
                at += len(chunk)
                window = last + chunk  # a mark across two chunks
                found.update(mark for mark in self.marks if mark in window)
                last = chunk[1 - longest :]
        return MarksResult(frozenset(found))

    def failed(self, reason: str) -> MarksResult:
        """The result of a range no worker could look through, for ``reason``."""
        return MarksResult(unreachable=reason)


def marks_by_workers(path: Path, results: Results, marks: tuple[bytes, ...]) -> set[bytes] | None:
    """Which of ``marks`` the plain file ``path`` holds, looked for by the workers of an
    executor's ``results`` in ranges of :data:`MARK_BYTES`; None where one could not open it
    (then this process looks)."""
    identity = identity_of(path)
    with path.open("rb") as handle:
        head = handle.read(1024)
    where = os.path.realpath(path)
    tasks = (
        MarksTask(where, identity, head, start, min(identity[0], start + MARK_BYTES), marks)
        for start in range(0, identity[0], MARK_BYTES)
    )
    found: set[bytes] = set()
    reachable = True
    for result in results(tasks):
        reachable = reachable and result.unreachable is None
        found |= result.found
    return found if reachable else None


Ranged = Generator[Node | PackedNode, None, tuple[int, bool]]
"""The nodes of a range, then where its scan ended and whether at the root's end."""


class RangeReading(SpreadReading):
    """The nodes of a plain CityGML file read from byte ranges by an executor's workers (see
    the module's docstring), in document order; read as :class:`SpreadReading` does where
    there is no executor, the document has appearances, or a worker cannot open the file."""

    path = ""
    """The file, as workers open it."""
    identity = (0, 0)
    """Its size and modification time when the main process read its prolog."""

    def nodes(self) -> Iterator[Node | PackedNode]:
        document = self.document
        if self.results is None or document.appearances is not None:
            yield from super().nodes()
            return
        path = document.path
        self.identity = identity_of(path)
        self.path = os.path.realpath(path)
        stream = open_document(path, document.limits)
        try:
            members = self.members = self._members(stream)
        finally:
            stream.close()
        if members.empty:
            return
        at, closed = len(members.prolog), False
        while not closed and not self.settled():
            task = self._range(at, at + self.sizer.wanted(), True)
            result = next(iter(self.results([task])))
            if result.unreachable is not None and at == len(members.prolog):
                self.progress(self._unopened(result.unreachable, "its members are sent as bytes"))
                yield from super().nodes()
                return
            at, closed = yield from self._taken_range(task, result, at)
        if closed:
            return
        sent: deque[RangeTask] = deque()

        def tasks() -> Iterator[RangeTask]:
            start, exact = at, True
            while start < self.identity[0] and not closed:
                task = self._range(start, start + self.sizer.wanted(), exact)
                sent.append(task)
                yield task
                start, exact = task.stop, False

        assert self.results is not None
        for result in self.results(tasks()):
            task = sent.popleft()
            if not closed:
                at, closed = yield from self._taken_range(task, result, at)
        if not closed:  # the last range ended before the root did
            yield from self._read_range(at, self.identity[0])

    def _range(self, start: int, stop: int, exact: bool) -> RangeTask:
        document, members = self.document, self.members
        assert members is not None
        stop = min(self.identity[0], max(stop, start + 1))
        return RangeTask(
            self.path, self.identity, members.prolog, members.root_end, start, stop, exact,
            document.source, document.limits, document.types, document.palette, document.crs,
        )  # fmt: skip

    def _taken_range(self, task: RangeTask, result: RangeResult, at: int) -> Ranged:
        """What ``result`` of ``task`` gives (``at``: where the range before it ended), and
        where this range ends (whether at the root's end): a worker's nodes, or the range
        read here (see the module's docstring)."""
        read = result.read
        if result.unreachable is not None:
            self._tell(self._unopened(result.unreachable, "the main process reads its range"))
        elif read.died is not None:
            self.progress(self.died(read.died))
        elif result.first == at and read.error is not None:
            raise self.one_process_error(InputError(read.error))
        elif result.first == at and result.in_main:
            self._tell(f"{self.document.source}: implicit geometry is read in the main process")
        elif result.first == at and not read.collided and self.document.taken.isdisjoint(read.ids):
            crs = self.document.crs
            if result.crs is not None and (crs is None or crs.frame is None):
                self.document.crs = result.crs
            if read.nodes:
                self.sizer.took(read.seconds, max(1, result.end - at))
            try:
                self.merge(read)
            except InputError as exc:
                raise self.one_process_error(exc) from None
            yield from read.nodes
            return result.end, result.closed
        return (yield from self._read_range(at, task.stop))

    def _read_range(self, start: int, stop: int) -> Ranged:
        """The nodes of the members from ``start`` (where one starts) to the first starting at
        or after ``stop``, read in this process; where that scan ended, and whether at the
        root's end."""
        document = self.document
        assert self.members is not None
        try:
            with opened(self.path, self.identity, self.members.prolog) as handle:
                found = scan(handle, start, stop, document.limits, document.source)
        except (OSError, Changed) as exc:
            raise InputError(f"cannot be read ({exc})", document.source) from None
        except NotSplit:
            raise self.one_process_error() from None
        except InputError as exc:
            raise self.one_process_error(exc) from None
        if found.members:
            yield from self.read_here(found.members)
        return found.end, found.closed

    def _unopened(self, reason: str, instead: str) -> str:
        """What ``-v`` tells where a worker could not open the file for ``reason``."""
        return (
            f"{self.document.source}: a worker cannot open it at {self.path} ({reason}); {instead}"
        )

    def _tell(self, text: str) -> None:
        """Tell ``text`` once a run."""
        if not self.told:
            self.progress(text)
            self.told = True
