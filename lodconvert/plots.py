"""Plot radii of city objects: the γ of their switching distances Y = α·β·γˣ.

In the ProxyPrismLOD paper γ is the radius of the plot an object stands on, in metres. A city
model draws no plots, so the radius is derived from the spacing of its objects: half the
distance from an object's centre to the nearest other object's centre (seen from above), kept
within :data:`MIN_RADIUS` … :data:`MAX_RADIUS` metres (γ must exceed 1 for the cutoffs to grow,
and a lone building far from others should not switch at kilometres). An object with no
neighbour gets :data:`LONE_RADIUS`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .model import Node

MIN_RADIUS = 2.0
MAX_RADIUS = 100.0
LONE_RADIUS = 10.0


def plot_radii(nodes: Sequence[Node]) -> dict[int, float]:
    """``id(node)`` → plot radius of every node with geometry, from its neighbours' spacing."""
    placed = [node for node in nodes if node.geometry is not None]
    if len(placed) < 2:
        return {id(node): LONE_RADIUS for node in placed}
    from scipy.spatial import cKDTree

    centres = np.array([node.geometry.bounds.mean(axis=0)[:2] for node in placed])
    distance, _ = cKDTree(centres).query(centres, k=2)
    radius = np.clip(distance[:, 1] / 2.0, MIN_RADIUS, MAX_RADIUS)
    return {id(node): float(r) for node, r in zip(placed, radius, strict=True)}
