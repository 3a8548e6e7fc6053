"""Fidelity of LOD levels against their source mesh (``lodconvert evaluate``): silhouette
precision, recall and F of each level against the source on a protocol of views and within the
level's own range (:func:`silhouette_scores`, :func:`level_window`), points drawn at their
declared size; Chamfer and Hausdorff distance between dense surface samples
(:func:`geometric_errors`); the chains of a file lodconvert wrote paired with the source's
objects (:func:`match_references`). How each is measured: ``docs/fidelity.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..errors import InputError, LodConvertError, UsageError
from ..model import Level, LodChain, Node, Surface
from ..ranges import REFERENCE_VIEW, ReferenceView, cutoff, diagonal
from .render import fibonacci_directions
from .silhouette import Geometry, SilhouetteRenderer

DEFAULT_VIEWS = 64
DEFAULT_SIZE = 512
DEFAULT_FOV = 45.0
DEFAULT_DISTANCES = (4.0, 8.0, 16.0)
DEFAULT_SAMPLES = 1_000_000
"""Surface samples for the geometric error: their mean spacing on the Stanford scans is
about 0.1 % of the diagonal (:func:`sample_spacing`)."""
SAMPLE_SEED = 0
BOUNDS_TOLERANCE = 1e-3
"""How far (fraction of α) REF's bounding-box centre and diagonal may be from OUT's."""
MIN_SIZE = 16
"""Smallest render (pixels a side) a :class:`Protocol` may ask for."""


def silhouette_scores(reference_masks: np.ndarray, level_masks: np.ndarray) -> dict[str, float]:
    """TP, FP, FN summed over all views and pixels, with precision, recall and F.

    TP = covered in both, FP = in the level only, FN = in the reference only.
    Precision = TP / (TP + FP), recall = TP / (TP + FN), F = 2PR / (P + R); all three are 0
    when TP = 0 (so two empty masks score 0), and identical non-empty masks score 1.
    """
    ref = np.asarray(reference_masks, dtype=bool)
    lod = np.asarray(level_masks, dtype=bool)
    if ref.shape != lod.shape:
        raise ValueError(f"mask shapes differ: {ref.shape} vs {lod.shape}")
    tp = int(np.count_nonzero(ref & lod))
    fp = int(np.count_nonzero(lod)) - tp
    fn = int(np.count_nonzero(ref)) - tp
    precision = tp / (tp + fp) if tp else 0.0
    recall = tp / (tp + fn) if tp else 0.0
    f = 2.0 * precision * recall / (precision + recall) if tp else 0.0
    return {"tp": tp, "fp": fp, "fn": fn, "precision": precision, "recall": recall, "f": f}


@dataclass
class DistanceScore:
    """One level seen from one distance: ``diagonals`` = distance / α; ``pixel_size`` is the
    point width drawn (None for a mesh level); the rest as in :func:`silhouette_scores`."""

    distance: float
    diagonals: float
    pixel_size: float | None
    precision: float
    recall: float
    f: float
    tp: int
    fp: int
    fn: int


@dataclass
class RangeScores:
    """A level within its own range (:func:`level_window`): where it first shows (``near``)
    and in the middle of its range, with the declared point size and (point levels only) with
    1-pixel points, as glTF viewers draw them."""

    near: DistanceScore
    middle: DistanceScore
    near_1px: DistanceScore | None = None
    middle_1px: DistanceScore | None = None


@dataclass
class LevelScores:
    """Silhouette scores of one level: per requested distance, and (when asked) at the level's
    own ``design_distance`` and within its range (neither is part of ``mean_f``)."""

    name: str
    kind: str
    count: int
    point_size: float | None
    scores: list[DistanceScore]
    at_design: DistanceScore | None = None
    in_range: RangeScores | None = None

    @property
    def mean_f(self) -> float:
        """Mean F over the requested distances."""
        return float(np.mean([s.f for s in self.scores])) if self.scores else 0.0


def level_window(chain: LodChain, index: int) -> tuple[float, float]:
    """(near, middle) distances of level ``index`` of ``chain``.

    A level shows between the cutoffs Y(x) = α·β·γˣ of the exponents around it; the finest
    level from x = 0 (α·β, the distance a baked finest level is designed for, standing in for
    "from nearest"). ``near`` is where it first shows, ``middle`` is Y at the mean of the two
    exponents: the geometric middle of its distances, where the object's on-screen size is
    halfway in scale. The last level of a chain that is not culled shows without end: its
    range is taken as one more step as wide, in x, as the one before it.
    """
    xs = [0.0, *chain.xs]
    low = xs[index]
    high = xs[index + 1] if index + 1 < len(xs) else low + (low - xs[index - 1] if index else 1.0)
    return (
        cutoff(chain.alpha, chain.beta, chain.gamma, low),
        cutoff(chain.alpha, chain.beta, chain.gamma, (low + high) / 2.0),
    )


class ReferenceRenders:
    """The source ``surface`` uploaded to ``renderer`` with its coverage masks from ``views``
    Fibonacci directions around ``center``, rendered once per distance and kept. One instance
    serves every chain baked from the same source (levels relative to the same origin), so a
    heavy mesh is drawn once per distance however many chains are scored against it."""

    def __init__(
        self, renderer: SilhouetteRenderer, surface: Surface, center: np.ndarray, views: int
    ) -> None:
        self.renderer, self.surface = renderer, surface
        self.center = np.asarray(center, dtype=np.float64)
        self.directions = fibonacci_directions(views)
        self.geometry = renderer.mesh(surface.vertices, surface.faces)
        self.cache: dict[float, np.ndarray] = {}

    def masks(self, distance: float) -> np.ndarray:
        """Coverage masks (views, height, width) of the source seen from ``distance``."""
        if distance not in self.cache:
            masks = self.renderer.render(self.geometry, self.center, distance, self.directions)
            self.cache[distance] = np.packbits(masks, axis=-1)  # 8× smaller while kept
        packed = self.cache[distance]
        return np.unpackbits(packed, axis=-1, count=self.renderer.width).astype(bool)

    def release(self) -> None:
        """Free the uploaded mesh and the cached masks."""
        self.geometry.release()
        self.cache.clear()


class _Scorer:
    """Scores the levels of one chain against :class:`ReferenceRenders`."""

    def __init__(self, references: ReferenceRenders, chain: LodChain, view: ReferenceView) -> None:
        if not np.allclose(references.center, chain.center):
            raise ValueError(f"{chain.object_id}: chain centre differs from the reference's")
        self.references, self.chain, self.view = references, chain, view
        self.renderer = references.renderer

    def score(
        self, level: Level, geometry: Geometry, distance: float, pixel_size: float | None = None
    ) -> DistanceScore:
        """``level`` from ``distance``, its points ``pixel_size`` wide (default: declared)."""
        size = self.renderer.declared_pixel_size(level, distance, self.view)
        if size is not None and pixel_size is not None:
            size = pixel_size
        refs = self.references
        masks = self.renderer.render(geometry, refs.center, distance, refs.directions, size or 1.0)
        s = silhouette_scores(refs.masks(distance), masks)
        return DistanceScore(distance, distance / self.chain.alpha, size, **s)

    def in_range(self, index: int, level: Level, geometry: Geometry) -> RangeScores:
        """:class:`RangeScores` of level ``index``."""
        near, middle = level_window(self.chain, index)
        one_px = level.is_points
        return RangeScores(
            near=self.score(level, geometry, near),
            middle=self.score(level, geometry, middle),
            near_1px=self.score(level, geometry, near, 1.0) if one_px else None,
            middle_1px=self.score(level, geometry, middle, 1.0) if one_px else None,
        )


def evaluate_chain(
    reference: Surface | ReferenceRenders | None,
    chain: LodChain,
    distances_in_diagonals: Sequence[float] = DEFAULT_DISTANCES,
    views: int = DEFAULT_VIEWS,
    size: int = DEFAULT_SIZE,
    *,
    at_design_distance: bool = False,
    in_range: bool = False,
    pixel_size: float | None = None,
    levels: Sequence[int] | None = None,
    view: ReferenceView = REFERENCE_VIEW,
    renderer: SilhouetteRenderer | None = None,
) -> list[LevelScores]:
    """Silhouette P/R/F of the levels of ``chain`` against the source mesh, finest first.

    ``reference`` is the source surface relative to ``chain.origin`` (as level geometry is),
    or :class:`ReferenceRenders` of it (whose renderer and views then win over ``renderer``,
    ``size`` and ``views``); None takes the chain's mesh level. Cameras look at the chain's
    centre from ``views`` Fibonacci directions at each distance ``k · chain.alpha`` (α, the
    bounding-box diagonal), rendering ``size × size`` pixels at 45°. Points are drawn at the
    size the files declare (:func:`~.render.point_pixel_size`, ``view`` being the reference
    view the sizes refer to), or all ``pixel_size`` wide when given. With
    ``at_design_distance`` each point level is also scored at its own ``design_distance``
    (where it switches in); with ``in_range``, every level within its range
    (:class:`RangeScores`). ``levels`` picks the levels to score by index (default all).
    ``renderer`` reuses a :class:`SilhouetteRenderer` (its size then wins over ``size``).
    """
    if reference is None:
        meshes = [lv.mesh for lv in chain.levels if not lv.is_points and lv.mesh is not None]
        if not meshes:
            raise LodConvertError(f"{chain.object_id}: no reference mesh to evaluate against")
        reference = meshes[0]
    own_renderer = renderer is None and not isinstance(reference, ReferenceRenders)
    if isinstance(reference, ReferenceRenders):
        references = reference
    else:
        renderer = renderer or SilhouetteRenderer(size)
        references = ReferenceRenders(renderer, reference, chain.center, views)
    rows: list[LevelScores] = []
    try:
        scorer = _Scorer(references, chain, view)
        picked = range(len(chain.levels)) if levels is None else levels
        for index in picked:
            level = chain.levels[index]
            geometry = references.renderer.level(level)
            scores = [
                scorer.score(level, geometry, k * chain.alpha, pixel_size)
                for k in distances_in_diagonals
            ]
            design = None
            if at_design_distance and level.is_points and level.design_distance:
                design = scorer.score(level, geometry, level.design_distance, pixel_size)
            window = scorer.in_range(index, level, geometry) if in_range else None
            geometry.release()
            rows.append(
                LevelScores(
                    name=level.name,
                    kind=level.kind,
                    count=level.count,
                    point_size=level.params.point_size if level.params is not None else None,
                    scores=scores,
                    at_design=design,
                    in_range=window,
                )
            )
    finally:
        if references is not reference:
            references.release()
        if own_renderer:
            references.renderer.release()
    return rows


# --- geometric error ----------------------------------------------------------------------------


@dataclass
class GeometricError:
    """Distances between a level and the source surface as fractions of α (None for an empty
    level): ``chamfer`` = the mean of the two mean nearest-neighbour distances (source → level
    and level → source), ``hausdorff`` = the larger of the two largest."""

    chamfer: float | None
    hausdorff: float | None


def _face_areas(surface: Surface) -> np.ndarray:
    """Area of every face (m,)."""
    tri = surface.triangles
    return np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) / 2.0


def sample_surface(surface: Surface, count: int, seed: int = SAMPLE_SEED) -> np.ndarray:
    """``count`` points (count, 3) spread uniformly over the area of ``surface``'s faces.

    Deterministic for a given seed; the same faces in the same order give the same points, so
    a mesh compared with itself is at distance 0.
    """
    tri = surface.triangles
    area = _face_areas(surface)
    if len(tri) == 0 or not area.sum() > 0:
        return np.zeros((0, 3))
    rng = np.random.default_rng(seed)
    cumulative = np.cumsum(area)
    faces = np.searchsorted(cumulative, rng.random(count) * cumulative[-1], side="right")
    faces = np.minimum(faces, len(tri) - 1)
    r1, r2 = np.sqrt(rng.random(count)), rng.random(count)
    weights = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    return np.einsum("ij,ijk->ik", weights, tri[faces])


def _kdtree(points: np.ndarray) -> Any:
    """A scipy ``cKDTree`` of ``points`` (scipy is imported on first use)."""
    try:
        from scipy.spatial import cKDTree
    except ImportError as exc:
        raise LodConvertError(
            f"geometric error needs scipy ({exc}); run: pip install scipy"
        ) from exc
    return cKDTree(points)


def geometric_errors(
    reference: Surface,
    chain: LodChain,
    samples: int = DEFAULT_SAMPLES,
    levels: Sequence[int] | None = None,
) -> list[GeometricError]:
    """:class:`GeometricError` of the levels of ``chain`` (all, or those indexed by
    ``levels``) against ``reference`` (relative to ``chain.origin``), from ``samples`` points
    on the reference and, for mesh levels, as many on the level (:func:`sample_surface`);
    point levels are their points."""
    source = sample_surface(reference, samples)
    source_tree = _kdtree(source)
    errors = []
    for index in range(len(chain.levels)) if levels is None else levels:
        level = chain.levels[index]
        if not level.is_points:
            assert level.mesh is not None
            points = sample_surface(level.mesh, samples)
        else:
            assert level.points is not None
            points = level.points.positions
        if len(points) == 0 or len(source) == 0:
            errors.append(GeometricError(None, None))
            continue
        to_level, _ = _kdtree(points).query(source, workers=-1)
        to_source, _ = source_tree.query(points, workers=-1)
        errors.append(
            GeometricError(
                chamfer=float(to_level.mean() + to_source.mean()) / 2.0 / chain.alpha,
                hausdorff=float(max(to_level.max(), to_source.max())) / chain.alpha,
            )
        )
    return errors


def sample_spacing(surface: Surface, samples: int = DEFAULT_SAMPLES) -> float:
    """Mean spacing √(area / samples) of :func:`sample_surface`'s points: distances measured
    against the samples are overestimated by up to about half of it."""
    return float(math.sqrt(_face_areas(surface).sum() / samples))


# --- files read back ----------------------------------------------------------------------------


def match_references(
    objects: Sequence[Node], chains: Sequence[LodChain], ref_name: str, out_name: str
) -> list[Surface]:
    """For each chain, the source object it was baked from, relative to the chain's origin.

    Objects are paired by id (a single object with a single chain in any case). Raises
    :class:`InputError` naming REF when an object is missing or its bounding box does not
    match the chain's (centre = origin and diagonal = α, within :data:`BOUNDS_TOLERANCE` α).
    """
    by_id = {obj.id: obj for obj in objects}
    surfaces = []
    for chain in chains:
        obj = by_id.get(chain.object_id)
        if obj is None and len(objects) == 1 and len(chains) == 1:
            obj = objects[0]
        if obj is None:
            raise InputError(f"has no object {chain.object_id!r}, which {out_name} holds", ref_name)
        lo, hi = obj.geometry.bounds
        shift = float(np.linalg.norm((lo + hi) / 2.0 - chain.origin)) / chain.alpha
        across = diagonal(obj.geometry.bounds)
        if shift > BOUNDS_TOLERANCE or abs(across - chain.alpha) > BOUNDS_TOLERANCE * chain.alpha:
            raise InputError(
                f"does not match {out_name}: object {chain.object_id!r} is centred "
                f"{shift:.3g} diagonals away and {across:.6g} across, against {chain.alpha:.6g} "
                f"in {out_name} (was it converted from this file?)",
                ref_name,
            )
        surfaces.append(obj.geometry.translated(-chain.origin))
    return surfaces


# --- reports ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Protocol:
    """How levels are scored: ``views`` Fibonacci directions, ``size`` × ``size`` renders at
    ``fov_y_deg``, at ``distances`` (multiples of α), and ``samples`` surface samples for the
    geometric error. Within each level's range the renders are ``range_size`` pixels high: by
    default those of the reference view the converter designs levels for (1080 px), so the
    declared point sizes are drawn as they are and 1-pixel points are one of its pixels."""

    views: int = DEFAULT_VIEWS
    size: int = DEFAULT_SIZE
    fov_y_deg: float = DEFAULT_FOV
    distances: tuple[float, ...] = DEFAULT_DISTANCES
    samples: int = DEFAULT_SAMPLES
    range_size: int = REFERENCE_VIEW.height_px

    def check(self) -> None:
        """Raise :class:`UsageError` for values that cannot be run."""
        if any(not d > 0 for d in self.distances):
            raise UsageError("must be positive", "distances")
        least = {"views": 1, "size": MIN_SIZE, "range_size": MIN_SIZE, "samples": 1}
        for name, smallest in least.items():
            value = getattr(self, name)
            if value < smallest:
                raise UsageError(f"must be at least {smallest}, got {value}", name)


@dataclass
class LevelReport:
    """One level's silhouette scores, geometric error and its count as a fraction of the
    source's vertices."""

    scores: LevelScores
    error: GeometricError
    fraction: float


@dataclass
class ObjectReport:
    """Everything measured on one object: α, the source's vertex count, the mean spacing of
    the surface samples (fraction of α) and each level's report, finest first."""

    object_id: str
    alpha: float
    source_vertices: int
    sample_spacing: float
    levels: list[LevelReport]

    @property
    def mean_point_f(self) -> float | None:
        """Mean F over the point levels and the protocol distances (None without points)."""
        values = [s.f for lv in self.levels if lv.scores.kind == "pcd" for s in lv.scores.scores]
        return float(np.mean(values)) if values else None

    def to_json(self) -> dict[str, Any]:
        """A JSON-able dict of the report, with ``mean_point_f``."""
        return {**asdict(self), "mean_point_f": self.mean_point_f}


def evaluate_object(
    references: ReferenceRenders,
    chain: LodChain,
    protocol: Protocol,
    *,
    range_references: ReferenceRenders | None = None,
    levels: Sequence[int] | None = None,
) -> ObjectReport:
    """Silhouettes on ``protocol`` against ``references`` (and, given ``range_references``,
    within each level's range against those), geometric errors and counts of the levels of
    ``chain`` (all, or those indexed by ``levels``); the source is ``references.surface``,
    relative to the chain origin."""
    picked = list(range(len(chain.levels)) if levels is None else levels)
    scores = evaluate_chain(references, chain, protocol.distances, levels=picked)
    if range_references is not None:
        ranged = evaluate_chain(range_references, chain, (), levels=picked, in_range=True)
        for row, other in zip(scores, ranged, strict=True):
            row.in_range = other.in_range
    source = references.surface
    errors = geometric_errors(source, chain, protocol.samples, picked)
    total = len(source.vertices)
    return ObjectReport(
        object_id=chain.object_id,
        alpha=chain.alpha,
        source_vertices=total,
        sample_spacing=sample_spacing(source, protocol.samples) / chain.alpha,
        levels=[
            LevelReport(row, error, row.count / total)
            for row, error in zip(scores, errors, strict=True)
        ],
    )
