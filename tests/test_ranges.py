"""Switching ranges Y = α·β·γˣ and the reference-view conversions."""

from __future__ import annotations

import itertools
import math

import pytest

from lodconvert.errors import UsageError
from lodconvert.ranges import (
    REFERENCE_VIEW,
    cutoffs,
    default_xs,
    projected_px,
    screen_coverage,
)


def test_cutoffs_follow_the_formula() -> None:
    alpha, beta, gamma = 2.5, 3.0, 20.0
    ys = cutoffs(alpha, beta, gamma, [0.33, 0.66, 1.0])
    assert ys == pytest.approx([alpha * beta * gamma**x for x in (0.33, 0.66, 1.0)])
    assert ys[-1] == pytest.approx(150.0)
    assert all(b > a for a, b in itertools.pairwise(ys))


def test_default_exponents_are_the_papers() -> None:
    assert default_xs(3) == [0.33, 0.66, 1.0]
    assert default_xs(1) == [1.0]
    assert default_xs(4) == [0.25, 0.5, 0.75, 1.0]


@pytest.mark.parametrize("gamma", [1.0, 0.5, -3.0, float("nan")])
def test_gamma_not_above_one_is_rejected(gamma: float) -> None:
    with pytest.raises(UsageError, match="greater than 1"):
        cutoffs(1.0, 3.0, gamma, [0.33, 0.66, 1.0])


@pytest.mark.parametrize("xs", [[0.5, 0.5, 1.0], [0.66, 0.33, 1.0], [0.0, 0.5, 1.0]])
def test_bad_exponents_are_rejected(xs: list[float]) -> None:
    with pytest.raises(UsageError):
        cutoffs(1.0, 3.0, 10.0, xs)


def test_screen_coverage_falls_with_distance_and_matches_the_view() -> None:
    alpha = 1.0
    near, far = screen_coverage(alpha, 5.0), screen_coverage(alpha, 50.0)
    assert near > far > 0
    assert near == pytest.approx(10 * far)
    # at the distance where α fills the viewport height, coverage is 1
    fill = alpha / (2 * math.tan(math.radians(REFERENCE_VIEW.fov_y_deg) / 2))
    assert screen_coverage(alpha, fill) == pytest.approx(1.0)
    assert projected_px(alpha, fill) == pytest.approx(REFERENCE_VIEW.height_px)
