"""Switching ranges Y = α·β·γˣ and the reference view that links distances to pixels.

α is the object's bounding-box diagonal, β = 3 (the ProxyPrismLOD user study's trade-off
between smoothness and popping), γ the plot radius (> 1, so that cutoffs grow with x) and x one
exponent per switch. The reference view (1080-pixel-high viewport, 45° vertical field of view)
turns a distance into a projected size: it sets default resolutions and point sizes and the
glTF ``MSFT_screencoverage`` values.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .errors import UsageError

DEFAULT_BETA = 3.0
DEFAULT_GAMMA = 10.0
DEFAULT_XS = (0.33, 0.66, 1.0)
MAX_SPAN = 1e38
"""Largest side of an object's bounding box that is baked: float32 coordinates (X3D, glTF) end
at 3.4e38, and levels are written relative to the box centre."""
MAX_ALPHA = MAX_SPAN * math.sqrt(3.0)
"""Largest bounding-box diagonal α of an object that is baked."""
MIN_SCALE = 1e-290
"""Least Y/α = β·γˣ: projected sizes α·focal/Y (resolutions, point sizes, screen coverages) stay
finite above it."""
CUTOFF_GAP = 1e-12
"""Least relative growth of γˣ from one exponent to the next: far above float64 rounding, so
cutoffs stay strictly increasing after the multiplication by α·β."""


@dataclass(frozen=True)
class ReferenceView:
    """A perspective view used to translate distances into pixels."""

    height_px: int = 1080
    fov_y_deg: float = 45.0

    @property
    def focal_px(self) -> float:
        """Focal length in pixels: a length s at distance d projects to s·focal_px/d pixels."""
        return self.height_px / (2.0 * math.tan(math.radians(self.fov_y_deg) / 2.0))


REFERENCE_VIEW = ReferenceView()


def default_xs(n_cutoffs: int) -> list[float]:
    """Evenly spread exponents ending at 1.0, truncated to two decimals (3 → 0.33, 0.66, 1.0)."""
    if n_cutoffs < 1:
        raise UsageError("must be at least 2: a chain needs at least one cutoff", "levels")
    return [math.floor(100 * k / n_cutoffs) / 100 for k in range(1, n_cutoffs + 1)]


def check_range_parameters(beta: float, gamma: float, xs: Sequence[float]) -> None:
    """Raise :class:`UsageError` unless β > 0, γ > 1 and the exponents are positive and
    strictly increasing (the conditions for cutoffs that grow level by level)."""
    if not math.isfinite(beta) or beta <= 0:
        raise UsageError(f"must be a positive number, got {beta:g}", "beta")
    if not math.isfinite(gamma) or gamma <= 1:
        raise UsageError(
            f"(γ) must be greater than 1 so that cutoffs increase, got {gamma:g}", "gamma"
        )
    if not xs:
        raise UsageError("needs at least one exponent", "xs")
    if any(not math.isfinite(x) or x <= 0 for x in xs):
        raise UsageError(f"exponents must be positive, got {', '.join(f'{x:g}' for x in xs)}", "xs")
    if any(b <= a for a, b in itertools.pairwise(xs)):
        raise UsageError(
            f"exponents must be strictly increasing, got {', '.join(f'{x:g}' for x in xs)}", "xs"
        )
    check_cutoffs(beta, gamma, [0.0, *xs])


def check_cutoffs(
    beta: float, gamma: float, xs: Sequence[float], fields: Sequence[str] = ()
) -> None:
    """Raise :class:`UsageError` unless the cutoffs Y = α·β·γˣ at the exponents ``xs`` (0 and
    increasing) are at least :data:`MIN_SCALE` · α, finite and strictly increasing for every α
    up to :data:`MAX_ALPHA`: γˣ must grow by more than rounding can undo from one exponent to
    the next, and the largest must stay finite at α = :data:`MAX_ALPHA`. ``fields`` names the
    option each exponent comes from (``xs`` where not given)."""
    if not MIN_SCALE <= beta < math.inf or not math.isfinite(MAX_ALPHA * beta):
        raise UsageError(
            f"must keep switching distances Y = α·β·γˣ between {MIN_SCALE:g}·α and the largest "
            f"float for objects up to {MAX_SPAN:g} across, got {beta:g}",
            "beta",
        )
    growth = [_power(gamma, x) for x in xs]
    for i, (x, g) in enumerate(zip(xs, growth, strict=True)):
        if not math.isfinite(MAX_ALPHA * beta * g):
            field = "gamma" if x <= 1 else fields[i] if i < len(fields) else "xs"
            raise UsageError(
                f"{gamma if field == 'gamma' else x:g} makes Y = α·β·γˣ overflow at x = {x:g} "
                f"(β {beta:g}, γ {gamma:g}) for objects up to {MAX_SPAN:g} across",
                field,
            )
        if i and not g > growth[i - 1] * (1 + CUTOFF_GAP):
            apart = _power(DEFAULT_GAMMA, x) > _power(DEFAULT_GAMMA, xs[i - 1]) * (1 + CUTOFF_GAP)
            raise UsageError(
                f"{'(γ) ' + repr(gamma) if apart else repr(x)} gives switching distances too "
                f"close to tell apart in floating point at x = {xs[i - 1]!r} and {x!r}",
                "gamma" if apart else fields[i] if i < len(fields) else "xs",
            )


def _power(gamma: float, x: float) -> float:
    """γˣ, ``inf`` where it overflows."""
    try:
        return float(gamma**x)
    except OverflowError:
        return math.inf


def cutoff(alpha: float, beta: float, gamma: float, x: float) -> float:
    """One switching distance Y = α·β·γˣ (``inf`` where it overflows)."""
    return float(alpha * beta * _power(gamma, x))


def cutoffs(
    alpha: float,
    beta: float = DEFAULT_BETA,
    gamma: float = DEFAULT_GAMMA,
    xs: Sequence[float] = DEFAULT_XS,
) -> list[float]:
    """Switching distances Y = α·β·γˣ for each exponent x, nearest first.

    >>> [round(y, 3) for y in cutoffs(1.0, 3.0, 10.0, [0.33, 0.66, 1.0])]
    [6.414, 13.713, 30.0]
    """
    check_range_parameters(beta, gamma, xs)
    if not math.isfinite(alpha) or alpha <= 0:
        raise UsageError(f"(the object's diagonal α) must be positive, got {alpha:g}", "alpha")
    return [cutoff(alpha, beta, gamma, x) for x in xs]


def diagonal(bounds: np.ndarray) -> float:
    """α of an object: the diagonal of its bounding box ``bounds`` ((2, 3): lowest and highest
    corner) — the box of the geometry its chain is made from (its finest level; a LoD 0
    object's prism), or of all its members' for a LOD parent. Every α is computed here."""
    return float(np.linalg.norm(bounds[1] - bounds[0]))


def screen_coverage(alpha: float, distance: float, view: ReferenceView = REFERENCE_VIEW) -> float:
    """Fraction of the viewport height covered by the object's diagonal α seen from
    ``distance``: the quantity glTF ``MSFT_screencoverage`` thresholds compare. Not capped at
    1 (an object can overfill the view), so thresholds of increasing cutoffs strictly fall."""
    if distance <= 0:
        raise ValueError("distance must be positive")
    return alpha * view.focal_px / (distance * view.height_px)


def projected_px(length: float, distance: float, view: ReferenceView = REFERENCE_VIEW) -> float:
    """Pixels that a length perpendicular to the view covers at ``distance``."""
    return length * view.focal_px / distance
