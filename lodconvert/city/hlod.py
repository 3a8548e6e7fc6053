"""LOD parents (HLOD): a city's objects grouped into grid cells, each cell seen from afar as one
level that stands for all its objects (Lee, Kim & Kim's "LOD parent"; 3D Tiles' REPLACE
refinement).

**Cells.** Objects go to the square cell of a grid anchored at the scene's coordinate origin
that holds their ground centre; with several sizes (``--hlod 250,1000``) each coarser cell
holds the finer cells whose centres fall in it. ``auto`` picks one size from the objects'
density: the side of a square holding :data:`AUTO_OBJECTS` objects on average (over the
objects' ground bounding rectangle), rounded to the nearest of :data:`AUTO_SIZES` in
proportion.

**Switching.** A cell shows its members (with their own chains) near and its ``far`` level
beyond ``Y_cell``, from its members' bounding-box centre. ``Y_cell`` follows the ranges'
formula with α = the cell's diagonal, β as for its objects, γ = half the cell's side (its plot
radius) and x = :data:`CELL_EXPONENT`, raised where needed by the **seam rule**: the far level
never shows while a member would still show a level finer than its coarsest. A viewer ``d``
from the cell centre is at least ``d - |c_m - c|`` from member ``m``'s centre, so
``Y_cell ≥ max_m (Y_m + |c_m - c|)``, where ``Y_m`` is where ``m`` reaches its coarsest level
(an object's last cutoff before it, 0 with one level; a finer cell's ``Y_cell``). A cell
therefore **admits** only the members whose reach ``Y_m + |c_m - c|`` lies within its formula
distance (a few lone or large buildings with wide plots would otherwise push a whole block's
switch out by kilometres); the others stay beside it, drawn on their own (a coarser tier may
admit them in turn). When it would admit none, it holds the one member that reaches its
coarsest level first: a cell of one. The members a coarsest cell leaves out, which no cell
admits, are gathered into a cell of their own (``{cell_id}_beside``) that admits them all: it
switches where the last of them reaches its coarsest level (the seam rule alone), so that they
too have a far level. With culling,
a cell disappears at the formula's distance for the cull exponent, and never before its far
level has shown.

**Far level kinds.** ``points``: one point cloud baked from all the members' finest geometry
together, designed for ``Y_cell`` as any point level is (:mod:`.chain`): no mesh merging, one
draw call, and it reduces what decimation cannot (a block is hundreds of separate parts).
``mesh``: the members' coarsest mesh levels merged into one mesh with vertex colours (one
draw call as well); where that mesh's silhouette F at ``Y_cell`` stays below
:data:`MIN_CELL_F` (a block of LOD1 prisms against its LoD2 roofs), the members' next finer
mesh levels in turn, their finest at most, each without its floor on the ground (seen from
no viewpoint above it). The merge is then simplified by quadric edge
collapse (:func:`~.bake.qem.simplify_within`) to within a tolerance of a few pixels at
``Y_cell`` in the reference view (:data:`SIMPLIFY_PX`; a pixel is ``Y_cell / focal_px``
metres there): the coarsest whose F still reaches :data:`MIN_CELL_F` (or is no lower than the
merge's), else the merge stays as it is. A cell of finer cells also merges what it replaces
(their far meshes, already simplified for their nearer switches, and its other members'
coarsest mesh levels) and simplifies that the same way, and keeps the lighter of the two that
reaches :data:`MIN_CELL_F`: the objects' own levels keep every building's corners and open
borders, so simplified again they left a coarser tier about as heavy as its children.
``blocks``: block proxies (:mod:`.blocks`), the objects' footprints unioned into blocks and
extruded in height bands; of the outline tolerances of :data:`BLOCK_PX` pixels at ``Y_cell``
and the band depths of :data:`BAND_M`, the proxy with the fewest vertices whose F reaches
:data:`MIN_CELL_F`, else the most faithful. A cell of finer cells also makes block proxies of
each member's objects apart (:func:`_member_blocks_level`: smaller blocks, whose one band's
height stays true where the whole cell's would not), each member's outlines as coarse as keeps
F at :data:`MIN_CELL_F`, roofs and walls sharing their corners (a vertex per corner, not per
colour: seen that far, a wall is a few pixels high), and keeps the lighter faithful one: its
children are block proxies and simplified meshes already, which a tier up cannot simplify much
further (their floors' rings stay in place). Where neither reaches :data:`MIN_CELL_F`, it
mixes them (:func:`_mixed_level`): blocks where they keep the F, and the fewest members' own
far content, or objects' own coarsest levels, that lift it there.
``auto`` makes all three and keeps the cheapest (points at :data:`~.plan.POINT_COST`; then
the fewer bytes) of those whose silhouette F against the members' finest geometry at
``Y_cell`` (:func:`~.plan.silhouette_estimate`) is at least :data:`MIN_CELL_F`; when none is,
the one with the highest F.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..bake import Backend
from ..bake.grid import Grid
from ..bake.numpy import silhouettes
from ..bake.qem import simplify_within
from ..chain import ChainOptions, point_level_at
from ..errors import UsageError
from ..limits import DEFAULT_LIMITS, Limits
from ..model import WHITE, CellChain, Level, LodChain, Mesh, Surface
from ..plan import (
    SilhouetteEstimate,
    _source_masks,
    level_bytes,
    level_cost,
    mesh_silhouette_estimate,
    silhouette_estimate,
)
from ..ranges import cutoff, diagonal
from .blocks import block_proxy, blocks_of, object_footprint, shared_corners

KINDS = ("auto", "points", "mesh", "blocks")
AUTO_OBJECTS = 64
"""Objects an ``auto`` cell holds on average."""
AUTO_SIZES = (25.0, 50.0, 100.0, 250.0, 500.0, 1000.0, 2000.0, 5000.0)
"""Cell sides (metres) that ``auto`` rounds to."""
CELL_EXPONENT = 0.0
"""x of a cell's switch to its far level: Y = α·β, where a chain's finest baked level is
designed (:mod:`.chain`)."""
MIN_CELL_F = 0.95
"""Least silhouette F of a far level against its members where it switches in."""
SEAM_MARGIN = 1e-9
"""Relative margin that keeps a far level's switch strictly beyond its members'."""
ADMISSION_ROUNDS = 4
"""Times a cell's admitted members (and so its centre) are found again."""
DOWN = -0.99
"""Unit normal z below which a face looks straight down."""
FLOOR_MARGIN = 0.01
"""Metres above an object's lowest point within which a face looking down is its floor on the
ground, left out of far meshes."""
MERGED_FROM = ("finer cells' far levels", "objects' levels")
"""What a merged far mesh is made of: what it replaces (a coarser tier's), or its objects'
levels."""
BLOCK_PX = (4.0, 2.0, 1.0)
"""Tolerances tried for block proxies' outlines, in pixels at the cell's switch distance."""
BAND_M = (math.inf, 6.0, 3.0, 1.0)
"""Height band depths tried for block proxies, metres (infinite: one band per block)."""
BLOCK_CLOSING_PX = 1.0
"""Gaps between footprints narrower than this many pixels at the switch distance are closed
into one block."""
SIMPLIFY_PX = (8.0, 4.0, 2.0, 1.0)
"""Tolerances tried for a far mesh's simplification, coarsest first: pixels at the cell's
switch distance in the reference view (one pixel at d is 2·d·tan(fov/2)/height_px metres:
0.77 m at 1 km, 1080 px, 45°), all within half the 16 px screen-space error at which CesiumJS
refines a tile by default (a tile's geometric error is 16 px at its switch)."""

PROBES = 64
"""Objects whose silhouettes a mixed far level (:func:`_mixed_level`) draws at once."""

Member = LodChain | CellChain
Warn = Callable[[str], None]
Made = tuple[Level, float, dict[str, Any]]
"""A far level, its silhouette F and its facts."""


@dataclass(frozen=True)
class HlodOptions:
    """Cell sides per tier in metres, finest first (``None``: one tier, ``auto``), and the far
    level kind."""

    sizes: tuple[float, ...] | None = None
    kind: str = "auto"

    def check(self) -> None:
        """Raise :class:`UsageError` for sizes that are not positive and increasing, or an
        unknown kind."""
        sizes = self.sizes or ()
        if any(not (math.isfinite(s) and s > 0) for s in sizes):
            raise UsageError("cell sizes must be positive numbers of metres", "hlod")
        if any(b <= a for a, b in itertools.pairwise(sizes)):
            raise UsageError("cell sizes must increase tier by tier (e.g. 250,1000)", "hlod")
        if self.kind not in KINDS:
            raise UsageError(f"must be one of {', '.join(KINDS)}, got {self.kind!r}", "hlod_kind")


def parse_sizes(text: str) -> tuple[float, ...] | None:
    """``--hlod`` text: ``auto`` (None) or comma-separated sizes in metres; raises
    :class:`UsageError`."""
    if text.strip().lower() == "auto":
        return None
    try:
        sizes = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise UsageError(
            f"must be 'auto' or sizes in metres like 250,1000, got {text!r}", "hlod"
        ) from None
    HlodOptions(sizes).check()
    return sizes


def auto_size(centres: np.ndarray) -> float:
    """The ``auto`` cell side for objects at ``centres`` ((n, 2) metres)."""
    if len(centres) < 2:
        return AUTO_SIZES[0]
    span = np.ptp(centres, axis=0)
    area = float(max(span[0], 1.0) * max(span[1], 1.0))
    wanted = math.sqrt(AUTO_OBJECTS * area / len(centres))
    return min(AUTO_SIZES, key=lambda size: abs(math.log(size / wanted)))


@dataclass
class CellPlan:
    """One cell before baking: its tier, side, grid key and members (object indices for
    tier 1, finer cells above)."""

    tier: int
    size: float
    key: tuple[int, int]
    objects: list[int]
    cells: list[CellPlan]
    suffix: str = ""
    """Added to the id (``_beside``: the members a coarsest cell left out, :func:`bake_cell`)."""

    @property
    def cell_id(self) -> str:
        """``cell{tier}_{column}_{row}`` (negative numbers with ``m``) and the suffix."""
        col, row = (str(k).replace("-", "m") for k in self.key)
        return f"cell{self.tier}_{col}_{row}{self.suffix}"

    def object_indices(self) -> list[int]:
        """The objects of this cell and its finer cells."""
        if self.tier == 1:
            return list(self.objects)
        return [i for cell in self.cells for i in cell.object_indices()]


def plan_cells(centres: np.ndarray, sizes: Sequence[float]) -> list[CellPlan]:
    """The coarsest tier's cells (each holding its finer cells), in grid order (row, column),
    for objects at ``centres`` ((n, 2), scene metres)."""
    groups: dict[tuple[int, int], list[int]] = {}
    for i, (x, y) in enumerate(np.asarray(centres, dtype=np.float64).reshape(-1, 2)):
        groups.setdefault(_key(x, y, sizes[0]), []).append(i)
    cells = [CellPlan(1, sizes[0], key, members, []) for key, members in _ordered(groups)]
    for tier, size in enumerate(sizes[1:], start=2):
        parents: dict[tuple[int, int], list[CellPlan]] = {}
        for cell in cells:
            x, y = ((k + 0.5) * cell.size for k in cell.key)
            parents.setdefault(_key(x, y, size), []).append(cell)
        cells = [CellPlan(tier, size, key, [], members) for key, members in _ordered(parents)]
    return cells


def _key(x: float, y: float, size: float) -> tuple[int, int]:
    return math.floor(x / size), math.floor(y / size)


def _ordered(groups: dict[tuple[int, int], list]) -> list[tuple[tuple[int, int], list]]:
    return sorted(groups.items(), key=lambda item: (item[0][1], item[0][0]))


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
    cells) that it admits (see the module docstring), and the members left out of it, to be
    drawn on their own; no cell when it admits none. With ``beside`` (a coarsest cell, whose
    left-out members no cell would admit), those left out come back as one cell of their own,
    ``{cell_id}_beside``, that admits all of them: its switch is the seam rule's alone."""
    gamma = max(plan.size / 2.0, 1.0 + 1e-6)
    beside_cell = bool(plan.suffix)  # gathers what no cell admits: admits every member
    admitted = list(members) if beside_cell else _admitted(members, options, gamma)
    if not admitted:
        return None, members
    members, left_out = admitted, [m for m in members if not any(m is a for a in admitted)]
    drawn_beside: list[Member] = left_out
    if beside and left_out:
        gathered, _ = bake_cell(
            replace(plan, suffix="_beside"), left_out, options, kind, backend, warn, limits
        )
        assert gathered is not None
        drawn_beside = [gathered]
    objects = [c for m in members for c in m.objects()]
    finest = _merged([_finest_mesh(chain) for chain in objects])
    world = finest.bounds
    origin = (world[0] + world[1]) / 2.0
    alpha = diagonal(world)
    seam = max(_reach(m, origin) for m in members)
    switch = max(cutoff(alpha, options.beta, gamma, CELL_EXPONENT), seam * (1 + SEAM_MARGIN))
    source = finest.translated(-origin)
    candidates: dict[str, tuple[Level, float]] = {}
    if kind in ("points", "auto"):
        level = point_level_at(source, "FAR", switch, options, backend, plan.cell_id, warn, limits)
        if level is not None:
            candidates["points"] = (level, _silhouette_f(source, level, switch, options))
    found = None
    # a cell of finer cells, or of scattered members: blocks of each member apart
    apart = beside_cell or any(isinstance(m, CellChain) for m in members)
    if kind in ("blocks", "auto"):
        found = _blocks_level(objects, origin, source, switch, options)
        if apart:
            found = _lighter(found, _member_blocks_level(members, origin, source, switch, options))
        if found is not None:
            candidates["blocks"] = found[:2]
    mesh_facts: dict[str, Any] = {"mesh_levels_finer": 0}
    if kind in ("mesh", "auto") or not candidates:
        level, f, mesh_facts = _mesh_level(members, objects, origin, source, switch, options)
        candidates["mesh"] = (level, f)
    if found is not None and found[1] < MIN_CELL_F and apart:
        cost = min(
            (level_cost(lv) for lv, f in candidates.values() if f >= MIN_CELL_F), default=math.inf
        )
        found = _lighter(found, _mixed_level(members, origin, source, switch, options, cost))
        candidates["blocks"] = found[:2]
    blocks = found[2] if found is not None else None
    chosen, why = _choice(candidates, kind)
    cutoffs = [switch]
    if options.cull is not None:
        cutoffs.append(max(cutoff(alpha, options.beta, gamma, options.cull), switch * 1.01))
    facts = {
        "kind": chosen,
        "why": why,
        "silhouette_f": {name: round(f, 4) for name, (_, f) in candidates.items()},
        "counts": {name: level.count for name, (level, _) in candidates.items()},
        "bytes": {name: level_bytes(level) for name, (level, _) in candidates.items()},
        **mesh_facts,
        **({"blocks": blocks} if blocks is not None else {}),
        **({"beside": True} if beside_cell else {}),
        "members": len(members),
        "objects": len(objects),
        "seam": seam,
        "left_out": [m.cell_id if isinstance(m, CellChain) else m.object_id for m in left_out],
    }
    cell = CellChain(
        cell_id=plan.cell_id,
        tier=plan.tier,
        size=plan.size,
        key=plan.key,
        members=members,
        far=candidates[chosen][0],
        cutoffs=cutoffs,
        origin=origin,
        center=np.zeros(3),
        alpha=alpha,
        beta=options.beta,
        gamma=gamma,
        xs=[CELL_EXPONENT, *([options.cull] if options.cull is not None else [])],
        culled=options.cull is not None,
        facts=facts,
    )
    return cell, drawn_beside


def _choice(candidates: dict[str, tuple[Level, float]], kind: str) -> tuple[str, str]:
    """The far level kind to keep and why."""
    if kind != "auto" or len(candidates) == 1:
        name = kind if kind in candidates else next(iter(candidates))
        return name, "asked" if name == kind else f"no {kind} level could be made"
    faithful = [name for name, (_, f) in candidates.items() if f >= MIN_CELL_F]
    if faithful:
        name = min(
            faithful, key=lambda n: (level_cost(candidates[n][0]), level_bytes(candidates[n][0]), n)
        )
        return name, f"cheapest with silhouette F ≥ {MIN_CELL_F}"
    name = max(candidates, key=lambda n: (candidates[n][1], n))
    return name, f"none reaches silhouette F {MIN_CELL_F}: the most faithful"


def _silhouette_f(source: Mesh, level: Level, distance: float, options: ChainOptions) -> float:
    """Silhouette F of ``level`` against ``source`` seen from ``distance`` (``source``'s
    silhouettes kept with it: a cell compares every candidate with the same)."""
    if level.points is not None:
        size = level.params.point_size if level.params is not None else 1.0
        estimate = silhouette_estimate(source, level.points, size, distance, options.view, True)
    else:
        assert level.mesh is not None
        estimate = mesh_silhouette_estimate(source, level.mesh, distance, options.view, True)
    return estimate.f


def _placed(chain: LodChain, mesh: Mesh) -> Mesh:
    """``mesh`` (a level of ``chain``) in scene coordinates."""
    return chain.in_scene(mesh)


def _finest_mesh(chain: LodChain) -> Mesh:
    """The finest mesh level of ``chain`` in scene coordinates."""
    level = next(lv for lv in chain.levels if lv.mesh is not None)
    assert level.mesh is not None
    return _placed(chain, level.mesh)


def _mesh_level(
    members: list[Member],
    objects: list[LodChain],
    origin: np.ndarray,
    source: Mesh,
    distance: float,
    options: ChainOptions,
) -> tuple[Level, float, dict[str, Any]]:
    """A cell's simplified merged far mesh (:func:`_simplified`), from what it replaces where
    it has finer cells (:func:`_far_meshes` of every member merged, kept where its silhouette
    F against ``source`` from ``distance`` reaches :data:`MIN_CELL_F`) and from its objects'
    levels (:func:`_merged_level`): the one with fewer vertices of those whose F reaches it,
    else the most faithful. Its level, F and facts (what it was merged from, the levels finer
    than the objects' coarsest it took, the simplification)."""
    merges = []
    if any(isinstance(m, CellChain) and m.far.mesh is not None for m in members):
        parts = [mesh for m in members for mesh in _far_meshes(m)]
        level = Level(name="FAR", kind="merged", mesh=_one_part(_merged(parts).translated(-origin)))
        f = _silhouette_f(source, level, distance, options)
        if f >= MIN_CELL_F:
            merges.append((MERGED_FROM[0], 0, level, f))
    level, f, finer = _merged_level(objects, origin, source, distance, options)
    merges.append((MERGED_FROM[1], finer, level, f))
    made = []
    for made_from, finer, merged, f in merges:
        level, after, simplified = _simplified(merged, f, source, distance, options)
        facts = {"merged_from": made_from, "mesh_levels_finer": finer, "simplified": simplified}
        made.append((level, after, facts))
    faithful = [m for m in made if m[1] >= MIN_CELL_F]
    if faithful:
        return min(faithful, key=lambda m: m[0].count)
    return max(made, key=lambda m: m[1])


def _merged_level(
    objects: list[LodChain],
    origin: np.ndarray,
    source: Mesh,
    distance: float,
    options: ChainOptions,
) -> tuple[Level, float, int]:
    """The objects' coarsest mesh levels (without their floors, :func:`_floorless`) merged into
    one far level, or, where its silhouette
    F against ``source`` (the objects' finest geometry about ``origin``) from ``distance``
    stays below :data:`MIN_CELL_F`, their next finer mesh levels in turn (their finest at
    most); the level, its F and how many levels finer than the coarsest it took."""
    meshes = [
        [lv.mesh for lv in reversed(chain.levels) if lv.mesh is not None] for chain in objects
    ]
    depth = max(len(levels) for levels in meshes)
    for finer in range(depth):
        merged = _merged(
            [
                _floorless(_placed(chain, levels[min(finer, len(levels) - 1)]))
                for chain, levels in zip(objects, meshes, strict=True)
            ]
        )
        level = Level(name="FAR", kind="merged", mesh=_one_part(merged.translated(-origin)))
        f = _silhouette_f(source, level, distance, options)
        if f >= MIN_CELL_F:
            break
    return level, f, finer


def _far_meshes(member: Member) -> list[Mesh]:
    """A member's far content in scene coordinates: a finer cell's far mesh (its objects'
    coarsest mesh levels where it is points), an object's coarsest mesh level, without
    floors."""
    if isinstance(member, CellChain) and member.far.mesh is not None:
        return [member.far.mesh.translated(member.origin)]
    chains = member.objects()
    coarsest = (next(lv.mesh for lv in reversed(c.levels) if lv.mesh is not None) for c in chains)
    return [_floorless(_placed(c, mesh)) for c, mesh in zip(chains, coarsest, strict=True)]


def _simplified(
    merged: Level, f: float, source: Mesh, distance: float, options: ChainOptions
) -> tuple[Level, float, dict[str, float | int | bool]]:
    """``merged`` (a far mesh of silhouette F ``f`` against ``source``) simplified to within the
    coarsest tolerance of :data:`SIMPLIFY_PX` at ``distance`` whose F reaches
    :data:`MIN_CELL_F` or is no lower than ``f``; ``merged`` itself when none does. The level
    kept, its F, and the tolerance, counts and F before and after (of the last tried)."""
    assert merged.mesh is not None
    floor = min(MIN_CELL_F, f)
    for px in SIMPLIFY_PX:
        tolerance = px * distance / options.view.focal_px
        mesh = Mesh([simplify_within(merged.mesh, tolerance)])
        level = Level(name="FAR", kind="merged", mesh=mesh)
        after = _silhouette_f(source, level, distance, options) if level.count else 0.0
        if after >= floor:
            break
    kept = after >= floor
    facts = {
        "tolerance_px": px,
        "tolerance_m": round(tolerance, 4),
        "vertices_before": merged.count,
        "vertices_after": level.count,
        "silhouette_f_before": round(f, 4),
        "silhouette_f_after": round(after, 4),
        "kept": kept,
    }
    return (level, after, facts) if kept else (merged, f, facts)


def _blocks_level(
    objects: list[LodChain],
    origin: np.ndarray,
    source: Mesh,
    distance: float,
    options: ChainOptions,
) -> tuple[Level, float, dict[str, float | int | None]] | None:
    """The objects as block proxies (:mod:`.blocks`) seen from ``distance``: of every
    tolerance of :data:`BLOCK_PX` and band depth of :data:`BAND_M`, the proxy with the fewest
    vertices whose silhouette F against ``source`` (the objects' finest geometry about
    ``origin``) reaches :data:`MIN_CELL_F` (tried fewest first), else the most faithful; its
    level, F and facts. ``None`` when no object has a footprint."""
    pixel = distance / options.view.focal_px
    prints = [p for chain in objects if (p := object_footprint(chain, _finest_mesh(chain)))]
    if not prints:
        return None
    found = blocks_of(prints, BLOCK_CLOSING_PX * pixel)
    tried = []
    for px, band in itertools.product(BLOCK_PX, BAND_M):
        mesh = block_proxy(found, px * pixel, band)
        if mesh is not None:
            tried.append((mesh.vertex_count, px, band, mesh.translated(-origin)))
    if not tried:
        return None
    best: tuple[float, Level, float, float] | None = None
    for _, px, band, mesh in sorted(tried, key=lambda t: t[:3]):
        level = Level(name="FAR", kind="merged", mesh=mesh)
        f = _silhouette_f(source, level, distance, options)
        if best is None or f > best[0]:
            best = (f, level, px, band)
        if f >= MIN_CELL_F:
            break
    assert best is not None
    f, level, px, band = best
    facts = {
        "blocks": len(found.polygons),
        "objects": len(prints),
        "tolerance_px": px,
        "band_m": band if math.isfinite(band) else None,
        "tried": len(tried),
    }
    return level, f, facts


def _member_blocks_level(
    members: list[Member],
    origin: np.ndarray,
    source: Mesh,
    distance: float,
    options: ChainOptions,
) -> tuple[Level, float, dict[str, Any]] | None:
    """A cell of finer cells as block proxies of each member's objects apart, one band per
    block, seen from ``distance``: every member's outlines at the finest of :data:`BLOCK_PX`
    first, then, coarser tolerance by coarser tolerance, as many of them made coarser (those
    that save the most vertices first) as keep the silhouette F against ``source`` at
    :data:`MIN_CELL_F`. Roofs and walls share their corners (:func:`~.blocks.shared_corners`).
    Its level, F and facts; ``None`` when no object has a footprint."""
    pixel = distance / options.view.focal_px
    ladder = sorted(BLOCK_PX)
    proxies = []
    blocks = objects = 0
    for member in members:
        chains = member.objects()
        prints = [p for c in chains if (p := object_footprint(c, _finest_mesh(c)))]
        if prints:
            found = blocks_of(prints, BLOCK_CLOSING_PX * pixel)
            blocks, objects = blocks + len(found.polygons), objects + len(prints)
            coarser = [block_proxy(found, px * pixel, math.inf) for px in ladder]
            proxies.append([shared_corners(m) if m is not None else None for m in coarser])
    if all(row[0] is None for row in proxies):
        return None

    def made(steps: list[int]) -> tuple[Level | None, float]:
        """The proxies at ``steps`` as one level (none where nothing with area is left) and
        its F."""
        meshes = [row[step] for row, step in zip(proxies, steps, strict=True)]
        if all(m is None for m in meshes):
            return None, 0.0
        mesh = _merged([m for m in meshes if m is not None]).translated(-origin)
        level = Level(name="FAR", kind="merged", mesh=_one_part(mesh))
        return level, _silhouette_f(source, level, distance, options)

    steps = [0] * len(proxies)
    level, f = made(steps)
    for step in range(1, len(ladder)):
        if f < MIN_CELL_F:
            break
        saving = [_count(row[step - 1]) - _count(row[step]) for row in proxies]
        order = sorted(
            (i for i, s in enumerate(steps) if s == step - 1), key=lambda i: (-saving[i], i)
        )
        low, high = 0, len(order)  # the most of ``order`` made coarser that keep F
        while low < high:
            middle = (low + high + 1) // 2
            if made(_raised(steps, order[:middle], step))[1] >= MIN_CELL_F:
                low = middle
            else:
                high = middle - 1
        steps = _raised(steps, order[:low], step)
        level, f = made(steps)
    assert level is not None  # the finest has area; a coarser one only where F is kept
    facts = {
        "blocks": blocks,
        "objects": objects,
        "tolerance_px": ladder[max(steps)],
        "band_m": None,
        "tried": len(ladder) * len(proxies),
        "per_member": {f"{px:g}": steps.count(i) for i, px in enumerate(ladder)},
        "shared_corners": True,
    }
    return level, f, facts


def _mixed_level(
    members: list[Member],
    origin: np.ndarray,
    source: Mesh,
    distance: float,
    options: ChainOptions,
    cost: float = math.inf,
) -> Made | None:
    """A cell of finer cells whose block proxies of each member apart stay below
    :data:`MIN_CELL_F` (:func:`_member_blocks_level`, outlines at the finest of
    :data:`BLOCK_PX`): block proxies where they keep the F, and, where they cost it, a member's
    own far content (:func:`_far_meshes`: a finer cell's far mesh, a building's coarsest level)
    or, inside such a member, single objects' own coarsest levels with blocks of the rest.
    Which ones cost the F is found on the silhouettes (:func:`_gains`); of the objects, then of
    the members, those that raise the F most per vertex added come first, and the fewest of
    them that reach :data:`MIN_CELL_F` are kept (the lighter of the two ways). Its level, F
    and facts; ``None`` when neither way reaches it with fewer than ``cost`` vertices (a
    faithful far level of another kind costs that much)."""
    pixel = distance / options.view.focal_px
    tolerance, closing = min(BLOCK_PX) * pixel, BLOCK_CLOSING_PX * pixel
    chains = [m.objects() for m in members]
    prints = [[object_footprint(c, _finest_mesh(c)) for c in row] for row in chains]
    parts: dict[tuple[int, frozenset[int] | None], tuple[Mesh | None, int]] = {}

    def part(i: int, own: frozenset[int] | None = frozenset()) -> tuple[Mesh | None, int]:
        """Member ``i`` about the cell's origin and its blocks: its own far content (``own``
        None), else block proxies of its objects but ``own`` and those objects' own coarsest
        levels."""
        if (i, own) not in parts:
            if own is None:
                meshes, blocks = _far_meshes(members[i]), 0
            else:
                rest = [p for k, p in enumerate(prints[i]) if p is not None and k not in own]
                found = blocks_of(rest, closing) if rest else None
                proxy = block_proxy(found, tolerance, math.inf) if found else None
                blocks = len(found.polygons) if proxy is not None and found else 0
                meshes = [shared_corners(proxy)] if proxy is not None else []
                meshes += [mesh for k in sorted(own) for mesh in _far_meshes(chains[i][k])]
            mesh = _merged(meshes).translated(-origin) if meshes else None
            parts[i, own] = mesh, blocks
        return parts[i, own]

    def made(choice: dict[int, frozenset[int] | None]) -> tuple[Level | None, float]:
        """The cell with ``choice``'s members as :func:`part` makes them (blocks elsewhere)
        and its F."""
        meshes = [m for i in range(len(members)) if (m := part(i, choice.get(i, frozenset()))[0])]
        if not meshes:
            return None, 0.0
        level = Level("FAR", "merged", mesh=_one_part(_merged(meshes)))
        return level, _silhouette_f(source, level, distance, options)

    base, _ = made({})
    if base is None or base.count >= cost:
        return None
    both = np.stack([source.bounds, base.mesh.bounds])  # the grid its F was measured on
    grid, want = _source_masks(
        source, pixel, np.stack([both[:, 0].min(0), both[:, 1].max(0)]), True
    )
    found = []
    gains, tried = _gains(members, part, lambda i, k: _far_meshes(chains[i][k]), origin, grid, want)
    for way, ranked in gains.items():
        low, high = 1, len(ranked)  # the fewest of ``ranked`` that reach MIN_CELL_F
        if not ranked or made(_choice_of(ranked))[1] < MIN_CELL_F:
            continue
        while low < high:
            middle = (low + high) // 2
            level, f = made(_choice_of(ranked[:middle]))
            if f >= MIN_CELL_F:
                high = middle
            elif level is not None and level.count >= cost:
                break  # those that reach it add more
            else:
                low = middle + 1
        choice = _choice_of(ranked[:low])
        level, f = made(choice)
        if level is None or level.count >= cost or f < MIN_CELL_F:
            continue
        kept = choice.values()
        facts = {
            "blocks": sum(part(i, choice.get(i, frozenset()))[1] for i in range(len(members))),
            "objects": sum(p is not None for row in prints for p in row),
            "tolerance_px": min(BLOCK_PX),
            "band_m": None,
            "tried": tried,
            "own_far": {
                "by": way,
                "members": sum(v is None for v in kept),
                "objects": sum(len(v or ()) for v in kept),
            },
            "shared_corners": True,
        }
        found.append((level, f, facts))
    return min(found, key=lambda m: m[0].count) if found else None


Ranked = list[tuple[float, int, frozenset[int] | None]]
"""Gain in F per vertex added, member and its objects kept as their own (``None``: the member's
own far content), best first."""


def _gains(
    members: list[Member],
    part: Callable[[int, frozenset[int] | None], tuple[Mesh | None, int]],
    own_object: Callable[[int, int], list[Mesh]],
    origin: np.ndarray,
    grid: Grid,
    want: list[np.ndarray],
) -> tuple[dict[str, Ranked], int]:
    """Which members' blocks cost the cell's F, and which of their objects': each member's own
    far content in place of its blocks, then, where that raises the F, each of its objects'
    own coarsest level over the blocks, on the silhouettes ``want`` of the cell's objects
    (``grid``); those that raise the F, ranked by gain per vertex added, and how many were
    tried."""
    blocks = [part(i)[0] for i in range(len(members))]
    covered = [np.zeros(mask.shape, dtype=np.int32) for mask in want]
    for mesh in blocks:
        if mesh is not None:
            for count, mask in zip(covered, silhouettes([mesh], grid)[0], strict=True):
                count += mask
    f = _masks_f(want, [count > 0 for count in covered])
    gains: dict[str, Ranked] = {"members": [], "objects": []}
    tried = 0
    for i, mesh in enumerate(blocks):
        own = part(i, None)[0]
        if own is None:
            continue
        tried += 1
        (drawn,) = silhouettes([own], grid)
        if mesh is not None:
            (mine,) = silhouettes([mesh], grid)
            drawn = [d | (c - m > 0) for d, c, m in zip(drawn, covered, mine, strict=True)]
        else:
            drawn = [d | (c > 0) for d, c in zip(drawn, covered, strict=True)]
        after = _masks_f(want, drawn)
        if after <= f:
            continue
        added = own.vertex_count - (mesh.vertex_count if mesh is not None else 0)
        gains["members"].append(((after - f) / max(added, 1), i, None))
        objects = len(members[i].objects())
        owned = [(k, _merged(meshes)) for k in range(objects) if (meshes := own_object(i, k))]
        for start in range(0, len(owned) if objects > 1 else 0, PROBES):
            batch = owned[start : start + PROBES]
            tried += len(batch)
            placed = [mesh.translated(-origin) for _, mesh in batch]
            for (k, mesh), drawn in zip(batch, silhouettes(placed, grid), strict=True):
                after = _masks_f(want, [d | (c > 0) for d, c in zip(drawn, covered, strict=True)])
                if after > f:
                    gain = (after - f) / max(mesh.vertex_count, 1)
                    gains["objects"].append((gain, i, frozenset([k])))
    for ranked in gains.values():
        ranked.sort(key=lambda g: (-g[0], g[1], sorted(g[2] or ())))
    return gains, tried


def _masks_f(want: list[np.ndarray], got: list[np.ndarray]) -> float:
    """Silhouette F of the masks ``got`` against ``want`` (worst precision and recall over the
    views, as :func:`~.plan.mesh_silhouette_estimate` measures it)."""
    precision = recall = 1.0
    for w, g in zip(want, got, strict=True):
        tp = int(np.count_nonzero(w & g))
        fp, fn = int(np.count_nonzero(g & ~w)), int(np.count_nonzero(w & ~g))
        if tp + fp + fn == 0:
            continue
        precision = min(precision, tp / (tp + fp) if tp + fp else 0.0)
        recall = min(recall, tp / (tp + fn) if tp + fn else 1.0)
    return SilhouetteEstimate(precision=precision, recall=recall).f


def _choice_of(ranked: Ranked) -> dict[int, frozenset[int] | None]:
    """Members with their own far content (None) or the objects of theirs with their own
    coarsest levels, from ``ranked`` (gain, member, objects or None)."""
    choice: dict[int, frozenset[int] | None] = {}
    for _, i, own in ranked:
        choice[i] = None if own is None else (choice.get(i) or frozenset()) | own
    return choice


def _raised(steps: list[int], which: list[int], step: int) -> list[int]:
    """``steps`` with those at the indices ``which`` set to ``step``."""
    raised = list(steps)
    for i in which:
        raised[i] = step
    return raised


def _count(mesh: Mesh | None) -> int:
    return mesh.vertex_count if mesh is not None else 0


def _lighter(one: Made | None, other: Made | None) -> Made | None:
    """Of two levels (with their F and facts), the one with fewer vertices of those whose F
    reaches :data:`MIN_CELL_F`, else the more faithful."""
    found = [m for m in (one, other) if m is not None]
    if not found:
        return None
    faithful = [m for m in found if m[1] >= MIN_CELL_F]
    if faithful:
        return min(faithful, key=lambda m: m[0].count)
    return max(found, key=lambda m: m[1])


def _floorless(mesh: Mesh) -> Mesh:
    """``mesh`` (an object's level, z up) without its floor on the ground: the faces looking
    straight down (:data:`DOWN`) that lie within :data:`FLOOR_MARGIN` of its lowest point,
    which no viewpoint above the ground sees; ``mesh`` itself when that is all of it."""
    low = mesh.bounds[0, 2] + FLOOR_MARGIN
    parts = []
    for part in mesh.parts:
        faces = np.arange(len(part.faces))
        floor = (part.face_normals(faces)[:, 2] < DOWN) & (
            part.triangles[:, :, 2].max(axis=1) <= low
        )
        if not floor.any():
            parts.append(part)
        elif not floor.all():
            parts.append(_with_faces(part, faces[~floor]))
    return Mesh(parts) if parts else mesh


def _with_faces(part: Surface, faces: np.ndarray) -> Surface:
    """``part`` with only the given faces and the vertices they use."""
    used, corners = np.unique(part.faces[faces], return_inverse=True)
    return replace(
        part,
        vertices=part.vertices[used],
        faces=corners.reshape(-1, 3),
        vertex_colors=None if part.vertex_colors is None else part.vertex_colors[used],
        uv=None if part.uv is None else part.uv[used],
    )


def _merged(meshes: Sequence[Mesh]) -> Mesh:
    return Mesh([part for mesh in meshes for part in mesh.parts])


def _one_part(mesh: Mesh) -> Mesh:
    """``mesh`` as one part (one draw call): parts' colours become vertex colours (on a white
    base colour, which glTF multiplies them by); textures are left out (their material colour
    stands in)."""
    colors = mesh.vertex_colors
    if colors is None:
        colors = np.concatenate(
            [np.repeat(p.material_color[None], len(p.vertices), axis=0) for p in mesh.parts]
        )
    return Mesh([Surface(mesh.vertices, mesh.faces, vertex_colors=colors, base_color=WHITE.copy())])


def _centre(member: Member) -> np.ndarray:
    """A member's switching centre in scene coordinates."""
    centre = np.asarray(member.origin, dtype=np.float64) + member.center
    if isinstance(member, LodChain) and member.transform is not None:
        matrix = np.asarray(member.transform, dtype=np.float64)
        centre = matrix[:3, :3] @ centre + matrix[:3, 3]
    return centre


def _admitted(members: list[Member], options: ChainOptions, gamma: float) -> list[Member]:
    """The members a cell admits: those that reach their coarsest level within the cell's
    switch distance by the formula, measured from the admitted members' centre (found again
    until it stays, at most :data:`ADMISSION_ROUNDS` times); when none does, the one that
    reaches it first (a cell of one switches where that member reaches its coarsest)."""
    bounds = {id(m): _world_bounds(m) for m in members}
    admitted = list(members)
    for _ in range(ADMISSION_ROUNDS):
        boxes = np.stack([bounds[id(m)] for m in admitted])
        low, high = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
        origin, alpha = (low + high) / 2.0, diagonal(np.stack([low, high]))
        limit = cutoff(alpha, options.beta, gamma, CELL_EXPONENT)
        kept = [m for m in members if _reach(m, origin) <= limit]
        if not kept:  # none would let it switch in time: a cell of the nearest-switching one
            return [min(members, key=lambda m: _reach(m, _centre(m)))]
        if [id(m) for m in kept] == [id(m) for m in admitted]:
            return kept
        admitted = kept
    return admitted


def _world_bounds(member: Member) -> np.ndarray:
    """(2, 3) bounding box of a member's objects' finest geometry in scene coordinates."""
    chains = member.objects()
    boxes = np.stack([_finest_mesh(chain).bounds for chain in chains])
    return np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])


def _reach(member: Member, origin: np.ndarray) -> float:
    """Distance from ``origin`` beyond which ``member`` surely shows its coarsest level."""
    return _coarsest_from(member) + float(np.linalg.norm(_centre(member) - origin))


def _coarsest_from(member: Member) -> float:
    """Distance from a member's centre beyond which it shows its coarsest level."""
    if isinstance(member, CellChain):
        return member.cutoffs[0]
    shown = len(member.levels)
    return member.cutoffs[shown - 2] if shown >= 2 else 0.0


def draw_counts(items: Sequence[Member]) -> dict[str, int]:
    """Scene-graph nodes (a root and a node per level for an object; a root, a near and a far
    node for a cell, as in glTF) and shapes written, and draw calls and vertices + points drawn
    when every item is seen from beyond all its cutoffs (culling aside): the far view of a
    city."""
    nodes = shapes = calls = drawn = 0
    for item in items:
        cells = item.cells() if isinstance(item, CellChain) else []
        chains = item.objects()
        nodes += 3 * len(cells) + sum(1 + len(chain.levels) for chain in chains)
        shapes += sum(_parts(cell.far) for cell in cells)
        shapes += sum(_parts(level) for chain in chains for level in chain.levels)
        far = item.far if isinstance(item, CellChain) else item.levels[-1]
        calls += _parts(far)
        drawn += far.count
    return {
        "nodes": nodes,
        "shapes": shapes,
        "far_draw_calls": calls,
        "far_vertices_and_points": drawn,
    }


def _parts(level: Level) -> int:
    return len(level.mesh.parts) if level.mesh is not None else 1
