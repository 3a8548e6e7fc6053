"""One LOD parent baked (:func:`bake_cell`): the members it admits (:mod:`.cell_switch`), where
it stands and switches, every far level its kind asks for (block proxies, a merged mesh,
blocks mixed with members' own content, and points baked from all its objects — with ``auto``
only where none of the others reaches silhouette F 0.95), the one kept by silhouette fidelity
(:mod:`.far_choice`) and the facts that say why."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..bake import Backend
from ..chain import ChainOptions, point_level_at
from ..limits import DEFAULT_LIMITS, Limits
from ..model import CellChain, Level, LodChain, Mesh
from ..plan import level_bytes
from ..ranges import diagonal
from .cell_switch import CELL_EXPONENT, admitted_members, cell_cutoffs, cell_gamma, reach
from .far_blocks import blocks_level, member_blocks_level
from .far_choice import MIN_CELL_F, Made, chosen_kind, faithful_cost, lighter, silhouette_f
from .far_mesh import finest_mesh, merge, mesh_level
from .far_mixed import mixed_level
from .hlod import CellPlan, Member

Warn = Callable[[str], None]


@dataclass(frozen=True)
class CellSite:
    """A cell over its admitted members: their objects, those objects' finest geometry about
    the cell's origin (``source``, what every far level is measured against), the origin (the
    centre of their bounding box, scene coordinates), its diagonal α, γ, the seam rule's
    distance and the cell's cutoffs (the switch to the far level first)."""

    members: list[Member]
    objects: list[LodChain]
    source: Mesh
    origin: np.ndarray
    alpha: float
    gamma: float
    seam: float
    cutoffs: list[float]

    @property
    def switch(self) -> float:
        """Where the far level shows from."""
        return self.cutoffs[0]


@dataclass
class FarLevels:
    """A cell's far level candidates by kind, in the order made, each with its silhouette F;
    the merged mesh's facts and the block proxies' (``None``: none were made)."""

    candidates: dict[str, tuple[Level, float]] = field(default_factory=dict)
    mesh_facts: dict[str, Any] = field(default_factory=lambda: {"mesh_levels_finer": 0})
    blocks: dict[str, Any] | None = None


def bake_cell(
    plan: CellPlan,
    members: list[Member],
    options: ChainOptions,
    kind: str,
    backend: Backend,
    warn: Warn | None = None,
    limits: Limits = DEFAULT_LIMITS,
    beside: bool = False,
) -> tuple[CellChain | None, list[Member]]:
    """The LOD parent of ``plan`` over those of its baked ``members`` (object chains or finer
    cells) that it admits (:func:`~.cell_switch.admitted_members`), and the members left out
    of it, to be drawn on their own; no cell when it admits none. With ``beside`` (a coarsest
    cell, whose left-out members no cell would admit), those left out come back as one cell of
    their own, ``{cell_id}_beside``, that admits all of them: its switch is the seam rule's
    alone."""
    gamma = cell_gamma(plan.size)
    gathering = bool(plan.suffix)  # gathers what no cell admits: admits every member
    admitted = list(members) if gathering else admitted_members(members, options, gamma)
    if not admitted:
        return None, members
    left_out = [m for m in members if not any(m is a for a in admitted)]
    drawn_beside: list[Member] = left_out
    if beside and left_out:
        gathered, _ = bake_cell(
            replace(plan, suffix="_beside"), left_out, options, kind, backend, warn, limits
        )
        assert gathered is not None
        drawn_beside = [gathered]
    site = _site(admitted, gamma, options)
    # a cell of finer cells, or of scattered members: blocks of each member apart
    apart = gathering or any(isinstance(m, CellChain) for m in admitted)
    far = _far_levels(site, kind, apart, options)
    if kind == "points" or (kind == "auto" and math.isinf(faithful_cost(far.candidates))):
        points = point_level_at(
            site.source, "FAR", site.switch, options, backend, plan.cell_id, warn, limits
        )
        if points is not None:
            far.candidates["points"] = (
                points,
                silhouette_f(site.source, points, site.switch, options),
            )
    if not far.candidates:  # nothing else could be made
        _add_mesh(far, site, options)
    return _cell(plan, site, far, kind, options, gathering, left_out), drawn_beside


def _site(members: list[Member], gamma: float, options: ChainOptions) -> CellSite:
    """The cell over ``members``: its origin and diagonal from their objects' finest geometry,
    the seam rule's distance from that origin, and its cutoffs."""
    objects = [c for m in members for c in m.objects()]
    finest = merge([finest_mesh(chain) for chain in objects])
    world = finest.bounds
    origin = (world[0] + world[1]) / 2.0
    alpha = diagonal(world)
    seam = max(reach(m, origin) for m in members)
    cutoffs = cell_cutoffs(alpha, gamma, seam, options)
    return CellSite(
        members, objects, finest.translated(-origin), origin, alpha, gamma, seam, cutoffs
    )


def _far_levels(site: CellSite, kind: str, apart: bool, options: ChainOptions) -> FarLevels:
    """The far levels but points that ``kind`` asks for (``auto``: both): block proxies
    (:func:`_blocks`), the merged mesh, and, where the blocks of a cell of members apart lose
    the silhouette, blocks mixed with members' own content when that is lighter."""
    far = FarLevels()
    found = _blocks(site, apart, options) if kind in ("blocks", "auto") else None
    if found is not None:
        far.candidates["blocks"] = found[:2]
    if kind in ("mesh", "auto"):
        _add_mesh(far, site, options)
    if found is not None and found[1] < MIN_CELL_F and apart:
        cost = faithful_cost(far.candidates)
        mixed = mixed_level(site.members, site.origin, site.source, site.switch, options, cost)
        found = lighter(found, mixed)
        far.candidates["blocks"] = found[:2]
    far.blocks = found[2] if found is not None else None
    return far


def _add_mesh(far: FarLevels, site: CellSite, options: ChainOptions) -> None:
    """Add the cell's merged mesh (:func:`~.far_mesh.mesh_level`) to ``far``."""
    level, f, far.mesh_facts = mesh_level(
        site.members, site.objects, site.origin, site.source, site.switch, options
    )
    far.candidates["mesh"] = (level, f)


def _blocks(site: CellSite, apart: bool, options: ChainOptions) -> Made | None:
    """Block proxies of the cell's objects (:func:`~.far_blocks.blocks_level`) or, for members
    apart, of each member's objects apart where that is lighter."""
    found = blocks_level(site.objects, site.origin, site.source, site.switch, options)
    if apart:
        each = member_blocks_level(site.members, site.origin, site.source, site.switch, options)
        found = lighter(found, each)
    return found


def _cell(
    plan: CellPlan,
    site: CellSite,
    far: FarLevels,
    kind: str,
    options: ChainOptions,
    gathering: bool,
    left_out: list[Member],
) -> CellChain:
    """The cell of ``plan`` at ``site`` with the far level kept (:func:`~.far_choice.chosen_kind`)
    and its facts."""
    chosen, why = chosen_kind(far.candidates, kind)
    candidates = far.candidates
    facts = {
        "kind": chosen,
        "why": why,
        "silhouette_f": {name: round(f, 4) for name, (_, f) in candidates.items()},
        "counts": {name: level.count for name, (level, _) in candidates.items()},
        "bytes": {name: level_bytes(level) for name, (level, _) in candidates.items()},
        **far.mesh_facts,
        **({"blocks": far.blocks} if far.blocks is not None else {}),
        **({"beside": True} if gathering else {}),
        "members": len(site.members),
        "objects": len(site.objects),
        "seam": site.seam,
        "left_out": [m.cell_id if isinstance(m, CellChain) else m.object_id for m in left_out],
    }
    return CellChain(
        cell_id=plan.cell_id,
        tier=plan.tier,
        size=plan.size,
        key=plan.key,
        members=site.members,
        far=candidates[chosen][0],
        cutoffs=site.cutoffs,
        origin=site.origin,
        center=np.zeros(3),
        alpha=site.alpha,
        beta=options.beta,
        gamma=site.gamma,
        xs=[CELL_EXPONENT, *([options.cull] if options.cull is not None else [])],
        culled=options.cull is not None,
        facts=facts,
    )
