"""Where a cell switches to its far level and which members it admits: the ranges' formula for
the cell (α its diagonal, γ half its side, x = :data:`CELL_EXPONENT`), raised by the seam rule
so the far level never shows while a member would still show a level finer than its coarsest;
a cell admits only the members that reach their coarsest level within its formula distance
(:func:`admitted_members`). Why: ``docs/lod-parents.md``."""

from __future__ import annotations

import numpy as np

from ..chain import ChainOptions
from ..model import CellChain, LodChain
from ..ranges import cutoff, diagonal
from .far_mesh import finest_mesh
from .hlod import Member

CELL_EXPONENT = 0.0
"""x of a cell's switch to its far level: Y = α·β, where a chain's finest baked level is
designed (:mod:`lodconvert.chain`)."""
SEAM_MARGIN = 1e-9
"""Relative margin that keeps a far level's switch strictly beyond its members'."""
ADMISSION_ROUNDS = 4
"""Times a cell's admitted members (and so its centre) are found again."""


def cell_gamma(size: float) -> float:
    """γ of a cell of side ``size``: its plot radius, half its side (above 1, as γ must be)."""
    return max(size / 2.0, 1.0 + 1e-6)


def cell_cutoffs(alpha: float, gamma: float, seam: float, options: ChainOptions) -> list[float]:
    """A cell's cutoffs: its switch to the far level, the formula's distance or just beyond the
    ``seam`` (the seam rule's distance) where that is farther; with culling, where it vanishes,
    the formula's distance for the cull exponent but never before the far level has shown."""
    switch = max(cutoff(alpha, options.beta, gamma, CELL_EXPONENT), seam * (1 + SEAM_MARGIN))
    if options.cull is None:
        return [switch]
    return [switch, max(cutoff(alpha, options.beta, gamma, options.cull), switch * 1.01)]


def admitted_members(members: list[Member], options: ChainOptions, gamma: float) -> list[Member]:
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
        kept = [m for m in members if reach(m, origin) <= limit]
        if not kept:  # none would let it switch in time: a cell of the nearest-switching one
            return [min(members, key=lambda m: reach(m, _centre(m)))]
        if [id(m) for m in kept] == [id(m) for m in admitted]:
            return kept
        admitted = kept
    return admitted


def _world_bounds(member: Member) -> np.ndarray:
    """(2, 3) bounding box of a member's objects' finest geometry in scene coordinates."""
    chains = member.objects()
    boxes = np.stack([finest_mesh(chain).bounds for chain in chains])
    return np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])


def reach(member: Member, origin: np.ndarray) -> float:
    """Distance from ``origin`` beyond which ``member`` surely shows its coarsest level."""
    return _coarsest_from(member) + float(np.linalg.norm(_centre(member) - origin))


def _coarsest_from(member: Member) -> float:
    """Distance from a member's centre beyond which it shows its coarsest level."""
    if isinstance(member, CellChain):
        return member.cutoffs[0]
    shown = len(member.levels)
    return member.cutoffs[shown - 2] if shown >= 2 else 0.0


def _centre(member: Member) -> np.ndarray:
    """A member's switching centre in scene coordinates."""
    centre = np.asarray(member.origin, dtype=np.float64) + member.center
    if isinstance(member, LodChain) and member.transform is not None:
        matrix = np.asarray(member.transform, dtype=np.float64)
        centre = matrix[:3, :3] @ centre + matrix[:3, 3]
    return centre
