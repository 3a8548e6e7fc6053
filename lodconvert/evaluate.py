"""Silhouette fidelity of LOD levels: the PCD paper's F-measure, rendered with moderngl.

The source mesh and each level are drawn as coverage masks (no shading, no depth test: a pixel
is covered when any fragment lands on it) from cameras on a sphere around the object's centre
(:func:`fibonacci_directions`), with a perspective camera of 45° vertical field of view. Per
pixel and summed over all views, TP = covered by both, FP = by the level only, FN = by the
reference only; precision = TP / (TP + FP), recall = TP / (TP + FN) and F = 2PR / (P + R)
(:func:`silhouette_scores`).

Point levels are drawn as square GL points (``gl_PointSize``) of the size the output files
declare: ``params.point_size`` pixels at ``design_distance`` in the reference view
(:data:`~lodconvert.ranges.REFERENCE_VIEW`, 1080 pixels high), scaling with 1/distance
(:func:`point_pixel_size`). A render of another height shows the same scene smaller or larger,
so the size is multiplied by the ratio of focal lengths (512 / 1080 for a 512-pixel render at
the same field of view): points keep the footprint on the object they were designed with.

The GL context (Mesa EGL, llvmpipe on a CPU-only machine) is made when a
:class:`SilhouetteRenderer` is created, never at import. On llvmpipe a process forked after its
parent made a context deadlocks in GL calls: worker pools must use the ``spawn`` start method.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .errors import LodConvertError
from .glcontext import create_context
from .ranges import REFERENCE_VIEW, ReferenceView
from .scene import Level, LodChain, Surface

if TYPE_CHECKING:
    import moderngl

GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
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


class SilhouetteRenderer:
    """Coverage masks of meshes and point clouds from perspective cameras, on one moderngl
    EGL context and one ``size × size`` framebuffer (or ``width × height``).

    Use :meth:`mesh` / :meth:`points` to upload geometry, then :meth:`render` for a batch of
    views. Raises :class:`LodConvertError` (naming the packages to install) when no EGL OpenGL
    3.3 context can be made.
    """

    def __init__(self, size: int = 512, fov_y_deg: float = 45.0, height: int | None = None) -> None:
        self.width = int(size)
        self.height = int(height if height is not None else size)
        self.fov_y_deg = float(fov_y_deg)
        self.ctx = create_context("silhouette evaluation unavailable")
        self.renderer_name = str(self.ctx.info.get("GL_RENDERER", "unknown"))
        self.max_point_size = float(self.ctx.info.get("GL_POINT_SIZE_RANGE", (1.0, 255.0))[1])
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

    def release(self) -> None:
        """Free the context and every GL object made on it."""
        self.ctx.release()

    def __enter__(self) -> SilhouetteRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def silhouette_scores(reference_masks: np.ndarray, level_masks: np.ndarray) -> dict[str, float]:
    """TP, FP, FN summed over all views and pixels, with precision, recall and F.

    TP = covered in both, FP = in the level only, FN = in the reference only.
    Precision = TP / (TP + FP), recall = TP / (TP + FN), F = 2PR / (P + R); all three are 0
    when TP = 0 (so two empty masks score 0), and identical non-empty masks score 1.
    """
    ref = np.asarray(reference_masks, dtype=bool)
    lod = np.asarray(level_masks, dtype=bool)
    if ref.shape != lod.shape:
        raise ValueError(f"mask shapes differ: {ref.shape} vs {lod.shape}")
    tp = int(np.count_nonzero(ref & lod))
    fp = int(np.count_nonzero(lod)) - tp
    fn = int(np.count_nonzero(ref)) - tp
    precision = tp / (tp + fp) if tp else 0.0
    recall = tp / (tp + fn) if tp else 0.0
    f = 2.0 * precision * recall / (precision + recall) if tp else 0.0
    return {"tp": tp, "fp": fp, "fn": fn, "precision": precision, "recall": recall, "f": f}


@dataclass
class DistanceScore:
    """One level seen from one distance: ``diagonals`` = distance / α; ``pixel_size`` is the
    point width drawn (None for a mesh level); the rest as in :func:`silhouette_scores`."""

    distance: float
    diagonals: float
    pixel_size: float | None
    precision: float
    recall: float
    f: float
    tp: int
    fp: int
    fn: int


@dataclass
class LevelScores:
    """Silhouette scores of one level: per requested distance, and (when asked) at the level's
    own ``design_distance`` (not part of ``mean_f``)."""

    name: str
    kind: str
    count: int
    point_size: float | None
    scores: list[DistanceScore]
    at_design: DistanceScore | None = None

    @property
    def mean_f(self) -> float:
        """Mean F over the requested distances."""
        return float(np.mean([s.f for s in self.scores])) if self.scores else 0.0


def _level_geometry(renderer: SilhouetteRenderer, level: Level) -> Geometry:
    if level.kind == "mesh":
        assert level.mesh is not None
        return renderer.mesh(level.mesh.vertices, level.mesh.faces)
    assert level.points is not None
    return renderer.points(level.points.positions)


def evaluate_chain(
    reference: Surface | None,
    chain: LodChain,
    distances_in_diagonals: Sequence[float] = (4, 8, 16),
    views: int = 64,
    size: int = 512,
    *,
    at_design_distance: bool = False,
    pixel_size: float | None = None,
    view: ReferenceView = REFERENCE_VIEW,
    renderer: SilhouetteRenderer | None = None,
) -> list[LevelScores]:
    """Silhouette P/R/F of every level of ``chain`` against the source mesh, finest first.

    ``reference`` is the source surface relative to ``chain.origin`` (as level geometry is);
    None takes the chain's mesh level. Cameras look at the chain's centre from
    ``views`` Fibonacci directions at each distance ``k · chain.alpha`` (α, the bounding-box
    diagonal), rendering ``size × size`` pixels at 45°. Points are drawn at the size the files
    declare (:func:`point_pixel_size`, ``view`` being the reference view the sizes refer to),
    or all ``pixel_size`` wide when given. With ``at_design_distance`` each point level is
    also scored at its own ``design_distance`` (where it switches in).
    ``renderer`` reuses a :class:`SilhouetteRenderer` (its size then wins over ``size``).
    """
    if reference is None:
        meshes = [lv.mesh for lv in chain.levels if lv.kind == "mesh" and lv.mesh is not None]
        if not meshes:
            raise LodConvertError(f"{chain.object_id}: no reference mesh to evaluate against")
        reference = meshes[0]
    own = renderer is None
    renderer = renderer or SilhouetteRenderer(size)
    directions = fibonacci_directions(views)
    center = np.asarray(chain.center, dtype=np.float64)
    ref_geometry = renderer.mesh(reference.vertices, reference.faces)
    ref_masks: dict[float, np.ndarray] = {}

    def score(level: Level, geometry: Geometry, distance: float) -> DistanceScore:
        if distance not in ref_masks:
            ref_masks[distance] = renderer.render(ref_geometry, center, distance, directions)
        size_px = None
        if level.kind == "pcd":
            size_px = (
                pixel_size
                if pixel_size is not None
                else point_pixel_size(
                    level.params.point_size if level.params is not None else 1.0,
                    level.design_distance,
                    distance,
                    view_scale=renderer.view_scale(view),
                    max_size=renderer.max_point_size,
                )
            )
        masks = renderer.render(geometry, center, distance, directions, size_px or 1.0)
        s = silhouette_scores(ref_masks[distance], masks)
        return DistanceScore(distance, distance / chain.alpha, size_px, **s)

    rows: list[LevelScores] = []
    try:
        for level in chain.levels:
            geometry = _level_geometry(renderer, level)
            scores = [score(level, geometry, k * chain.alpha) for k in distances_in_diagonals]
            design = None
            if at_design_distance and level.kind == "pcd" and level.design_distance:
                design = score(level, geometry, level.design_distance)
            geometry.release()
            rows.append(
                LevelScores(
                    name=level.name,
                    kind=level.kind,
                    count=level.count,
                    point_size=level.params.point_size if level.params is not None else None,
                    scores=scores,
                    at_design=design,
                )
            )
    finally:
        ref_geometry.release()
        if own:
            renderer.release()
    return rows
