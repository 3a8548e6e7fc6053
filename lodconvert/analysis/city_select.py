"""What one frame draws: per object a level by range switching (X3D ``LOD``) or prism
switching (ProxyPrismLOD's boxes), frustum culling, LOD parents resolved from the coarsest tier
used down, and every cutoff times a LOD scale. See ``docs/render-bench.md`` (selection).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .bench import frustum_planes, spheres_in_frustum
from .city_cameras import Camera
from .city_draw import CityDraw

SWITCHINGS = ("range", "prism")


def range_levels(distances: np.ndarray, cutoffs: np.ndarray) -> np.ndarray:
    """Level index (N,) per object: how many of its cutoffs (N, K; padded with +inf) its
    viewer ``distances`` (N,) have reached (X3D ``LOD``)."""
    return (np.asarray(distances)[:, None] >= cutoffs).sum(axis=1)


def prism_levels(eye: np.ndarray, boxes: np.ndarray, cutoffs: np.ndarray) -> np.ndarray:
    """Level index (N,) per object: how many of its boxes — its box (N, 2, 3) grown by each
    cutoff (N, K; padded with +inf) on every side — leave the viewer at ``eye`` outside."""
    centre = boxes.mean(axis=1)
    half = (boxes[:, 1] - boxes[:, 0]) / 2.0
    outside = (np.abs(np.asarray(eye) - centre) - half).max(axis=1)
    return (outside[:, None] >= cutoffs).sum(axis=1)


@dataclass(frozen=True)
class Mode:
    """How a frame selects what it draws: frustum ``culling``, per-object levels (``lod``,
    else every object's finest level) switched by ``switching`` ("range" or "prism"), LOD
    parents of the finest ``tiers`` tiers (0: none), and whether cutoffs are multiplied by the
    LOD scale (``los_scale``)."""

    name: str
    culling: bool = True
    lod: bool = True
    switching: str = "range"
    tiers: int = 0
    los_scale: bool = False

    def __post_init__(self) -> None:
        if self.switching not in SWITCHINGS:
            raise ValueError(f"switching must be one of {SWITCHINGS}, got {self.switching!r}")


@dataclass
class Selection:
    """What one frame draws: its draw parts and the cells shown as their far level."""

    parts: np.ndarray
    far_cells: np.ndarray

    def vertices(self, city: CityDraw) -> int:
        """Vertices (mesh parts) plus points (point parts) submitted."""
        return int(city.geometry.size[self.parts].sum())

    @property
    def calls(self) -> int:
        """Draw calls: one per part."""
        return len(self.parts)


def _ranges(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """``starts[i] + k`` for k < ``counts[i]``, every i, concatenated."""
    total = int(counts.sum())
    before = np.cumsum(counts) - counts
    return np.repeat(starts - before, counts) + np.arange(total, dtype=np.int64)


def _open_cells(
    city: CityDraw, eye: np.ndarray, planes: np.ndarray | None, mode: Mode, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which cells open (members resolved) and which show their far level, tier by tier from
    the coarsest used down."""
    used = (city.cell_tier <= mode.tiers) & (mode.tiers > 0)
    shown = np.ones(len(city.cell_tier), dtype=bool)
    if planes is not None and len(shown):
        shown = spheres_in_frustum(city.cell_centres, city.cell_radii[:, None], planes)
    distance = np.linalg.norm(city.cell_centres - eye, axis=1) / scale
    far = distance >= city.cell_cutoffs[:, 0]
    gone = distance >= city.cell_cutoffs[:, 1]
    has_parent = city.cell_parent >= 0
    parent = np.where(has_parent, city.cell_parent, 0)
    opened = np.zeros(len(shown), dtype=bool)
    far_shown = np.zeros(len(shown), dtype=bool)
    for tier in range(mode.tiers, 0, -1):
        top = ~has_parent | ~used[parent]
        active = used & (city.cell_tier == tier) & (top | opened[parent])
        far_shown |= active & shown & far & ~gone
        opened |= active & shown & ~far
    return opened, far_shown


def select(city: CityDraw, camera: Camera, mode: Mode, scale: float = 1.0) -> Selection:
    """The draw parts of one frame seen by ``camera`` in ``mode``, cutoffs times ``scale``
    (the rules: ``docs/render-bench.md``, selection)."""
    eye = np.asarray(camera.eye, dtype=np.float64)
    planes = frustum_planes(camera.view_proj(city.far_plane(eye))) if mode.culling else None
    opened, far_shown = _open_cells(city, eye, planes, mode, scale)
    candidates = np.arange(city.objects)
    if mode.tiers > 0:
        cell = np.maximum(city.object_cell, 0)
        # an object in no cell, or held directly by a tier above those in use, draws alone
        alone = (city.object_cell < 0) | (city.cell_tier[cell] > mode.tiers)
        candidates = candidates[alone | opened[cell]]
    if planes is not None:
        inside = spheres_in_frustum(city.centres[candidates], city.radii[candidates, None], planes)
        candidates = candidates[inside]
    cutoffs = city.cutoffs[candidates] * scale
    if not mode.lod:
        levels = np.zeros(len(candidates), dtype=np.int64)
    elif mode.switching == "prism":
        levels = prism_levels(eye, city.boxes[candidates], cutoffs)
    else:
        levels = range_levels(np.linalg.norm(city.centres[candidates] - eye, axis=1), cutoffs)
    drawn = levels < city.level_parts.shape[1]
    candidates, levels = candidates[drawn], levels[drawn]
    parts = _ranges(city.level_first[candidates, levels], city.level_parts[candidates, levels])
    far_cells = np.flatnonzero(far_shown)
    return Selection(np.concatenate([parts, city.cell_far[far_cells]]), far_cells)
