"""Which levels an object gets: a coarser level only where it is cheaper to draw than the level
before it and still looks like the object where it first shows.

**Cheaper**: draw cost in mesh-vertex units, a point costing :data:`POINT_COST` of a vertex.
**Looks like the object**: at its switch-in distance in the reference view, the level's
silhouette precision and recall against the source both reach :data:`MIN_SILHOUETTE`, as
:func:`silhouette_estimate` rasterises them without GL along the three axes
(``tests/test_plan.py`` holds it against GL renders); a city object's derived levels are
judged over the upper hemisphere instead (:func:`view_estimate`). When no coarser
representation passes, the finer level stays on to the next cutoff. The rule, and its
evidence: ``docs/levels.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .bake.grid import Grid
from .bake.numpy import silhouettes
from .model import Level, Mesh, PointCloud
from .ranges import REFERENCE_VIEW, ReferenceView
from .views import GUARD_BASES

POINT_COST = 1 / 1.6
"""Draw cost of one point in mesh-vertex units (the slowest measured speed-up of points)."""
MIN_SILHOUETTE = 0.9
"""Least silhouette precision and recall of a level at its switch-in distance."""
MIN_CELLS_ACROSS = 8
"""Fewest grid cells along the longest side that can give a silhouette within
:data:`MIN_SILHOUETTE`: the squares of a coarser grid err by a large share of the outline. Used
to skip baking where even that many cells would not be cheaper."""


def level_cost(level: Level) -> float:
    """Draw cost of a level in mesh-vertex units."""
    return level.count * (POINT_COST if level.is_points else 1.0)


def level_bytes(level: Level) -> int:
    """Bytes of a level's geometry as the glTF writer lays it out (textures aside): per vertex
    or point a float32 position, a float32 normal (none for a merged far mesh) and, where it
    has them, colours as four normalised uint16; per triangle three uint16 indices (uint32 in a
    part of 65,536 vertices or more)."""
    if level.mesh is None:
        return level.count * 32
    normal = 0 if level.kind == "merged" else 12
    total = 0
    for part in level.mesh.parts:
        per_vertex = 12 + normal + (8 if part.vertex_colors is not None else 0)
        per_triangle = 6 if len(part.vertices) < 65536 else 12
        total += len(part.vertices) * per_vertex + len(part.faces) * per_triangle
    return total


def surface_area(mesh: Mesh) -> float:
    """Total triangle area of ``mesh``."""

    def compute() -> float:
        tri = mesh.triangles
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        return float(0.5 * np.linalg.norm(cross, axis=1).sum())

    return mesh.derived("area", compute)


def fewest_points(mesh: Mesh) -> float:
    """A lower estimate of the points of any point level that could look like ``mesh``: the
    cells of a :data:`MIN_CELLS_ACROSS` grid that the surface passes through (each holds one
    point), taken as half the surface area over a cell face."""
    pitch = float(np.ptp(mesh.bounds, axis=0).max()) / MIN_CELLS_ACROSS
    return surface_area(mesh) / pitch**2 / 2.0


def least_point_cost(mesh: Mesh) -> float:
    """The draw cost below which no point level of ``mesh`` can look like it (see
    :func:`fewest_points`): a level before that costs no more than this is never replaced by
    points, and none is baked."""
    return fewest_points(mesh) * POINT_COST


@dataclass(frozen=True)
class SilhouetteEstimate:
    """Silhouette precision and recall of a level against its source: the worst of the three
    axis views."""

    precision: float
    recall: float

    @property
    def passes(self) -> bool:
        """Both at least :data:`MIN_SILHOUETTE`."""
        return self.precision >= MIN_SILHOUETTE and self.recall >= MIN_SILHOUETTE

    @property
    def f(self) -> float:
        """Silhouette F: the harmonic mean of precision and recall."""
        p, r = self.precision, self.recall
        return 2 * p * r / (p + r) if p + r > 0 else 0.0


def _source_masks(
    mesh: Mesh, pixel: float, bounds: np.ndarray | None = None, keep: bool = False
) -> tuple[Grid, list[np.ndarray]]:
    """The source's silhouettes along x, y and z on a grid of pitch ``pixel`` over ``bounds``
    (the mesh's own by default); with ``keep``, kept with ``mesh`` for the next call with the
    same pixel and bounds."""
    bounds = mesh.bounds if bounds is None else bounds

    def compute() -> tuple[Grid, list[np.ndarray]]:
        grid = _grid(pixel, bounds)
        return grid, silhouettes([mesh], grid)[0]

    if not keep:
        return compute()
    return mesh.derived(f"silhouette-masks-{pixel!r}-{bounds.tobytes().hex()}", compute)


def _grid(pixel: float, bounds: np.ndarray) -> Grid:
    """A grid of pitch ``pixel`` over ``bounds``."""
    resolution = max(1, math.ceil(float(np.ptp(bounds, axis=0).max()) / pixel - 1e-9))
    return Grid.for_bounds(bounds, resolution, 1)


def _splat(centres: np.ndarray, size: float, shape: tuple[int, int], pad: int) -> np.ndarray:
    """Pixels (of an image padded by ``pad`` on every side) whose centres lie in the squares of
    side ``size`` around ``centres`` ((k, 2) pixel coordinates (col, row), centre of pixel
    (0, 0) at (0, 0))."""
    rows, cols = shape[0] + 2 * pad, shape[1] + 2 * pad
    half = max(size, 1.0) / 2.0
    lo = np.ceil(centres - half - 1e-9).astype(np.int64) + pad
    hi = np.floor(centres + half + 1e-9).astype(np.int64) + pad
    lo, hi = np.clip(lo, 0, [cols, rows]), np.clip(hi, -1, [cols - 1, rows - 1])
    keep = (hi >= lo).all(axis=1)
    lo, hi = lo[keep], hi[keep]
    acc = np.zeros((rows + 1, cols + 1), dtype=np.int32)
    np.add.at(acc, (lo[:, 1], lo[:, 0]), 1)
    np.add.at(acc, (lo[:, 1], hi[:, 0] + 1), -1)
    np.add.at(acc, (hi[:, 1] + 1, lo[:, 0]), -1)
    np.add.at(acc, (hi[:, 1] + 1, hi[:, 0] + 1), 1)
    return acc.cumsum(axis=0).cumsum(axis=1)[:rows, :cols] > 0


def silhouette_estimate(
    mesh: Mesh,
    cloud: PointCloud,
    point_px: float,
    distance: float,
    view: ReferenceView = REFERENCE_VIEW,
) -> SilhouetteEstimate:
    """Silhouette precision and recall of ``cloud`` (points ``point_px`` wide) against ``mesh``
    seen from ``distance`` in ``view``, both in the same frame; the worst over the axis views
    (a model's point levels, whatever way up it is)."""
    pixel = distance / view.focal_px
    grid, masks = _source_masks(mesh, pixel)
    pad = math.ceil(max(point_px, 1.0))
    if not any(mask.any() for mask in masks):  # thinner than a pixel: nothing to look like
        return SilhouetteEstimate(precision=0.0, recall=0.0)
    precision = recall = 1.0
    for axis, source in enumerate(masks):
        if not source.any():  # seen edge-on from this axis
            continue
        u, v = grid.plane_axes(axis)
        centres = (cloud.positions[:, [u, v]] - grid.lo[[u, v]]) / grid.pitch - 0.5
        drawn = _splat(centres, point_px, source.shape, pad)
        padded = np.pad(source, pad)
        tp = int(np.count_nonzero(drawn & padded))
        fp = int(np.count_nonzero(drawn & ~padded))
        fn = int(np.count_nonzero(~drawn & padded))
        precision = min(precision, tp / (tp + fp) if tp + fp else 0.0)
        recall = min(recall, tp / (tp + fn) if tp + fn else 1.0)
    return SilhouetteEstimate(precision=precision, recall=recall)


GUARD_MARGIN = 0.25
"""How much of its size a source's image in a guard view has on every side beyond it, for the
levels drawn against it (:func:`view_estimate`)."""


def view_estimate(
    source: Mesh,
    other: Mesh | PointCloud,
    distance: float,
    view: ReferenceView = REFERENCE_VIEW,
    point_px: float = 1.0,
    keep: bool = False,
    stop_below: float = 0.0,
) -> SilhouetteEstimate:
    """Silhouette precision and recall of ``other`` (a mesh, or points ``point_px`` wide)
    against ``source`` seen from ``distance`` in ``view`` (both in the same frame, z up), over
    the guard's views of the upper hemisphere (:mod:`.views`): those of the view where F is
    least. Both are drawn on one pixel grid per view (:mod:`.bake.spans`; numba loaded here,
    where a run first judges a derived level); with ``keep``, ``source``'s silhouettes are kept
    with it for the next estimate at that distance (a cell's candidates), and the views stop
    at the first whose F is below ``stop_below``: then the F is that view's (the least is no
    higher), for a caller that only needs to know it is below."""
    from .bake import spans

    if isinstance(other, PointCloud):
        positions, faces, size = other.positions, np.zeros((0, 3), np.int64), max(point_px, 1.0)
    else:
        positions, faces, size = other.vertices, other.faces, 0.0
    args = (_floats(positions), _indices(faces), size)
    seen = (distance, view.focal_px)
    mesh = (_floats(source.vertices), _indices(source.faces))
    if not keep:
        counts = spans.overlap_counts(*mesh, *args, GUARD_BASES, *seen)
    else:
        frames, bits = source.derived(
            f"guard-{seen!r}", lambda: spans.silhouettes(*mesh, GUARD_BASES, *seen, GUARD_MARGIN)
        )
        counts = spans.counts_against(frames, bits, *args, GUARD_BASES, *seen, stop_below)
        if (counts[:, 0] == -2).any():  # stopped at a view below ``stop_below``
            counts = counts[counts[:, 0] >= 0]
        elif len(apart := np.flatnonzero(counts[:, 0] < 0)):  # beyond the source's images
            counts[apart] = spans.overlap_counts(*mesh, *args, GUARD_BASES[apart], *seen)
    worst = SilhouetteEstimate(precision=1.0, recall=1.0)
    for wanted, drawn, tp in counts.tolist():
        if not wanted and not drawn:
            continue
        here = SilhouetteEstimate(
            precision=tp / drawn if drawn else 0.0, recall=tp / wanted if wanted else 1.0
        )
        if here.f < worst.f:
            worst = here
    return worst


def _floats(array: np.ndarray) -> np.ndarray:
    """``array`` as contiguous float64 (what the compiled loops are compiled for)."""
    return np.ascontiguousarray(array, dtype=np.float64)


def _indices(array: np.ndarray) -> np.ndarray:
    """``array`` as contiguous int64 (what the compiled loops are compiled for)."""
    return np.ascontiguousarray(array, dtype=np.int64)
