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
    from scipy.spatial import cKDTree

    distance, _ = cKDTree(centres).query(centres, k=2)
    return np.clip(distance[:, 1] / 2.0, MIN_RADIUS, MAX_RADIUS)
