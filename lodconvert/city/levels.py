"""A city object's chain from its own LoDs: its finest source LoD, the source's coarser LoDs in
their slots, a LOD1 prism derived from its footprint where the source has none, and points
baked where they pay (docs/levels.md, docs/cities.md). :mod:`lodconvert.plans` chooses this
plan for a city object, :mod:`lodconvert.chain` bakes it."""

from __future__ import annotations

import numpy as np

from ..bake.far_textures import in_source_textures
from ..chain import (
    NO_POINTS_PAY,
    ChainOptions,
    ChainPlan,
    PlannedLevel,
    framed,
    least_cost,
    plan_of,
    points_may_pay,
)
from ..model import Level, Mesh, Node
from ..model.lods import GROUND_COVERS, SLOTS, lod_name, unused_levels
from ..plan import view_estimate
from ..ranges import cutoff
from .prisms import (
    FOOTPRINT_TOLERANCE_PX,
    LOW_F,
    MIN_PRISM_F,
    MORE_TRIANGLES,
    in_texture_colours,
    prism,
)


def source_plan(obj: Node, sources: dict[int, tuple[str, Mesh]], opts: ChainOptions) -> ChainPlan:
    """The CityGML-style chain of a city object with its own LoDs (:mod:`.model.lods`): its
    finest source LoD covers every slot up to its own; each coarser slot is the source's LoD
    there (in a texture baked from the finest one's where it has none of its own), else
    (LOD1) a prism from its footprint, else (LOD3, LOD2) baked points where they pay; a slot
    with none of these leaves the finer level on."""
    finest_slot = max(k for k in sources if k in SLOTS)
    finest = sources[finest_slot][1]
    frame = framed(finest)
    origin, surface = frame[0], frame[2]
    xs = list(opts.exponents)
    name = f"LOD{finest_slot}"
    levels = [PlannedLevel(name, None, Level(name=name, kind="source", mesh=surface))]
    dropped: dict[str, str] = {}
    for slot in range(finest_slot - 1, 0, -1):
        index = SLOTS.index(slot) - 1  # LOD3 → 0 … LOD1 → 2: its cutoff and exponent
        name = f"LOD{slot}"
        level: Level | str | None = None
        distance = cutoff(frame[1], opts.beta, opts.gamma, xs[index])
        if slot in sources:
            coarse = in_texture_colours(sources[slot][1], finest, distance / opts.view.focal_px)
            level = Level(name=name, kind="source", mesh=coarse.translated(-origin))
        elif slot == 1 and obj.type in GROUND_COVERS:
            level = f"a {obj.type} covers the ground: no prism"
        elif slot == 1:
            made = [p.level for p in levels if p.level is not None]
            level = _prism_level(obj, finest, origin, surface, made[-1], distance, opts)
        elif not points_may_pay([p.level for p in levels], least_cost(surface, opts)):
            level = NO_POINTS_PAY
        if isinstance(level, str):
            dropped[name] = level
            continue
        levels.append(PlannedLevel(name, xs[index], level, index))
    unused = unused_levels(obj.lods)
    if 0 in sources and not any(p.level and p.level.kind == "prism" for p in levels):
        unused[sources[0][0]] = (
            f"LOD1 is the source's {lod_name(sources[1][0])}, not a prism of this footprint"
            if 1 in sources
            else dropped["LOD1"]
        )
    return plan_of(obj, opts, levels, frame, dropped, unused)


def _prism_level(
    obj: Node,
    finest: Mesh,
    origin: np.ndarray,
    surface: Mesh,
    previous: Level,
    distance: float,
    opts: ChainOptions,
) -> Level | str:
    """The LOD1 prism of ``obj`` (its footprint simplified within
    :data:`~.prisms.FOOTPRINT_TOLERANCE_PX` pixels at ``distance``, where it switches in; in a
    texture baked from ``finest``'s where that is textured), or
    why it is left out: no footprint, no fewer triangles than ``previous`` (the source LoD
    planned before it), or a silhouette F against ``surface`` (the finest level) below
    :data:`~.prisms.MIN_PRISM_F` at ``distance``."""
    pixel = distance / opts.view.focal_px
    shape = prism(obj.lods, finest, obj.attributes, FOOTPRINT_TOLERANCE_PX * pixel)
    if shape is None:
        return "no footprint with area to extrude"
    assert previous.mesh is not None
    if shape.face_count >= previous.mesh.face_count:
        return (
            f"{MORE_TRIANGLES} {previous.name}: the prism has {shape.face_count:,} "
            f"triangles, {previous.name} {previous.mesh.face_count:,}"
        )
    mesh = shape.translated(-origin)
    f = view_estimate(surface, mesh, distance, opts.view).f
    if f < MIN_PRISM_F:
        return f"{LOW_F} {f:.3f} where it switches in, below {MIN_PRISM_F}"
    mesh = in_source_textures(mesh, surface, pixel)
    return Level(name="LOD1", kind="prism", mesh=mesh, silhouette_f=f)


def lod0_plan(obj: Node, opts: ChainOptions) -> ChainPlan | None:
    """The chain of a city object whose only source LoD is 0 (footprints, roof edges): its
    LOD1 prism, the height of which only ``measuredHeight`` can give (None without one, or for
    a ground cover: then its LoD 0 surfaces are its geometry, as a mesh's)."""
    if obj.type in GROUND_COVERS:
        return None
    shape = prism(obj.lods, obj.geometry, obj.attributes)
    if shape is None:
        return None
    frame = framed(shape)
    level = Level(name="LOD1", kind="prism", mesh=frame[2])
    dropped = {f"LOD{slot}": "the source has only LoD 0" for slot in SLOTS[:-1]}
    return plan_of(
        obj, opts, [PlannedLevel("LOD1", None, level)], frame, dropped, unused_levels(obj.lods)
    )
