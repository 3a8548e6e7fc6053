"""LOD parents (HLOD, ``--hlod``): a city's objects grouped into the square cells of a grid
anchored at the scene's coordinate origin, by their ground centre, finest tier first, each
coarser cell holding the finer cells whose centres fall in it; the options, the grid plan
(:func:`plan_cells`) and what the far view of a city draws (:func:`draw_counts`).

A cell is baked by :func:`~.cell_bake.bake_cell`: where it switches and which members it admits
(:mod:`.cell_switch`), its far level as points, a merged mesh (:mod:`.far_mesh`) or block
proxies (:mod:`.far_blocks`, :mod:`.far_mixed`), kept by silhouette fidelity
(:mod:`.far_choice`). The method and the reasons for each rule: ``docs/lod-parents.md``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import UsageError
from ..model import CellChain, LodChain

KINDS = ("auto", "points", "mesh", "blocks")
AUTO_OBJECTS = 64
"""Objects an ``auto`` cell holds on average."""
AUTO_SIZES = (25.0, 50.0, 100.0, 250.0, 500.0, 1000.0, 2000.0, 5000.0)
"""Cell sides (metres) that ``auto`` rounds to."""

Member = LodChain | CellChain
"""What a cell holds: objects' chains, or finer cells (and the objects they left out)."""


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
    """The ``auto`` cell side for objects at ``centres`` ((n, 2) metres): the side of a square
    holding :data:`AUTO_OBJECTS` objects on average over their ground bounding rectangle,
    rounded to the nearest of :data:`AUTO_SIZES` in proportion."""
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
    """Added to the id (``_beside``: the members a coarsest cell left out,
    :func:`~.cell_bake.bake_cell`)."""

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
        shapes += sum(cell.far.parts for cell in cells)
        shapes += sum(level.parts for chain in chains for level in chain.levels)
        far = item.far if isinstance(item, CellChain) else item.levels[-1]
        calls += far.parts
        drawn += far.count
    return {
        "nodes": nodes,
        "shapes": shapes,
        "far_draw_calls": calls,
        "far_vertices_and_points": drawn,
    }
