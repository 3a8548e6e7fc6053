"""The conversion as stages over data, with one :class:`RunOptions`: read → plan tasks (each
object's γ, geometry placed by several nodes baked once, batches) → execute them
(:mod:`.tasks`: in this process or in worker processes) → assemble (records, LOD parents) →
write → check → commit every output together.

Readers are free of processing and writers of baking; this module joins them, times each stage
and collects what the ``--report`` file records. The main process takes each object's outcome in
order: one that cannot be baked is reported and skipped; when none can, the conversion fails
and no output file appears.
"""

from __future__ import annotations

import contextlib
import gc
import hashlib
import itertools
import json
import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .bake import Backend, get_backend
from .chain import ChainOptions, ChainPlan
from .city.cells import CellBaker
from .city.hlod import HlodOptions, auto_size, draw_counts, plan_cells
from .city.plots import plot_radii
from .clock import Clock
from .errors import InputError, UsageError
from .io import Format, OutputInfo, Pieces, input_format, output_format
from .io.archive import inflated_size
from .io.crs import checked_crs_option
from .io.frame import SceneFrame, scene_frame
from .io.geometry_checks import InputTally, attach_tally, tally_of
from .limits import DEFAULT_LIMITS, Limits
from .model import CellChain, LodChain, Node, PackedNode, Scene, with_geometry
from .model.lods import GROUND_COVERS, source_levels
from .report import Records, cell_record, chain_record, options_record, report_text, run_report
from .reproject import SOURCE_CRS_KEYS, Georef, in_one_crs
from .sinks import DirectorySink, FileSink, Outputs
from .spool import NodeSpool
from .tasks import (
    Baked,
    BakeTask,
    Executor,
    PoolExecutor,
    SerialExecutor,
    batches,
    default_workers,
)
from .validate import check_written, streamed_check
from .validate.along import CheckAlong
from .version import __version__

Message = Callable[[str], None]
Step = Callable[[str, int, "int | None"], None]
"""``step(stage, done, total)``: ``done`` of ``total`` (``None``: unknown) items finished."""


def _quiet(_: str) -> None:
    """Discard a message."""


def _no_step(stage: str, done: int, total: int | None) -> None:
    """Discard a progress count."""


def _add_counts(total: dict[str, int], more: dict[str, int]) -> None:
    for key, value in more.items():
        total[key] = total.get(key, 0) + value


def iter_chains(
    scene: Scene,
    options: ChainOptions,
    backend: Backend,
    progress: Message = _quiet,
    warn: Message = _quiet,
    skipped: list[dict[str, str]] | None = None,
    step: Step = _no_step,
    limits: Limits = DEFAULT_LIMITS,
    strict: bool = False,
    hlod: HlodOptions | None = None,
    executor: Executor | None = None,
    clock: Clock | None = None,
    pieces: Pieces | None = None,
    first_at: Callable[[np.ndarray], None] | None = None,
) -> Iterator[LodChain | CellChain]:
    """Bake the scene's objects (by ``executor``: in this process by default); objects with bad
    geometry are reported through ``warn`` (unless ``strict``: the caller fails), recorded in
    ``skipped`` and left out. ``step`` hears how many are done, ``clock`` how long planning
    and baking took; ``pieces`` keeps what its formatter made of each chain where it was baked
    (those chains come without their geometry, but for LOD parents, which merge it);
    ``first_at`` hears where the scene's first object lies (its bounding-box centre) before any
    chain comes. With ``hlod``, the objects come grouped in LOD parents (:mod:`.city.hlod`): one
    :class:`CellChain` per cell of the coarsest tier, in grid order, each followed by the
    members it left out (objects or finer cells, drawn on their own)."""
    bakery = _Bakery(
        scene.source, options, executor or SerialExecutor(backend, progress), backend, warn,
        skipped, limits, strict, step, _object_count(scene), clock=clock or Clock(),
        pieces=pieces, lean=hlod is None,
    )  # fmt: skip
    nodes = scene.with_geometry()
    if first_at is not None:
        nodes = _first_told(nodes, first_at)
    if hlod is not None:
        yield from _cell_chains(nodes, options, hlod, bakery)
        return
    for chain in bakery.chains(_with_plot_radii(nodes, options)):
        if chain is not None:
            yield chain


def _first_told(
    nodes: Iterator[Node | PackedNode], first_at: Callable[[np.ndarray], None]
) -> Iterator[Node | PackedNode]:
    """``nodes``, telling ``first_at`` where the first lies (its bounding-box centre) as it
    passes."""
    first = next(nodes, None)
    if first is None:
        return
    first_at(np.array(first.placed_centre()))
    yield first
    yield from nodes


def _object_count(scene: Scene) -> int | None:
    """How many objects with geometry ``scene`` holds (``None``: unknown before reading)."""
    if scene.size is not None or not isinstance(scene.nodes, list):
        return scene.size
    return sum(1 for _ in with_geometry(scene.nodes))


@dataclass
class _Bakery:
    """Objects sent to an executor in batches and their outcomes taken in, in order, here in
    the main process: warnings told, skipped objects (bad geometry) reported and left out
    (``None``), progress stepped, and geometry placed by several nodes baked once (its key is
    decided here, where the nodes were read). With ``lean``, a chain whose piece of the output
    was made where it was baked comes without its geometry (:class:`~.tasks.BakeTask`)."""

    source: str
    options: ChainOptions
    executor: Executor
    backend: Backend
    warn: Message
    skipped: list[dict[str, str]] | None
    limits: Limits
    strict: bool
    step: Step = _no_step
    total: int | None = None
    plan_only: bool = False
    clock: Clock = field(default_factory=lambda: Clock())
    pieces: Pieces | None = None
    lean: bool = False
    done: int = 0

    def chains(
        self, objects: Iterable[tuple[Node | PackedNode, float | None]]
    ) -> Iterator[LodChain | ChainPlan | None]:
        """The chain (the plan, with ``plan_only``) of each of ``objects`` (each with the plot
        radius to use as its γ, or ``None``), in order; ``None`` for one that is skipped."""
        seen: set[int | None] = set()  # keys of geometry placed by a node sent before
        shared: dict[int, LodChain | ChainPlan] = {}
        # each object, and whether it was sent
        order: deque[tuple[Node | PackedNode, float | None, bool]] = deque()
        per_object = [0.0]

        def sent() -> Iterator[tuple[Node | PackedNode, ChainOptions]]:
            for node, radius in objects:
                key = id(node.geometry) if node.transform is not None else None
                first = key is None or key not in seen
                order.append((node, radius, first))
                if first:
                    seen.add(key)
                    yield node, self._options(radius)

        self.step("converting", self.done, self.total)  # the stage starts: nothing sent yet
        formatter = self.pieces.formatter if self.pieces is not None else None
        made = batches(
            sent(), per_object, self.limits, self.plan_only, formatter,
            self.executor.task_seconds, self.lean,
        )  # fmt: skip
        tasks = self.clock.iterate("plan", made)
        for result in self.clock.iterate("execute", self.executor.results(tasks)):
            per_object[0] = result.seconds / len(result.outcomes)
            for outcome in result.outcomes:
                while not order[0][2]:
                    yield self._reused(order.popleft(), shared)
                yield self._taken(order.popleft()[0], outcome, shared)
        while order:
            yield self._reused(order.popleft(), shared)

    def _options(self, radius: float | None) -> ChainOptions:
        """The options of an object whose plot radius is ``radius`` (γ, where given)."""
        return replace(self.options, gamma=radius) if radius is not None else self.options

    def _taken(
        self, obj: Node | PackedNode, outcome: Baked, shared: dict[int, LodChain | ChainPlan]
    ) -> LodChain | ChainPlan | None:
        """The chain of ``outcome`` for ``obj`` (placed by its transform, kept in ``shared``
        for other nodes of its geometry), or ``None`` when it was skipped."""
        for text in outcome.warnings:
            self.warn(text)
        try:
            if outcome.chain is None:
                return self._skip(obj, outcome.reason or "could not be converted")
            chain = outcome.chain
            if outcome.piece is not None and self.pieces is not None:
                self.pieces.add(chain, outcome.piece)
            if obj.transform is not None:
                shared.setdefault(id(obj.geometry), chain)
                chain = replace(chain, transform=np.asarray(obj.transform, dtype=np.float64))
            return chain
        finally:
            self.done += 1
            self.step("converting", self.done, self.total)

    def _reused(
        self,
        job: tuple[Node | PackedNode, float | None, bool],
        shared: dict[int, LodChain | ChainPlan],
    ) -> LodChain | ChainPlan | None:
        """The chain of an object whose geometry an earlier node placed: that node's chain
        with this one's id, attributes and placement (baked here when that node's failed)."""
        obj, radius, _ = job
        assert isinstance(obj, Node)  # placed by a transform: never packed
        base = shared.get(id(obj.geometry))
        if base is None:
            task = BakeTask(((obj, self._options(radius)),), self.limits, self.plan_only)
            return self._taken(obj, task.run(self.backend).outcomes[0], shared)
        try:
            text = obj.written()
            chain = replace(base, object_id=text.id, metadata=text.attributes, cut=text.cut)
            return replace(chain, transform=np.asarray(obj.transform, dtype=np.float64))
        except InputError as exc:
            return self._skip(obj, str(exc))
        finally:
            self.done += 1
            self.step("converting", self.done, self.total)

    def _skip(self, obj: Node | PackedNode, reason: str) -> None:
        """Report ``obj`` as skipped for ``reason``."""
        if self.total != 1 and not self.strict:  # with one object, the run's error says it
            self.warn(f"{self.source}: object {reason} — skipped")
        if self.skipped is not None:
            self.skipped.append({"id": obj.id, "reason": reason})


def _cell_chains(
    nodes: Iterable[Node | PackedNode], options: ChainOptions, hlod: HlodOptions, bakery: _Bakery
) -> Iterator[LodChain | CellChain]:
    """The objects ``nodes`` baked and grouped into LOD parents, one coarsest cell at a time
    (the objects wait on disk meanwhile, and go to be baked in the cells' order, so memory is
    bounded by the cells in flight), each followed by the members it left out; the cells are
    baked by the bakery's executor (:mod:`.city.cells`)."""
    hlod.check()
    with NodeSpool() as spool:
        centres, radii = _spooled(nodes, options, spool)
        plans = plan_cells(centres, hlod.sizes or (auto_size(centres),))
        order = (i for plan in plans for i in plan.object_indices())
        found = bakery.chains((spool.get(i), radii[i]) for i in order)
        baker = CellBaker(
            bakery.executor.results, options, hlod.kind, bakery.limits, bakery.warn, bakery.source
        )
        yield from baker.cells(plans, found)


def merged(scenes: Sequence[Scene]) -> Scene:
    """One scene of several inputs. City objects (nodes with their own LoDs) of the same id
    are one object whose LoDs are merged: the first keeps its attributes and children, takes
    the LoD labels it lacks from the later ones, and its geometry is its finest LoD. Other
    objects all stay, in input order (the writers keep their names apart). The first declared
    CRS is the scene's, with its vertical CRS and local frame (:func:`~.reproject.in_one_crs`
    puts every input in it first); a scene of one input is returned as it is."""
    if len(scenes) == 1:
        return scenes[0]
    nodes: list[Node] = []
    cities: dict[str, Node] = {}
    for scene in scenes:
        for node in scene.nodes:
            first = cities.setdefault(node.id, node) if node.lods else node
            if first is node:
                nodes.append(node)
                continue
            for label, mesh in node.lods.items():
                first.lods.setdefault(label, mesh)
            levels = source_levels(first.lods)
            first.geometry = levels[max(levels)][1] if levels else first.geometry
    declaring = next((scene for scene in scenes if scene.crs), None)
    crs = declaring.crs if declaring is not None else None
    whole = Scene(" + ".join(scene.source for scene in scenes), nodes, crs)
    if declaring is not None:  # its vertical CRS and local frame, where the reader found them
        whole.attributes.update(
            {k: v for k, v in declaring.attributes.items() if k in SOURCE_CRS_KEYS}
        )
    whole.city = any(scene.city for scene in scenes)
    tallies = [tally for scene in scenes if (tally := tally_of(scene)) is not None]
    if tallies:  # complete: every input's nodes have been read
        tally = InputTally(whole.source, tallies[0].limits)
        for part in tallies:
            tally.dropped_faces += part.dropped_faces
            tally.dropped_by_object.update(part.dropped_by_object)
            for entry in part.skipped:
                tally.add_skipped(entry["id"], entry["reason"])
            tally.unlisted += part.unlisted
        attach_tally(whole, tally)
    return whole


def _with_plot_radii(
    nodes: Iterator[Node | PackedNode], options: ChainOptions
) -> Iterator[tuple[Node | PackedNode, float | None]]:
    """``nodes`` (a scene's with geometry), each with the plot radius to use as its γ: unless
    ``options`` set γ, a city object's (a node with its own LoDs) comes from its neighbours'
    spacing (:mod:`.city.plots`), so a city is read through first, its nodes parked on disk
    (:class:`~.spool.NodeSpool`); a mesh file's nodes stay streamed (radius ``None``)."""
    first = next(nodes, None) if options.gamma is None else None
    if first is None or not first.is_city_object():
        for node in itertools.chain([first] if first is not None else [], nodes):
            yield node, None
        return
    with NodeSpool() as spool:
        _, radii = _spooled(itertools.chain([first], nodes), options, spool)
        yield from zip(spool, radii, strict=True)


def _spooled(
    nodes: Iterable[Node | PackedNode], options: ChainOptions, spool: NodeSpool
) -> tuple[np.ndarray, list[float | None]]:
    """Park ``nodes`` in ``spool``; their ground centres ((n, 2), scene coordinates) and the
    plot radius of each city object standing on the ground, from its neighbours among them
    (``None`` for others, terrain and ground covers among them, and for all where ``options``
    set γ)."""
    centres: list[tuple[float, float]] = []
    city: list[bool] = []
    for node in nodes:
        spool.add(node)
        centres.append(node.ground_centre())
        city.append(node.is_city_object() and node.type not in GROUND_COVERS)
    placed = np.array(centres, dtype=np.float64).reshape(-1, 2)
    radii: list[float | None] = [None] * len(placed)
    chosen = np.flatnonzero(city)
    if options.gamma is None and len(chosen):
        for i, radius in zip(chosen, plot_radii(placed[chosen]).tolist(), strict=True):
            radii[i] = radius
    return placed, radii


STAGES = ("read", "plan", "execute", "assemble", "write", "validate")
"""The timed stages of a run, in order (the commit that follows is not in the report it
writes)."""

Also = Callable[[Outputs, FileSink, dict[str, Any]], None]
"""``also(outputs, sink, report)``: stage more outputs of the run before its commit."""


@dataclass(frozen=True)
class RunOptions:
    """How one conversion runs: the chain options, the baker and how many processes bake
    (``workers``: 1 bakes in this process; ``None``: as many as the inputs' size pays for,
    :func:`~.tasks.default_workers`) or the dask scheduler whose workers do
    (``scheduler``: an address or a scheduler file), the report file, the readers' and writer's
    options, limits, ``strict`` (a broken object fails the run), LOD parents (``hlod``), what
    hears of progress, warnings and steps, and ``also`` (more outputs to stage)."""

    chain: ChainOptions = field(default_factory=ChainOptions)
    backend: str = "auto"
    workers: int | None = 1
    scheduler: str | None = None
    report_path: str | Path | None = None
    read_options: Mapping[str, Any] = field(default_factory=dict)
    write_options: Mapping[str, Any] = field(default_factory=dict)
    limits: Limits = DEFAULT_LIMITS
    strict: bool = False
    hlod: HlodOptions | None = None
    progress: Message = _quiet
    warn: Message = _quiet
    step: Step = _no_step
    also: Also | None = None

    def check(self) -> None:
        """Raise :class:`UsageError` for options out of range."""
        self.chain.check()
        if self.hlod is not None:
            self.hlod.check()
        if self.workers is not None and self.workers < 1:
            raise UsageError(f"must be at least 1, got {self.workers}", "workers")
        if self.scheduler is not None:
            _check_scheduler(self.scheduler, self.workers)


def convert(
    input_path: str | Path | Sequence[str | Path],
    output_path: str | Path,
    run: RunOptions | None = None,
) -> dict[str, Any]:
    """Convert ``input_path`` (several inputs: one scene, :func:`merged`) into ``output_path``
    as ``run`` says; return the report. Stages (:data:`STAGES`) stream into one another; every
    output (the model once it passes its checks, the report, what ``run.also`` stages) is
    committed together (:mod:`~lodconvert.sinks`). Raises :class:`UsageError` for bad options
    or output suffix and :class:`~lodconvert.errors.LodConvertError` for a bad output path,
    unreadable input, no object baked (with ``run.strict``: any skipped) or an output failing
    its checks; then nothing is written."""
    run = run or RunOptions()
    run.check()
    target = output_format(output_path)
    inputs = [input_path] if isinstance(input_path, str | Path) else list(input_path)
    sources = [input_format(path) for path in inputs]
    named = " + ".join(str(path) for path in inputs)
    for path in (output_path, run.report_path):
        _without_link_loop(path)
    folder = target.output_folder(Path(output_path)) if target.output_folder else None
    run = _resolved(run, inputs, folder)
    clock = Clock(*STAGES)
    with contextlib.ExitStack() as stack, Outputs(inputs=inputs) as outputs:
        sink = _sink(outputs, output_path, folder, inputs, run)
        report_sink = outputs.file(run.report_path) if run.report_path is not None else None
        scene, crs_record, baker, executor = _read_stage(
            inputs, sources, run, clock, stack, target.georeferenced
        )
        assembly = _Assembly(scene, _output_info(inputs, scene, crs_record, run.chain), run.hlod)
        pieces = _pieces(target, assembly.info, run, executor)
        skipped: list[dict[str, str]] = []
        along = stack.enter_context(_check_along(sink, output_path, executor))
        items = iter_chains(
            scene, run.chain, baker, run.progress, run.warn, skipped, run.step, run.limits,
            run.strict, run.hlod, executor, clock, pieces, assembly.first_at,
        )  # fmt: skip
        with clock("write"):
            chains = clock.iterate("assemble", assembly.recorded(items))
            target.write_chains(
                chains, sink, assembly.info, executor=executor, progress=run.progress,
                pieces=pieces, **run.write_options,
            )  # fmt: skip
        tally = _finished(scene, assembly.records, skipped, run, named)
        with clock("validate"):
            _checked(sink, output_path, run.step, along)
        report = assembly.report(named, output_path, baker, run, skipped, clock, tally, crs_record)
        if run.also is not None:
            run.also(outputs, sink, report)
        if report_sink is not None:
            _stage_report(report_sink, report)
    return report


def _without_link_loop(path: str | Path | None) -> None:
    """Raise :class:`InputError` naming the output ``path`` when a link on its way leads
    back to itself (a link loop: nothing can be written through it)."""
    if path is None:
        return
    for step in (*reversed(Path(path).parents), Path(path)):
        try:
            step.resolve()
        except (RuntimeError, OSError):  # RuntimeError up to Python 3.12, OSError from 3.13
            raise InputError(
                f"cannot write here: {str(step)!r} is a link loop", str(path)
            ) from None


def _resolved(run: RunOptions, inputs: Sequence[str | Path], folder: Path | None) -> RunOptions:
    """``run`` with what it leaves open decided: LOD parents for a folder output (``folder``),
    and where it gives no ``workers``, as many as the size of ``inputs`` pays for
    (:func:`~.tasks.default_workers`; 1 with a scheduler)."""
    if folder is not None and run.hlod is None:
        run = replace(run, hlod=HlodOptions())
    if run.workers is None:
        size = sum(inflated_size(Path(path)) for path in inputs)
        run = replace(run, workers=1 if run.scheduler else default_workers(size))
    return run


def _sink(
    outputs: Outputs,
    output_path: str | Path,
    folder: Path | None,
    inputs: Sequence[str | Path],
    run: RunOptions,
) -> FileSink | DirectorySink:
    """Where the output is staged: ``folder`` (a folder output, under its resume key) or the
    file ``output_path``."""
    if folder is None:
        return outputs.file(output_path)
    return outputs.directory(folder, resume=_resume_key(inputs, run))


def _read_stage(
    inputs: Sequence[str | Path],
    sources: Sequence[Any],
    run: RunOptions,
    clock: Clock,
    stack: contextlib.ExitStack,
    georeferenced: bool = False,
) -> tuple[Scene, dict[str, Any], Backend, Executor]:
    """The ``read`` stage: the scene of ``inputs`` and the report's ``crs`` (``georeferenced``:
    for an output placed on the globe by its CRS, :func:`read_inputs`), the baker and the
    executor, entered on ``stack`` (which reads too, where the reader spreads its work)."""
    others = run.workers > 1 or run.scheduler is not None  # processes other than this one
    spread = {"spread": others and len(inputs) == 1 and _read_through(run)}
    baker = get_backend(run.backend)
    # a cluster is reached first: an unreachable scheduler fails the run before any reading;
    # workers that will read are started first, so that they start while this process reads
    early = run.scheduler or (spread["spread"] and "spread" in sources[0].read_options)
    executor = stack.enter_context(_executor(run, baker, None)) if early else None
    with clock("read"):
        scene, crs_record = read_inputs(
            inputs, {**run.read_options, **spread}, run.limits, sources, run.warn, georeferenced
        )
    stack.enter_context(_input_kept_out_of_gc())
    executor = executor or stack.enter_context(_executor(run, baker, _object_count(scene)))
    if scene.spread is not None:  # reading (its rest, or all of it) by the executor
        with clock("read"):
            scene.spread(executor.results, run.progress, executor.task_seconds)
    return scene, crs_record, baker, executor


def _pieces(target: Format, info: OutputInfo, run: RunOptions, executor: Executor) -> Pieces | None:
    """Where the chains' pieces of the output (``target``'s formatter) are kept, made by the
    workers that bake them; ``None`` where this process bakes (it formats as it writes)."""
    return None if isinstance(executor, SerialExecutor) else target.pieces(info, run.write_options)


def _finished(
    scene: Scene, records: Records, skipped: list[dict[str, str]], run: RunOptions, named: str
) -> InputTally | None:
    """The reader's skipped objects added to ``skipped`` (told to ``run.warn`` unless nothing
    was converted or the run is strict), the run failed where nothing (strict: not
    everything) was converted; the reader's tally."""
    tally = _reader_skipped(scene, skipped, run.warn if records and not run.strict else _quiet)
    _check_converted(records, skipped, run.strict, named)
    return tally


def _resume_key(inputs: Sequence[str | Path], run: RunOptions) -> str:
    """The key under which a folder output is staged, so that an interrupted run's folder is
    taken up again by the same command: a hash of the inputs (path, size, modification time)
    and of every option that changes the output (not of ``workers``, which does not)."""
    what = {
        "version": __version__,
        "inputs": [(str(Path(path).resolve()), _stat(path)) for path in inputs],
        "chain": options_record(run.chain),
        "hlod": asdict(run.hlod) if run.hlod is not None else None,
        "backend": run.backend,
        "read": dict(run.read_options),
        "write": dict(run.write_options),
        "limits": asdict(run.limits),
        "strict": run.strict,
    }
    text = json.dumps(what, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _stat(path: str | Path) -> tuple[int, int] | None:
    """Size and modification time (ns) of ``path``; ``None`` where it cannot be read (its
    reader says why)."""
    try:
        found = os.stat(path)
    except OSError:
        return None
    return found.st_size, found.st_mtime_ns


def _check_along(
    sink: FileSink | DirectorySink, output_path: str | Path, executor: Executor
) -> contextlib.AbstractContextManager[CheckAlong | None]:
    """The check of the file ``sink`` stages, run while it is written where other processes
    bake (so that this one mostly waits) and its format is checked as a stream; else
    ``None``: it is checked once written."""
    if isinstance(sink, DirectorySink) or isinstance(executor, SerialExecutor):
        return contextlib.nullcontext()
    if not streamed_check(output_path):
        return contextlib.nullcontext()
    return CheckAlong(sink.staged.temp, output_path)


def _checked(
    sink: FileSink | DirectorySink, output_path: str | Path, step: Step, along: CheckAlong | None
) -> None:
    """Check the staged output of ``sink`` by its format (a folder's: its file named like
    ``output_path``), or take the result of ``along``, its check while it was written;
    ``step`` hears when."""
    step("checking", 0, 1)
    staged = sink.staged.temp
    if isinstance(sink, DirectorySink):
        staged = staged / Path(output_path).name
    if along is not None:
        along.result()
    else:
        check_written(staged, output_path)
    step("checking", 1, 1)


def _stage_report(sink: FileSink, report: dict[str, Any]) -> None:
    """Stage ``report`` as the run's ``--report`` file."""
    with sink.open() as stream:
        for piece in report_text(report):
            stream.write(piece.encode())


def _check_scheduler(scheduler: str, workers: int | None) -> None:
    """:class:`UsageError` unless dask.distributed is installed, ``scheduler`` is an address or
    a scheduler file, and ``workers`` is 1 or left open (the cluster's workers read and
    bake)."""
    if workers not in (1, None):
        raise UsageError(
            "is for this machine's processes; with a dask scheduler, its workers read and bake",
            "workers",
        )
    try:
        from .dask_executor import scheduler_address
    except ImportError:
        raise UsageError(
            "needs dask.distributed: pip install '.[dask]' in a clone of lodconvert", "scheduler"
        ) from None
    scheduler_address(scheduler)


def _executor(run: RunOptions, backend: Backend, objects: int | None) -> Executor:
    """Where the run's objects are baked: by the workers of ``run.scheduler``, in
    ``run.workers`` processes, each with a backend like ``backend``, or in this one with
    ``backend`` (one worker, or one object)."""
    if run.scheduler is not None:
        from .dask_executor import DaskExecutor

        return DaskExecutor(run.scheduler, backend.name, run.progress)
    if run.workers == 1 or objects == 1:
        return SerialExecutor(backend, run.progress)
    run.progress(f"{run.workers} worker processes")
    return PoolExecutor(run.workers, backend.name, run.progress)


def _read_through(run: RunOptions) -> bool:
    """Whether a city is read through before its first object is baked (its plot radii or
    its LOD parents need every object): then the executor can read it first (with γ given,
    objects are baked as they are read, so reading stays in the main process)."""
    return run.chain.gamma is None or run.hlod is not None


def _output_info(
    inputs: Sequence[str | Path], scene: Scene, crs_record: dict[str, Any], options: ChainOptions
) -> OutputInfo:
    """What the writers record of the run."""
    return OutputInfo(
        generator=f"lodconvert {__version__}",
        source=" + ".join(Path(path).name for path in inputs),
        crs=scene.crs,
        vertical=crs_record["vertical"] if scene.city else None,
        view=options.view,
        options=options_record(options),
        city=scene.city,
        georef=_georef(scene),
    )


def _georef(scene: Scene) -> Georef | None:
    """Where ``scene``'s coordinates lie; ``None`` without a CRS or with one pyproj does not
    know."""
    import pyproj

    try:
        return Georef.of(scene)
    except pyproj.exceptions.CRSError:
        return None


@dataclass
class _Assembly:
    """What the run records of each baked item as the writer takes it: the objects' records,
    the LOD parents and their draw counts, and the writers' scene frame (at the first object)."""

    scene: Scene
    info: OutputInfo
    hlod: HlodOptions | None
    records: Records = field(default_factory=Records)
    cells: list[dict[str, Any]] = field(default_factory=list)
    draw: dict[str, dict[str, int]] = field(default_factory=lambda: {"without": {}, "with": {}})
    frame: SceneFrame | None = None
    started: bool = False

    def first_at(self, centre: np.ndarray) -> None:
        """Where the input's first object lies: the scene frame's origin, for the writer too
        (:attr:`~.io.OutputInfo.origin`), whatever the LOD parents bake first."""
        self.info.origin = centre

    def recorded(self, items: Iterable[LodChain | CellChain]) -> Iterator[LodChain | CellChain]:
        """``items``, each recorded as it passes."""
        tally = tally_of(self.scene)
        dropped = tally.dropped_by_object if tally is not None else {}
        for item in items:
            if not self.started:
                frame = scene_frame(self.info.framed, item, self.info.origin)
                self.frame, self.started = frame, True
            objects = item.objects()
            for chain in objects:
                self.records.append(
                    {**chain_record(chain), "dropped_faces": dropped.get(chain.object_id, 0)}
                )
            if isinstance(item, CellChain):
                self.cells.extend(cell_record(cell) for cell in item.cells())
            if self.hlod is not None:
                _add_counts(self.draw["without"], draw_counts(objects))
                _add_counts(self.draw["with"], draw_counts([item]))
            yield item

    def report(
        self,
        named: str,
        output_path: str | Path,
        baker: Backend,
        run: RunOptions,
        skipped: list[dict[str, str]],
        clock: Clock,
        tally: InputTally | None,
        crs_record: dict[str, Any],
    ) -> dict[str, Any]:
        """The ``--report`` of the run."""
        report = run_report(
            named, output_path, baker, run.chain, self.records, skipped, clock.timings, tally
        )
        report["crs"] = crs_record
        report["up"] = "z" if self.info.city else run.read_options.get("up") or "y"
        report["frame"] = self.frame.record() if self.frame is not None else None
        if self.hlod is not None:
            report["hlod"] = {"kind": self.hlod.kind, "cells": self.cells, "draw": self.draw}
        return report


def _check_converted(
    records: Records, skipped: list[dict[str, str]], strict: bool, named: str
) -> None:
    """Raise :class:`InputError` when no object of ``named`` was converted or, with ``strict``,
    when any was skipped."""
    if strict and skipped:
        more = f" (and {len(skipped) - 1} more)" if len(skipped) > 1 else ""
        raise InputError(
            f"object {skipped[0]['reason']}{more} (--strict: a broken object fails the run)", named
        )
    if not records:
        raise _none_converted(skipped, named)


def read_inputs(
    inputs: Sequence[str | Path],
    read_options: dict[str, Any] | None = None,
    limits: Limits = DEFAULT_LIMITS,
    sources: Sequence[Any] | None = None,
    warn: Message = _quiet,
    georeferenced: bool = False,
) -> tuple[Scene, dict[str, Any]]:
    """The scene of ``inputs`` (one, or several in one CRS and merged: :func:`merged`), each
    read by its format (in ``sources`` where the caller found them) with the options it takes,
    and the report's ``crs`` (:func:`~.reproject.in_one_crs`; ``georeferenced``: for an
    output placed on the globe by its CRS, an input without one beside one with one is an
    error)."""
    if (read_options or {}).get("crs") is not None:
        checked_crs_option(read_options["crs"])
    sources = sources or [input_format(path) for path in inputs]
    if (read_options or {}).get("up") is not None:
        _check_up(inputs, sources)
    scenes = [
        source.read_file(path, limits=limits, **(read_options or {}))
        for source, path in zip(sources, inputs, strict=True)
    ]
    for scene in scenes if (read_options or {}).get("crs") is not None else ():
        if not scene.city:
            warn(
                f"{scene.source}: not a city model: --crs is not applied (a mesh keeps its own "
                "axes and coordinates)"
            )
    one_crs = in_one_crs(scenes, warn, georeferenced)
    return merged(one_crs.scenes), one_crs.record


def _check_up(inputs: Sequence[str | Path], sources: Sequence[Format]) -> None:
    """:class:`UsageError` where an up axis is given for an input whose reader takes none: a
    city model, z-up by definition and turned y-up by its frame (:mod:`.io.frame`)."""
    for path, source in zip(inputs, sources, strict=True):
        if "up" not in source.read_options:
            raise UsageError(
                f"is for mesh files; {path} is a city model, z-up by definition (its scene is "
                "turned y-up already)",
                "up",
            )


def _reader_skipped(
    scene: Scene, skipped: list[dict[str, str]], warn: Message
) -> InputTally | None:
    """Add the objects the reader of ``scene`` skipped to ``skipped``, each told to ``warn``
    (with nothing converted, the run's error says it), those past the listed ones in one
    line; ``scene``'s tally."""
    tally = tally_of(scene)
    for entry in tally.skipped if tally is not None else ():
        warn(f"{scene.source}: object {entry['reason']} — skipped")
        skipped.append(entry)
    if tally is not None and tally.unlisted:
        warn(f"{scene.source}: {tally.unlisted:,} more objects skipped (not listed)")
    return tally


def _none_converted(skipped: list[dict[str, str]], source: str) -> InputError:
    """The error of a run in which no object of ``source`` could be converted (``skipped``:
    why)."""
    reason = (
        skipped[0]["reason"]
        if len(skipped) == 1
        else f"none of its {len(skipped)} objects could be converted"
    )
    return InputError(reason, source)


@contextlib.contextmanager
def _input_kept_out_of_gc() -> Iterator[None]:
    """Move what exists now (the input as read) out of the cyclic garbage collector's full
    passes for the rest of the run: with tens of thousands of objects those passes re-scan it
    again and again (a third of the run time at 10,000 objects) and free none of it."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def object_ranges(
    scene: Scene, options: ChainOptions, warn: Message = _quiet
) -> list[dict[str, Any]]:
    """α, γ, the levels and the cutoffs of every object of ``scene`` (:func:`read_inputs`) as
    :func:`convert` plans them (:func:`~.plans.plan_chain`), without baking: a level to bake
    (``to_bake``) is kept, and its cutoff with it, where baking finds it cheaper than the level
    before and faithful. Objects that cannot be converted are reported through ``warn`` and
    left out; when none can, :class:`InputError`."""
    options.check()
    skipped: list[dict[str, str]] = []
    backend = get_backend("numpy")  # plans bake nothing
    plan = _Bakery(
        scene.source, options, SerialExecutor(backend), backend, warn, skipped, DEFAULT_LIMITS,
        strict=False, total=_object_count(scene), plan_only=True,
    )  # fmt: skip
    rows = [
        _range_record(planned, options)
        for planned in plan.chains(_with_plot_radii(scene.with_geometry(), options))
        if isinstance(planned, ChainPlan)
    ]
    _reader_skipped(scene, skipped, warn if rows else _quiet)
    if not rows:
        raise _none_converted(skipped, scene.source)
    return rows


def _range_record(plan: ChainPlan, options: ChainOptions) -> dict[str, Any]:
    """What ``lodconvert ranges`` says of one object's plan."""
    levels = []
    for planned in plan.levels:
        entry: dict[str, Any] = {"name": planned.name}
        if planned.level is not None:
            entry["kind"] = planned.level.kind
        else:
            entry.update(kind=options.level_kind(planned.index), to_bake=True)
        levels.append(entry)
    return {
        "id": plan.object_id,
        "alpha": plan.alpha,
        "beta": plan.beta,
        "gamma": plan.gamma,
        "xs": plan.xs,
        "cutoffs": plan.cutoffs,
        "levels": levels,
        "dropped": dict(plan.dropped),
        "unused": dict(plan.unused),
    }
