"""The conversion as stages over data, with one :class:`RunOptions`: read (:mod:`.inputs`) →
plan tasks and execute them (:mod:`.bakery`, on the run's executor: :mod:`.tasks`) → assemble
(:class:`~.report.Assembly`) → write → check → commit every output together (:mod:`.sinks`).
Each stage is timed; docs/architecture.md draws them."""

from __future__ import annotations

import contextlib
import gc
import hashlib
import json
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from .bake import Backend, get_backend
from .bakery import check_converted, iter_chains, object_count
from .chain import ChainOptions
from .city.hlod import HlodOptions
from .clock import Clock
from .context import Message, RunContext, Step, no_step, quiet
from .errors import InputError, UsageError
from .inputs import read_inputs, reader_skipped
from .io import Format, OutputInfo, Pieces, input_format, output_format
from .io.archive import inflated_size
from .io.geometry_checks import InputTally
from .limits import DEFAULT_LIMITS, Limits
from .model import Scene
from .report import Assembly, Records, options_record, report_text
from .reproject import Georef
from .sinks import DirectorySink, FileSink, Outputs
from .tasks import Executor, PoolExecutor, SerialExecutor, default_workers
from .validate import check_written, streamed_check
from .validate.along import CheckAlong
from .version import __version__

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
    hlod_kind: str = "auto"
    """The far-level kind of the LOD parents an output format has without ``hlod`` (3D
    Tiles')."""
    progress: Message = quiet
    warn: Message = quiet
    step: Step = no_step
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
    run = _resolved(run, inputs, target)
    clock = Clock(*STAGES)
    with contextlib.ExitStack() as stack, Outputs(inputs=inputs) as outputs:
        sink = _sink(outputs, output_path, folder, inputs, run)
        report_sink = outputs.file(run.report_path) if run.report_path is not None else None
        scene, crs_record, context = _read_stage(
            inputs, sources, run, clock, stack, target.georeferenced
        )
        executor = context.executor
        assembly = Assembly(scene, _output_info(inputs, scene, crs_record, run.chain), run.hlod)
        pieces = _pieces(target, output_path, assembly.info, run, executor)
        along = stack.enter_context(_check_along(sink, output_path, executor))
        packed = target.takes_packed and not isinstance(executor, SerialExecutor)
        items = iter_chains(scene, run.chain, context, run.hlod, pieces, assembly.first_at, packed)
        with clock("write"):
            chains = clock.iterate("assemble", assembly.recorded(items))
            target.write_chains(chains, sink, assembly.info, context, pieces, **run.write_options)
        tally = _finished(scene, assembly.records, context.skipped, run, named)
        with clock("validate"):
            _checked(sink, output_path, run.step, along)
        report = assembly.report(
            named, output_path, context.backend, run.chain, run.read_options.get("up"),
            context.skipped, clock, tally, crs_record,
        )  # fmt: skip
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


def _resolved(run: RunOptions, inputs: Sequence[str | Path], target: Format) -> RunOptions:
    """``run`` with what it leaves open decided, once: LOD parents for a format that always
    has them (:attr:`~.io.Format.lod_parents`: 3D Tiles), of ``run.hlod_kind``; and where it
    gives no ``workers``, as many as the size of ``inputs`` pays for
    (:func:`~.tasks.default_workers`; 1 with a scheduler). :class:`UsageError` for a far-level
    kind without LOD parents."""
    if run.hlod is None and target.lod_parents:
        run = replace(run, hlod=HlodOptions(kind=run.hlod_kind))
    if run.hlod is None and run.hlod_kind != "auto":
        raise UsageError("is for the cells that --hlod makes", "hlod_kind")
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
    sources: Sequence[Format],
    run: RunOptions,
    clock: Clock,
    stack: contextlib.ExitStack,
    georeferenced: bool = False,
) -> tuple[Scene, dict[str, Any], RunContext]:
    """The ``read`` stage: the scene of ``inputs`` and the report's ``crs`` (``georeferenced``:
    for an output placed on the globe by its CRS, :func:`read_inputs`), and the run's context
    with its executor, entered on ``stack``; a city read through by a format that reads on
    workers is read by that executor's workers."""
    others = run.workers > 1 or run.scheduler is not None  # processes other than this one
    spread = others and len(inputs) == 1 and _read_through(run) and sources[0].reads_on_workers
    baker = get_backend(run.backend)

    def context_of(executor: Executor) -> RunContext:
        return RunContext(
            executor, baker, run.progress, run.warn, run.step, clock, run.limits, run.strict
        )

    # a cluster is reached first: an unreachable scheduler fails the run before any reading;
    # workers that will read are started first, so that they start while this process reads
    early = None
    if run.scheduler or spread:
        early = context_of(stack.enter_context(_executor(run, baker, None)))
    with clock("read"):
        scene, crs_record = read_inputs(
            inputs, dict(run.read_options), run.limits, sources, run.warn, georeferenced,
            early if spread else None,
        )  # fmt: skip
    stack.enter_context(_input_kept_out_of_gc())
    if early is not None:
        return scene, crs_record, early
    executor = stack.enter_context(_executor(run, baker, object_count(scene)))
    return scene, crs_record, context_of(executor)


def _pieces(
    target: Format, output_path: str | Path, info: OutputInfo, run: RunOptions, executor: Executor
) -> Pieces | None:
    """Where the chains' pieces of the output ``output_path`` (``target``'s formatter) are
    kept, made by the workers that bake them; ``None`` where this process bakes (it formats as
    it writes)."""
    if isinstance(executor, SerialExecutor):
        return None
    return target.pieces(info, run.write_options, Path(output_path).suffix.lower())


def _finished(
    scene: Scene, records: Records, skipped: list[dict[str, str]], run: RunOptions, named: str
) -> InputTally | None:
    """The reader's skipped objects added to ``skipped`` (told to ``run.warn`` unless nothing
    was converted or the run is strict), the run failed where nothing (strict: not
    everything) was converted; the reader's tally."""
    tally = reader_skipped(scene, skipped, run.warn if records and not run.strict else quiet)
    check_converted(records, skipped, run.strict, named)
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
    return sink.with_staged(lambda staged: CheckAlong(staged, output_path))


def _checked(
    sink: FileSink | DirectorySink, output_path: str | Path, step: Step, along: CheckAlong | None
) -> None:
    """Check the staged output of ``sink`` by its format (a folder's: its file named like
    ``output_path``), or take the result of ``along``, its check while it was written;
    ``step`` hears when."""
    step("checking", 0, 1)
    if along is not None:
        along.result()
    elif isinstance(sink, DirectorySink):  # its tiles' contents were checked as they were made
        name = Path(output_path).name
        sink.with_staged(lambda staged: check_written(staged, output_path, False), name)
    else:
        sink.with_staged(lambda staged: check_written(staged, output_path))
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
