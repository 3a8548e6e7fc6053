"""Cameras walking or flying through a city: a viewer looking along a heading, pitched down, on
the 1920×1080 framebuffer of :mod:`.bench`; walks sampled every simulated frame step at a fixed
speed (so that positions, and every count, do not depend on the machine), random walks over an
area, and flights crossing it at one altitude. See ``docs/render-bench.md`` (cameras).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..ranges import REFERENCE_VIEW, ReferenceView
from .bench import HEIGHT, WIDTH
from .line_of_sight import REFERENCE_FOV_DEG
from .render import look_at, perspective

NEAR = 1.0
"""Near plane of every camera, metres."""


@dataclass(frozen=True)
class Camera:
    """A viewer at ``eye`` (scene coordinates, z up) looking along unit ``forward``, with a
    vertical field of view of ``fov_y_deg``."""

    eye: np.ndarray
    forward: np.ndarray
    fov_y_deg: float = REFERENCE_FOV_DEG

    def view_proj(self, far: float) -> np.ndarray:
        """View-projection matrix (4, 4) on the 1920×1080 framebuffer, near plane :data:`NEAR`."""
        projection = perspective(self.fov_y_deg, WIDTH / HEIGHT, NEAR, far)
        return projection @ look_at(self.eye, self.eye + self.forward)

    @property
    def view_scale(self) -> float:
        """Focal length of this view over the reference view's (point sizes scale by it)."""
        return ReferenceView(HEIGHT, self.fov_y_deg).focal_px / REFERENCE_VIEW.focal_px


def forward_vector(heading: np.ndarray, pitch_deg: float) -> np.ndarray:
    """Unit view direction (3,) along ground ``heading`` (2,), pitched ``pitch_deg`` down."""
    ground = np.asarray(heading, dtype=np.float64)[:2]
    ground = ground / np.linalg.norm(ground)
    pitch = math.radians(pitch_deg)
    return np.array([ground[0] * math.cos(pitch), ground[1] * math.cos(pitch), -math.sin(pitch)])


def walk_cameras(
    start: np.ndarray,
    end: np.ndarray,
    speed: float,
    frame_step: float,
    pitch_deg: float,
    fov_y_deg: float,
) -> list[Camera]:
    """Cameras every simulated frame (``frame_step`` seconds at ``speed`` m/s) on the straight
    line from ``start`` to ``end`` (3,), looking along it pitched ``pitch_deg`` down."""
    start, end = np.asarray(start, dtype=np.float64), np.asarray(end, dtype=np.float64)
    length = float(np.linalg.norm(end - start))
    frames = math.floor(length / (speed * frame_step) + 1e-9) + 1
    forward = forward_vector(end - start, pitch_deg)
    steps = np.arange(frames) * speed * frame_step / max(length, 1e-12)
    return [Camera(start + t * (end - start), forward, fov_y_deg) for t in steps]


def random_walks(
    rng: np.random.Generator,
    area: np.ndarray,
    count: int,
    length: float,
    altitude: float,
    ground: float = 0.0,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` straight walks (start, end) of ``length`` metres, ``altitude`` metres above the
    ``ground`` height, each from a uniformly random start in ``area`` ((2, 2): ground min and
    max corners) in a uniformly random direction, drawn again until both ends lie in ``area``.
    Raises :class:`ValueError` when ``length`` does not fit the area's diagonal."""
    low, high = np.asarray(area, dtype=np.float64)
    if length >= float(np.linalg.norm(high - low)):
        raise ValueError(f"walks of {length:g} m do not fit an area of {high - low} m")
    walks = []
    while len(walks) < count:
        start = rng.uniform(low, high)
        angle = rng.uniform(0.0, 2.0 * math.pi)
        end = start + length * np.array([math.cos(angle), math.sin(angle)])
        if np.all(end >= low) and np.all(end <= high):
            z = ground + altitude
            walks.append((np.append(start, z), np.append(end, z)))
    return walks


def flight_cameras(
    area: np.ndarray,
    altitude: float,
    pitch_deg: float,
    positions: int,
    fov_y_deg: float,
    ground: float = 0.0,
) -> list[Camera]:
    """``positions`` cameras evenly spaced on a straight flight ``altitude`` metres above the
    ``ground`` height, along x across ``area`` ((2, 2) ground corners) through its middle,
    looking ahead pitched ``pitch_deg`` down: the centre of the view sweeps the ground from the
    area's x minimum to its maximum."""
    low, high = np.asarray(area, dtype=np.float64)
    lead = altitude / math.tan(math.radians(pitch_deg))
    y = (low[1] + high[1]) / 2.0
    xs = np.linspace(low[0] - lead, high[0] - lead, positions)
    forward = forward_vector(np.array([1.0, 0.0]), pitch_deg)
    return [Camera(np.array([x, y, ground + altitude]), forward, fov_y_deg) for x in xs]
