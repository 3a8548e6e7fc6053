"""Colours of city objects' surfaces, one table for every city reader.

A surface takes its material's colour where the source gives one; else the colour of its
semantic class (roof, wall, ground, other), and a surface of no class the colour of its
object's type (vegetation green, water blue…). ``--colors roof=#b05a4a,wall=…`` changes the
class colours of a run. All colours are sRGB bytes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .errors import UsageError


def _rgba(r: int, g: int, b: int) -> np.ndarray:
    return np.array([r, g, b, 255], dtype=np.uint8)


CLASS_OF = {
    "RoofSurface": "roof",
    "RoofEdge": "roof",
    "WallSurface": "wall",
    "GroundSurface": "ground",
    "FootPrint": "ground",
    "InteriorWallSurface": "wall",
    "FloorSurface": "ground",
}
"""Semantic surface types (CityGML, CityJSON) → class; any other type is ``other``."""

DEFAULT_CLASS_COLORS = {
    "roof": _rgba(178, 90, 74),  # a muted red
    "wall": _rgba(224, 216, 200),  # a light warm grey
    "ground": _rgba(84, 84, 84),  # a dark grey
    "other": _rgba(200, 200, 200),  # a light grey
}
"""Default colour of each class."""

TYPE_COLORS = {
    "PlantCover": _rgba(120, 160, 90),
    "SolitaryVegetationObject": _rgba(90, 140, 70),
    "WaterBody": _rgba(100, 150, 200),
    "Road": _rgba(110, 110, 115),
    "LandUse": _rgba(215, 205, 170),
    "ReliefFeature": _rgba(150, 155, 110),  # terrain: CityGML's type
    "TINRelief": _rgba(150, 155, 110),  # terrain: CityJSON's type
}
"""Colour of surfaces of no semantic class, by object type (others: the ``other`` class)."""


@dataclass(frozen=True)
class Palette:
    """The class colours of a run (defaults, changed by ``--colors``)."""

    classes: Mapping[str, np.ndarray] = field(default_factory=lambda: dict(DEFAULT_CLASS_COLORS))

    def of(self, semantic: str | None, object_type: str | None = None) -> np.ndarray:
        """The colour of a surface of ``semantic`` type (None: unclassified) of an object of
        ``object_type``."""
        if semantic is None or semantic not in CLASS_OF:
            if object_type in TYPE_COLORS and semantic is None:
                return TYPE_COLORS[object_type]
            return self.classes["other"]
        return self.classes[CLASS_OF[semantic]]

    def with_text(self, text: str) -> Palette:
        """This palette with ``class=#rrggbb`` assignments (comma-separated) applied."""
        classes = dict(self.classes)
        for item in filter(None, (part.strip() for part in text.split(","))):
            name, _, value = item.partition("=")
            name, value = name.strip().lower(), value.strip().lstrip("#")
            if name not in classes:
                raise UsageError(f"knows {', '.join(classes)}, not {name!r}", "colors")
            if len(value) != 6 or any(c not in "0123456789abcdefABCDEF" for c in value):
                raise UsageError(f"needs #rrggbb colours, got {item!r}", "colors")
            classes[name] = _rgba(*(int(value[i : i + 2], 16) for i in (0, 2, 4)))
        return Palette(classes)


DEFAULT_PALETTE = Palette()
