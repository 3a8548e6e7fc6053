"""What the analysis renderers share: their GL context (:class:`OffscreenRenderer`), view and
projection matrices, view directions spread over a sphere, and the pixel width at which a point
level's declared point size is drawn.

Contexts are made when a renderer is created, never at import; on Mesa llvmpipe a process forked
after its parent made one deadlocks at its first GL call (see :mod:`lodconvert.glcontext`).
"""

from __future__ import annotations

import math
from typing import Self

import numpy as np

from ..glcontext import create_context

GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` unit vectors (n, 3) spread evenly over the sphere (Fibonacci lattice).

    Point ``i`` has ``z = 1 - (2i + 1) / n`` and azimuth ``i`` times the golden angle, so the
    directions are deterministic and each covers about the same area of the sphere.
    """
    if n < 1:
        raise ValueError(f"need at least one direction, got {n}")
    i = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / n
    r = np.sqrt(1.0 - z * z)
    phi = GOLDEN_ANGLE * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def point_pixel_size(
    point_size: float,
    design_distance: float | None,
    distance: float,
    *,
    view_scale: float = 1.0,
    max_size: float = 255.0,
) -> float:
    """Pixel width of a point level's points seen from ``distance``, as its files declare.

    ``size = clamp(point_size · design_distance / distance · view_scale, 1, max_size)``: the
    points are ``point_size`` pixels wide at ``design_distance`` in the reference view and
    shrink with 1/distance (X3D ``PointProperties`` attenuation ``0 1/d 0``). ``view_scale``
    is the focal length of the render over that of the reference view (1 when rendering the
    reference view itself); ``max_size`` the renderer's largest point. Without a design
    distance the size is the constant ``point_size · view_scale``, clamped alike.
    """
    size = point_size * view_scale
    if design_distance is not None and design_distance > 0:
        size *= design_distance / distance
    return float(min(max(size, 1.0), max_size))


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """View matrix (4, 4) of a camera at ``eye`` looking at ``target``; its up vector is +z,
    or +y when the view direction is within about 8° of the z axis."""
    forward = target - eye
    forward = forward / np.linalg.norm(forward)
    up = np.array([0.0, 1.0, 0.0]) if abs(forward[2]) > 0.99 else np.array([0.0, 0.0, 1.0])
    side = np.cross(forward, up)
    side /= np.linalg.norm(side)
    true_up = np.cross(side, forward)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = side, true_up, -forward
    view[:3, 3] = -view[:3, :3] @ eye
    return view


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL projection matrix (4, 4) of a symmetric perspective frustum."""
    f = 1.0 / math.tan(math.radians(fov_y_deg) / 2.0)
    proj = np.zeros((4, 4))
    proj[0, 0] = f / aspect
    proj[1, 1] = f
    proj[2, 2] = (far + near) / (near - far)
    proj[2, 3] = 2.0 * far * near / (near - far)
    proj[3, 2] = -1.0
    return proj


class OffscreenRenderer:
    """One standalone moderngl EGL context (OpenGL 3.3), its renderer's name and largest point
    size; freed by :meth:`release` or on leaving a ``with`` block. Raises
    :class:`~lodconvert.errors.LodConvertError` naming ``purpose`` and the packages to install
    when no context can be made."""

    def __init__(self, purpose: str) -> None:
        self.ctx = create_context(purpose)
        self.renderer_name = str(self.ctx.info.get("GL_RENDERER", "unknown"))
        self.max_point_size = float(self.ctx.info.get("GL_POINT_SIZE_RANGE", (1.0, 255.0))[1])

    def release(self) -> None:
        """Free the context and every GL object made on it."""
        self.ctx.release()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
