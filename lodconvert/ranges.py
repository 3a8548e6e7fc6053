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

from .errors import UsageError

DEFAULT_BETA = 3.0
DEFAULT_GAMMA = 10.0
DEFAULT_XS = (0.33, 0.66, 1.0)


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


def cutoff(alpha: float, beta: float, gamma: float, x: float) -> float:
    """One switching distance Y = α·β·γˣ."""
    return float(alpha * beta * gamma**x)


def cutoffs(
    alpha: float,
    beta: float = DEFAULT_BETA,
    gamma: float = DEFAULT_GAMMA,
    xs: Sequence[float] = DEFAULT_XS,
) -> list[float]:
    """Switching distances Y = α·β·γˣ for each exponent x, nearest first.

    >>> [round(y, 3) for y in cutoffs(1.0, 3.0, 10.0, [0.33, 0.66, 1.0])]
    [6.414, 13.714, 30.0]
    """
    check_range_parameters(beta, gamma, xs)
    if not math.isfinite(alpha) or alpha <= 0:
        raise UsageError(f"(the object's diagonal α) must be positive, got {alpha:g}", "alpha")
    return [cutoff(alpha, beta, gamma, x) for x in xs]


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
