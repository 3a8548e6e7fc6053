"""Bake scheduling: a scene's objects sent to the run's executor in batches and their outcomes
taken in order in the main process (:func:`iter_chains`), grouped into LOD parents where asked,
and the plans that ``lodconvert ranges`` prints (:func:`object_ranges`); docs/architecture.md."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .bake import get_backend
from .chain import ChainOptions, ChainPlan
from .city.cells import CellBaker
from .city.hlod import HlodOptions, auto_size, plan_cells
from .city.prepare import spooled, with_plot_radii
from .context import Message, RunContext, quiet
from .errors import InputError
from .inputs import none_converted, reader_skipped
from .io import Pieces
from .model import CellChain, LodChain, Node, PackedNode, Scene, with_geometry
from .report import Records
from .spool import NodeSpool
from .tasks import Baked, BakeTask, batches


def iter_chains(
    scene: Scene,
    options: ChainOptions,
    context: RunContext,
    hlod: HlodOptions | None = None,
    pieces: Pieces | None = None,
    first_at: Callable[[np.ndarray], None] | None = None,
    packed: bool = False,
) -> Iterator[LodChain | CellChain]:
    """Bake the scene's objects by the context's executor; objects with bad geometry are
    reported through its ``warn`` (unless ``strict``: the caller fails), recorded in its
    ``skipped`` and left out; its ``step`` hears how many are done, its ``clock`` how long
    planning and baking took. ``pieces`` keeps what its formatter made of each chain where it
    was baked (those chains come without their geometry, but for LOD parents, which merge it)
    and what its ``cells`` formatter made of each coarsest cell;
    ``first_at`` hears where the scene's first object lies (its bounding-box centre) before any
    chain comes; with ``packed``, chains baked elsewhere come with their geometry packed
    (:meth:`~.model.LodChain.packed`: the writer only passes it on to its own tasks). With
    ``hlod``, the objects come grouped in LOD parents (:mod:`.city.hlod`): one
    :class:`CellChain` per cell of the coarsest tier, in grid order, each followed by the
    members it left out (objects or finer cells, drawn on their own)."""
    bakery = _Bakery(
        scene.source, options, context, object_count(scene), pieces=pieces,
        lean=hlod is None, packed=packed,
    )  # fmt: skip
    nodes = scene.with_geometry()
    if first_at is not None:
        nodes = _first_told(nodes, first_at)
    if hlod is not None:
        yield from _cell_chains(nodes, options, hlod, bakery)
        return
    for chain in bakery.chains(with_plot_radii(nodes, options)):
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


def object_count(scene: Scene) -> int | None:
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
    was made where it was baked comes without its geometry, with ``packed`` every chain with
    its geometry packed (:class:`~.tasks.BakeTask`)."""

    source: str
    options: ChainOptions
    context: RunContext
    total: int | None = None
    plan_only: bool = False
    pieces: Pieces | None = None
    lean: bool = False
    packed: bool = False
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

        self.context.step("converting", self.done, self.total)  # the stage starts: nothing sent yet
        formatter = self.pieces.formatter if self.pieces is not None else None
        made = batches(
            sent(), per_object, self.context.limits, self.plan_only, formatter,
            self.context.executor.task_seconds, self.lean, self.packed,
        )  # fmt: skip
        tasks = self.context.clock.iterate("plan", made)
        for result in self.context.clock.iterate("execute", self.context.executor.results(tasks)):
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
            self.context.warn(text)
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
            self.context.step("converting", self.done, self.total)

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
            task = BakeTask(((obj, self._options(radius)),), self.context.limits, self.plan_only)
            return self._taken(obj, task.run(self.context.backend).outcomes[0], shared)
        try:
            text = obj.written()
            chain = replace(base, object_id=text.id, metadata=text.attributes, cut=text.cut)
            return replace(chain, transform=np.asarray(obj.transform, dtype=np.float64))
        except InputError as exc:
            return self._skip(obj, str(exc))
        finally:
            self.done += 1
            self.context.step("converting", self.done, self.total)

    def _skip(self, obj: Node | PackedNode, reason: str) -> None:
        """Report ``obj`` as skipped for ``reason``."""
        if self.total != 1 and not self.context.strict:  # with one object, the run's error says it
            self.context.warn(f"{self.source}: object {reason} — skipped")
        self.context.skipped.append({"id": obj.id, "reason": reason})


def _cell_chains(
    nodes: Iterable[Node | PackedNode], options: ChainOptions, hlod: HlodOptions, bakery: _Bakery
) -> Iterator[LodChain | CellChain]:
    """The objects ``nodes`` baked and grouped into LOD parents, one coarsest cell at a time
    (the objects wait on disk meanwhile, and go to be baked in the cells' order, so memory is
    bounded by the cells in flight), each followed by the members it left out; the cells are
    baked by the bakery's executor (:mod:`.city.cells`)."""
    hlod.check()
    with NodeSpool() as spool:
        centres, radii = spooled(nodes, options, spool)
        plans = plan_cells(centres, hlod.sizes or (auto_size(centres),))
        order = (i for plan in plans for i in plan.object_indices())
        found = bakery.chains((spool.get(i), radii[i]) for i in order)
        context = bakery.context
        pieces = bakery.pieces
        baker = CellBaker(
            context.executor.results,
            options,
            hlod.kind,
            context.limits,
            context.warn,
            bakery.source,
            pieces.cells if pieces is not None else None,
            pieces.add if pieces is not None else None,
        )
        yield from baker.cells(plans, found)


def check_converted(
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
        raise none_converted(skipped, named)


def object_ranges(
    scene: Scene, options: ChainOptions, warn: Message = quiet
) -> list[dict[str, Any]]:
    """α, γ, the levels and the cutoffs of every object of ``scene`` (:func:`read_inputs`) as
    :func:`convert` plans them (:func:`~.plans.plan_chain`), without baking: a level to bake
    (``to_bake``) is kept, and its cutoff with it, where baking finds it cheaper than the level
    before and faithful. Objects that cannot be converted are reported through ``warn`` and
    left out; when none can, :class:`InputError`."""
    options.check()
    context = RunContext.here(get_backend("numpy"), warn=warn)  # plans bake nothing
    plan = _Bakery(scene.source, options, context, object_count(scene), plan_only=True)
    rows = [
        _range_record(planned, options)
        for planned in plan.chains(with_plot_radii(scene.with_geometry(), options))
        if isinstance(planned, ChainPlan)
    ]
    reader_skipped(scene, context.skipped, warn if rows else quiet)
    if not rows:
        raise none_converted(context.skipped, scene.source)
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
