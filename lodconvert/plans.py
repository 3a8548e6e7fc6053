"""Which chain an object gets: a city object's from its own LoDs (:mod:`.city.levels`), else a
mesh's, its points baked from the finest geometry (:mod:`.chain`); docs/levels.md explains
both."""

from __future__ import annotations

from dataclasses import replace

from .bake import Backend
from .chain import ChainOptions, ChainPlan, Progress, bake_plan, check_geometry, mesh_plan
from .city.levels import lod0_plan, source_plan
from .limits import DEFAULT_LIMITS, Limits
from .model import LodChain, Node
from .model.lods import SLOTS, source_levels
from .ranges import DEFAULT_GAMMA


def plan_chain(obj: Node, opts: ChainOptions) -> ChainPlan:
    """The plan of ``obj``'s chain (``opts.gamma`` ``None``: the default γ); nothing is
    baked. ``lodconvert ranges`` prints it, :func:`bake_chain` bakes it."""
    opts.check()
    check_geometry(obj)
    if opts.gamma is None:
        opts = replace(opts, gamma=DEFAULT_GAMMA)
    sources = source_levels(obj.lods)
    if opts.keep_mesh and opts.levels == len(SLOTS) and any(k in SLOTS for k in sources):
        return source_plan(obj, sources, opts)
    if opts.keep_mesh and opts.levels == len(SLOTS) and 0 in sources:
        only_prism = lod0_plan(obj, opts)
        if only_prism is not None:
            return only_prism
    return mesh_plan(obj, opts)


def bake_chain(
    obj: Node,
    opts: ChainOptions,
    backend: Backend,
    progress: Progress | None = None,
    warn: Progress | None = None,
    limits: Limits = DEFAULT_LIMITS,
) -> LodChain:
    """Plan and bake ``obj``'s chain (levels relative to its bounding-box centre), within
    ``limits`` (grid cells per level, working memory)."""
    return bake_plan(plan_chain(obj, opts), opts, backend, progress, warn, limits)
