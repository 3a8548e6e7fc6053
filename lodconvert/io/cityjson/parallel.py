"""CityJSON read by worker processes. A CityJSONSeq file: the main process reads the lines
(inflated and held to the limits there) and the first feature itself (its vertices centre a
geographic CRS's frame), then ships runs of lines as bytes with the header (:class:`LinesTask`).
A ``.json`` file: after its one ``json.loads`` (and its vertices put in metres) in the main
process, batches of CityObjects with the rows of the vertices they use (:class:`ObjectsTask`,
:class:`UsedRows`); the main process joins parts to their objects once all are read. Each
worker reads as one process reads and gives back the nodes and what it counted; the main
process takes the results in order, so nodes, skipped objects and counts are those of one
process. The node of an object with neither parts nor a parent comes back packed, as CityGML's
do (:class:`~..citygml.parallel.ReadTask`); so do the nodes of a run of lines. A file with
geometry templates is read in the main process (its instances share one mesh per template); a
task whose workers died is read in the main process; one a worker cannot read has the file read
by the one-process reader, so that the error is the one it gives."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import closing
from dataclasses import dataclass
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from ...limits import Limits
from ...model import Node, PackedNode, with_geometry
from ..crs import Crs
from ..geometry_checks import InputTally
from ..images import Images
from ..spread import TASK_SECONDS, Results, Sizer, Spread, add_tally, runs
from .geometry import SURFACE_DEPTH
from .objects import Objects, checked_nodes, read_kept
from .sequence import Line
from .source import Context, context_of

Lines = list[Line]
"""Lines of a file, each with its number."""
ReadLines = Callable[[Iterator[Line], dict[str, Any], Context, Any], Iterator[Node]]
"""How one process reads lines into nodes: ``read(lines, header, ctx, types)``."""


@dataclass(frozen=True)
class LinesResult:
    """The nodes of a run of lines and what reading them counted, or why it could not."""

    nodes: tuple[Node | PackedNode, ...] = ()
    tally: InputTally | None = None
    error: str | None = None
    died: str | None = None
    """Why no worker could read the task (they died): then this process reads it."""
    seconds: float = 0.0
    unreachable: str | None = None
    """Why a worker could not open the file to read its range (:mod:`.ranges`)."""


@dataclass(frozen=True)
class LinesTask:
    """A run of a CityJSONSeq file's lines to read against its ``header`` in ``declared``
    (the main process's CRS, its frame settled), by ``read``. Its features' nodes come back
    packed (:func:`_flattened`)."""

    lines: Lines
    header: dict[str, Any]
    declared: Crs | None
    source: str
    limits: Limits
    types: frozenset[str] | None
    palette: Any
    read: ReadLines
    theme: str | None = None
    """The appearance theme asked for (its images are read beside ``source``)."""

    def run(self, backend: Any = None, progress: Any = None) -> LinesResult:
        """Read the lines (``backend`` and ``progress`` are not used)."""
        start = time.process_time()
        tally = InputTally(self.source, self.limits)
        images = Images(Path(self.source), self.limits, tally.warn)
        try:
            ctx = context_of(self.header, tally, self.declared, self.palette, images, self.theme)
            nodes = _flattened(list(self.read(_each(self.lines), self.header, ctx, self.types)))
        except InputError as exc:
            return LinesResult(error=str(exc))
        return LinesResult(nodes, tally, seconds=time.process_time() - start)

    def failed(self, reason: str) -> LinesResult:
        """The result of a run no worker could read, for ``reason``."""
        return LinesResult(died=reason)


def _flattened(roots: list[Node]) -> tuple[Node | PackedNode, ...]:
    """The nodes with geometry of the trees of ``roots``, in the order the main process walks
    them, each packed as it parks them; ``roots`` as they are where a node is placed by a
    transform (an instance, which cannot be packed)."""
    found = list(with_geometry(roots))
    if any(node.transform is not None for node in found):
        return tuple(roots)
    return tuple(PackedNode.of(node) for node in found)


class SequenceReading(Spread[Lines, LinesTask]):
    """The nodes of a CityJSONSeq file's ``lines`` (after its header) read as
    :class:`LinesTask` on an executor once one is given (:meth:`use`), until then and without
    one in this process by ``read``; ``again`` reads the whole file in one process."""

    def __init__(
        self,
        lines: Iterator[Line],
        header: dict[str, Any],
        ctx: Context,
        types: frozenset[str] | None,
        read: ReadLines,
        again: Callable[[], Iterator[Node]],
    ) -> None:
        super().__init__()
        self.lines, self.header, self.ctx, self.types = lines, header, ctx, types
        self.read, self.again = read, again

    def read_here_only(self) -> str | None:
        return _templates_here(self.ctx)

    def nodes(self) -> Iterator[Node | PackedNode]:
        """The file's nodes, in line order."""
        with closing(self.lines):
            yield from self.spread(runs(self.lines, _line_size, self.sizer))

    def settled(self) -> bool:
        declared = self.ctx.declared
        frame = declared is None or declared.geographic is None or declared.frame
        return bool(frame) and self.sizer.timed

    def read_here(self, run: Lines) -> Iterator[Node]:
        """The nodes of ``run``, read in this process."""
        start = time.process_time()
        nodes = list(self.read(_each(run), self.header, self.ctx, self.types))
        if nodes:
            self.sizer.took(time.process_time() - start, _size(run))
        yield from nodes

    def task(self, run: Lines) -> LinesTask:
        tally = self.ctx.tally
        return LinesTask(
            run, self.header, self.ctx.declared, tally.source, tally.limits, self.types,
            self.ctx.palette, self.read, self.ctx.theme,
        )  # fmt: skip

    def size(self, run: Lines) -> int:
        return _size(run)

    def merge(self, result: LinesResult) -> None:
        assert result.tally is not None
        add_tally(self.ctx.tally, result.tally)

    def died(self, how: str) -> str:
        return _died_here(self.ctx, how)

    def one_process_error(self, error: InputError) -> InputError:
        """The error reading the file in one process gives (``error`` if none)."""
        try:
            for _ in self.again():
                pass
        except InputError as exc:
            return exc
        return error


def _templates_here(ctx: Context) -> str | None:
    """Why a file is read in the main process: its geometry templates (instances share one
    mesh per template), if it has any."""
    if ctx.templates:
        return f"{ctx.tally.source}: geometry templates are read in the main process"
    return None


def _died_here(ctx: Context, died: str) -> str:
    """What ``-v`` tells of a task read here because its workers died (``died``: how)."""
    return f"{ctx.tally.source}: {died}; its objects are read in the main process"


def _size(lines: Lines) -> int:
    """Bytes of ``lines`` (a line too long to read: none)."""
    return sum(_line_size(line) for line in lines)


def _line_size(line: Line) -> int:
    """Bytes of ``line`` (one too long to read: none)."""
    return len(line[1] or b"")


def _each(lines: Lines) -> Iterator[Line]:
    """``lines`` as the generator the reader takes (and closes)."""
    yield from lines


@dataclass(frozen=True)
class ObjectsResult:
    """The node of each object of a task (None: left out), in order, and what reading them
    counted, or why they could not be read."""

    nodes: tuple[Node | PackedNode | None, ...] = ()
    tally: InputTally | None = None
    error: str | None = None
    died: str | None = None
    """Why no worker could read the task (they died): then this process reads it."""
    seconds: float = 0.0


@dataclass(frozen=True)
class ObjectsTask:
    """CityObjects of a ``.json`` file to read, each ``(key, object, below)`` (``below``: how
    many objects are left out with one nested too deep, else None), against the file's
    vertices (in metres): only the rows the objects use (:class:`UsedRows`). The node of an
    object ``alone`` (:meth:`~.objects.Objects.alone`) comes back packed
    (:class:`~...model.PackedNode`) where it has geometry and no transform."""

    objects: tuple[tuple[str, Any, int | None], ...]
    alone: tuple[bool, ...]
    vertices: UsedRows
    materials: list[Any]
    declared: Crs | None
    source: str
    limits: Limits
    palette: Any

    def run(self, backend: Any = None, progress: Any = None) -> ObjectsResult:
        """Read the objects (``backend`` and ``progress`` are not used)."""
        start = time.process_time()
        tally = InputTally(self.source, self.limits)
        vertices = self.vertices.array()
        ctx = Context(tally, vertices, self.declared, self.materials, palette=self.palette)
        try:
            reads = [read_kept(key, obj, ctx, below) for key, obj, below in self.objects]
            read = zip(checked_nodes(reads), self.alone, strict=True)
            nodes = tuple(_packed(node) if alone else node for node, alone in read)
        except InputError as exc:
            return ObjectsResult(error=str(exc))
        return ObjectsResult(nodes, tally, seconds=time.process_time() - start)

    def failed(self, reason: str) -> ObjectsResult:
        """The result of objects no worker could read, for ``reason``."""
        return ObjectsResult(died=reason)


def _packed(node: Node | None) -> Node | PackedNode | None:
    """``node`` packed where it has geometry and neither children nor a transform."""
    if node is None or node.geometry is None or node.children or node.transform is not None:
        return node
    return PackedNode.of(node)


class ObjectsReading(Spread[list[str], ObjectsTask]):
    """The root nodes of a ``.json`` file's ``objects`` (after one ``json.loads``), read as
    :class:`ObjectsTask` on an executor when one is given (:meth:`use`, which reads them
    then), else by ``read_here`` in this process as they are first taken (:meth:`nodes`);
    ``check`` judges the roots once all are read, ``again`` reads the whole file in one
    process."""

    def __init__(
        self,
        objects: dict[str, Any],
        ctx: Context,
        types: frozenset[str] | None,
        read_all: Callable[[], list[Node]],
        check: Callable[[list[Node | PackedNode]], object],
        again: Callable[[], object],
    ) -> None:
        super().__init__(Sizer(MIN_OBJECTS, MAX_OBJECTS))
        self.tree = Objects(objects, types)
        self.ctx, self.read_all, self.check, self.again = ctx, read_all, check, again
        self.roots: list[Node | PackedNode] | None = None

    def use(
        self, results: Results, progress: Callable[[str], None], seconds: float = TASK_SECONDS
    ) -> None:
        """Read the objects now by ``results`` (an executor's), in batches of about
        ``seconds`` of reading; a file with geometry templates is read here (``progress``
        hears so)."""
        super().use(results, progress, seconds)
        if self.results is None:
            return
        found = dict(self.spread(runs(self.tree.order, lambda _: 1, self.sizer)))
        self.roots = self.tree.roots(found.__getitem__)
        self.check(self.roots)

    def nodes(self) -> Iterator[Node | PackedNode]:
        """The root nodes, read here if :meth:`use` did not read them."""
        if self.roots is None:
            self.roots = self.read_all()
            self.check(self.roots)
        yield from self.roots

    def read_here(self, run: list[str]) -> Iterator[tuple[str, Node | PackedNode | None]]:
        """Each object of ``run`` with its node, read in this process."""
        start = time.process_time()
        reads = [self.tree.read(key, self.ctx) for key in run]
        found = list(zip(run, checked_nodes(reads), strict=True))
        self.sizer.took(time.process_time() - start, len(run))
        yield from found

    def task(self, run: list[str]) -> ObjectsTask:
        """The task of the objects ``run``."""
        tree, ctx, tally = self.tree, self.ctx, self.ctx.tally
        objects = tuple((key, tree.objects[key], tree.too_deep.get(key)) for key in run)
        return ObjectsTask(
            objects, tuple(tree.alone(key) for key in run), UsedRows.of(ctx.vertices, objects),
            ctx.materials, ctx.declared, tally.source, tally.limits, ctx.palette,
        )  # fmt: skip

    def size(self, run: list[str]) -> int:
        return len(run)

    def merge(self, result: ObjectsResult) -> None:
        assert result.tally is not None
        add_tally(self.ctx.tally, result.tally)

    def given(
        self, run: list[str], result: ObjectsResult
    ) -> Iterator[tuple[str, Node | PackedNode | None]]:
        yield from zip(run, result.nodes, strict=True)

    def died(self, how: str) -> str:
        return _died_here(self.ctx, how)

    def read_here_only(self) -> str | None:
        return _templates_here(self.ctx)

    def one_process_error(self, error: InputError) -> InputError:
        """The error reading the file in one process gives (``error`` if none)."""
        try:
            self.again()
        except InputError as exc:
            return exc
        return error


MIN_OBJECTS, MAX_OBJECTS = 32, 256
"""Objects a task holds at least (but for the last) and at most."""

_FLATTEN = {**{kind: depth + 1 for kind, depth in SURFACE_DEPTH.items()}, "GeometryInstance": 0}
"""How many levels of lists lie above the vertex indices of each geometry type the reader
reads (a surface's rings, their indices; an instance's one reference point)."""


@dataclass(frozen=True)
class UsedRows:
    """The rows of a file's vertex list that some objects use (``rows``, in the order of the
    sorted indices ``used``; ``None``: every row, as ``rows``) and how many it has: what a task
    ships instead of the whole list (10× Delft's 23 tasks: 16 MB in all, not 110 MB). The
    worker puts them back in place, so its objects index them as the file does."""

    rows: np.ndarray
    used: np.ndarray | None
    count: int

    @classmethod
    def of(cls, vertices: np.ndarray, objects: Iterable[tuple[str, Any, Any]]) -> UsedRows:
        """The rows of ``vertices`` that the geometry of ``objects`` (``(key, object, _)``)
        names; every row where a boundary is not nested lists of numbers (the reader says
        what is wrong)."""
        try:
            index = np.array(_indices(objects), dtype=np.int64)
        except (TypeError, ValueError, OverflowError):
            return cls(vertices, None, len(vertices))
        index = np.sort(index[(index >= 0) & (index < len(vertices))])
        used = index[np.diff(index, prepend=-1) != 0]
        return cls(vertices[used], used, len(vertices))

    def array(self) -> np.ndarray:
        """The vertex list, of all its rows, those not used zero (where no row is written, no
        memory is taken: the array is mapped as it is written)."""
        if self.used is None:
            return self.rows
        vertices = np.zeros((self.count, *self.rows.shape[1:]), self.rows.dtype)
        vertices[self.used] = self.rows
        return vertices


def _indices(objects: Iterable[tuple[str, Any, Any]]) -> list[Any]:
    """The vertex indices of the geometry of ``objects`` that the reader reads, end to end
    (``TypeError`` where a boundary is not nested lists)."""
    found: list[Any] = []
    for _, obj, _ in objects:
        geometries = obj.get("geometry") if isinstance(obj, dict) else None
        for geometry in geometries or ():
            depth = _FLATTEN.get(geometry.get("type")) if isinstance(geometry, dict) else None
            if depth is None:
                continue
            values = geometry.get("boundaries")
            for _ in range(depth):
                values = chain.from_iterable(values)
            found.extend(values)
    return found
