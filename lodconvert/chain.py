"""Plan and bake one object's LOD chain: levels, parameters and switching distances.

Default parameters follow from the reference view (:mod:`.ranges`): a point level is designed
for the distance where it first shows (its switch-in cutoff; ``α·β``, i.e. x = 0, for a baked
finest level). Its resolution is the smallest T3 whose grid pitch ``L / T3`` projects to at
most ``spacing_px`` pixels there, and its point size is that projected pitch, so
neighbouring points close up without gaps. Each point then sits ``inset`` pitches inside the
surface (along its face normal, turned inward), so that the square it is drawn as ends at the
surface instead of straddling it: at the outline it no longer spills half a point width past
the silhouette (``benchmarks/results/fidelity.md``). Point counts must fall strictly level by
level: a level that would not be lighter than the one before is re-baked at a lower resolution,
and a level that cannot be (the one before has a single point) is dropped with a warning.

A level of kind ``qem`` is the source mesh decimated by quadric edge collapse
(:mod:`.bake.qem`) to the vertex count the point level would have had.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from .bake import Backend, Grid, bake_points
from .errors import InputError, UsageError
from .limits import DEFAULT_LIMITS, Limits
from .model import BakeParams, Level, LodChain, Mesh, Node, PointCloud
from .model.lods import SLOTS, unused_levels
from .plan import (
    POINT_COST,
    least_point_cost,
    level_cost,
    silhouette_estimate,
)
from .ranges import (
    DEFAULT_BETA,
    DEFAULT_GAMMA,
    MAX_SPAN,
    REFERENCE_VIEW,
    ReferenceView,
    check_cutoffs,
    check_range_parameters,
    cutoff,
    default_xs,
    diagonal,
    projected_px,
)

LEVEL_NAMES = ("LOD4", "LOD3", "LOD2", "LOD1", "LOD0")
MAX_LEVELS = len(LEVEL_NAMES)
DEFAULT_SPACING_PX = 1.5
POINT_SIZE_FACTOR = 1.0  # point size / projected grid pitch; see default_point_size
DEFAULT_INSET = 0.5  # how far inside the surface points sit, in grid pitches; see inset_points
LEVEL_KINDS = ("pcd", "qem")
MAX_RESOLUTION = 1024
MIN_RESOLUTION = 2
# |signed volume| below this × (longest side)³: the surface encloses nothing (no inset).
VOLUME_EPSILON = 1e-9

Progress = Callable[[str], None]


@dataclass(frozen=True)
class ChainOptions:
    """Everything that shapes a chain; ``None`` means "derive the default"."""

    levels: int = 4
    keep_mesh: bool = True
    resolutions: tuple[int, ...] | None = None
    slices: tuple[int, ...] | None = None
    point_sizes: tuple[float, ...] | None = None
    filter: str = "median"
    beta: float = DEFAULT_BETA
    gamma: float | None = None
    """γ; ``None``: 10 for a mesh's objects, each city object's plot radius (:mod:`.city.plots`)."""
    xs: tuple[float, ...] | None = None
    cull: float | None = None
    spacing_px: float = DEFAULT_SPACING_PX
    inset: float = DEFAULT_INSET
    level_kinds: tuple[str, ...] | None = None
    view: ReferenceView = field(default=REFERENCE_VIEW)

    @property
    def pcd_levels(self) -> int:
        """How many levels are baked point clouds."""
        return self.levels - 1 if self.keep_mesh else self.levels

    def level_kind(self, index: int) -> str:
        """``pcd`` or ``qem`` for baked level ``index`` (0 = the first); a single
        ``level_kinds`` value applies to every baked level."""
        if not self.level_kinds:
            return "pcd"
        return self.level_kinds[index if len(self.level_kinds) > 1 else 0]

    @property
    def exponents(self) -> tuple[float, ...]:
        """The x of each cutoff between levels (``levels - 1`` of them)."""
        return self.xs if self.xs is not None else tuple(default_xs(self.levels - 1))

    def check(self) -> None:
        """Raise :class:`UsageError` for inconsistent or out-of-range options."""
        if not 2 <= self.levels <= MAX_LEVELS:
            raise UsageError(f"must be between 2 and {MAX_LEVELS}, got {self.levels}", "levels")
        xs = self.exponents
        if len(xs) != self.levels - 1:
            raise UsageError(
                f"needs {self.levels - 1} exponents for {self.levels} levels, got {len(xs)}", "xs"
            )
        gamma = DEFAULT_GAMMA if self.gamma is None else self.gamma
        check_range_parameters(self.beta, gamma, xs)
        if self.cull is not None and not (math.isfinite(self.cull) and self.cull > xs[-1]):
            raise UsageError(f"must be greater than the last exponent ({xs[-1]:g})", "cull")
        if self.cull is not None:
            check_cutoffs(
                self.beta, gamma, [0.0, *xs, self.cull], ["xs"] * (len(xs) + 1) + ["cull"]
            )
        n = self.pcd_levels
        for name, values in (
            ("resolutions", self.resolutions),
            ("slices", self.slices),
            ("point_sizes", self.point_sizes),
        ):
            if values is None:
                continue
            if len(values) != n:
                raise UsageError(f"needs {n} values (one per point level), got {len(values)}", name)
            if any(not (math.isfinite(v) and v > 0) for v in values):
                raise UsageError("values must be positive", name)
        for name, values in (("resolutions", self.resolutions), ("slices", self.slices)):
            if values is not None and any(v > MAX_RESOLUTION for v in values):
                raise UsageError(f"values must be at most {MAX_RESOLUTION}", name)
        if self.spacing_px <= 0:
            raise UsageError("(the pixel spacing target) must be positive", "spacing_px")
        if not 0 <= self.inset <= 1:
            raise UsageError(
                f"(the point inset) must be between 0 and 1 pitch, got {self.inset:g}", "inset"
            )
        if self.level_kinds is not None:
            if len(self.level_kinds) not in (1, n):
                raise UsageError(
                    f"needs 1 value or {n} (one per baked level), got {len(self.level_kinds)}",
                    "level_kinds",
                )
            unknown = sorted(set(self.level_kinds) - set(LEVEL_KINDS))
            if unknown:
                raise UsageError(
                    f"values must be {' or '.join(LEVEL_KINDS)}, got {unknown[0]!r}",
                    "level_kinds",
                )


def default_resolution(longest: float, distance: float, opts: ChainOptions) -> int:
    """Smallest T3 whose pitch ``longest / T3`` projects to ≤ ``spacing_px`` at ``distance``."""
    t3 = math.ceil(projected_px(longest, distance, opts.view) / opts.spacing_px - 1e-9)
    return int(min(MAX_RESOLUTION, max(MIN_RESOLUTION, t3)))


def default_point_size(pitch: float, distance: float, opts: ChainOptions) -> float:
    """The grid pitch projected at ``distance`` (≥ 1 px), rounded up to 0.01 px.

    Points one pitch wide close up the surface without gaps, and measured silhouette fidelity
    is best there: larger points spill past the outline, smaller ones open holes
    (``benchmarks/results/fidelity.md``).
    """
    size = POINT_SIZE_FACTOR * projected_px(pitch, distance, opts.view)
    return max(1.0, math.ceil(100 * size - 1e-9) / 100)


def outward_sign(surface: Mesh) -> float:
    """+1 when the faces wind so that their normals point out of the solid (positive signed
    volume), -1 when they point in, 0 for a surface that encloses no volume (flat or open sheet).

    The sign is that of the whole surface: a mesh whose faces wind inconsistently gets the
    majority's orientation.
    """

    def compute() -> float:
        tri = surface.triangles - surface.bounds.mean(axis=0)
        volume = float(np.einsum("ij,ij->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))) / 6.0
        extent = float((surface.bounds[1] - surface.bounds[0]).max())
        return 0.0 if abs(volume) <= VOLUME_EPSILON * extent**3 else math.copysign(1.0, volume)

    return surface.derived("outward-sign", compute)


def inset_points(cloud: PointCloud, surface: Mesh, depth: float) -> PointCloud:
    """``cloud`` with every point moved ``depth`` into the solid along its face normal.

    A point is drawn as a square one pitch wide centred on it. On the surface, the squares of
    the points along the outline reach half a pitch past it; ``depth`` = half a pitch puts
    their outer edges on the surface. Surfaces that enclose no volume are left as they are.
    """
    sign = outward_sign(surface)
    if depth == 0 or sign == 0 or len(cloud) == 0:
        return cloud
    inward = -sign * cloud.normals.astype(np.float64)
    return replace(cloud, positions=cloud.positions + depth * inward)


def check_geometry(obj: Node) -> None:
    """Raise :class:`InputError` (naming the object) unless ``obj`` has faces and finite
    vertices spanning more than nothing and at most :data:`~.ranges.MAX_SPAN`."""
    surface = obj.geometry
    if len(surface.faces) == 0:
        raise InputError("has no faces (a point cloud or empty mesh cannot be baked)", obj.id)
    if not np.isfinite(surface.vertices).all():
        raise InputError("has NaN or infinite vertex coordinates", obj.id)
    span = float((surface.bounds[1] - surface.bounds[0]).max())
    if not span > 0:
        raise InputError("has zero extent (all vertices coincide)", obj.id)
    if not span <= MAX_SPAN:
        raise InputError(
            f"spans {span:.3g}, more than the {MAX_SPAN:g} that float32 coordinates (X3D, glTF) "
            "can hold around its centre",
            obj.id,
        )


def _params_for(
    index: int, longest: float, distance: float, opts: ChainOptions, resolution: int | None = None
) -> BakeParams:
    t3 = resolution or (
        opts.resolutions[index] if opts.resolutions else default_resolution(longest, distance, opts)
    )
    if opts.slices and resolution is None:
        t1 = opts.slices[index]
    elif opts.slices:
        asked = (
            opts.resolutions[index]
            if opts.resolutions
            else default_resolution(longest, distance, opts)
        )
        t1 = max(1, round(opts.slices[index] * resolution / asked))
    else:
        t1 = t3
    size = (
        opts.point_sizes[index]
        if opts.point_sizes
        else default_point_size(longest / t3, distance, opts)
    )
    return BakeParams(
        resolution=int(t3), slices=int(t1), point_size=float(size), filter=opts.filter
    )


def _within_grid_limit(
    params: BakeParams,
    bounds: np.ndarray,
    index: int,
    distance: float,
    opts: ChainOptions,
    limits: Limits,
    where: str,
    warn: Progress | None,
) -> BakeParams:
    """``params``, at a lower resolution where their grid would have more cells than
    ``limits.grid_cells``; an explicit resolution over the limit is a :class:`UsageError`."""
    longest = float(np.ptp(bounds, axis=0).max())
    asked = params.resolution
    cells = Grid.for_bounds(bounds, params.resolution, params.slices).size
    if cells <= limits.grid_cells:
        return params
    if opts.resolutions:
        raise UsageError(
            f"{asked} gives {where} a grid of {cells:,} cells, more than the grid_cells limit "
            f"({limits.grid_cells:,}; --limit grid_cells=N raises it)",
            "resolutions",
        )
    while cells > limits.grid_cells and params.resolution > 1:
        t3 = params.resolution
        t3 = max(1, min(t3 - 1, math.floor(t3 * (limits.grid_cells / cells) ** (1 / 3))))
        params = _params_for(index, longest, distance, opts, resolution=t3)
        cells = Grid.for_bounds(bounds, params.resolution, params.slices).size
    if warn:
        warn(
            f"{where} baked at resolution {params.resolution} instead of {asked}: its grid "
            f"would have more cells than the grid_cells limit ({limits.grid_cells:,})"
        )
    return params


def _decimated(
    level: Level, surface: Mesh, budget: float, object_id: str, warn: Progress | None
) -> Level:
    """The ``qem`` level replacing point level ``level``: the source decimated to the point
    level's count, or fewer where a mesh of that many vertices would cost ``budget`` (the draw
    cost of the level before) or more. When decimation leaves no triangle or cannot get below
    ``budget``, the point level is kept, with a warning; when it stops above the point level's
    count, the mesh is kept with a warning."""
    from .bake.qem import decimate

    target = int(min(level.count, math.ceil(budget) - 1))
    mesh = decimate(surface, max(target, 1))
    if len(mesh.faces) == 0 or len(mesh.vertices) >= budget:
        if warn:
            warn(
                f"{object_id}: {level.name} kept as points: decimation to {target:,} "
                f"vertices leaves {len(mesh.vertices):,} in {len(mesh.faces):,} triangles "
                f"(the level before costs {budget:,.0f})"
            )
        return level
    if len(mesh.vertices) > target and warn:
        warn(
            f"{object_id}: {level.name} decimated to {len(mesh.vertices):,} vertices, not "
            f"{target:,}: the mesh's separate parts and borders stop the collapses"
        )
    return Level(name=level.name, kind="qem", mesh=mesh, design_distance=level.design_distance)


def _point_level(
    surface: Mesh,
    bounds: np.ndarray,
    name: str,
    index: int,
    distance: float,
    previous: Level | None,
    opts: ChainOptions,
    backend: Backend,
    object_id: str,
    warn: Progress | None,
    limits: Limits = DEFAULT_LIMITS,
) -> Level | str:
    """Point level ``index`` (``qem`` when asked) designed for ``distance``, or why it is left
    out: it cannot be made cheaper than ``previous``, or (default resolutions only, and where a
    finer level can stay on instead) its silhouette at ``distance`` is not within
    :data:`~.plan.MIN_SILHOUETTE` of the source's."""
    longest = float(np.ptp(bounds, axis=0).max())
    budget = math.inf if previous is None else level_cost(previous)
    params = _within_grid_limit(
        _params_for(index, longest, distance, opts),
        bounds,
        index,
        distance,
        opts,
        limits,
        f"{object_id}: {name}",
        warn,
    )
    start = time.perf_counter()
    cloud, grid = bake_points(surface, params, backend, bounds, limits.memory_bytes)
    while len(cloud) * POINT_COST >= budget and params.resolution > 1:
        shrink = math.sqrt((budget / POINT_COST - 1) / max(len(cloud), 1)) * 0.95
        smaller = max(1, min(params.resolution - 1, math.floor(params.resolution * shrink)))
        params = _params_for(index, longest, distance, opts, resolution=smaller)
        cloud, grid = bake_points(surface, params, backend, bounds, limits.memory_bytes)
    if len(cloud) * POINT_COST >= budget or len(cloud) == 0:
        return f"no point level is cheaper than {previous.name if previous else 'nothing'}"
    if warn and opts.resolutions and params.resolution != opts.resolutions[index]:
        warn(
            f"{object_id}: {name} baked at resolution {params.resolution} instead of "
            f"{opts.resolutions[index]}: it must cost less than {previous.name if previous else ''}"
        )
    points = inset_points(cloud, surface, opts.inset * grid.pitch)
    if previous is not None and not opts.resolutions:
        estimate = silhouette_estimate(surface, points, params.point_size, distance, opts.view)
        if not estimate.passes:
            return (
                f"points at resolution {params.resolution} would not look like the object "
                f"(silhouette precision {estimate.precision:.2f}, recall {estimate.recall:.2f})"
            )
    level = Level(
        name=name,
        kind="pcd",
        points=points,
        params=params,
        spacing=grid.pitch,
        design_distance=distance,
    )
    if opts.level_kind(index) == "qem":
        level = _decimated(level, surface, budget, object_id, warn)
    level.bake_seconds = time.perf_counter() - start
    return level


def point_level_at(
    surface: Mesh,
    name: str,
    distance: float,
    opts: ChainOptions,
    backend: Backend,
    where: str,
    warn: Progress | None = None,
    limits: Limits = DEFAULT_LIMITS,
) -> Level | None:
    """A point level of ``surface`` (in its own frame) designed for ``distance`` with the
    default resolution and point size for that distance (``opts``' per-level values do not
    apply), or None when it holds no point."""
    own = replace(opts, resolutions=None, slices=None, point_sizes=None, level_kinds=None)
    bounds = surface.bounds
    level = _point_level(
        surface, bounds, name, 0, distance, None, own, backend, where, warn, limits
    )
    return level if isinstance(level, Level) else None


def least_cost(surface: Mesh, opts: ChainOptions) -> float:
    """The draw cost at or below which a level is not replaced by points of ``surface``
    (:func:`~.plan.least_point_cost`; 0 where ``opts`` give the resolutions)."""
    return least_point_cost(surface) if not opts.resolutions else 0.0


NO_POINTS_PAY = "no point level could be both cheaper and faithful"


@dataclass(frozen=True)
class PlannedLevel:
    """One level of a plan: its ``name``, the exponent ``x`` of the cutoff where it switches in
    (``None`` for the nearest level), and the ``level`` itself where planning made it (the mesh,
    a source LoD, a prism), or ``None`` for points still to bake: baked level ``index`` of the
    per-level options."""

    name: str
    x: float | None
    level: Level | None = None
    index: int = 0


@dataclass
class ChainPlan:
    """An object's chain before any point is baked: which levels it gets and where they switch
    (Y = α·β·γˣ, α the diagonal of the box of the geometry the chain is made from, ``origin``
    its centre). A level to bake is kept when baking finds it cheaper than the level before
    and faithful (:func:`bake_plan`); else the finer level stays on to the next cutoff."""

    object_id: str
    levels: list[PlannedLevel]
    origin: np.ndarray
    alpha: float
    beta: float
    gamma: float
    cull: float | None
    surface: Mesh
    """The geometry points are baked from, relative to ``origin``."""
    bounds: np.ndarray
    dropped: dict[str, str] = field(default_factory=dict)
    unused: dict[str, str] = field(default_factory=dict)
    metadata: dict[str, object] = field(default_factory=dict)
    cut: tuple[str, ...] = ()
    """What was cut from the id and attributes (:mod:`~lodconvert.model.safe_text`)."""
    transform: np.ndarray | None = None

    @property
    def xs(self) -> list[float]:
        """The exponents of the planned levels' switch-in cutoffs, and the cull's."""
        xs = [level.x for level in self.levels if level.x is not None]
        return xs + ([self.cull] if self.cull is not None else [])

    @property
    def cutoffs(self) -> list[float]:
        """The cutoffs of the planned levels (and the cull), nearest first."""
        return [cutoff(self.alpha, self.beta, self.gamma, x) for x in self.xs]


def points_may_pay(levels: Sequence[Level | None], floor: float) -> bool:
    """Whether a point level after ``levels`` (those kept so far, ``None`` for one still to
    bake) may be cheaper than the last of them: unless that one costs no more than ``floor``
    (:func:`least_cost`)."""
    return not levels or levels[-1] is None or level_cost(levels[-1]) > floor


def framed(mesh: Mesh) -> tuple[np.ndarray, float, Mesh, np.ndarray]:
    """The chain frame of ``mesh``: its bounding-box centre, α, and it and its bounds relative
    to that centre."""
    world = mesh.bounds
    origin = (world[0] + world[1]) / 2.0
    return origin, diagonal(world), mesh.translated(-origin), world - origin


def plan_of(
    obj: Node,
    opts: ChainOptions,
    levels: list[PlannedLevel],
    frame: tuple[np.ndarray, float, Mesh, np.ndarray],
    dropped: dict[str, str],
    unused: dict[str, str],
) -> ChainPlan:
    """The plan of ``obj`` of ``levels`` in ``frame`` (:func:`framed`)."""
    origin, alpha, surface, bounds = frame
    assert opts.gamma is not None
    text = obj.written()
    return ChainPlan(
        object_id=text.id,
        levels=levels,
        origin=origin,
        alpha=alpha,
        beta=opts.beta,
        gamma=opts.gamma,
        cull=opts.cull,
        surface=surface,
        bounds=bounds,
        dropped=dropped,
        unused=unused,
        metadata=text.attributes,
        cut=text.cut,
    )


def mesh_plan(obj: Node, opts: ChainOptions) -> ChainPlan:
    """A mesh's chain: the mesh (unless ``--no-mesh``) and points baked from it."""
    frame = framed(obj.geometry)
    alpha, surface = frame[1], frame[2]
    assert opts.gamma is not None
    xs = list(opts.exponents)
    # Distance each level first shows at; a baked finest level is designed for x = 0.
    design = [cutoff(alpha, opts.beta, opts.gamma, x) for x in [0.0, *xs]]
    if not (design[0] > 0 and all(b > a for a, b in itertools.pairwise(design))):
        raise InputError(
            f"is too small (diagonal {alpha:.3g}) for switching distances that increase", obj.id
        )
    levels: list[PlannedLevel] = []
    dropped: dict[str, str] = {}
    if opts.keep_mesh:
        levels.append(
            PlannedLevel(
                LEVEL_NAMES[0], None, Level(name=LEVEL_NAMES[0], kind="mesh", mesh=surface)
            )
        )
    floor = least_cost(surface, opts)
    for i in range(opts.pcd_levels):
        n = i + 1 if opts.keep_mesh else i
        if not points_may_pay([planned.level for planned in levels], floor):
            dropped[LEVEL_NAMES[n]] = NO_POINTS_PAY
            continue
        levels.append(PlannedLevel(LEVEL_NAMES[n], xs[n - 1] if n > 0 else None, index=i))
    unused = unused_levels(obj.lods)
    if not (opts.keep_mesh and opts.levels == len(SLOTS)):
        option = "--no-mesh" if not opts.keep_mesh else f"--levels {opts.levels}"
        for label, mesh in obj.lods.items():
            if label not in unused and mesh is not obj.geometry:
                unused[label] = f"{option}: every level is made from the finest geometry"
    return plan_of(obj, opts, levels, frame, dropped, unused)


def bake_plan(
    plan: ChainPlan,
    opts: ChainOptions,
    backend: Backend,
    progress: Progress | None = None,
    warn: Progress | None = None,
    limits: Limits = DEFAULT_LIMITS,
) -> LodChain:
    """The chain of ``plan``: its levels to bake baked, and kept where they pay (cheaper than
    the level before and faithful, :func:`_point_level`); one that does not is dropped with
    its cutoff."""
    levels: list[Level] = []
    xs: list[float] = []
    dropped = dict(plan.dropped)
    for planned in plan.levels:
        level: Level | str | None = planned.level
        if level is None and not points_may_pay(levels, least_cost(plan.surface, opts)):
            level = NO_POINTS_PAY
        elif level is None:
            if progress:
                progress(f"{plan.object_id}: baking {planned.name}")
            design = cutoff(
                plan.alpha, plan.beta, plan.gamma, 0.0 if planned.x is None else planned.x
            )
            level = _point_level(
                plan.surface, plan.bounds, planned.name, planned.index, design,
                levels[-1] if levels else None, opts, backend, plan.object_id, warn, limits,
            )  # fmt: skip
        if isinstance(level, str):
            dropped[planned.name] = level
            continue
        levels.append(level)
        if planned.x is not None:
            xs.append(planned.x)
    if plan.cull is not None:
        xs.append(plan.cull)
    return LodChain(
        object_id=plan.object_id,
        levels=levels,
        cutoffs=[cutoff(plan.alpha, plan.beta, plan.gamma, x) for x in xs],
        origin=plan.origin,
        center=np.zeros(3),
        alpha=plan.alpha,
        beta=plan.beta,
        gamma=plan.gamma,
        xs=xs,
        culled=plan.cull is not None,
        dropped=dict(sorted(dropped.items(), key=lambda item: LEVEL_NAMES.index(item[0]))),
        unused=plan.unused,
        metadata=plan.metadata,
        cut=plan.cut,
    )
