"""Connected components of a graph given by its edges, in numpy (:func:`components`): the
groups of a footprint's pieces (:mod:`.city.prisms`) and the flat pieces of a far level
(:mod:`.bake.far_textures`)."""

from __future__ import annotations

import numpy as np


def components(pairs: np.ndarray, n: int) -> np.ndarray:
    """The connected components of the graph of ``n`` nodes and edges ``pairs`` ((2, k)): each
    node's component, numbered in the order of their first nodes. Each round points every node
    at its tree's root, then hooks each root onto the least other root it meets; a component's
    root ends as its first node (100,000 nodes in one path: 0.02 s)."""
    parent = np.arange(n)
    first, second = pairs
    while True:
        while not np.array_equal(grand := parent[parent], parent):
            parent = grand
        one, other = parent[first], parent[second]
        apart = one != other
        if not apart.any():
            return np.unique(parent, return_inverse=True)[1]
        first, second, one, other = first[apart], second[apart], one[apart], other[apart]
        np.minimum.at(parent, np.maximum(one, other), np.minimum(one, other))
