"""The views a city object's derived levels (LOD1 prisms, a cell's far level) are judged over:
the upper hemisphere as a viewer sees a city, from the street to high above it
(docs/levels.md). Perspective, as the reference view's, about z up, the frame city levels are
made in."""

from __future__ import annotations

import math

import numpy as np

AZIMUTHS_DEG = tuple(range(0, 360, 45))
"""Compass directions of the guard's cameras."""
ELEVATIONS_DEG = (0, 30, 60)
"""Heights of the guard's cameras above the horizon."""


def towards_camera(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """The unit vector from what a camera looks at towards the camera, ``azimuth_deg`` from +x
    towards +y and ``elevation_deg`` above the horizon."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def view_basis(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Right and up in the image of a camera looking at the origin from ``azimuth_deg`` and
    ``elevation_deg``, z up in its image, and towards it (:func:`towards_camera`): (3, 3)."""
    right = np.array([-math.sin(math.radians(azimuth_deg)), math.cos(math.radians(azimuth_deg)), 0])
    towards = towards_camera(azimuth_deg, elevation_deg)
    return np.stack([right, np.cross(towards, right), towards])


def guard_views() -> list[tuple[int, int]]:
    """(azimuth, elevation) of each of the guard's views: every azimuth at every elevation."""
    return [(a, e) for e in ELEVATIONS_DEG for a in AZIMUTHS_DEG]


def guard_record() -> dict[str, object]:
    """The guard's views as a run's report states them."""
    return {
        "azimuths_deg": list(AZIMUTHS_DEG),
        "elevations_deg": list(ELEVATIONS_DEG),
        "views": len(guard_views()),
        "camera": "perspective, the reference view's, looking at the level's centre from "
        "where it switches in; F is the least over the views",
    }


GUARD_BASES = np.ascontiguousarray(np.stack([view_basis(a, e) for a, e in guard_views()]))
"""The bases ((views, 3, 3)) of the guard's views (:func:`view_basis`)."""
