"""The first view of an X3D scene: a ``Viewpoint`` framing everything written, seen obliquely
(from the south and :data:`PITCH_DEG` above the horizon in a y-up scene, so a city looks 3-D),
and a ``NavigationInfo`` to examine it. A plain X3D browser otherwise starts at (0, 0, 10)
looking along −z: black, until "view all".

The frame is the box of every object's bounding sphere (its centre, half its diagonal α) in
scene coordinates; the viewer stands where that box's bounding sphere fills the vertical
field of view.
"""

from __future__ import annotations

import math

import numpy as np

from ...model import CellChain, LodChain
from ..frame import ROTATION, SceneFrame
from ..numbers import format_exact

PITCH_DEG = 35.0
"""How far the first view looks down from the horizontal."""
FIELD_OF_VIEW = math.pi / 4
"""The Viewpoint's field of view (X3D's default, 45°)."""


class SceneBox:
    """The box (scene coordinates) of the bounding spheres of the objects added so far."""

    def __init__(self, frame: SceneFrame | None) -> None:
        self.frame = frame
        self.low = np.full(3, np.inf)
        self.high = np.full(3, -np.inf)

    def add(self, item: LodChain | CellChain) -> None:
        """Grow the box by a chain's sphere, or by those of a LOD parent's objects."""
        for chain in item.objects():
            centre = np.asarray(chain.origin, dtype=np.float64) + chain.center
            if chain.transform is not None:
                centre = chain.transform[:3, :3] @ centre + chain.transform[:3, 3]
            if self.frame is not None:
                centre = ROTATION @ (centre - self.frame.origin)
            self.low = np.minimum(self.low, centre - chain.alpha / 2)
            self.high = np.maximum(self.high, centre + chain.alpha / 2)

    def viewpoint(self) -> dict[str, str] | None:
        """The ``Viewpoint`` fields that frame the box (``None`` for an empty box)."""
        if not np.isfinite(self.low).all():
            return None
        centre = (self.low + self.high) / 2
        radius = max(float(np.linalg.norm(self.high - self.low)) / 2, 1e-6)
        distance = radius / math.sin(FIELD_OF_VIEW / 2)
        pitch = math.radians(PITCH_DEG)
        position = centre + distance * np.array([0.0, math.sin(pitch), math.cos(pitch)])
        return {
            "DEF": "lodconvert_view",
            "description": "lodconvert: the whole scene, seen obliquely",
            "position": format_exact(position),
            "orientation": format_exact([1.0, 0.0, 0.0, -pitch]),
            "fieldOfView": format_exact([FIELD_OF_VIEW]),
            "centerOfRotation": format_exact(centre),
        }


NAVIGATION = {"type": '"EXAMINE" "ANY"'}
"""The ``NavigationInfo`` fields: examine the scene (about the Viewpoint's centre of rotation)."""
