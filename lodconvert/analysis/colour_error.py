"""How far a far level's colours lie from its source's, as seen from afar: the area-weighted
mean ΔE (CIE76, or another difference) between a far level's roofs (faces facing up) and the
source's roof colour, and between its walls (steep faces) and the source's wall colour, each
face's colour taken at its centre (vertex colours interpolated); the source's colours are the
area-weighted means of its textures where it has them."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..city.prisms import STEEP, prism_colors
from ..colors import delta_e
from ..model import Mesh


def class_delta_e(
    source: Mesh, far: Mesh, difference: Callable[[np.ndarray, np.ndarray], np.ndarray] = delta_e
) -> dict[str, float]:
    """The mean ΔE (``difference``: CIE76 by default; over the faces' areas) of ``far``'s
    ``roof`` faces (facing up, less steep than 60°) against ``source``'s roof colour and of its
    ``wall`` faces (steeper) against its wall colour, the source's colours as its LOD1 prism
    takes them (:func:`~lodconvert.city.prisms.prism_colors`, textures included); 0 for a
    class of no area."""
    faces = np.arange(far.face_count)
    tri = far.triangles
    areas = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) / 2
    colours = far.colors_at(faces, tri.mean(axis=1))
    up = far.face_normals(faces)[:, 2]
    out = {}
    for name, chosen, expected in zip(
        ("roof", "wall"), (up > STEEP, np.abs(up) < STEEP), prism_colors(source), strict=True
    ):
        weights = areas[chosen]
        errors = difference(colours[chosen], expected)
        out[name] = float(weights @ errors / weights.sum()) if weights.sum() > 0 else 0.0
    return out
