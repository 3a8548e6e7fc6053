"""Render benchmark (``lodconvert bench``): a grid of instances each drawing the level its
distance selects, against the same grid drawing the original mesh — the shape of the PCD
paper's Tables 4–7. N = k² instances stand on a square lattice seen from a fixed camera
(:data:`EYE`, :data:`TARGET`, in object diagonals) on a 1920×1080 framebuffer, the reference
view; levels switch as X3D ``LOD`` does, with per-instance frustum culling; every level is drawn
instanced by :class:`GridRenderer`, and the median of the timed frames is reported. The grid,
camera, drawing and timing rules: ``docs/render-bench.md``.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputError, UsageError
from ..io import read_chains, read_scene
from ..io.frame import ROTATION, y_up
from ..model import Level, LodChain
from ..ranges import REFERENCE_VIEW, ReferenceView
from .render import OffscreenRenderer, look_at, perspective

if TYPE_CHECKING:
    import moderngl

PAPER_INSTANCES = (121, 441, 961, 1681, 5041, 6561)
"""The instance counts of the paper's Tables 4–7 (11² … 81²)."""
GRID_SPACING = 1.5
"""Default distance between neighbouring instances, in object diagonals α."""
EYE = (0.0, -5.0, 1.5)
"""Eye position in α (x across the grid, y along it, z up), relative to the first row's centre."""
TARGET = (0.0, 12.0, 0.0)
"""Point looked at, in α."""
WIDTH, HEIGHT = 1920, 1080
FOV_Y_DEG = 45.0
NEAR = 0.05
"""Near plane in α (the nearest instance is about 5 α from the eye)."""
CHUNK_VERTICES = 16_000_000
"""Most vertices plus points one draw call submits: the frame budget is checked between calls."""
DEFAULT_FRAMES = 5
DEFAULT_WARMUP = 1
DEFAULT_BUDGET_S = 300.0
MESH_GREY = 200
"""Colour byte of meshes that have no vertex colours."""

Message = Callable[[str], None]

VERTEX_SHADER = """
#version 330
uniform mat4 view_proj;
uniform vec3 eye;
uniform float point_size;       // pixels at design_distance
uniform float design_distance;  // 0: constant point_size
uniform float max_point_size;
in vec3 in_pos;     // relative to the LOD centre, world axes
in vec4 in_color;
in vec3 in_offset;  // per instance: the LOD centre
out vec4 color;
void main() {
    vec3 world = in_pos + in_offset;
    gl_Position = view_proj * vec4(world, 1.0);
    float size = point_size;
    if (design_distance > 0.0) {
        size *= design_distance / max(distance(world, eye), 1e-9);
    }
    gl_PointSize = clamp(size, 1.0, max_point_size);
    color = in_color;
}
"""

FRAGMENT_SHADER = """
#version 330
in vec4 color;
out vec4 frag;
void main() {
    frag = color;
}
"""


# --- the object read back from a file -----------------------------------------------------------


@dataclass
class BenchObject:
    """What a benchmark draws: an object's ``chain`` as :func:`~lodconvert.io.read_chains` read
    it back (geometry relative to ``chain.origin``), the ``reference`` level the original grid
    draws, and the number of ``objects`` in the file."""

    chain: LodChain
    reference: Level
    objects: int = 1


def read_object(
    path: str | Path, object_id: str | None = None, reference: str | Path | None = None
) -> BenchObject:
    """Object ``object_id`` (default: the first) of a file lodconvert wrote, with its
    ``reference``: the finest level when it is a mesh, else (or when given) the mesh read from
    the ``reference`` file — its object of the same id, or its only object — placed by the
    chain's origin, as a level named "original".

    Raises :class:`InputError` for an unreadable file, an unknown object or a missing reference.
    """
    chains = read_chains(path)
    if not chains:
        raise InputError("holds no LOD object", str(path))
    ids = [chain.object_id for chain in chains]
    if object_id is not None and object_id not in ids:
        raise InputError(f"has no object {object_id!r} (objects: {', '.join(ids)})", str(path))
    chain = chains[ids.index(object_id) if object_id is not None else 0]
    if reference is not None:
        original = _reference_level(reference, chain)
    elif not chain.levels[0].is_points:
        original = chain.levels[0]
    else:
        raise InputError(
            "its finest level is a point cloud: give the original mesh with --reference", str(path)
        )
    return BenchObject(chain, original, objects=len(chains))


def _reference_level(path: str | Path, chain: LodChain) -> Level:
    """The original mesh for ``chain`` from a mesh file (world coordinates → chain origin)."""
    nodes = list(read_scene(path).with_geometry())
    matches = [obj for obj in nodes if obj.id == chain.object_id]
    if not matches and len(nodes) == 1:
        matches = nodes
    if not matches:
        raise InputError(f"has {len(nodes)} objects and none is {chain.object_id!r}", str(path))
    mesh = matches[0].geometry
    assert mesh is not None
    return Level("original", "mesh", mesh=mesh.translated(-chain.origin))


def level_kind(level: Level) -> str:
    """How a level is drawn: "pcd" (points) or "mesh" (triangles, whatever its bake kind)."""
    return "pcd" if level.is_points else "mesh"


def level_triangles(level: Level) -> int:
    """Triangles of a mesh level (0 for points)."""
    return 0 if level.mesh is None else level.mesh.face_count


def _level_arrays(level: Level) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Positions (k, 3), faces (m, 3) or None for points, and RGBA colours (k, 4) or None."""
    if level.mesh is not None:
        return level.mesh.vertices, level.mesh.faces, level.mesh.vertex_colors
    assert level.points is not None
    return level.points.positions, None, level.points.colors


# --- grid, camera, selection --------------------------------------------------------------------


def grid_side(count: int) -> int:
    """k for N = k² instances; :class:`UsageError` unless ``count`` is a positive square."""
    side = math.isqrt(count) if count > 0 else 0
    if side * side != count or side == 0:
        raise UsageError(f"must be perfect squares (k×k grids), got {count}", "instances")
    return side


def grid_points(count: int, spacing: float) -> np.ndarray:
    """Ground positions (N, 2) of a k×k grid of pitch ``spacing``: x centred on 0, y from 0
    away from the camera, row by row."""
    side = grid_side(count)
    steps = np.arange(side, dtype=np.float64)
    x, y = np.meshgrid((steps - (side - 1) / 2.0) * spacing, steps * spacing)
    return np.column_stack([x.ravel(), y.ravel()])


def up_rotation(up: str) -> np.ndarray:
    """Rotation (3, 3) taking a model's ``up`` axis (one of :data:`~..io.frame.UP_AXES`) to
    world +z: to +y as ``convert --up`` turns it, then +y to +z."""
    return ROTATION.T @ y_up(up)


def frustum_planes(view_proj: np.ndarray) -> np.ndarray:
    """The six planes (6, 4) of a view-projection matrix's frustum, normals of unit length
    pointing inside: a point p is inside when ``planes[:, :3] @ p + planes[:, 3] >= 0``."""
    m = np.asarray(view_proj, dtype=np.float64)
    planes = np.stack(
        [m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2], m[3] - m[2]]
    )
    return planes / np.linalg.norm(planes[:, :3], axis=1, keepdims=True)


def spheres_in_frustum(centers: np.ndarray, radius: float, planes: np.ndarray) -> np.ndarray:
    """(N,) bool: which spheres of ``radius`` around ``centers`` (N, 3) reach into the frustum
    (conservative: a sphere outside near a frustum corner may count as inside)."""
    signed = centers @ planes[:, :3].T + planes[:, 3]
    return (signed >= -radius).all(axis=1)


def select_levels(distances: np.ndarray, cutoffs: Sequence[float]) -> np.ndarray:
    """Level index (N,) per distance: ``i`` for ``cutoffs[i-1] <= d < cutoffs[i]``;
    ``len(cutoffs)`` beyond the last (for a culled chain, one past its last level: nothing)."""
    return np.searchsorted(np.asarray(cutoffs, dtype=np.float64), distances, side="right")


@dataclass
class GridView:
    """One grid of N instances seen by the fixed camera: LOD-centre positions (N, 3), which
    survive frustum culling, the level each selects, and the camera."""

    centers: np.ndarray
    visible: np.ndarray
    levels: np.ndarray
    view_proj: np.ndarray
    eye: np.ndarray


def grid_view(
    chain: LodChain,
    count: int,
    spacing: float = GRID_SPACING,
    lift: float = 0.0,
    frustum_culling: bool = True,
) -> GridView:
    """Lay out N = ``count`` instances of ``chain`` ``spacing · α`` apart, with LOD centres
    ``lift`` above the ground, and select their levels from the camera
    (``docs/render-bench.md``)."""
    alpha = chain.alpha
    ground = grid_points(count, spacing * alpha)
    centers = np.column_stack([ground, np.full(len(ground), lift)])
    eye, target = np.array(EYE) * alpha, np.array(TARGET) * alpha
    distances = np.linalg.norm(centers - eye, axis=1)
    far = float(distances.max()) + alpha
    view_proj = perspective(FOV_Y_DEG, WIDTH / HEIGHT, NEAR * alpha, far) @ look_at(eye, target)
    visible = np.ones(count, dtype=bool)
    if frustum_culling:
        visible = spheres_in_frustum(centers, alpha / 2.0, frustum_planes(view_proj))
    levels = select_levels(distances, chain.cutoffs)
    return GridView(centers, visible, levels, view_proj, eye)


# --- rendering and timing -----------------------------------------------------------------------


@dataclass
class Drawable:
    """A level uploaded to a :class:`GridRenderer`: vertex array, primitive mode, the level,
    and its instance buffer (LOD-centre positions, 3 floats each)."""

    level: Level
    vao: moderngl.VertexArray
    mode: int
    instance_buffer: moderngl.Buffer
    instances: int = 0


@dataclass
class Timing:
    """Frame times of one grid. ``status``: "ok", "over budget" (a frame was stopped after
    ``stopped_after_s``) or "skipped" (over budget at a smaller N)."""

    status: str = "ok"
    frame_seconds: list[float] = field(default_factory=list)
    stopped_after_s: float | None = None

    @property
    def median_s(self) -> float | None:
        """Median frame time, when every frame completed."""
        if self.status != "ok" or not self.frame_seconds:
            return None
        return statistics.median(self.frame_seconds)

    @property
    def fps(self) -> float | None:
        """Frames per second of the median frame."""
        median = self.median_s
        return 1.0 / median if median else None


class GridRenderer(OffscreenRenderer):
    """Instanced drawing of uploaded levels into a 1920×1080 RGBA + depth framebuffer on its
    own moderngl EGL context. Raises :class:`~lodconvert.errors.LodConvertError` (naming the
    packages to install) when no EGL OpenGL 3.3 context can be made."""

    def __init__(self) -> None:
        super().__init__("render benchmark unavailable")
        self.ctx.enable(self.ctx.DEPTH_TEST | self.ctx.PROGRAM_POINT_SIZE)
        self.program = self.ctx.program(
            vertex_shader=VERTEX_SHADER, fragment_shader=FRAGMENT_SHADER
        )
        self.fbo = self.ctx.framebuffer(
            color_attachments=[self.ctx.renderbuffer((WIDTH, HEIGHT))],
            depth_attachment=self.ctx.depth_renderbuffer((WIDTH, HEIGHT)),
        )
        self.offset_location = self.program["in_offset"].location
        render_view = ReferenceView(height_px=HEIGHT, fov_y_deg=FOV_Y_DEG)
        self.view_scale = render_view.focal_px / REFERENCE_VIEW.focal_px

    def upload(self, level: Level, center: np.ndarray, rotation: np.ndarray) -> Drawable:
        """Upload ``level`` once: positions relative to ``center``, turned by ``rotation``."""
        positions, faces, colors = _level_arrays(level)
        local = (np.asarray(positions, dtype=np.float64) - center) @ rotation.T
        if colors is None:
            colors = np.full((level.count, 4), MESH_GREY, dtype=np.uint8)
            colors[:, 3] = 255
        vbo = self.ctx.buffer(local.astype(np.float32).tobytes())
        cbo = self.ctx.buffer(np.ascontiguousarray(colors, dtype=np.uint8).tobytes())
        instance_buffer = self.ctx.buffer(reserve=12)
        content = [
            (vbo, "3f", "in_pos"),
            (cbo, "4f1", "in_color"),
            (instance_buffer, "3f/i", "in_offset"),
        ]
        ibo = None
        if faces is not None:
            ibo = self.ctx.buffer(np.asarray(faces, dtype=np.uint32).tobytes())
        vao = self.ctx.vertex_array(self.program, content, index_buffer=ibo, index_element_size=4)
        mode = self.ctx.POINTS if faces is None else self.ctx.TRIANGLES
        return Drawable(level, vao, mode, instance_buffer)

    def place(self, drawable: Drawable, centers: np.ndarray) -> None:
        """Set the instances ``drawable`` draws: LOD-centre positions (n, 3)."""
        data = np.ascontiguousarray(centers, dtype=np.float32).tobytes()
        if len(data) > drawable.instance_buffer.size:
            drawable.instance_buffer.orphan(len(data))
        if data:
            drawable.instance_buffer.write(data)
        drawable.instances = len(centers)

    def _draw(self, drawable: Drawable, instances: int, deadline: float) -> bool:
        """Draw ``instances`` of ``drawable`` in calls of at most :data:`CHUNK_VERTICES`
        vertices; False when the clock passed ``deadline`` before all were drawn."""
        level = drawable.level
        point_size, design = 1.0, 0.0
        if level.is_points:
            declared = level.params.point_size if level.params is not None else 1.0
            point_size, design = declared * self.view_scale, level.design_distance or 0.0
        self.program["point_size"].value = point_size
        self.program["design_distance"].value = design
        chunk = max(1, CHUNK_VERTICES // max(level.count, 1))
        for start in range(0, instances, chunk):
            if time.perf_counter() > deadline:
                return False
            drawable.vao.bind(
                self.offset_location,
                "f",
                drawable.instance_buffer,
                "3f",
                offset=12 * start,
                divisor=1,
            )
            drawable.vao.render(drawable.mode, instances=min(chunk, instances - start))
        return True

    def frame(self, drawables: Sequence[Drawable], budget_s: float) -> tuple[float, bool]:
        """Clear and draw every drawable's instances; (seconds, completed). The frame is
        stopped between draw calls once ``budget_s`` has passed."""
        self.ctx.finish()
        start = time.perf_counter()
        self.fbo.use()
        self.fbo.clear(0.6, 0.7, 0.8, 1.0)
        completed = all(
            self._draw(d, d.instances, start + budget_s) for d in drawables if d.level.count
        )
        self.ctx.finish()
        return time.perf_counter() - start, completed

    def measure(
        self,
        drawables: Sequence[Drawable],
        view: GridView,
        frames: int,
        warmup: int,
        budget_s: float,
    ) -> Timing:
        """Time ``frames`` frames of the placed ``drawables`` after drawing each once and
        ``warmup`` untimed frames (``docs/render-bench.md``, timing)."""
        self.program["view_proj"].write(view.view_proj.T.astype(np.float32).tobytes())
        self.program["eye"].value = tuple(float(v) for v in view.eye)
        self.program["max_point_size"].value = self.max_point_size
        self.fbo.use()
        for drawable in drawables:  # compile the shader variants, make buffers resident
            if drawable.level.count and drawable.instances:
                self._draw(drawable, 1, math.inf)
        timing = Timing()
        for k in range(warmup + frames):
            seconds, completed = self.frame(drawables, budget_s)
            if not completed:
                return Timing("over budget", timing.frame_seconds, seconds)
            if k >= warmup:
                timing.frame_seconds.append(seconds)
        return timing

    def read_image(self) -> np.ndarray:
        """The last frame as RGB uint8 (height, width, 3), row 0 at the top."""
        data = self.fbo.read(components=3, alignment=1)
        return np.frombuffer(data, dtype=np.uint8).reshape(HEIGHT, WIDTH, 3)[::-1]


# --- the benchmark ------------------------------------------------------------------------------


@dataclass
class GridResult:
    """One grid at one N: instances drawn after frustum culling, how many draw each level,
    vertices + points and triangles submitted per frame, and the frame times."""

    drawn: int
    level_instances: dict[str, int]
    submitted: int
    triangles: int
    timing: Timing

    def record(self) -> dict[str, Any]:
        """JSON-able form."""
        return {
            "drawn": self.drawn,
            "level_instances": self.level_instances,
            "submitted": self.submitted,
            "triangles": self.triangles,
            "status": self.timing.status,
            "frame_seconds": [round(s, 6) for s in self.timing.frame_seconds],
            "median_s": self.timing.median_s,
            "fps": self.timing.fps,
            "stopped_after_s": self.timing.stopped_after_s,
        }


@dataclass
class BenchRow:
    """Both grids at N = ``instances``."""

    instances: int
    lod: GridResult
    original: GridResult

    @property
    def speedup(self) -> float | None:
        """Original median frame time over the LOD grid's, when both were measured."""
        lod, original = self.lod.timing.median_s, self.original.timing.median_s
        return original / lod if lod and original else None

    def record(self) -> dict[str, Any]:
        """JSON-able form."""
        return {
            "instances": self.instances,
            "lod": self.lod.record(),
            "original": self.original.record(),
            "speedup": self.speedup,
        }


@dataclass
class BenchSettings:
    """What a benchmark run draws and how it times it (the defaults: ``docs/render-bench.md``)."""

    instances: tuple[int, ...] = PAPER_INSTANCES
    frames: int = DEFAULT_FRAMES
    warmup: int = DEFAULT_WARMUP
    budget_s: float = DEFAULT_BUDGET_S
    spacing: float = GRID_SPACING
    frustum_culling: bool = True
    up: str = "y"

    def check(self) -> None:
        """Raise :class:`UsageError` for values that cannot be run."""
        for count in self.instances:
            grid_side(count)
        if self.frames < 1 or self.warmup < 0:
            raise UsageError("must be at least 1, and warmup at least 0", "frames")
        if not self.budget_s > 0 or not self.spacing > 0:
            raise UsageError("and spacing must be positive", "budget")
        up_rotation(self.up)

    def record(self) -> dict[str, Any]:
        """JSON-able form, with the fixed camera and framebuffer."""
        return {
            "instances": list(self.instances),
            "frames": self.frames,
            "warmup": self.warmup,
            "budget_s": self.budget_s,
            "spacing_alpha": self.spacing,
            "frustum_culling": self.frustum_culling,
            "up": self.up,
            "eye_alpha": list(EYE),
            "target_alpha": list(TARGET),
            "fov_y_deg": FOV_Y_DEG,
            "size": [WIDTH, HEIGHT],
        }


def _grid_result(drawables: list[Drawable], groups: list[np.ndarray], timing: Timing) -> GridResult:
    counts = [len(group) for group in groups]
    return GridResult(
        drawn=sum(counts),
        level_instances={d.level.name: n for d, n in zip(drawables, counts, strict=True)},
        submitted=sum(n * d.level.count for d, n in zip(drawables, counts, strict=True)),
        triangles=sum(n * level_triangles(d.level) for d, n in zip(drawables, counts, strict=True)),
        timing=timing,
    )


def run_bench(
    target: BenchObject,
    settings: BenchSettings,
    renderer: GridRenderer,
    progress: Message | None = None,
) -> list[BenchRow]:
    """Time the LOD grid and the original grid of ``target`` at every N of ``settings``."""
    settings.check()
    chain, rotation = target.chain, up_rotation(settings.up)
    center = chain.center
    lod = [renderer.upload(level, center, rotation) for level in chain.levels]
    reference = renderer.upload(target.reference, center, rotation)
    # LOD centres stand so high that the original's lowest point touches the ground
    positions = _level_arrays(target.reference)[0]
    lift = -float(((positions - center) @ rotation.T)[:, 2].min(initial=0.0))
    rows: list[BenchRow] = []
    over = {"lod": False, "original": False}
    for count in settings.instances:
        view = grid_view(chain, count, settings.spacing, lift, settings.frustum_culling)
        grids = {
            "lod": (
                lod,
                [view.centers[view.visible & (view.levels == i)] for i in range(len(lod))],
            ),
            "original": ([reference], [view.centers[view.visible]]),
        }
        results = {}
        for name, (drawables, groups) in grids.items():
            if over[name]:
                timing = Timing("skipped")
            else:
                if progress:
                    progress(f"N = {count}: {name} grid")
                for drawable, group in zip(drawables, groups, strict=True):
                    renderer.place(drawable, group)
                timing = renderer.measure(
                    drawables, view, settings.frames, settings.warmup, settings.budget_s
                )
                over[name] = timing.status != "ok"
            results[name] = _grid_result(drawables, groups, timing)
        rows.append(BenchRow(count, results["lod"], results["original"]))
    return rows
