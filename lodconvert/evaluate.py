"""Fidelity of LOD levels against their source mesh: silhouettes, geometric error, counts.

**Silhouettes** (the PCD paper's F-measure). The source mesh and each level are drawn as coverage
masks (no shading, no depth test: a pixel is covered when any fragment lands on it) from
cameras on a sphere around the object's centre (:func:`fibonacci_directions`), with a
perspective camera of 45° vertical field of view. Per pixel and summed over all views,
TP = covered by both, FP = by the level only, FN = by the reference only; precision =
TP / (TP + FP), recall = TP / (TP + FN) and F = 2PR / (P + R) (:func:`silhouette_scores`).
Each level is scored at fixed multiples of the bounding-box diagonal α (the protocol: 4, 8 and
16 α) and within its own range (:func:`level_window`): where it first shows and in the middle
of its range, with its declared point size and with 1-pixel points.

Point levels are drawn as square GL points (``gl_PointSize``) of the size the output files
declare: ``params.point_size`` pixels at ``design_distance`` in the reference view
(:data:`~lodconvert.ranges.REFERENCE_VIEW`, 1080 pixels high), scaling with 1/distance
(:func:`point_pixel_size`). A render of another height shows the same scene smaller or larger,
so the size is multiplied by the ratio of focal lengths (512 / 1080 for a 512-pixel render at
the same field of view): points keep the footprint on the object they were designed with. The
X3D ``pointSizeMaxValue`` is not applied: it is the size at the nearest distance the level is
shown from, so it never binds within the level's range (where the in-range scores are exactly
what a viewer draws), and applying it on the fixed protocol, which looks at coarse levels from
nearer than they ever show, would measure the cap instead of the level; glTF declares no cap.

**Geometric error** (:func:`geometric_errors`): symmetric Chamfer and Hausdorff distance
between dense area-weighted samples of the source surface and the level (its points, or
samples of its mesh), as fractions of α, with scipy's cKDTree.

**Files read back** (:func:`~lodconvert.io.readback.read_chains`): the chains of a
``.glb``/``.gltf``/``.x3d`` that lodconvert wrote, with the parameters the file declares;
:func:`match_references` pairs them with the objects of the source and checks that their bounds
agree.

The GL context (Mesa EGL, llvmpipe on a CPU-only machine) is made when a
:class:`SilhouetteRenderer` is created, never at import. On llvmpipe a process forked after its
parent made a context deadlocks in GL calls: worker pools must use the ``spawn`` start method.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from .errors import InputError, LodConvertError
from .glcontext import create_context
from .model import Level, LodChain, Node, Surface
from .ranges import REFERENCE_VIEW, ReferenceView, cutoff

if TYPE_CHECKING:
    import moderngl

GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
# Near/far planes lie this fraction outside the geometry's bounding sphere.
DEPTH_MARGIN = 0.01

DEFAULT_VIEWS = 64
DEFAULT_SIZE = 512
DEFAULT_FOV = 45.0
DEFAULT_DISTANCES = (4.0, 8.0, 16.0)
DEFAULT_SAMPLES = 1_000_000
"""Surface samples for the geometric error: their mean spacing on the Stanford scans is
about 0.1 % of the diagonal (:func:`sample_spacing`)."""
SAMPLE_SEED = 0
BOUNDS_TOLERANCE = 1e-3
"""How far (fraction of α) REF's bounding-box centre and diagonal may be from OUT's."""

SHEET_VIEWS = 3
SHEET_TILE = 240
SHEET_FONT_PX = 13
SHEET_COLORS = {
    "both": (150, 150, 150),
    "level only": (220, 40, 40),
    "source only": (40, 90, 230),
}

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
class RangeScores:
    """A level within its own range (:func:`level_window`): where it first shows (``near``)
    and in the middle of its range, with the declared point size and (point levels only) with
    1-pixel points, as glTF viewers draw them."""

    near: DistanceScore
    middle: DistanceScore
    near_1px: DistanceScore | None = None
    middle_1px: DistanceScore | None = None


@dataclass
class LevelScores:
    """Silhouette scores of one level: per requested distance, and (when asked) at the level's
    own ``design_distance`` and within its range (neither is part of ``mean_f``)."""

    name: str
    kind: str
    count: int
    point_size: float | None
    scores: list[DistanceScore]
    at_design: DistanceScore | None = None
    in_range: RangeScores | None = None

    @property
    def mean_f(self) -> float:
        """Mean F over the requested distances."""
        return float(np.mean([s.f for s in self.scores])) if self.scores else 0.0


def level_window(chain: LodChain, index: int) -> tuple[float, float]:
    """(near, middle) distances of level ``index`` of ``chain``.

    A level shows between the cutoffs Y(x) = α·β·γˣ of the exponents around it; the finest
    level from x = 0 (α·β, the distance a baked finest level is designed for, standing in for
    "from nearest"). ``near`` is where it first shows, ``middle`` is Y at the mean of the two
    exponents: the geometric middle of its distances, where the object's on-screen size is
    halfway in scale. The last level of a chain that is not culled shows without end: its
    range is taken as one more step as wide, in x, as the one before it.
    """
    xs = [0.0, *chain.xs]
    low = xs[index]
    high = xs[index + 1] if index + 1 < len(xs) else low + (low - xs[index - 1] if index else 1.0)
    return (
        cutoff(chain.alpha, chain.beta, chain.gamma, low),
        cutoff(chain.alpha, chain.beta, chain.gamma, (low + high) / 2.0),
    )


def _level_geometry(renderer: SilhouetteRenderer, level: Level) -> Geometry:
    if not level.is_points:
        assert level.mesh is not None
        return renderer.mesh(level.mesh.vertices, level.mesh.faces)
    assert level.points is not None
    return renderer.points(level.points.positions)


def declared_pixel_size(
    level: Level,
    distance: float,
    renderer: SilhouetteRenderer,
    view: ReferenceView = REFERENCE_VIEW,
) -> float | None:
    """Width in pixels of ``renderer``'s render at which ``level``'s points are drawn from
    ``distance`` (:func:`point_pixel_size`); None for a mesh level."""
    if not level.is_points:
        return None
    return point_pixel_size(
        level.params.point_size if level.params is not None else 1.0,
        level.design_distance,
        distance,
        view_scale=renderer.view_scale(view),
        max_size=renderer.max_point_size,
    )


class ReferenceRenders:
    """The source ``surface`` uploaded to ``renderer`` with its coverage masks from ``views``
    Fibonacci directions around ``center``, rendered once per distance and kept. One instance
    serves every chain baked from the same source (levels relative to the same origin), so a
    heavy mesh is drawn once per distance however many chains are scored against it."""

    def __init__(
        self, renderer: SilhouetteRenderer, surface: Surface, center: np.ndarray, views: int
    ) -> None:
        self.renderer, self.surface = renderer, surface
        self.center = np.asarray(center, dtype=np.float64)
        self.directions = fibonacci_directions(views)
        self.geometry = renderer.mesh(surface.vertices, surface.faces)
        self.cache: dict[float, np.ndarray] = {}

    def masks(self, distance: float) -> np.ndarray:
        """Coverage masks (views, height, width) of the source seen from ``distance``."""
        if distance not in self.cache:
            masks = self.renderer.render(self.geometry, self.center, distance, self.directions)
            self.cache[distance] = np.packbits(masks, axis=-1)  # 8× smaller while kept
        packed = self.cache[distance]
        return np.unpackbits(packed, axis=-1, count=self.renderer.width).astype(bool)

    def release(self) -> None:
        """Free the uploaded mesh and the cached masks."""
        self.geometry.release()
        self.cache.clear()


class _Scorer:
    """Scores the levels of one chain against :class:`ReferenceRenders`."""

    def __init__(self, references: ReferenceRenders, chain: LodChain, view: ReferenceView) -> None:
        if not np.allclose(references.center, chain.center):
            raise ValueError(f"{chain.object_id}: chain centre differs from the reference's")
        self.references, self.chain, self.view = references, chain, view
        self.renderer = references.renderer

    def score(
        self, level: Level, geometry: Geometry, distance: float, pixel_size: float | None = None
    ) -> DistanceScore:
        """``level`` from ``distance``, its points ``pixel_size`` wide (default: declared)."""
        size = declared_pixel_size(level, distance, self.renderer, self.view)
        if size is not None and pixel_size is not None:
            size = pixel_size
        refs = self.references
        masks = self.renderer.render(geometry, refs.center, distance, refs.directions, size or 1.0)
        s = silhouette_scores(refs.masks(distance), masks)
        return DistanceScore(distance, distance / self.chain.alpha, size, **s)

    def in_range(self, index: int, level: Level, geometry: Geometry) -> RangeScores:
        """:class:`RangeScores` of level ``index``."""
        near, middle = level_window(self.chain, index)
        one_px = level.is_points
        return RangeScores(
            near=self.score(level, geometry, near),
            middle=self.score(level, geometry, middle),
            near_1px=self.score(level, geometry, near, 1.0) if one_px else None,
            middle_1px=self.score(level, geometry, middle, 1.0) if one_px else None,
        )


def evaluate_chain(
    reference: Surface | ReferenceRenders | None,
    chain: LodChain,
    distances_in_diagonals: Sequence[float] = DEFAULT_DISTANCES,
    views: int = DEFAULT_VIEWS,
    size: int = DEFAULT_SIZE,
    *,
    at_design_distance: bool = False,
    in_range: bool = False,
    pixel_size: float | None = None,
    levels: Sequence[int] | None = None,
    view: ReferenceView = REFERENCE_VIEW,
    renderer: SilhouetteRenderer | None = None,
) -> list[LevelScores]:
    """Silhouette P/R/F of the levels of ``chain`` against the source mesh, finest first.

    ``reference`` is the source surface relative to ``chain.origin`` (as level geometry is),
    or :class:`ReferenceRenders` of it (whose renderer and views then win over ``renderer``,
    ``size`` and ``views``); None takes the chain's mesh level. Cameras look at the chain's
    centre from ``views`` Fibonacci directions at each distance ``k · chain.alpha`` (α, the
    bounding-box diagonal), rendering ``size × size`` pixels at 45°. Points are drawn at the
    size the files declare (:func:`point_pixel_size`, ``view`` being the reference view the
    sizes refer to), or all ``pixel_size`` wide when given. With ``at_design_distance`` each
    point level is also scored at its own ``design_distance`` (where it switches in); with
    ``in_range``, every level within its range (:class:`RangeScores`). ``levels`` picks the
    levels to score by index (default all). ``renderer`` reuses a
    :class:`SilhouetteRenderer` (its size then wins over ``size``).
    """
    if reference is None:
        meshes = [lv.mesh for lv in chain.levels if not lv.is_points and lv.mesh is not None]
        if not meshes:
            raise LodConvertError(f"{chain.object_id}: no reference mesh to evaluate against")
        reference = meshes[0]
    own_renderer = renderer is None and not isinstance(reference, ReferenceRenders)
    if isinstance(reference, ReferenceRenders):
        references = reference
    else:
        renderer = renderer or SilhouetteRenderer(size)
        references = ReferenceRenders(renderer, reference, chain.center, views)
    rows: list[LevelScores] = []
    try:
        scorer = _Scorer(references, chain, view)
        picked = range(len(chain.levels)) if levels is None else levels
        for index in picked:
            level = chain.levels[index]
            geometry = _level_geometry(references.renderer, level)
            scores = [
                scorer.score(level, geometry, k * chain.alpha, pixel_size)
                for k in distances_in_diagonals
            ]
            design = None
            if at_design_distance and level.is_points and level.design_distance:
                design = scorer.score(level, geometry, level.design_distance, pixel_size)
            window = scorer.in_range(index, level, geometry) if in_range else None
            geometry.release()
            rows.append(
                LevelScores(
                    name=level.name,
                    kind=level.kind,
                    count=level.count,
                    point_size=level.params.point_size if level.params is not None else None,
                    scores=scores,
                    at_design=design,
                    in_range=window,
                )
            )
    finally:
        if references is not reference:
            references.release()
        if own_renderer:
            references.renderer.release()
    return rows


# --- geometric error ----------------------------------------------------------------------------


@dataclass
class GeometricError:
    """Distances between a level and the source surface as fractions of α (None for an empty
    level): ``chamfer`` = the mean of the two mean nearest-neighbour distances (source → level
    and level → source), ``hausdorff`` = the larger of the two largest."""

    chamfer: float | None
    hausdorff: float | None


def _face_areas(surface: Surface) -> np.ndarray:
    """Area of every face (m,)."""
    tri = surface.triangles
    return np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) / 2.0


def sample_surface(surface: Surface, count: int, seed: int = SAMPLE_SEED) -> np.ndarray:
    """``count`` points (count, 3) spread uniformly over the area of ``surface``'s faces.

    Deterministic for a given seed; the same faces in the same order give the same points, so
    a mesh compared with itself is at distance 0.
    """
    tri = surface.triangles
    area = _face_areas(surface)
    if len(tri) == 0 or not area.sum() > 0:
        return np.zeros((0, 3))
    rng = np.random.default_rng(seed)
    cumulative = np.cumsum(area)
    faces = np.searchsorted(cumulative, rng.random(count) * cumulative[-1], side="right")
    faces = np.minimum(faces, len(tri) - 1)
    r1, r2 = np.sqrt(rng.random(count)), rng.random(count)
    weights = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    return np.einsum("ij,ijk->ik", weights, tri[faces])


def _kdtree(points: np.ndarray) -> Any:
    """A scipy ``cKDTree`` of ``points`` (scipy is imported on first use)."""
    try:
        from scipy.spatial import cKDTree
    except ImportError as exc:
        raise LodConvertError(
            f"geometric error needs scipy ({exc}); run: pip install scipy"
        ) from exc
    return cKDTree(points)


def geometric_errors(
    reference: Surface,
    chain: LodChain,
    samples: int = DEFAULT_SAMPLES,
    levels: Sequence[int] | None = None,
) -> list[GeometricError]:
    """:class:`GeometricError` of the levels of ``chain`` (all, or those indexed by
    ``levels``) against ``reference`` (relative to ``chain.origin``), from ``samples`` points
    on the reference and, for mesh levels, as many on the level (:func:`sample_surface`);
    point levels are their points."""
    source = sample_surface(reference, samples)
    source_tree = _kdtree(source)
    errors = []
    for index in range(len(chain.levels)) if levels is None else levels:
        level = chain.levels[index]
        if not level.is_points:
            assert level.mesh is not None
            points = sample_surface(level.mesh, samples)
        else:
            assert level.points is not None
            points = level.points.positions
        if len(points) == 0 or len(source) == 0:
            errors.append(GeometricError(None, None))
            continue
        to_level, _ = _kdtree(points).query(source, workers=-1)
        to_source, _ = source_tree.query(points, workers=-1)
        errors.append(
            GeometricError(
                chamfer=float(to_level.mean() + to_source.mean()) / 2.0 / chain.alpha,
                hausdorff=float(max(to_level.max(), to_source.max())) / chain.alpha,
            )
        )
    return errors


def sample_spacing(surface: Surface, samples: int = DEFAULT_SAMPLES) -> float:
    """Mean spacing √(area / samples) of :func:`sample_surface`'s points: distances measured
    against the samples are overestimated by up to about half of it."""
    return float(math.sqrt(_face_areas(surface).sum() / samples))


# --- files read back ----------------------------------------------------------------------------


def match_references(
    objects: Sequence[Node], chains: Sequence[LodChain], ref_name: str, out_name: str
) -> list[Surface]:
    """For each chain, the source object it was baked from, relative to the chain's origin.

    Objects are paired by id (a single object with a single chain in any case). Raises
    :class:`InputError` naming REF when an object is missing or its bounding box does not
    match the chain's (centre = origin and diagonal = α, within :data:`BOUNDS_TOLERANCE` α).
    """
    by_id = {obj.id: obj for obj in objects}
    surfaces = []
    for chain in chains:
        obj = by_id.get(chain.object_id)
        if obj is None and len(objects) == 1 and len(chains) == 1:
            obj = objects[0]
        if obj is None:
            raise InputError(f"has no object {chain.object_id!r}, which {out_name} holds", ref_name)
        lo, hi = obj.geometry.bounds
        shift = float(np.linalg.norm((lo + hi) / 2.0 - chain.origin)) / chain.alpha
        diagonal = float(np.linalg.norm(hi - lo))
        if shift > BOUNDS_TOLERANCE or abs(diagonal - chain.alpha) > BOUNDS_TOLERANCE * chain.alpha:
            raise InputError(
                f"does not match {out_name}: object {chain.object_id!r} is centred "
                f"{shift:.3g} diagonals away and {diagonal:.6g} across, against {chain.alpha:.6g} "
                f"in {out_name} (was it converted from this file?)",
                ref_name,
            )
        surfaces.append(obj.geometry.translated(-chain.origin))
    return surfaces


# --- reports ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Protocol:
    """How levels are scored: ``views`` Fibonacci directions, ``size`` × ``size`` renders at
    ``fov_y_deg``, at ``distances`` (multiples of α), and ``samples`` surface samples for the
    geometric error. Within each level's range the renders are ``range_size`` pixels high: by
    default those of the reference view the converter designs levels for (1080 px), so the
    declared point sizes are drawn as they are and 1-pixel points are one of its pixels."""

    views: int = DEFAULT_VIEWS
    size: int = DEFAULT_SIZE
    fov_y_deg: float = DEFAULT_FOV
    distances: tuple[float, ...] = DEFAULT_DISTANCES
    samples: int = DEFAULT_SAMPLES
    range_size: int = REFERENCE_VIEW.height_px


@dataclass
class LevelReport:
    """One level's silhouette scores, geometric error and its count as a fraction of the
    source's vertices."""

    scores: LevelScores
    error: GeometricError
    fraction: float


@dataclass
class ObjectReport:
    """Everything measured on one object: α, the source's vertex count, the mean spacing of
    the surface samples (fraction of α) and each level's report, finest first."""

    object_id: str
    alpha: float
    source_vertices: int
    sample_spacing: float
    levels: list[LevelReport]

    @property
    def mean_point_f(self) -> float | None:
        """Mean F over the point levels and the protocol distances (None without points)."""
        values = [s.f for lv in self.levels if lv.scores.kind == "pcd" for s in lv.scores.scores]
        return float(np.mean(values)) if values else None

    def to_json(self) -> dict[str, Any]:
        """A JSON-able dict of the report, with ``mean_point_f``."""
        return {**asdict(self), "mean_point_f": self.mean_point_f}


def evaluate_object(
    references: ReferenceRenders,
    chain: LodChain,
    protocol: Protocol,
    *,
    range_references: ReferenceRenders | None = None,
    levels: Sequence[int] | None = None,
) -> ObjectReport:
    """Silhouettes on ``protocol`` against ``references`` (and, given ``range_references``,
    within each level's range against those), geometric errors and counts of the levels of
    ``chain`` (all, or those indexed by ``levels``); the source is ``references.surface``,
    relative to the chain origin."""
    picked = list(range(len(chain.levels)) if levels is None else levels)
    scores = evaluate_chain(references, chain, protocol.distances, levels=picked)
    if range_references is not None:
        ranged = evaluate_chain(range_references, chain, (), levels=picked, in_range=True)
        for row, other in zip(scores, ranged, strict=True):
            row.in_range = other.in_range
    source = references.surface
    errors = geometric_errors(source, chain, protocol.samples, picked)
    total = len(source.vertices)
    return ObjectReport(
        object_id=chain.object_id,
        alpha=chain.alpha,
        source_vertices=total,
        sample_spacing=sample_spacing(source, protocol.samples) / chain.alpha,
        levels=[
            LevelReport(row, error, row.count / total)
            for row, error in zip(scores, errors, strict=True)
        ],
    )


# --- contact sheet ------------------------------------------------------------------------------


def _coloured(reference: np.ndarray, level: np.ndarray) -> np.ndarray:
    """RGB image (h, w, 3) uint8: both covered grey, level only red, reference only blue."""
    image = np.full((*reference.shape, 3), 255, dtype=np.uint8)
    image[reference & level] = SHEET_COLORS["both"]
    image[level & ~reference] = SHEET_COLORS["level only"]
    image[reference & ~level] = SHEET_COLORS["source only"]
    return image


def _crop_box(masks: list[np.ndarray], margin: int) -> tuple[int, int, int]:
    """A square (top, left, side) around everything covered in ``masks`` (each (views, h, w)),
    ``margin`` pixels wider on every side."""
    covered = np.any(np.stack(masks), axis=(0, 1))
    rows, cols = np.flatnonzero(covered.any(axis=1)), np.flatnonzero(covered.any(axis=0))
    if len(rows) == 0:
        return 0, 0, max(covered.shape)
    side = int(max(rows[-1] - rows[0], cols[-1] - cols[0])) + 1 + 2 * margin
    top = int((rows[0] + rows[-1]) // 2 - side // 2)
    left = int((cols[0] + cols[-1]) // 2 - side // 2)
    return top, left, side


def contact_sheet(
    renderer: SilhouetteRenderer,
    reference: Surface,
    chain: LodChain,
    diagonals: float = DEFAULT_DISTANCES[0],
    views: int = SHEET_VIEWS,
    tile: int = SHEET_TILE,
    view: ReferenceView = REFERENCE_VIEW,
) -> Image.Image:
    """The source and every level of ``chain`` side by side (columns) from ``views`` Fibonacci
    directions (rows), at ``diagonals`` α, as the metric sees them: each level's silhouette
    against the source's, both grey, level only red, source only blue. Tiles are the
    renderer's pixels around the object, enlarged (nearest neighbour) to ``tile`` pixels.
    Captions give each column's count and its F over the views shown."""
    directions = fibonacci_directions(views)
    distance = diagonals * chain.alpha
    center = np.asarray(chain.center, dtype=np.float64)
    geometry = renderer.mesh(reference.vertices, reference.faces)
    source = renderer.render(geometry, center, distance, directions)
    geometry.release()
    columns = [(f"source\n{len(reference.vertices):,} vertices", source)]
    for level in chain.levels:
        geometry = _level_geometry(renderer, level)
        size = declared_pixel_size(level, distance, renderer, view)
        masks = renderer.render(geometry, center, distance, directions, size or 1.0)
        geometry.release()
        f = silhouette_scores(source, masks)["f"]
        unit = "points" if level.is_points else "vertices"
        columns.append((f"{level.name} {level.count:,} {unit}\nF {f:.3f}", masks))
    top, left, side = _crop_box([masks for _, masks in columns], margin=4)
    font = ImageFont.load_default(size=SHEET_FONT_PX)
    caption = 3 * SHEET_FONT_PX
    sheet = Image.new("RGB", (tile * len(columns), caption + tile * views), "white")
    draw = ImageDraw.Draw(sheet)
    # Padded by one side all round, so the crop window never leaves the image.
    pad = ((0, 0), (side, side), (side, side))
    window = np.s_[top + side : top + 2 * side, left + side : left + 2 * side]
    source_window = np.pad(source, pad)[:, window[0], window[1]]
    for c, (text, masks) in enumerate(columns):
        draw.multiline_text((c * tile + 6, 4), text, fill="black", font=font, spacing=2)
        cropped = np.pad(masks, pad)[:, window[0], window[1]]
        for r in range(views):
            rgb = _coloured(source_window[r], cropped[r])
            image = Image.fromarray(rgb).resize((tile, tile), Image.Resampling.NEAREST)
            sheet.paste(image, (c * tile, caption + r * tile))
    return sheet


def legend(width: int, renderer: SilhouetteRenderer, diagonals: float) -> Image.Image:
    """A strip explaining a contact sheet's colours and scale."""
    font = ImageFont.load_default(size=SHEET_FONT_PX)
    strip = Image.new("RGB", (width, 2 * SHEET_FONT_PX + 8), "white")
    draw = ImageDraw.Draw(strip)
    x = 6
    for name, color in SHEET_COLORS.items():
        draw.rectangle((x, 6, x + SHEET_FONT_PX, 6 + SHEET_FONT_PX), fill=tuple(color))
        x += SHEET_FONT_PX + 4
        draw.text((x, 4), name, fill="black", font=font)
        x += int(draw.textlength(name, font=font)) + 16
    note = (
        f"{diagonals:g} diagonals away, {renderer.width} x {renderer.height} px at "
        f"{renderer.fov_y_deg:g}°, points at their declared size"
    )
    draw.text((x, 4), note, fill="black", font=font)
    return strip


def stack_images(images: Sequence[Image.Image]) -> Image.Image:
    """``images`` one below the other on white, left-aligned."""
    width = max(image.width for image in images)
    out = Image.new("RGB", (width, sum(image.height for image in images)), "white")
    y = 0
    for image in images:
        out.paste(image, (0, y))
        y += image.height
    return out
