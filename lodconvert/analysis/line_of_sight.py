"""The line-of-sight LOD scale (Lee, Kim & Kim's "LOD scale"): the mean distance from a camera
to the ground over its vertical field of view, against the reference view's; every cutoff
times that factor keeps finer levels farther out for a camera high above a city. See
``docs/render-bench.md`` (the LOD scale).
"""

from __future__ import annotations

import math

from ..ranges import REFERENCE_VIEW

MAX_LOS = 20_000.0
"""Line-of-sight distance counted for a ray that meets the ground farther away, or not at all
(at or above the horizon), metres."""
REFERENCE_ALTITUDE = 300.0
"""Altitude (m) at which :func:`lod_scale` is 1 for the reference pitch and field of view."""
REFERENCE_PITCH_DEG = 45.0
"""Pitch below the horizontal of the reference view of :func:`lod_scale`."""
REFERENCE_FOV_DEG = REFERENCE_VIEW.fov_y_deg
"""Vertical field of view of the reference view of :func:`lod_scale` (the ranges' 45°)."""


def los_average(
    altitude: float,
    pitch_deg: float,
    fov_y_deg: float = REFERENCE_FOV_DEG,
    max_distance: float = MAX_LOS,
) -> float:
    """Mean line-of-sight distance (m) from a camera ``altitude`` metres above flat ground,
    pitched ``pitch_deg`` below the horizontal, to the ground, over its vertical field of view.

    A ray ``φ`` below the horizontal meets the ground ``altitude / sin φ`` away; the mean is
    taken over φ uniformly from ``pitch - fov/2`` to ``pitch + fov/2`` (the integral of
    ``h / sin φ`` is ``h · ln tan(φ/2)``). Rays that meet the ground farther than
    ``max_distance``, or never (at or above the horizon), count ``max_distance``. The mean does
    not fall as the altitude rises. Raises :class:`ValueError` for a non-positive altitude,
    field of view or ``max_distance``, or a view reaching past the nadir to the horizon behind.
    """
    if not (altitude > 0 and 0 < fov_y_deg < 180 and max_distance > 0):
        raise ValueError(
            f"need a positive altitude, field of view and distance cap, got {altitude:g} m, "
            f"{fov_y_deg:g}°, {max_distance:g} m"
        )
    low = math.radians(pitch_deg - fov_y_deg / 2.0)
    high = math.radians(pitch_deg + fov_y_deg / 2.0)
    if high >= math.pi:
        raise ValueError(f"a view pitched {pitch_deg:g}° sees the horizon behind the camera")
    grazing = math.asin(min(1.0, altitude / max_distance))  # shallower rays are capped
    start, end = max(low, grazing), min(high, math.pi - grazing)
    hit = 0.0
    if end > start:
        hit = altitude * (math.log(math.tan(end / 2.0)) - math.log(math.tan(start / 2.0)))
    capped = max_distance * ((high - low) - max(end - start, 0.0))
    return (hit + capped) / (high - low)


REFERENCE_LOS = los_average(REFERENCE_ALTITUDE, REFERENCE_PITCH_DEG, REFERENCE_FOV_DEG)
"""The reference line of sight of :func:`lod_scale`: :func:`los_average` at
:data:`REFERENCE_ALTITUDE`, :data:`REFERENCE_PITCH_DEG` and :data:`REFERENCE_FOV_DEG`
(about 463 m)."""


def lod_scale(
    altitude: float,
    pitch_deg: float,
    fov_y_deg: float = REFERENCE_FOV_DEG,
    reference: float = REFERENCE_LOS,
    max_distance: float = MAX_LOS,
) -> float:
    """The line-of-sight LOD scale ``s = los_average(altitude, pitch, fov) / reference``, the
    factor on every cutoff (Lee, Kim & Kim's "LOD scale").

    ``s`` is 1 at the reference view (:data:`REFERENCE_LOS`: 300 m up, pitched 45° down, 45°
    field of view), below 1 lower down and above 1 higher up: a camera high above the city,
    whose view lies mostly far away, keeps finer levels farther out in proportion. It does not
    fall as the altitude rises. Raises :class:`ValueError` as :func:`los_average` does, or for
    a non-positive ``reference``.
    """
    if not reference > 0:
        raise ValueError(f"the reference line of sight must be positive, got {reference:g}")
    return los_average(altitude, pitch_deg, fov_y_deg, max_distance) / reference
