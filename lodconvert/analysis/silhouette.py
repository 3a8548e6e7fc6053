"""Coverage masks of meshes, point clouds and chain levels from perspective cameras: the
renders that :mod:`.evaluate` scores and :mod:`.contact_sheet` shows.

The geometry is drawn with no shading and no depth test: a pixel is covered when any fragment
lands on it. Point levels are drawn as square GL points (``gl_PointSize``) of the size the
output files declare: ``params.point_size`` pixels at ``design_distance`` in the reference view
(:data:`~lodconvert.ranges.REFERENCE_VIEW`, 1080 pixels high), scaling with 1/distance
(:func:`~.render.point_pixel_size`). A render of another height shows the same scene smaller or
larger, so the size is multiplied by the ratio of focal lengths (512 / 1080 for a 512-pixel
render at the same field of view): points keep the footprint on the object they were designed
with (:meth:`SilhouetteRenderer.declared_pixel_size`).

The GL context (Mesa EGL, llvmpipe on a CPU-only machine) is made when a
:class:`SilhouetteRenderer` is created, never at import. On llvmpipe a process forked after its
parent made a context deadlocks in GL calls: worker pools must use the ``spawn`` start method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..model import Level, Mesh
from ..ranges import REFERENCE_VIEW, ReferenceView
from .render import OffscreenRenderer, look_at, perspective, point_pixel_size

if TYPE_CHECKING:
    import moderngl

# Near/far planes lie this fraction outside the geometry's bounding sphere.
DEPTH_MARGIN = 0.01

VERTEX_SHADER = """
#version 330
uniform mat4 mvp;
uniform float point_size;
in vec3 in_pos;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    gl_PointSize = point_size;
}
"""

FRAGMENT_SHADER = """
#version 330
out float covered;
void main() {
    covered = 1.0;
}
"""


@dataclass
class Geometry:
    """Geometry uploaded to a :class:`SilhouetteRenderer` once and drawn from many views.

    ``vao`` is None for empty geometry (it covers no pixel). ``center`` and ``radius`` bound
    the vertices (a sphere around their bounding box); they set the near and far planes.
    """

    vao: moderngl.VertexArray | None
    buffers: list[moderngl.Buffer]
    mode: int
    center: np.ndarray
    radius: float

    def release(self) -> None:
        """Free the vertex array and its buffers (the renderer's context frees any left)."""
        if self.vao is not None:
            self.vao.release()
        for buffer in self.buffers:
            buffer.release()
        self.vao, self.buffers = None, []


class SilhouetteRenderer(OffscreenRenderer):
    """Coverage masks of meshes and point clouds from perspective cameras, on one moderngl
    EGL context and one ``size × size`` framebuffer (or ``width × height``).

    Use :meth:`mesh`, :meth:`points` or :meth:`level` to upload geometry, then :meth:`render`
    for a batch of views. Raises :class:`~lodconvert.errors.LodConvertError` (naming the
    packages to install) when no EGL OpenGL 3.3 context can be made.
    """

    def __init__(self, size: int = 512, fov_y_deg: float = 45.0, height: int | None = None) -> None:
        self.width = int(size)
        self.height = int(height if height is not None else size)
        self.fov_y_deg = float(fov_y_deg)
        super().__init__("silhouette evaluation unavailable")
        self.ctx.enable(self.ctx.PROGRAM_POINT_SIZE)
        self.program = self.ctx.program(
            vertex_shader=VERTEX_SHADER, fragment_shader=FRAGMENT_SHADER
        )
        target = self.ctx.renderbuffer((self.width, self.height), components=1, dtype="f1")
        self.fbo = self.ctx.framebuffer(color_attachments=[target])

    @property
    def focal_px(self) -> float:
        """Focal length in pixels: a length s at distance d projects to s·focal_px/d pixels."""
        return self.height / (2.0 * math.tan(math.radians(self.fov_y_deg) / 2.0))

    def view_scale(self, view: ReferenceView = REFERENCE_VIEW) -> float:
        """Ratio of this render's focal length to ``view``'s (see :func:`point_pixel_size`)."""
        return self.focal_px / view.focal_px

    def _upload(self, positions: np.ndarray, faces: np.ndarray | None, mode: int) -> Geometry:
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        if len(positions) == 0 or (faces is not None and len(faces) == 0):
            return Geometry(None, [], mode, np.zeros(3), 0.0)
        lo, hi = positions.min(axis=0), positions.max(axis=0)
        vbo = self.ctx.buffer(positions.astype(np.float32).tobytes())
        ibo = None
        if faces is not None:
            ibo = self.ctx.buffer(np.asarray(faces, dtype=np.int32).tobytes())
        vao = self.ctx.vertex_array(
            self.program, [(vbo, "3f", "in_pos")], index_buffer=ibo, index_element_size=4
        )
        buffers = [vbo] if ibo is None else [vbo, ibo]
        return Geometry(vao, buffers, mode, (lo + hi) / 2.0, float(np.linalg.norm(hi - lo)) / 2.0)

    def mesh(self, vertices: np.ndarray, faces: np.ndarray) -> Geometry:
        """Upload a triangle mesh: vertices (n, 3), faces (m, 3) indices."""
        return self._upload(vertices, np.asarray(faces).reshape(-1, 3), self.ctx.TRIANGLES)

    def points(self, positions: np.ndarray) -> Geometry:
        """Upload a point cloud (k, 3), drawn as square points of a chosen pixel size."""
        return self._upload(positions, None, self.ctx.POINTS)

    def level(self, level: Level) -> Geometry:
        """Upload a chain level: its mesh, or its points."""
        if level.mesh is not None:
            return self.mesh(level.mesh.vertices, level.mesh.faces)
        assert level.points is not None
        return self.points(level.points.positions)

    def declared_pixel_size(
        self, level: Level, distance: float, view: ReferenceView = REFERENCE_VIEW
    ) -> float | None:
        """Width in this render's pixels at which ``level``'s points are drawn from
        ``distance`` (:func:`~.render.point_pixel_size`, ``view`` being the reference view the
        declared sizes refer to); None for a mesh level."""
        if not level.is_points:
            return None
        return point_pixel_size(
            level.params.point_size if level.params is not None else 1.0,
            level.design_distance,
            distance,
            view_scale=self.view_scale(view),
            max_size=self.max_point_size,
        )

    def least_f(self, source: Mesh, level: Mesh, distance: float, directions: np.ndarray) -> float:
        """The least silhouette F, over the views from ``distance`` along ``directions``
        (looking at the origin), of mesh ``level`` against mesh ``source``, both rendered."""
        masks = []
        for mesh in (source, level):
            geometry = self.mesh(mesh.vertices, mesh.faces)
            masks.append(self.render(geometry, np.zeros(3), distance, directions))
            geometry.release()
        want, got = masks
        both = (want & got).sum(axis=(1, 2))
        total = want.sum(axis=(1, 2)) + got.sum(axis=(1, 2))
        return float(np.min(np.where(total > 0, 2 * both / np.maximum(total, 1), 1.0)))

    def render(
        self,
        geometry: Geometry,
        center: np.ndarray,
        distance: float,
        directions: np.ndarray,
        pixel_size: float = 1.0,
    ) -> np.ndarray:
        """Coverage masks (views, height, width) bool, row 0 at the top, of ``geometry`` seen
        from ``center + distance · direction`` for each unit direction (views, 3), looking at
        ``center``. Points are ``pixel_size`` pixels wide (clamped to the GL range)."""
        directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        masks = np.zeros((len(directions), self.height, self.width), dtype=bool)
        if geometry.vao is None:
            return masks
        center = np.asarray(center, dtype=np.float64)
        self.program["point_size"].value = float(min(max(pixel_size, 1.0), self.max_point_size))
        self.fbo.use()
        for k, direction in enumerate(directions):
            eye = center + distance * direction
            reach = float(np.linalg.norm(eye - geometry.center))
            far = (reach + geometry.radius) * (1.0 + DEPTH_MARGIN)
            near = max((reach - geometry.radius) * (1.0 - DEPTH_MARGIN), far * 1e-4)
            proj = perspective(self.fov_y_deg, self.width / self.height, near, far)
            mvp = proj @ look_at(eye, center)
            self.program["mvp"].write(mvp.T.astype(np.float32).tobytes())
            self.fbo.clear(0.0, 0.0, 0.0, 0.0)
            geometry.vao.render(geometry.mode)
            data = self.fbo.read(components=1, dtype="f1", alignment=1)
            image = np.frombuffer(data, dtype=np.uint8).reshape(self.height, self.width)
            masks[k] = image[::-1] > 0
        return masks
