"""Plot radii of city objects: the γ of their switching distances Y = α·β·γˣ.

In the ProxyPrismLOD paper γ is the radius of the plot an object stands on, in metres. A city
model draws no plots, so the radius is derived from the spacing of its objects: half the
distance from an object's centre to the nearest other object's centre (seen from above), kept
within :data:`MIN_RADIUS` … :data:`MAX_RADIUS` metres (γ must exceed 1 for the cutoffs to grow,
and a lone building far from others should not switch at kilometres). An object with no
neighbour gets :data:`LONE_RADIUS`.
"""

from __future__ import annotations

import numpy as np

MIN_RADIUS = 2.0
MAX_RADIUS = 100.0
LONE_RADIUS = 10.0


def plot_radii(centres: np.ndarray) -> np.ndarray:
    """The plot radius of each object whose centre (seen from above, (n, 2) metres) is in
    ``centres``, from its nearest neighbour's distance."""
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    if len(centres) < 2:
        return np.full(len(centres), LONE_RADIUS)
    return np.clip(nearest_distances(centres) / 2.0, MIN_RADIUS, MAX_RADIUS)


def nearest_distances(centres: np.ndarray) -> np.ndarray:
    """Each of ``centres``' ((n, 2), n ≥ 2) distance to the nearest other one, as
    ``sqrt(dx² + dy²)`` (0 where another lies at the same place). Shapely's tree finds the
    nearest (it skips those equal to a point, which lie at 0), so that no scipy module (slow
    to import, in every process) is needed."""
    import shapely

    points = shapely.points(centres)
    (i, j), _ = shapely.STRtree(points).query_nearest(
        points, exclusive=True, all_matches=True, return_distance=True
    )
    nearest = np.full(len(centres), np.inf)
    np.minimum.at(nearest, i, np.sqrt(((centres[i] - centres[j]) ** 2).sum(axis=1)))
    _, where, count = np.unique(centres, axis=0, return_inverse=True, return_counts=True)
    nearest[count[where.ravel()] > 1] = 0.0
    return nearest
