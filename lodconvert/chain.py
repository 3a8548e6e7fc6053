"""Plan and bake one object's LOD chain: levels, parameters and switching distances.

Default parameters follow from the reference view (:mod:`.ranges`): a point level is designed
for the distance where it first shows (its switch-in cutoff; ``α·β``, i.e. x = 0, for a baked
finest level). Its resolution is the smallest T3 whose grid pitch ``L / T3`` projects to at
most ``spacing_px`` pixels there, and its point size is that projected pitch, so
neighbouring points close up without gaps. Point counts must fall strictly level by level: a
level that would not be lighter than the one before is re-baked at a lower resolution, and a
level that cannot be (the one before has a single point) is dropped with a warning.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from .bake import Backend, bake_points
from .errors import InputError, UsageError
from .ranges import (
    DEFAULT_BETA,
    DEFAULT_GAMMA,
    REFERENCE_VIEW,
    ReferenceView,
    check_range_parameters,
    cutoff,
    default_xs,
    projected_px,
)
from .scene import BakeParams, Level, LodChain, SceneObject

LEVEL_NAMES = ("LOD4", "LOD3", "LOD2", "LOD1", "LOD0")
MAX_LEVELS = len(LEVEL_NAMES)
DEFAULT_SPACING_PX = 1.5
POINT_SIZE_FACTOR = 1.0  # point size / projected grid pitch; see default_point_size
MAX_RESOLUTION = 1024
MIN_RESOLUTION = 2

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
    gamma: float = DEFAULT_GAMMA
    xs: tuple[float, ...] | None = None
    cull: float | None = None
    spacing_px: float = DEFAULT_SPACING_PX
    view: ReferenceView = field(default=REFERENCE_VIEW)

    @property
    def pcd_levels(self) -> int:
        """How many levels are baked point clouds."""
        return self.levels - 1 if self.keep_mesh else self.levels

    @property
    def exponents(self) -> tuple[float, ...]:
        """The x of each cutoff between levels (``levels - 1`` of them)."""
        return self.xs if self.xs is not None else tuple(default_xs(self.levels - 1))

    def check(self) -> None:
        """Raise :class:`UsageError` for inconsistent or out-of-range options."""
        if not 2 <= self.levels <= MAX_LEVELS:
            raise UsageError(f"--levels must be between 2 and {MAX_LEVELS}, got {self.levels}")
        xs = self.exponents
        if len(xs) != self.levels - 1:
            raise UsageError(
                f"--x needs {self.levels - 1} exponents for {self.levels} levels, got {len(xs)}"
            )
        check_range_parameters(self.beta, self.gamma, xs)
        if self.cull is not None and not (math.isfinite(self.cull) and self.cull > xs[-1]):
            raise UsageError(f"--cull must be greater than the last --x ({xs[-1]:g})")
        n = self.pcd_levels
        for flag, values in (
            ("--resolution", self.resolutions),
            ("--slices", self.slices),
            ("--point-size", self.point_sizes),
        ):
            if values is None:
                continue
            if len(values) != n:
                raise UsageError(
                    f"{flag} needs {n} values (one per point level), got {len(values)}"
                )
            if any(not (math.isfinite(v) and v > 0) for v in values):
                raise UsageError(f"{flag} values must be positive")
        for flag, values in (("--resolution", self.resolutions), ("--slices", self.slices)):
            if values is not None and any(v > MAX_RESOLUTION for v in values):
                raise UsageError(f"{flag} values must be at most {MAX_RESOLUTION}")
        if self.spacing_px <= 0:
            raise UsageError("the pixel spacing target must be positive")


def default_resolution(longest: float, distance: float, opts: ChainOptions) -> int:
    """Smallest T3 whose pitch ``longest / T3`` projects to ≤ ``spacing_px`` at ``distance``."""
    t3 = math.ceil(projected_px(longest, distance, opts.view) / opts.spacing_px - 1e-9)
    return int(min(MAX_RESOLUTION, max(MIN_RESOLUTION, t3)))


def default_point_size(pitch: float, distance: float, opts: ChainOptions) -> float:
    """The grid pitch projected at ``distance`` (≥ 1 px), rounded up to 0.01 px.

    Points one pitch wide close up the surface without gaps, and measured silhouette fidelity
    is best there: larger points spill past the outline, smaller ones open holes
    (``benchmarks/results/point_size.md``).
    """
    size = POINT_SIZE_FACTOR * projected_px(pitch, distance, opts.view)
    return max(1.0, math.ceil(100 * size - 1e-9) / 100)


def _check_geometry(obj: SceneObject) -> None:
    surface = obj.surface
    if len(surface.faces) == 0:
        raise InputError("has no faces (a point cloud or empty mesh cannot be baked)", obj.id)
    if not np.isfinite(surface.vertices).all():
        raise InputError("has NaN or infinite vertex coordinates", obj.id)
    if not (surface.bounds[1] - surface.bounds[0]).max() > 0:
        raise InputError("has zero extent (all vertices coincide)", obj.id)


def _params_for(
    index: int, longest: float, distance: float, opts: ChainOptions, resolution: int | None = None
) -> BakeParams:
    t3 = resolution or (
        opts.resolutions[index] if opts.resolutions else default_resolution(longest, distance, opts)
    )
    if opts.slices and resolution is None:
        t1 = opts.slices[index]
    elif opts.slices:
        t1 = max(1, round(opts.slices[index] * resolution / opts.resolutions[index]))
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


def bake_chain(
    obj: SceneObject,
    opts: ChainOptions,
    backend: Backend,
    progress: Progress | None = None,
    warn: Progress | None = None,
) -> LodChain:
    """Bake ``obj`` into a chain (levels relative to its bounding-box centre)."""
    opts.check()
    _check_geometry(obj)
    world_bounds = obj.surface.bounds
    origin = (world_bounds[0] + world_bounds[1]) / 2.0
    surface = replace(obj.surface, vertices=obj.surface.vertices - origin)
    bounds = world_bounds - origin
    alpha = float(np.linalg.norm(world_bounds[1] - world_bounds[0]))
    longest = float((world_bounds[1] - world_bounds[0]).max())
    xs = list(opts.exponents)
    cuts = [cutoff(alpha, opts.beta, opts.gamma, x) for x in xs]
    # Distance each level first shows at; a baked finest level is designed for x = 0.
    design = [cutoff(alpha, opts.beta, opts.gamma, 0.0), *cuts]

    levels: list[Level] = []
    if opts.keep_mesh:
        levels.append(Level(name=LEVEL_NAMES[0], kind="mesh", mesh=surface))
    previous = len(surface.vertices) if opts.keep_mesh else math.inf
    for i in range(opts.pcd_levels):
        n = len(levels)
        name = LEVEL_NAMES[n]
        distance = design[n]
        params = _params_for(i, longest, distance, opts)
        if progress:
            progress(f"{obj.id}: baking {name} at {params.resolution}")
        start = time.perf_counter()
        cloud, grid = bake_points(surface, params, backend, bounds)
        while len(cloud) >= previous and params.resolution > 1:
            shrink = math.sqrt((previous - 1) / max(len(cloud), 1)) * 0.95
            smaller = max(1, min(params.resolution - 1, math.floor(params.resolution * shrink)))
            params = _params_for(i, longest, distance, opts, resolution=smaller)
            cloud, grid = bake_points(surface, params, backend, bounds)
        if warn and opts.resolutions and params.resolution != opts.resolutions[i]:
            warn(
                f"{obj.id}: {name} baked at resolution {params.resolution} instead of "
                f"{opts.resolutions[i]}: it must have fewer points than {LEVEL_NAMES[n - 1]} "
                f"({previous:,})"
            )
        if len(cloud) >= previous:
            if warn:
                warn(
                    f"{obj.id}: {name} and coarser levels dropped: "
                    f"{LEVEL_NAMES[n - 1]} has only {previous} point(s)"
                )
            break
        levels.append(
            Level(
                name=name,
                kind="pcd",
                points=cloud,
                params=params,
                spacing=grid.pitch,
                design_distance=distance,
                bake_seconds=time.perf_counter() - start,
            )
        )
        previous = len(cloud)

    kept_cuts = cuts[: len(levels) - 1]
    culled = opts.cull is not None
    if culled:
        kept_cuts.append(cutoff(alpha, opts.beta, opts.gamma, opts.cull))
    return LodChain(
        object_id=obj.id,
        levels=levels,
        cutoffs=kept_cuts,
        origin=origin,
        center=np.zeros(3),
        alpha=alpha,
        beta=opts.beta,
        gamma=opts.gamma,
        xs=xs[: len(levels) - 1] + ([opts.cull] if culled else []),
        culled=culled,
        metadata=dict(obj.metadata),
    )
