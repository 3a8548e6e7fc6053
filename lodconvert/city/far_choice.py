"""Choosing a cell's far level by silhouette fidelity: each candidate's silhouette F against the
cell's objects' finest geometry, seen from where the far level switches in
(:func:`silhouette_f`); of those reaching :data:`MIN_CELL_F` the cheapest, else the most
faithful (:func:`chosen_kind`, :func:`lighter`)."""

from __future__ import annotations

import math
from typing import Any

from ..chain import ChainOptions
from ..model import Level, Mesh
from ..plan import level_bytes, level_cost, view_estimate

MIN_CELL_F = 0.95
"""Least silhouette F of a far level against its members where it switches in."""

Made = tuple[Level, float, dict[str, Any]]
"""A far level, its silhouette F and its facts."""


def silhouette_f(
    source: Mesh, level: Level, distance: float, options: ChainOptions, stop_below: float = 0.0
) -> float:
    """Silhouette F of ``level`` against ``source`` seen from ``distance`` over the guard's
    views (:func:`~lodconvert.plan.view_estimate`; ``source``'s silhouettes kept with it: a
    cell compares every candidate with the same); below ``stop_below``, only some F below it
    (the views stop at the first below: for a candidate whose F counts only if it is not)."""
    if level.points is not None:
        size = level.params.point_size if level.params is not None else 1.0
        return view_estimate(source, level.points, distance, options.view, size, True, stop_below).f
    assert level.mesh is not None
    return view_estimate(
        source, level.mesh, distance, options.view, keep=True, stop_below=stop_below
    ).f


def lighter(one: Made | None, other: Made | None) -> Made | None:
    """Of two levels (with their F and facts), the one with fewer vertices of those whose F
    reaches :data:`MIN_CELL_F`, else the more faithful."""
    found = [m for m in (one, other) if m is not None]
    if not found:
        return None
    faithful = [m for m in found if m[1] >= MIN_CELL_F]
    if faithful:
        return min(faithful, key=lambda m: m[0].count)
    return max(found, key=lambda m: m[1])


def chosen_kind(candidates: dict[str, tuple[Level, float]], kind: str) -> tuple[str, str]:
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


def faithful_cost(candidates: dict[str, tuple[Level, float]]) -> float:
    """The least draw cost of the ``candidates`` whose F reaches :data:`MIN_CELL_F` (infinite
    when none does)."""
    return min(
        (level_cost(lv) for lv, f in candidates.values() if f >= MIN_CELL_F), default=math.inf
    )
