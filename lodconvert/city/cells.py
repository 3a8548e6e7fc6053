"""LOD parents baked as tasks on the run's executor (:mod:`lodconvert.tasks`), so that with
``--workers`` or a dask cluster the workers bake cells while the main process goes on feeding
them objects.

Each tier is a stream of :class:`CellTask` s, one per cell with members, in the cells' order:
tier 1 takes its members from the objects' chains as they come back baked, each coarser tier
from the results of the tier below, one coarsest cell's finer cells at a time, while the
finer tiers' next cells are already being baked. A task carries its plan and its members; its
result is the cell without them (which members it admits, by index, and the cell gathering
those a coarsest cell left out), so the main process puts the cell together of the very
member chains it holds: members are shipped to a worker once per tier, never back (only the
block footprints found for their objects come back, for the coarser tier). Results are
taken in submission order, so cells are the same for any executor. A task whose workers died
gives no cell: its members are drawn on their own, and a warning says so.
"""

from __future__ import annotations

import itertools
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any

from ..bake import Backend
from ..chain import ChainOptions
from ..limits import Limits
from ..model import CellChain, Level, LodChain, travelling_tables
from .cell_bake import bake_cell
from .hlod import CellPlan, Member

Warn = Callable[[str], None]
Results = Callable[[Iterable["CellTask"]], Iterator["CellResult"]]
"""An executor's ``results``: each task's result, in order."""
Formatter = Callable[[CellChain], Any]
"""An output format's ``cell_formatter``: the output's piece of a coarsest cell."""


@dataclass(frozen=True)
class CellResult:
    """A baked cell without its members (``None``: it admits none) and the indices of the
    members it admits; the cell gathering the others (``beside``, without its members, where
    a coarsest cell left some out); the warnings its baking gave; ``error``: why it could not
    be baked."""

    cell: CellChain | None
    admitted: tuple[int, ...] = ()
    beside: CellChain | None = None
    warnings: tuple[str, ...] = ()
    error: str | None = None
    derived: tuple[dict[str, Any], ...] = ()
    """What the members' objects' finest levels derived that
    :data:`~lodconvert.model.TRAVELLING` names, each object's in order (for a coarser tier's
    task; none for a coarsest cell)."""
    made: tuple[Any, ...] = ()
    """What the task's ``formatter`` made of the cell and of the ``beside`` cell, in that
    order (none without one)."""

    def items(self, members: list[Member]) -> list[Member]:
        """The cell of ``members`` (the task's, as the main process holds them, their geometry
        packed or not) and the members it leaves out (gathered into the ``beside`` cell where
        there is one), as :func:`~.cell_bake.bake_cell` gives them; ``members`` themselves
        without a cell. The objects' finest levels keep what was derived from them there."""
        for chain, found in zip(_objects(members), self.derived, strict=False):
            _finest(chain).keep_derived(found)
        if self.cell is None:
            return list(members)
        chosen = set(self.admitted)
        rest = [m for i, m in enumerate(members) if i not in chosen]
        if self.beside is not None:
            rest = [replace(self.beside, members=rest)]
        return [replace(self.cell, members=[members[i] for i in self.admitted]), *rest]


@dataclass(frozen=True)
class CellTask:
    """The LOD parent of ``plan`` over its baked ``members`` (:func:`~.cell_bake.bake_cell`;
    ``top``: a coarsest cell, which gathers what it leaves out into a cell of its own); the
    members' geometry may come packed (:meth:`~lodconvert.model.LodChain.packed`). A
    ``formatter`` (a coarsest cell's, an output format's ``cell_formatter``) makes the output's
    piece of the cell and of the cell gathering the others here, their members' geometry at
    hand."""

    plan: CellPlan
    members: tuple[Member, ...]
    options: ChainOptions
    kind: str
    limits: Limits
    top: bool
    formatter: Formatter | None = None

    def run(self, backend: Backend, progress: object = None) -> CellResult:
        """Bake the cell with ``backend``; its warnings are data."""
        warnings: list[str] = []
        members = [member.unpacked() for member in self.members]
        cell, beside = bake_cell(
            self.plan, members, self.options, self.kind, backend, warnings.append, self.limits,
            beside=self.top,
        )  # fmt: skip
        found = () if self.top else tuple(_finest_tables(c) for c in _objects(members))
        if cell is None:
            return CellResult(None, warnings=tuple(warnings), derived=found)
        chosen = {id(m) for m in cell.members}
        admitted = tuple(i for i, m in enumerate(members) if id(m) in chosen)
        gathered = None
        if self.top and len(admitted) < len(members):
            gathered = beside[0]
            assert isinstance(gathered, CellChain) and len(beside) == 1
        made = ()
        if self.formatter is not None:
            made = tuple(self.formatter(c) for c in (cell, gathered) if c is not None)
        if gathered is not None:
            gathered = replace(gathered, members=[])
        return CellResult(
            replace(cell, members=[]), admitted, gathered, tuple(warnings), derived=found, made=made
        )

    def __reduce__(self) -> tuple[type[CellTask], tuple[Any, ...]]:
        """Pickled with its members' meshes keeping only the derived tables that travel
        (:meth:`~lodconvert.model.Mesh.shipped`); packed geometry as it is."""
        members = tuple(_shipped(m) for m in self.members)
        values = (self.options, self.kind, self.limits, self.top, self.formatter)
        return CellTask, (self.plan, members, *values)

    def failed(self, reason: str) -> CellResult:
        """The result of this task when it could not run, for ``reason``: no cell."""
        return CellResult(None, error=f"LOD parent {self.plan.cell_id}: {reason}")


@dataclass(frozen=True)
class CellBaker:
    """How a run bakes its cells: by ``results`` (its executor's), with the run's options,
    far level kind and limits; ``warn`` hears the cells' warnings (``source`` names the
    input). With a ``formatter``, each coarsest cell's task makes the output's piece of it
    (and of the cell gathering what it leaves out), which ``keep`` is given with that cell."""

    results: Results
    options: ChainOptions
    kind: str
    limits: Limits
    warn: Warn
    source: str
    formatter: Formatter | None = None
    keep: Callable[[CellChain, Any], None] | None = None

    def cells(self, plans: list[CellPlan], chains: Iterator[LodChain | None]) -> Iterator[Member]:
        """The coarsest cells of ``plans`` (in order) over the objects' ``chains`` (in the
        plans' object order, ``None`` for one skipped), each followed by the members it left
        out: what :func:`~.cell_bake.bake_cell` gives for each coarsest cell, its finer cells baked
        first."""
        if not plans:
            return
        top = plans[0].tier
        stream = self._baked(_first_tier(_at_tier(plans, 1), chains), top == 1)
        for tier in range(2, top + 1):
            stream = self._baked(_gathered(_at_tier(plans, tier), stream), tier == top)
        for _, items in stream:
            yield from items

    def _baked(
        self, planned: Iterator[tuple[CellPlan, list[Member]]], top: bool
    ) -> Iterator[tuple[CellPlan, list[Member]]]:
        """Each of ``planned`` (a cell's plan and members) with what its baking gives, in
        order; a cell without members gives nothing."""
        order: deque[tuple[CellPlan, list[Member]]] = deque()

        def tasks() -> Iterator[CellTask]:
            for plan, members in planned:
                order.append((plan, members))
                if members:
                    formatter = self.formatter if top else None
                    yield CellTask(
                        plan, tuple(members), self.options, self.kind, self.limits, top, formatter
                    )

        for result in self.results(tasks()):
            while not order[0][1]:
                yield order.popleft()[0], []
            plan, members = order.popleft()
            for text in result.warnings:
                self.warn(text)
            if result.error is not None:
                self.warn(f"{self.source}: {result.error} — its members are drawn on their own")
            items = result.items(members)
            if self.keep is not None:
                for cell, piece in zip(items, result.made, strict=False):
                    assert isinstance(cell, CellChain)
                    self.keep(cell, piece)
            yield plan, items
        while order:
            yield order.popleft()[0], []


def _shipped(member: Member) -> Member:
    """``member`` with meshes sharing its arrays but keeping only the derived tables that
    travel (:meth:`~lodconvert.model.Mesh.shipped`)."""
    if isinstance(member, CellChain):
        members = [_shipped(m) for m in member.members]
        return replace(member, members=members, far=_shipped_level(member.far))
    if all(level.mesh is None for level in member.levels):
        return member  # its geometry packed (or none): nothing derived travels but that
    return replace(member, levels=[_shipped_level(level) for level in member.levels])


def _shipped_level(level: Level) -> Level:
    """``level`` with its mesh (if any) as :func:`_shipped` ships it."""
    return level if level.mesh is None else replace(level, mesh=level.mesh.shipped())


def _finest_tables(chain: LodChain) -> dict[str, Any]:
    """The travelling tables derived from ``chain``'s finest mesh (its geometry unpacked)."""
    mesh = _finest(chain).mesh
    assert mesh is not None
    return travelling_tables(mesh)


def _objects(members: list[Member]) -> list[LodChain]:
    """The object chains of ``members``, in order."""
    return [c for m in members for c in m.objects()]


def _finest(chain: LodChain) -> Level:
    """The finest mesh level of ``chain`` (where its block footprint is kept)."""
    return next(level for level in chain.levels if not level.is_points)


def _at_tier(plans: list[CellPlan], tier: int) -> list[CellPlan]:
    """The cells of ``tier`` under ``plans``, in order."""
    found: list[CellPlan] = []
    for plan in plans:
        found += [plan] if plan.tier == tier else _at_tier(plan.cells, tier)
    return found


def _first_tier(
    plans: list[CellPlan], chains: Iterator[LodChain | None]
) -> Iterator[tuple[CellPlan, list[Member]]]:
    """Each tier-1 cell of ``plans`` with its objects' chains taken from ``chains`` (those
    skipped left out)."""
    for plan in plans:
        found = itertools.islice(chains, len(plan.objects))
        yield plan, [chain for chain in found if chain is not None]


def _gathered(
    plans: list[CellPlan], finer: Iterator[tuple[CellPlan, list[Member]]]
) -> Iterator[tuple[CellPlan, list[Member]]]:
    """Each of ``plans`` with its members: what baking each of its finer cells gave
    (``finer``, in order)."""
    for plan in plans:
        members: list[Member] = []
        for cell in plan.cells:
            baked, items = next(finer)
            assert baked is cell
            members += items
        yield plan, members
