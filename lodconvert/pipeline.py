"""The conversion session: read → bake each object → stream chains into the writer → check →
commit every output together.

Readers are free of processing and writers of baking; this module joins them, times each step
and collects what the ``--report`` file records. One object that cannot be baked is reported and
skipped; when none can, the conversion fails and no output file appears.
"""

from __future__ import annotations

import contextlib
import gc
import itertools
import platform
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .bake import Backend, get_backend
from .chain import ChainOptions, ChainPlan, bake_chain, plan_chain
from .errors import InputError
from .hlod import CellPlan, HlodOptions, auto_size, bake_cell, draw_counts, plan_cells
from .io import OutputInfo, input_format, output_format
from .io.crs import checked_crs_option
from .io.frame import SceneFrame, scene_frame
from .io.geometry_checks import InputTally, attach_tally, tally_of
from .limits import DEFAULT_LIMITS, Limits
from .model import CellChain, LodChain, Node, Scene
from .plots import plot_radii
from .records import Records, report_text
from .reproject import in_one_crs
from .sinks import FileSink, Outputs
from .sourcelods import GROUND_COVERS, source_levels
from .spool import NodeSpool
from .validate import check_written

Message = Callable[[str], None]
Step = Callable[[str, int, "int | None"], None]
"""``step(stage, done, total)``: ``done`` of ``total`` (``None``: unknown) items finished."""


def _quiet(_: str) -> None:
    """Discard a message."""


def _no_step(stage: str, done: int, total: int | None) -> None:
    """Discard a progress count."""


def options_record(options: ChainOptions) -> dict[str, Any]:
    """The chain options as JSON-able values (recorded in outputs and reports)."""
    record = asdict(options)
    record["view"] = {"height_px": options.view.height_px, "fov_y_deg": options.view.fov_y_deg}
    record["xs"] = list(options.exponents)
    return {k: list(v) if isinstance(v, tuple) else v for k, v in record.items()}


def cell_record(cell: CellChain) -> dict[str, Any]:
    """What the report says of one LOD parent."""
    return {
        "id": cell.cell_id,
        "tier": cell.tier,
        "size": cell.size,
        "members": cell.member_ids(),
        "cutoffs": list(cell.cutoffs),
        "alpha": cell.alpha,
        "gamma": cell.gamma,
        "far": {"kind": cell.far.kind, "count": cell.far.count},
        **{key: value for key, value in cell.facts.items() if key != "members"},
    }


def _add_counts(total: dict[str, int], more: dict[str, int]) -> None:
    for key, value in more.items():
        total[key] = total.get(key, 0) + value


def chain_record(chain: LodChain) -> dict[str, Any]:
    """What the report says of one baked object."""
    levels = []
    for level in chain.levels:
        entry: dict[str, Any] = {"name": level.name, "kind": level.kind, "count": level.count}
        if not level.is_points:
            assert level.mesh is not None
            entry["faces"] = len(level.mesh.faces)
            if level.silhouette_f is not None:
                entry["silhouette_f"] = round(level.silhouette_f, 4)
        else:
            assert level.params is not None
            entry.update(
                resolution=level.params.resolution,
                slices=level.params.slices,
                point_size_px=level.params.point_size,
                filter=level.params.filter,
                spacing=level.spacing,
                design_distance=level.design_distance,
                bake_seconds=round(level.bake_seconds, 4),
            )
        levels.append(entry)
    return {
        "id": chain.object_id,
        "alpha": chain.alpha,
        "beta": chain.beta,
        "gamma": chain.gamma,
        "xs": list(chain.xs),
        "cutoffs": list(chain.cutoffs),
        "culled": chain.culled,
        "origin": [float(v) for v in chain.origin],
        "levels": levels,
        "dropped": dict(chain.dropped),
        "unused": dict(chain.unused),
        **({"cut": list(chain.cut)} if chain.cut else {}),
    }


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
) -> Iterator[LodChain | CellChain]:
    """Bake the scene's objects one at a time; objects with bad geometry are reported through
    ``warn`` (unless ``strict``: the caller fails), recorded in ``skipped`` and left out.
    ``step`` hears how many are done. With ``hlod``, the objects come grouped in LOD parents
    (:mod:`.hlod`): one :class:`CellChain` per cell of the coarsest tier, in grid order, each
    followed by the members it left out (objects or finer cells, drawn on their own)."""
    bake = _ObjectBaker(scene.source, options, backend, progress, warn, skipped, limits, strict)
    bake.step, bake.total = step, _object_count(scene)
    if hlod is not None:
        yield from _cell_chains(scene, options, hlod, bake)
        return
    for obj, radius in _with_plot_radii(scene, options):
        chain = bake(obj, radius)
        if chain is not None:
            yield chain


def _object_count(scene: Scene) -> int | None:
    """How many objects with geometry ``scene`` holds (``None``: unknown before reading)."""
    if scene.size is not None or not isinstance(scene.nodes, list):
        return scene.size
    return sum(1 for node in scene.nodes for n in node.walk() if n.geometry is not None)


@dataclass
class _ObjectBaker:
    """Bakes one object at a time (without a ``backend``: plans it, bakes nothing): geometry
    placed by several nodes once, objects with bad geometry reported and left out (``None``)."""

    source: str
    options: ChainOptions
    backend: Backend | None
    progress: Message
    warn: Message
    skipped: list[dict[str, str]] | None
    limits: Limits
    strict: bool
    step: Step = _no_step
    total: int | None = None
    done: int = 0
    shared: dict[int, Any] = field(default_factory=dict)

    def __call__(self, obj: Node, radius: float | None) -> Any:
        """The chain of ``obj`` (its plan without a backend; γ = ``radius`` where given), or
        None when it is skipped."""
        chain: LodChain | ChainPlan
        try:
            if obj.transform is not None and id(obj.geometry) in self.shared:
                base = self.shared[id(obj.geometry)]
                text = obj.written()
                chain = replace(base, object_id=text.id, metadata=text.attributes, cut=text.cut)
            else:
                opts = replace(self.options, gamma=radius) if radius is not None else self.options
                chain = plan_chain(obj, opts) if self.backend is None else bake_chain(
                    obj, opts, self.backend, progress=self.progress, warn=self.warn,
                    limits=self.limits,
                )  # fmt: skip
            if obj.transform is not None:
                self.shared.setdefault(id(obj.geometry), chain)
                chain = replace(chain, transform=np.asarray(obj.transform, dtype=np.float64))
        except InputError as exc:
            if self.total != 1 and not self.strict:  # with one object, the run's error says it
                self.warn(f"{self.source}: object {exc} — skipped")
            if self.skipped is not None:
                self.skipped.append({"id": obj.id, "reason": str(exc)})
            return None
        finally:
            self.done += 1
            self.step("converting", self.done, self.total)
        return chain


def _cell_chains(
    scene: Scene, options: ChainOptions, hlod: HlodOptions, bake: _ObjectBaker
) -> Iterator[LodChain | CellChain]:
    """The scene's objects baked and grouped into LOD parents, one coarsest cell at a time
    (the objects wait on disk meanwhile, so memory is bounded by a cell), each followed by
    the members it left out."""
    hlod.check()
    with NodeSpool() as spool:
        centres, radii = _spooled(scene.with_geometry(), options, spool)
        sizes = hlod.sizes or (auto_size(centres),)

        def baked(plan: CellPlan) -> list[LodChain | CellChain]:
            """The cell of ``plan`` (if it admits any member) and the members it left out."""
            if plan.tier == 1:
                found = [bake(spool.get(i), radii[i]) for i in plan.objects]
                members = [m for m in found if m is not None]
            else:
                members = [item for cell in plan.cells for item in baked(cell)]
            if not members:
                return []
            cell, left_out = bake_cell(
                plan, members, options, hlod.kind, bake.backend, bake.warn, bake.limits
            )
            return ([cell] if cell is not None else []) + left_out

        for plan in plan_cells(centres, sizes):
            yield from baked(plan)


def merged(scenes: Sequence[Scene]) -> Scene:
    """One scene of several inputs. City objects (nodes with their own LoDs) of the same id
    are one object whose LoDs are merged: the first keeps its attributes and children, takes
    the LoD labels it lacks from the later ones, and its geometry is its finest LoD. Other
    objects all stay, in input order (the writers keep their names apart). The first declared
    CRS is the scene's (:func:`~.reproject.in_one_crs` puts every input in it first); a scene
    of one input is returned as it is."""
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
    crs = next((scene.crs for scene in scenes if scene.crs), None)
    whole = Scene(" + ".join(scene.source for scene in scenes), nodes, crs)
    whole.city = any(scene.city for scene in scenes)
    tallies = [tally for scene in scenes if (tally := tally_of(scene)) is not None]
    if tallies:  # complete: every input's nodes have been read
        tally = InputTally(whole.source, tallies[0].limits)
        for part in tallies:
            tally.dropped_faces += part.dropped_faces
            tally.dropped_by_object.update(part.dropped_by_object)
            tally.skipped += part.skipped
        attach_tally(whole, tally)
    return whole


def _with_plot_radii(scene: Scene, options: ChainOptions) -> Iterator[tuple[Node, float | None]]:
    """The scene's nodes with geometry, each with the plot radius to use as its γ: unless
    ``options`` set γ, a city object's (a node with its own LoDs) comes from its neighbours'
    spacing (:mod:`.plots`), so a city is read through first, its nodes parked on disk
    (:class:`~.spool.NodeSpool`); a mesh file's nodes stay streamed (radius ``None``)."""
    nodes = scene.with_geometry()
    first = next(nodes, None) if options.gamma is None else None
    if first is None or not first.lods:
        for node in itertools.chain([first] if first is not None else [], nodes):
            yield node, None
        return
    with NodeSpool() as spool:
        _, radii = _spooled(itertools.chain([first], nodes), options, spool)
        yield from zip(spool, radii, strict=True)


def _spooled(
    nodes: Iterable[Node], options: ChainOptions, spool: NodeSpool
) -> tuple[np.ndarray, list[float | None]]:
    """Park ``nodes`` in ``spool``; their ground centres ((n, 2), scene coordinates) and the
    plot radius of each city object standing on the ground, from its neighbours among them
    (``None`` for others, terrain and ground covers among them, and for all where ``options``
    set γ)."""
    centres: list[tuple[float, float]] = []
    city: list[bool] = []
    for node in nodes:
        spool.add(node)
        centres.append(_ground_centre(node))
        city.append(bool(node.lods) and node.type not in GROUND_COVERS)
    placed = np.array(centres, dtype=np.float64).reshape(-1, 2)
    radii: list[float | None] = [None] * len(placed)
    chosen = np.flatnonzero(city)
    if options.gamma is None and len(chosen):
        for i, radius in zip(chosen, plot_radii(placed[chosen]).tolist(), strict=True):
            radii[i] = radius
    return placed, radii


def _ground_centre(node: Node) -> tuple[float, float]:
    """Where ``node``'s bounding-box centre is, seen from above, in scene coordinates."""
    centre = np.append(node.geometry.bounds.mean(axis=0), 1.0)
    if node.transform is not None:
        centre = np.asarray(node.transform, dtype=np.float64) @ centre
    x, y = node.offset[:2] + centre[:2]
    return float(x), float(y)


def convert(
    input_path: str | Path | Sequence[str | Path],
    output_path: str | Path,
    options: ChainOptions | None = None,
    backend: str = "auto",
    progress: Message = _quiet,
    warn: Message = _quiet,
    report_path: str | Path | None = None,
    step: Step = _no_step,
    read_options: dict[str, Any] | None = None,
    write_options: dict[str, Any] | None = None,
    also: Callable[[Outputs, FileSink, dict[str, Any]], None] | None = None,
    limits: Limits = DEFAULT_LIMITS,
    strict: bool = False,
    hlod: HlodOptions | None = None,
) -> dict[str, Any]:
    """Convert ``input_path`` (or several inputs: one scene, see :func:`merged`) into
    ``output_path`` and return the report (a JSON-able dict); with ``strict``, an object
    skipped as broken fails the run.

    Every output of the run is staged and committed together (:mod:`~lodconvert.sinks`): the
    model file, after it passes its format's structural checks; the report at
    ``report_path`` when given; and whatever ``also`` stages (it is called with the run's
    :class:`~lodconvert.sinks.Outputs`, the model's sink and the report before the commit).
    Output paths are checked before any work. Raises
    :class:`~lodconvert.errors.UsageError` for bad options or an unknown output suffix and
    :class:`~lodconvert.errors.LodConvertError` for a bad output path, unreadable input, when
    no object could be baked or when the output fails its checks; then nothing is written and
    existing files are left as they were.
    """
    options = options or ChainOptions()
    options.check()
    if hlod is not None:
        hlod.check()
    target = output_format(output_path)
    inputs = [input_path] if isinstance(input_path, str | Path) else list(input_path)
    sources = [input_format(path) for path in inputs]
    timings: dict[str, float] = {}
    records = Records()
    skipped: list[dict[str, str]] = []
    cells: list[dict[str, Any]] = []
    draw: dict[str, dict[str, int]] = {"without": {}, "with": {}}
    frames: list[SceneFrame | None] = []  # the writers' scene frame, from the first item
    with contextlib.ExitStack() as stack, Outputs(inputs=inputs) as outputs:
        sink = outputs.file(output_path)
        report_sink = outputs.file(report_path) if report_path is not None else None
        start = time.perf_counter()
        scene, crs_record = read_inputs(inputs, read_options, limits, sources, warn)
        timings["read"] = time.perf_counter() - start
        stack.enter_context(_input_kept_out_of_gc())
        baker = get_backend(backend)
        info = OutputInfo(
            generator=f"lodconvert {__version__}",
            source=" + ".join(Path(path).name for path in inputs),
            crs=scene.crs,
            vertical=crs_record["vertical"] if scene.city else None,
            view=options.view,
            options=options_record(options),
            city=scene.city,
        )

        def recorded(items: Iterator[LodChain | CellChain]) -> Iterator[LodChain | CellChain]:
            tally = tally_of(scene)
            dropped = tally.dropped_by_object if tally is not None else {}
            for item in items:
                if not frames:
                    frames.append(scene_frame(info.framed, item))
                objects = item.objects() if isinstance(item, CellChain) else [item]
                for chain in objects:
                    records.append(
                        {**chain_record(chain), "dropped_faces": dropped.get(chain.object_id, 0)}
                    )
                if isinstance(item, CellChain):
                    cells.extend(cell_record(cell) for cell in item.cells())
                if hlod is not None:
                    _add_counts(draw["without"], draw_counts(objects))
                    _add_counts(draw["with"], draw_counts([item]))
                yield item

        start = time.perf_counter()
        chains = recorded(
            iter_chains(scene, options, baker, progress, warn, skipped, step, limits, strict, hlod)
        )
        target.write_chains(chains, sink, info, **(write_options or {}))
        timings["bake_and_write"] = time.perf_counter() - start
        tally = _reader_skipped(scene, skipped, warn if records and not strict else _quiet)
        if strict and skipped:
            more = f" (and {len(skipped) - 1} more)" if len(skipped) > 1 else ""
            raise InputError(
                f"object {skipped[0]['reason']}{more} (--strict: a broken object fails the run)",
                " + ".join(str(path) for path in inputs),
            )
        if not records:
            raise _none_converted(skipped, " + ".join(str(path) for path in inputs))
        step("checking", 0, 1)
        start = time.perf_counter()
        check_written(sink.staged.temp, output_path)
        timings["validate"] = time.perf_counter() - start
        step("checking", 1, 1)
        named = " + ".join(str(path) for path in inputs)
        report = _report(named, output_path, baker, options, records, skipped, timings, tally)
        report["crs"] = crs_record
        report["frame"] = frames[0].record() if frames[0] is not None else None
        if hlod is not None:
            report["hlod"] = {"kind": hlod.kind, "cells": cells, "draw": draw}
        if also is not None:
            also(outputs, sink, report)
        if report_sink is not None:
            with report_sink.open() as stream:
                for piece in report_text(report):
                    stream.write(piece.encode())
    return report


def read_inputs(
    inputs: Sequence[str | Path],
    read_options: dict[str, Any] | None = None,
    limits: Limits = DEFAULT_LIMITS,
    sources: Sequence[Any] | None = None,
    warn: Message = _quiet,
) -> tuple[Scene, dict[str, Any]]:
    """The scene of ``inputs`` (one, or several in one CRS and merged: :func:`merged`), each
    read by its format (in ``sources`` where the caller found them) with the options it takes,
    and the report's ``crs`` (:func:`~.reproject.in_one_crs`)."""
    if (read_options or {}).get("crs") is not None:
        checked_crs_option(read_options["crs"])
    sources = sources or [input_format(path) for path in inputs]
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
    one_crs = in_one_crs(scenes, warn)
    return merged(one_crs.scenes), one_crs.record


def _reader_skipped(
    scene: Scene, skipped: list[dict[str, str]], warn: Message
) -> InputTally | None:
    """Add the objects the reader of ``scene`` skipped to ``skipped``, each told to ``warn``
    (with nothing converted, the run's error says it); ``scene``'s tally."""
    tally = tally_of(scene)
    for entry in tally.skipped if tally is not None else ():
        warn(f"{scene.source}: object {entry['reason']} — skipped")
        skipped.append(entry)
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


def _report(
    input_path: str | Path,
    output_path: str | Path,
    baker: Backend,
    options: ChainOptions,
    records: Records,
    skipped: list[dict[str, str]],
    timings: dict[str, float],
    tally: InputTally | None = None,
) -> dict[str, Any]:
    """What ``--report`` records of a run; ``tally``: what the reader's checks dropped."""
    reduced = points = 0
    for record in records:
        reduced += bool(record["dropped"])
        points += sum(lv["count"] for lv in record["levels"] if lv["kind"] == "pcd")
    return {
        "lodconvert": __version__,
        "input": str(input_path),
        "output": str(output_path),
        "backend": baker.name,
        "renderer": baker.renderer,
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
        "options": options_record(options),
        "objects": records,
        "skipped": skipped,
        "totals": {
            "objects": len(records),
            "fewer_levels": reduced,
            "dropped_faces": tally.dropped_faces if tally is not None else 0,
            "points": int(points),
        },
        "timings": {k: round(v, 4) for k, v in timings.items()},
    }


def object_ranges(
    scene: Scene, options: ChainOptions, warn: Message = _quiet
) -> list[dict[str, Any]]:
    """α, γ, the levels and the cutoffs of every object of ``scene`` (:func:`read_inputs`) as
    :func:`convert` plans them (:func:`~.chain.plan_chain`), without baking: a level to bake
    (``to_bake``) is kept, and its cutoff with it, where baking finds it cheaper than the level
    before and faithful. Objects that cannot be converted are reported through ``warn`` and
    left out; when none can, :class:`InputError`."""
    options.check()
    skipped: list[dict[str, str]] = []
    plan = _ObjectBaker(scene.source, options, None, _quiet, warn, skipped, DEFAULT_LIMITS, False)
    plan.total = _object_count(scene)
    rows = []
    for obj, radius in _with_plot_radii(scene, options):
        planned = plan(obj, radius)
        if planned is not None:
            rows.append(_range_record(planned, options))
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
