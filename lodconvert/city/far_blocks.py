"""A cell's far level as block proxies (:mod:`.blocks`): its objects' footprints unioned into
blocks and extruded in height bands, the lightest outline tolerance and band depth that keeps
the silhouette (:func:`blocks_level`); for a cell of finer cells, each member's objects apart,
outlines made coarser member by member while the silhouette holds
(:func:`member_blocks_level`)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from ..bake.far_textures import in_source_textures
from ..chain import ChainOptions
from ..model import Level, LodChain, Mesh
from .blocks import block_proxy, blocks_of, object_footprint, shared_corners
from .far_choice import MIN_CELL_F, silhouette_f
from .far_mesh import finest_mesh, merge, one_part
from .hlod import Member

BLOCK_PX = (4.0, 2.0, 1.0)
"""Tolerances tried for block proxies' outlines, in pixels at the cell's switch distance."""
BAND_M = (math.inf, 6.0, 3.0, 1.0)
"""Height band depths tried for block proxies, metres (infinite: one band per block)."""
BLOCK_CLOSING_PX = 1.0
"""Gaps between footprints narrower than this many pixels at the switch distance are closed
into one block."""


def blocks_level(
    objects: list[LodChain],
    origin: np.ndarray,
    source: Mesh,
    distance: float,
    options: ChainOptions,
) -> tuple[Level, float, dict[str, float | int | None]] | None:
    """The objects as block proxies (:mod:`.blocks`) seen from ``distance``: of every
    tolerance of :data:`BLOCK_PX` and band depth of :data:`BAND_M`, the proxy with the fewest
    vertices whose silhouette F against ``source`` (the objects' finest geometry about
    ``origin``) reaches :data:`MIN_CELL_F` (tried fewest first), else the most faithful, its
    faces in a texture baked from ``source``'s where it is textured
    (:func:`~..bake.far_textures.in_source_textures`); its level, F and facts. ``None`` when
    no object has a footprint."""
    pixel = distance / options.view.focal_px
    prints = [p for chain in objects if (p := object_footprint(chain, finest_mesh(chain)))]
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
        # one that neither reaches MIN_CELL_F nor beats the best so far counts for nothing
        floor = 0.0 if best is None else min(MIN_CELL_F, best[0])
        f = silhouette_f(source, level, distance, options, floor)
        if best is None or f > best[0]:
            best = (f, level, px, band)
        if f >= MIN_CELL_F:
            break
    assert best is not None
    f, level, px, band = best
    assert level.mesh is not None
    level = replace(level, mesh=in_source_textures(level.mesh, source, pixel))
    facts = {
        "blocks": len(found.polygons),
        "objects": len(prints),
        "tolerance_px": px,
        "band_m": band if math.isfinite(band) else None,
        "tried": len(tried),
    }
    return level, f, facts


def member_blocks_level(
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
    :data:`MIN_CELL_F`. Roofs and walls share their corners (:func:`~.blocks.shared_corners`);
    faces take the textures of what they stand for as :func:`blocks_level`'s do. Its level, F and
    facts; ``None`` when no object has a footprint."""
    ladder = sorted(BLOCK_PX)
    pixel = distance / options.view.focal_px
    proxies, blocks, objects = _member_proxies(members, pixel, ladder)
    if all(row[0] is None for row in proxies):
        return None

    def made(steps: list[int]) -> tuple[Level | None, float]:
        """The proxies at ``steps`` as one level (none where nothing with area is left) and
        its F."""
        meshes = [row[step] for row, step in zip(proxies, steps, strict=True)]
        if all(m is None for m in meshes):
            return None, 0.0
        mesh = merge([m for m in meshes if m is not None]).translated(-origin)
        level = Level(name="FAR", kind="merged", mesh=one_part(mesh))
        return level, silhouette_f(source, level, distance, options)

    steps = [0] * len(proxies)
    level, f = made(steps)
    for step in range(1, len(ladder)):
        if f < MIN_CELL_F:
            break
        steps = _coarsened(steps, step, proxies, made)
        level, f = made(steps)
    # the finest has area; a coarser one only where F is kept
    assert level is not None and level.mesh is not None
    level = replace(level, mesh=in_source_textures(level.mesh, source, pixel))
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


def _member_proxies(
    members: list[Member], pixel: float, ladder: list[float]
) -> tuple[list[list[Mesh | None]], int, int]:
    """Block proxies of each member's objects (those with a footprint) at each outline
    tolerance of ``ladder`` (pixels of ``pixel`` metres), roofs and walls sharing corners; how
    many blocks and objects they hold."""
    proxies = []
    blocks = objects = 0
    for member in members:
        chains = member.objects()
        prints = [p for c in chains if (p := object_footprint(c, finest_mesh(c)))]
        if prints:
            found = blocks_of(prints, BLOCK_CLOSING_PX * pixel)
            blocks, objects = blocks + len(found.polygons), objects + len(prints)
            coarser = [block_proxy(found, px * pixel, math.inf) for px in ladder]
            proxies.append([shared_corners(m) if m is not None else None for m in coarser])
    return proxies, blocks, objects


def _coarsened(
    steps: list[int],
    step: int,
    proxies: list[list[Mesh | None]],
    made: Callable[[list[int]], tuple[Level | None, float]],
) -> list[int]:
    """``steps`` with as many of the members at ``step - 1`` raised to ``step`` as keep the
    level (``made``) at :data:`MIN_CELL_F`, those that save the most vertices first (found by
    bisection)."""
    saving = [_count(row[step - 1]) - _count(row[step]) for row in proxies]
    order = sorted((i for i, s in enumerate(steps) if s == step - 1), key=lambda i: (-saving[i], i))
    low, high = 0, len(order)  # the most of ``order`` made coarser that keep F
    while low < high:
        middle = (low + high + 1) // 2
        if made(_raised(steps, order[:middle], step))[1] >= MIN_CELL_F:
            low = middle
        else:
            high = middle - 1
    return _raised(steps, order[:low], step)


def _raised(steps: list[int], which: list[int], step: int) -> list[int]:
    """``steps`` with those at the indices ``which`` set to ``step``."""
    raised = list(steps)
    for i in which:
        raised[i] = step
    return raised


def _count(mesh: Mesh | None) -> int:
    """Vertices of ``mesh`` (none for no mesh)."""
    return mesh.vertex_count if mesh is not None else 0
