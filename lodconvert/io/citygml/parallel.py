"""A CityGML document read by worker processes from its members sent as bytes (a ``.gz`` or
``.zip`` one, or a plain one whose file workers cannot open; otherwise a plain one is read
from byte ranges, :mod:`.ranges`): the main process cuts it into its root's children
(:mod:`.members`, inflated and held to the text limit there), reads the first of them
itself until the CRS is settled, then ships runs of members as bytes with the root's start tag
(:class:`ReadTask`: no path, so that a worker needs no shared file system); each worker reads
its run inside that root with the reader of one process (:class:`~.document.Document`) and
gives back the nodes and what it counted, as data (:class:`ReadResult`). The main process takes
the results in order and merges them into the document's state, so the nodes, ids, skips and
counts are those of reading in one process.

What depends on the members before a run is kept exact: ids made unique across the document
are checked against those taken before, and a run whose ids would differ is read again in the
main process (so is a run whose workers died); a run holding implicit geometry (whose templates
later objects link to) is read in the main process; a run a worker cannot read is read by the
one-process reader from the start of the document, so that the error is the one it gives.
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from lxml import etree

from ...errors import InputError
from ...limits import Limits
from ...model import Node, PackedNode, with_geometry
from ...semantics import Palette
from ..crs import Crs
from ..geometry_checks import InputTally
from ..spread import Spread, add_tally, runs
from .document import Document
from .members import Members, NotSplit
from .names import MEMBERS
from .source import Stream, first_look, open_document

READ = MEMBERS | {"boundedBy"}
"""The root's children the reader reads (others are not shipped)."""
IMPLICIT = b"ImplicitGeometry"


class _Taken(set[str]):
    """A set of ids that notes whether a name asked for was taken already."""

    collided = False

    def __contains__(self, name: object) -> bool:
        found = super().__contains__(name)
        self.collided = self.collided or found
        return found


@dataclass(frozen=True)
class ReadResult:
    """What a worker read of a run of members: the nodes with geometry (packed: the main
    process passes them on unopened), the ids it took in order (``collided``: one was asked
    for twice), what the tally counted, the document's counts, and the reason it could not
    read the run (then nothing else)."""

    nodes: tuple[PackedNode, ...] = ()
    ids: frozenset[str] = frozenset()
    collided: bool = False
    tally: InputTally | None = None
    stats: dict[str, dict[str, int]] = field(default_factory=dict)
    error: str | None = None
    died: str | None = None
    """Why no worker could read the run (they died): then this process reads it."""
    seconds: float = 0.0


@dataclass(frozen=True)
class ReadTask:
    """A run of a document's members (bytes) to read inside its root (``prolog``: the
    document up to the end of the root's start tag; ``root_end``: its end tag) with the
    document's CRS; ``source`` names the file in messages."""

    prolog: bytes
    members: bytes
    root_end: bytes
    source: str
    limits: Limits
    types: frozenset[str] | None
    palette: Palette
    crs: Crs
    in_main: bool = False
    """Read by the main process (it holds implicit geometry, or the document appearances,
    whose images are read beside the input): a worker returns nothing."""

    def run(self, backend: Any = None, progress: Any = None) -> ReadResult:
        """Read the run (``backend`` and ``progress`` are not used)."""
        if self.in_main:
            return ReadResult()
        return read_members(self, self.members)[0]

    def failed(self, reason: str) -> ReadResult:
        """The result of a run no worker could read, for ``reason``."""
        return ReadResult(died=reason)


class Reading(Protocol):
    """Where a worker's members come from and how to read them: a :class:`ReadTask`, or a
    range of the file (:class:`~.ranges.RangeTask`)."""

    @property
    def prolog(self) -> bytes: ...
    @property
    def root_end(self) -> bytes: ...
    @property
    def source(self) -> str: ...
    @property
    def limits(self) -> Limits: ...
    @property
    def types(self) -> frozenset[str] | None: ...
    @property
    def palette(self) -> Palette: ...
    @property
    def crs(self) -> Crs | None: ...


def read_members(task: Reading, members: bytes) -> tuple[ReadResult, Crs | None]:
    """What reading ``members`` (a run of a document's members, as bytes) inside the document's
    root gives a worker, and the CRS the document has after them."""
    start = time.process_time()
    tally = InputTally(task.source, task.limits)
    document = Document(Path(task.source), task.limits, task.types, tally, task.palette)
    document.crs, document.taken = task.crs, _Taken()
    try:
        read = document.read(io.BytesIO(task.prolog + members + task.root_end))
        nodes = tuple(PackedNode.of(n) for n in with_geometry(read))
    except InputError as exc:
        return ReadResult(error=str(exc)), None
    taken = document.taken
    assert isinstance(taken, _Taken)
    result = ReadResult(
        nodes, frozenset(taken), taken.collided, tally, document.stats,
        seconds=time.process_time() - start,
    )  # fmt: skip
    return result, document.crs


class SpreadReading(Spread[list[bytes], ReadTask]):
    """The nodes of the document ``make`` gives read as :class:`ReadTask` on an executor once
    one is given (:meth:`use`); until then, and without one, each run of members is read in
    this process (:class:`~..spread.Spread`)."""

    def __init__(self, make: Callable[[], Document]) -> None:
        super().__init__()
        self.make = make
        self.document = make()
        self.told = False
        self.members: Members | None = None

    def nodes(self) -> Iterator[Node | PackedNode]:
        """The document's city objects with geometry, in document order."""
        document = self.document
        stream = open_document(document.path, document.limits)
        try:
            self.members = self._members(stream)
            read = (member for name, member in self.members if name in READ)
            yield from self.spread(runs(read, len, self.sizer))
        except NotSplit:
            raise self.one_process_error() from None
        finally:
            stream.close()

    def _members(self, stream: Stream) -> Members:
        """The document's members, its root checked first (as one process reads it)."""
        try:
            replay, root = first_look(stream, self.document.limits, self.document.source)
        except etree.XMLSyntaxError:
            raise self.one_process_error() from None
        self.document.check_root(root)
        return Members(replay)

    def settled(self) -> bool:
        """Whether the CRS (a geographic one's frame too) is settled and reading timed."""
        crs = self.document.crs
        frame = crs is not None and (crs.geographic is None or crs.frame is not None)
        return frame and self.sizer.timed

    def read_here(self, run: list[bytes]) -> Iterator[Node]:
        """The nodes of the members ``run``, read in this process into the document's state."""
        assert self.members is not None
        members = b"".join(run)
        start = time.process_time()
        whole = self.members.prolog + members + self.members.root_end
        nodes = list(self.document.read(io.BytesIO(whole)))
        if nodes:
            self.sizer.took(time.process_time() - start, len(members))
        yield from nodes

    def task(self, run: list[bytes]) -> ReadTask:
        """The task of the members ``run``."""
        document, members = self.document, self.members
        assert document.crs is not None and members is not None
        joined = b"".join(run)
        return ReadTask(
            members.prolog, joined, members.root_end, document.source, document.limits,
            document.types, document.palette, document.crs,
            in_main=IMPLICIT in joined or document.appearances is not None,
        )  # fmt: skip

    def size(self, run: list[bytes]) -> int:
        return sum(len(member) for member in run)

    def read_instead(self, task: ReadTask, result: ReadResult) -> bool:
        """Implicit geometry (its templates are shared across objects) and objects whose ids
        another run took or that collide are read here, where they are what one process
        reads."""
        if task.in_main and not self.told:
            what = (
                "its appearances are"
                if self.document.appearances is not None
                else "implicit geometry is"
            )
            self.progress(f"{self.document.source}: {what} read in the main process")
            self.told = True
        return task.in_main or result.collided or not self.document.taken.isdisjoint(result.ids)

    def merge(self, result: ReadResult) -> None:
        _merge(self.document, result)

    def died(self, how: str) -> str:
        return f"{self.document.source}: {how}; its run is read in the main process"

    def one_process_error(self, error: InputError | None = None) -> InputError:
        """The error reading the document in one process gives (``error`` if none)."""
        try:
            for _ in self.make().nodes():
                pass
        except InputError as exc:
            return exc
        return error or InputError("cannot be cut into its objects", self.document.source)


def _merge(document: Document, result: ReadResult) -> None:
    """Add what a worker read and counted to ``document``'s state."""
    assert result.tally is not None
    add_tally(document.tally, result.tally)
    document.taken.update(result.ids)
    for key, counts in result.stats.items():
        total = document.stats[key]
        for name, count in counts.items():
            total[name] = total.get(name, 0) + count
