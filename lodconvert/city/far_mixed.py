"""A cell's far level mixing block proxies with members' own far content, for a cell of finer
cells whose blocks alone lose the silhouette: blocks where they keep it and, where they cost it,
the fewest members' own far meshes, or single objects' own coarsest levels, that lift the F to
:data:`~.far_choice.MIN_CELL_F`, found on the silhouettes (:func:`mixed_level`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..bake.far_textures import in_source_textures
from ..bake.grid import Grid
from ..bake.numpy import silhouettes
from ..chain import ChainOptions
from ..model import Level, LodChain, Mesh
from ..plan import SilhouetteEstimate, _source_masks
from .blocks import Footprint, block_proxy, blocks_of, object_footprint, shared_corners
from .far_blocks import BLOCK_CLOSING_PX, BLOCK_PX
from .far_choice import MIN_CELL_F, Made, silhouette_f
from .far_mesh import far_meshes, finest_mesh, merge, one_part
from .hlod import Member

PROBES = 64
"""Objects whose silhouettes a mixed far level (:func:`mixed_level`) draws at once."""

Ranked = list[tuple[float, int, frozenset[int] | None]]
"""Gain in F per vertex added, member and its objects kept as their own (``None``: the member's
own far content), best first."""
Choice = dict[int, frozenset[int] | None]
"""Members with their own far content (``None``) or the objects of theirs with their own
coarsest levels, by member index."""


@dataclass
class _Mix:
    """A cell's members seen from ``distance``, each about the cell's ``origin`` as block
    proxies of its objects (outlines at the finest of :data:`BLOCK_PX`) or with its own far
    content (:func:`~.far_mesh.far_meshes`), in whole or object by object; the parts made so
    far are kept."""

    members: list[Member]
    origin: np.ndarray
    source: Mesh
    distance: float
    options: ChainOptions
    chains: list[list[LodChain]] = field(init=False)
    prints: list[list[Footprint | None]] = field(init=False)
    parts: dict[tuple[int, frozenset[int] | None], tuple[Mesh | None, int]] = field(
        init=False, default_factory=dict
    )

    def __post_init__(self) -> None:
        self.chains = [m.objects() for m in self.members]
        self.prints = [[object_footprint(c, finest_mesh(c)) for c in row] for row in self.chains]

    @property
    def pixel(self) -> float:
        """Metres a pixel spans at ``distance`` in the reference view."""
        return self.distance / self.options.view.focal_px

    def part(self, i: int, own: frozenset[int] | None = frozenset()) -> tuple[Mesh | None, int]:
        """Member ``i`` about the cell's origin and its blocks: its own far content (``own``
        None), else block proxies of its objects but ``own`` and those objects' own coarsest
        levels."""
        if (i, own) not in self.parts:
            if own is None:
                meshes, blocks = far_meshes(self.members[i]), 0
            else:
                meshes, blocks = self._blocks_but(i, own)
            mesh = merge(meshes).translated(-self.origin) if meshes else None
            self.parts[i, own] = mesh, blocks
        return self.parts[i, own]

    def _blocks_but(self, i: int, own: frozenset[int]) -> tuple[list[Mesh], int]:
        """Block proxies of member ``i``'s objects but ``own``, and those objects' own coarsest
        levels (scene coordinates); how many blocks."""
        rest = [p for k, p in enumerate(self.prints[i]) if p is not None and k not in own]
        found = blocks_of(rest, BLOCK_CLOSING_PX * self.pixel) if rest else None
        proxy = block_proxy(found, min(BLOCK_PX) * self.pixel, math.inf) if found else None
        blocks = len(found.polygons) if proxy is not None and found else 0
        meshes = [shared_corners(proxy)] if proxy is not None else []
        meshes += [mesh for k in sorted(own) for mesh in far_meshes(self.chains[i][k])]
        return meshes, blocks

    def made(self, choice: Choice) -> tuple[Level | None, float]:
        """The cell with ``choice``'s members as :meth:`part` makes them (blocks elsewhere)
        and its F."""
        meshes = [
            m
            for i in range(len(self.members))
            if (m := self.part(i, choice.get(i, frozenset()))[0])
        ]
        if not meshes:
            return None, 0.0
        level = Level("FAR", "merged", mesh=one_part(merge(meshes)))
        return level, silhouette_f(self.source, level, self.distance, self.options)

    def facts(self, choice: Choice, way: str, tried: int) -> dict[str, Any]:
        """What the level of ``choice`` holds, found ``way`` after ``tried`` probes."""
        kept = choice.values()
        members = range(len(self.members))
        return {
            "blocks": sum(self.part(i, choice.get(i, frozenset()))[1] for i in members),
            "objects": sum(p is not None for row in self.prints for p in row),
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


def mixed_level(
    members: list[Member],
    origin: np.ndarray,
    source: Mesh,
    distance: float,
    options: ChainOptions,
    cost: float = math.inf,
) -> Made | None:
    """A cell of finer cells whose block proxies of each member apart stay below
    :data:`MIN_CELL_F` (:func:`~.far_blocks.member_blocks_level`, outlines at the finest of
    :data:`BLOCK_PX`): block proxies where they keep the F, and, where they cost it, a member's
    own far content (:func:`~.far_mesh.far_meshes`: a finer cell's far mesh, a building's
    coarsest level) or, inside such a member, single objects' own coarsest levels with blocks of
    the rest. Which ones cost the F is found on the silhouettes (:func:`_gains`); of the
    objects, then of the members, those that raise the F most per vertex added come first, and
    the fewest of them that reach :data:`MIN_CELL_F` are kept (the lighter of the two ways). Its
    level, F and facts; ``None`` when neither way reaches it with fewer than ``cost`` vertices
    (a faithful far level of another kind costs that much). Over textured buildings, the
    level takes a texture baked from theirs (:func:`~..bake.far_textures.in_source_textures`)."""
    mix = _Mix(members, origin, source, distance, options)
    base, _ = mix.made({})
    if base is None or base.count >= cost:
        return None
    both = np.stack([source.bounds, base.mesh.bounds])  # the grid its F was measured on
    grid, want = _source_masks(
        source, mix.pixel, np.stack([both[:, 0].min(0), both[:, 1].max(0)]), True
    )
    found = []
    gains, tried = _gains(mix, grid, want)
    for way, ranked in gains.items():
        fewest = _fewest_reaching(ranked, mix.made, cost)
        if fewest is not None:
            choice, level, f = fewest
            found.append((level, f, mix.facts(choice, way, tried)))
    if not found:
        return None
    level, f, facts = min(found, key=lambda m: m[0].count)
    assert level.mesh is not None
    return replace(level, mesh=in_source_textures(level.mesh, source, mix.pixel)), f, facts


def _fewest_reaching(
    ranked: Ranked, made: Callable[[Choice], tuple[Level | None, float]], cost: float
) -> tuple[Choice, Level, float] | None:
    """The fewest first of ``ranked`` whose level (``made``) reaches :data:`MIN_CELL_F` with
    fewer than ``cost`` vertices, found by bisection, with the level and its F; ``None`` when
    all of them do not reach it or no such level is lighter than ``cost``."""
    low, high = 1, len(ranked)
    if not ranked or made(_choice_of(ranked))[1] < MIN_CELL_F:
        return None
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
        return None
    return choice, level, f


def _gains(mix: _Mix, grid: Grid, want: list[np.ndarray]) -> tuple[dict[str, Ranked], int]:
    """Which members' blocks cost the cell's F, and which of their objects': each member's own
    far content in place of its blocks, then, where that raises the F, each of its objects'
    own coarsest level over the blocks, on the silhouettes ``want`` of the cell's objects
    (``grid``); those that raise the F, ranked by gain per vertex added, and how many were
    tried."""
    blocks = [mix.part(i)[0] for i in range(len(mix.members))]
    covered = _coverage(blocks, grid, want)
    f = _masks_f(want, [count > 0 for count in covered])
    gains: dict[str, Ranked] = {"members": [], "objects": []}
    tried = 0
    for i, mesh in enumerate(blocks):
        own = mix.part(i, None)[0]
        if own is None:
            continue
        tried += 1
        after = _masks_f(want, _drawn_instead(own, mesh, covered, grid))
        if after <= f:
            continue
        added = own.vertex_count - (mesh.vertex_count if mesh is not None else 0)
        gains["members"].append(((after - f) / max(added, 1), i, None))
        objects = mix.chains[i]
        owned = [
            (k, merge(meshes)) for k, chain in enumerate(objects) if (meshes := far_meshes(chain))
        ]
        probed = owned if len(objects) > 1 else []
        tried += len(probed)
        gains["objects"] += _object_gains(i, probed, mix.origin, grid, want, covered, f)
    for ranked in gains.values():
        ranked.sort(key=lambda g: (-g[0], g[1], sorted(g[2] or ())))
    return gains, tried


def _coverage(blocks: list[Mesh | None], grid: Grid, want: list[np.ndarray]) -> list[np.ndarray]:
    """Per view of ``grid``, how many of the members' ``blocks`` cover each pixel."""
    covered = [np.zeros(mask.shape, dtype=np.int32) for mask in want]
    for mesh in blocks:
        if mesh is not None:
            for count, mask in zip(covered, silhouettes([mesh], grid)[0], strict=True):
                count += mask
    return covered


def _drawn_instead(
    own: Mesh, blocks: Mesh | None, covered: list[np.ndarray], grid: Grid
) -> list[np.ndarray]:
    """The cell's silhouettes with a member's own far content ``own`` in place of its
    ``blocks``."""
    (drawn,) = silhouettes([own], grid)
    if blocks is None:
        return [d | (c > 0) for d, c in zip(drawn, covered, strict=True)]
    (mine,) = silhouettes([blocks], grid)
    return [d | (c - m > 0) for d, c, m in zip(drawn, covered, mine, strict=True)]


def _object_gains(
    i: int,
    owned: list[tuple[int, Mesh]],
    origin: np.ndarray,
    grid: Grid,
    want: list[np.ndarray],
    covered: list[np.ndarray],
    f: float,
) -> Ranked:
    """Member ``i``'s objects (their index and own coarsest level, scene coordinates) whose own
    level drawn over the blocks raises the F above ``f``, with their gain per vertex; drawn
    :data:`PROBES` at a time."""
    gains: Ranked = []
    for start in range(0, len(owned), PROBES):
        batch = owned[start : start + PROBES]
        placed = [mesh.translated(-origin) for _, mesh in batch]
        for (k, mesh), drawn in zip(batch, silhouettes(placed, grid), strict=True):
            after = _masks_f(want, [d | (c > 0) for d, c in zip(drawn, covered, strict=True)])
            if after > f:
                gains.append(((after - f) / max(mesh.vertex_count, 1), i, frozenset([k])))
    return gains


def _masks_f(want: list[np.ndarray], got: list[np.ndarray]) -> float:
    """Silhouette F of the masks ``got`` against ``want`` (worst precision and recall over the
    views, as :func:`~lodconvert.plan.mesh_silhouette_estimate` measures it)."""
    precision = recall = 1.0
    for w, g in zip(want, got, strict=True):
        tp = int(np.count_nonzero(w & g))
        fp, fn = int(np.count_nonzero(g & ~w)), int(np.count_nonzero(w & ~g))
        if tp + fp + fn == 0:
            continue
        precision = min(precision, tp / (tp + fp) if tp + fp else 0.0)
        recall = min(recall, tp / (tp + fn) if tp + fn else 1.0)
    return SilhouetteEstimate(precision=precision, recall=recall).f


def _choice_of(ranked: Ranked) -> Choice:
    """The :data:`Choice` that ``ranked`` (gain, member, objects or None) makes."""
    choice: Choice = {}
    for _, i, own in ranked:
        choice[i] = None if own is None else (choice.get(i) or frozenset()) | own
    return choice
