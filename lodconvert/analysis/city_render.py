"""A camera walking or flying through a city whose objects switch levels (and LOD parents),
frame by frame: what each frame draws, and how long it takes to draw it.

**The city** (:func:`city_draw`) is flattened from baked object chains
(:class:`~lodconvert.model.LodChain`, placed by their ``transform`` where they have one) and LOD
parents (:class:`~lodconvert.model.CellChain`, every tier) into arrays in *scene coordinates*:
metres relative to one float64 ``origin`` near the city's middle. Every level part — one
surface of a mesh level, or one point level — is a *draw part*: one draw call, as a viewer
issues one per Shape or glTF primitive. Each object has a switching centre (``origin +
center``), a bounding sphere (radius α/2, α the diagonal of its finest level's box), the
axis-aligned box of its finest level, and its cutoffs; each cell its centre, sphere (α/2 of its
members' box), switch distance (``cutoffs[0]``), cull distance (``cutoffs[1]``, if any) and
far level.

**Selection** (:func:`select`), per frame and :class:`Mode`:

- *range switching* (X3D ``LOD``): level ``i`` = how many cutoffs the viewer's distance to the
  switching centre has reached (:func:`range_levels`);
- *prism switching* (ProxyPrismLOD's nested ProximitySensors): level ``i`` = how many of the
  boxes — the finest level's box grown by each cutoff on every side — do not contain the viewer
  (:func:`prism_levels`): the level of the smallest box that does. A box holds the sphere of
  the same cutoff around its centre (a baked chain's switching centre), so prisms never pick a
  coarser level than ranges;
- beyond a culled chain's last cutoff nothing is drawn; without LOD every object draws its
  finest level;
- *frustum culling*: objects (and cells) whose bounding sphere lies wholly outside the view
  frustum are skipped;
- *LOD parents*: cells are resolved from the coarsest tier used down. A cell in the frustum whose
  centre is at least its switch distance away draws its far level **instead of** its members;
  nearer, it opens and its members (finer cells, or objects with their own levels and culling)
  are resolved in turn; a cell outside the frustum is culled with everything in it. With
  ``tiers = 1`` only the finest tier's cells are used (a coarser tier is ignored).
- the *LOD scale* ``s`` (:func:`lod_scale`) multiplies every cutoff, objects' and cells'.

**Cameras** (:class:`Camera`) look along a heading, pitched down by ``pitch`` degrees, on a
1920×1080 framebuffer (:data:`~.bench.WIDTH` × :data:`~.bench.HEIGHT`) with the near plane at
:data:`NEAR` metres and the far plane just beyond the city. Walks (:func:`walk_cameras`) move
at a fixed speed sampled every simulated frame step, so the positions — and every count — do
not depend on the machine; flights (:func:`flight_cameras`) cross a rectangle at one altitude.

**Drawing and timing** (:class:`CityRenderer`, a :class:`~.bench.GridRenderer`): all parts are
uploaded once into one vertex, colour and index buffer for triangles and one for points, in
scene coordinates (float32: millimetres over kilometres); a frame clears and issues one draw
call per selected part (triangles first, then points sized as their level declares, see
:func:`~.render.point_pixel_size`), clocked from a finished pipeline to ``ctx.finish()``. The
selection itself (numpy, over all objects at once) is not in the frame time.
:func:`walk` runs a list of cameras through several modes, interleaved frame by frame (the mode
order turns by one each frame, so drifts of a shared machine fall on every mode alike), and
gathers per mode the counts and, with a renderer, the frame times (:class:`PathStats`).
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..model import CellChain, Level, LodChain
from ..ranges import REFERENCE_VIEW, ReferenceView
from .bench import HEIGHT, WIDTH, GridRenderer, frustum_planes, spheres_in_frustum
from .render import look_at, perspective

if TYPE_CHECKING:
    import moderngl

NEAR = 1.0
"""Near plane of every camera, metres."""
MAX_LOS = 20_000.0
"""Line-of-sight distance counted for a ray that meets the ground farther away, or not at all
(at or above the horizon), metres."""
REFERENCE_ALTITUDE = 300.0
"""Altitude (m) at which :func:`lod_scale` is 1 for the reference pitch and field of view."""
REFERENCE_PITCH_DEG = 45.0
"""Pitch below the horizontal of the reference view of :func:`lod_scale`."""
REFERENCE_FOV_DEG = REFERENCE_VIEW.fov_y_deg
"""Vertical field of view of the reference view of :func:`lod_scale` (the ranges' 45°)."""
SWITCHINGS = ("range", "prism")


# --- line-of-sight LOD scale --------------------------------------------------------------------


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


# --- level selection ----------------------------------------------------------------------------


def range_levels(distances: np.ndarray, cutoffs: np.ndarray) -> np.ndarray:
    """Level index (N,) per object: how many of its cutoffs (N, K; padded with +inf) its
    viewer ``distances`` (N,) have reached (X3D ``LOD``)."""
    return (np.asarray(distances)[:, None] >= cutoffs).sum(axis=1)


def prism_levels(eye: np.ndarray, boxes: np.ndarray, cutoffs: np.ndarray) -> np.ndarray:
    """Level index (N,) per object: how many of its boxes — its box (N, 2, 3) grown by each
    cutoff (N, K; padded with +inf) on every side — leave the viewer at ``eye`` outside."""
    centre = boxes.mean(axis=1)
    half = (boxes[:, 1] - boxes[:, 0]) / 2.0
    outside = (np.abs(np.asarray(eye) - centre) - half).max(axis=1)
    return (outside[:, None] >= cutoffs).sum(axis=1)


@dataclass(frozen=True)
class Mode:
    """How a frame selects what it draws: frustum ``culling``, per-object levels (``lod``,
    else every object's finest level) switched by ``switching`` ("range" or "prism"), LOD
    parents of the finest ``tiers`` tiers (0: none), and whether cutoffs are multiplied by the
    LOD scale (``los_scale``)."""

    name: str
    culling: bool = True
    lod: bool = True
    switching: str = "range"
    tiers: int = 0
    los_scale: bool = False

    def __post_init__(self) -> None:
        if self.switching not in SWITCHINGS:
            raise ValueError(f"switching must be one of {SWITCHINGS}, got {self.switching!r}")


# --- the city as arrays -------------------------------------------------------------------------


@dataclass
class Geometry:
    """Every draw part packed for upload (scene coordinates, float32) and its table: the first
    index (triangles) or point, the GL count, vertices or points drawn, whether it is points,
    and a point level's declared size and design distance."""

    triangle_positions: np.ndarray
    triangle_colors: np.ndarray
    triangle_indices: np.ndarray
    point_positions: np.ndarray
    point_colors: np.ndarray
    first: np.ndarray
    count: np.ndarray
    size: np.ndarray
    points: np.ndarray
    point_size: np.ndarray
    design_distance: np.ndarray


@dataclass
class CityDraw:
    """A city flattened for selection and drawing (module docstring); positions are relative to
    ``origin``. Objects: ``centres`` (N, 3), ``radii`` (N,), finest-level ``boxes`` (N, 2, 3),
    ``cutoffs`` (N, K, +inf padded), ``level_first`` and ``level_parts`` (N, L: first draw part
    and part count of each level, 0 parts past the last), ``object_cell`` (N, finest-tier cell
    or -1). Cells: ``cell_centres``, ``cell_radii``, ``cell_cutoffs`` (C, 2: switch, cull or
    +inf), ``cell_far`` (draw part), ``cell_parent`` (-1 for the coarsest), ``cell_tier`` and
    ``cell_f`` (silhouette F of the far level at its switch-in distance), ``cell_ids``."""

    origin: np.ndarray
    geometry: Geometry
    centres: np.ndarray
    radii: np.ndarray
    boxes: np.ndarray
    cutoffs: np.ndarray
    level_first: np.ndarray
    level_parts: np.ndarray
    object_cell: np.ndarray
    cell_centres: np.ndarray
    cell_radii: np.ndarray
    cell_cutoffs: np.ndarray
    cell_far: np.ndarray
    cell_parent: np.ndarray
    cell_tier: np.ndarray
    cell_f: np.ndarray
    cell_ids: list[str]

    @property
    def objects(self) -> int:
        """Objects in the city."""
        return len(self.centres)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) box of every object's box, scene coordinates."""
        return np.stack([self.boxes[:, 0].min(axis=0), self.boxes[:, 1].max(axis=0)])

    def far_plane(self, eye: np.ndarray) -> float:
        """A far-plane distance beyond every object seen from ``eye``."""
        low, high = self.bounds
        return float(np.linalg.norm(np.maximum(np.abs(eye - low), np.abs(high - eye)))) + NEAR


def scene_points(chain: LodChain | CellChain, local: np.ndarray) -> np.ndarray:
    """World positions (n, 3) of points ``local`` of ``chain``'s frame (relative to its origin,
    then placed by its ``transform`` when it has one)."""
    world = np.asarray(local, dtype=np.float64) + chain.origin
    transform = getattr(chain, "transform", None)
    if transform is None:
        return world
    matrix = np.asarray(transform, dtype=np.float64)
    return world @ matrix[:3, :3].T + matrix[:3, 3]


class _Packer:
    """Collects draw parts into the arrays of a :class:`Geometry`."""

    def __init__(self, origin: np.ndarray) -> None:
        self.origin = origin
        self.arrays: dict[str, list[np.ndarray]] = {
            k: [] for k in ("tri_pos", "tri_col", "tri_idx", "pt_pos", "pt_col")
        }
        self.vertices = self.indices = self.point_count = 0
        self.table: list[tuple[int, int, int, bool, float, float]] = []

    def level(self, chain: LodChain | CellChain, level: Level) -> tuple[int, int, np.ndarray]:
        """Pack ``level`` of ``chain``: its first part, its part count and its box (2, 3)."""
        start = len(self.table)
        placed: list[np.ndarray] = []
        if level.points is not None:
            cloud = level.points
            positions = scene_points(chain, cloud.positions) - self.origin
            self.arrays["pt_pos"].append(positions.astype(np.float32))
            self.arrays["pt_col"].append(np.asarray(cloud.colors, dtype=np.uint8))
            size = level.params.point_size if level.params is not None else 1.0
            design = level.design_distance or 0.0
            self.table.append((self.point_count, len(cloud), len(cloud), True, size, design))
            self.point_count += len(cloud)
            placed.append(positions)
        else:
            assert level.mesh is not None
            for part in level.mesh.parts:
                positions = scene_points(chain, part.vertices) - self.origin
                colors = part.vertex_colors
                if colors is None:
                    colors = np.repeat(part.material_color[None], len(positions), axis=0)
                faces = np.asarray(part.faces, dtype=np.int64) + self.vertices
                self.arrays["tri_pos"].append(positions.astype(np.float32))
                self.arrays["tri_col"].append(np.asarray(colors, dtype=np.uint8))
                self.arrays["tri_idx"].append(faces.astype(np.uint32).ravel())
                self.table.append((self.indices, faces.size, len(positions), False, 1.0, 0.0))
                self.indices += faces.size
                self.vertices += len(positions)
                placed.append(positions)
        every = np.concatenate(placed)
        return start, len(self.table) - start, np.stack([every.min(axis=0), every.max(axis=0)])

    def geometry(self) -> Geometry:
        """The packed arrays and the part table."""

        def joined(key: str, shape: tuple[int, ...], dtype: type) -> np.ndarray:
            found = self.arrays[key]
            return np.concatenate(found) if found else np.zeros(shape, dtype=dtype)

        table = np.array(self.table, dtype=np.float64).reshape(-1, 6)
        return Geometry(
            triangle_positions=joined("tri_pos", (0, 3), np.float32),
            triangle_colors=joined("tri_col", (0, 4), np.uint8),
            triangle_indices=joined("tri_idx", (0,), np.uint32),
            point_positions=joined("pt_pos", (0, 3), np.float32),
            point_colors=joined("pt_col", (0, 4), np.uint8),
            first=table[:, 0].astype(np.int64),
            count=table[:, 1].astype(np.int64),
            size=table[:, 2].astype(np.int64),
            points=table[:, 3].astype(bool),
            point_size=table[:, 4],
            design_distance=table[:, 5],
        )


def _flatten(
    items: Iterable[LodChain | CellChain],
) -> tuple[list[LodChain], list[int], list[CellChain], list[int]]:
    """Objects with their finest-tier cell index (-1: none), and cells (coarsest first) with
    their parent index (-1: a coarsest cell)."""
    objects: list[LodChain] = []
    object_cell: list[int] = []
    cells: list[CellChain] = []
    parents: list[int] = []

    def add(cell: CellChain, parent: int) -> None:
        index = len(cells)
        cells.append(cell)
        parents.append(parent)
        for member in cell.members:
            if isinstance(member, CellChain):
                add(member, index)
            else:
                objects.append(member)
                object_cell.append(index)

    for item in items:
        if isinstance(item, CellChain):
            add(item, -1)
        else:
            objects.append(item)
            object_cell.append(-1)
    return objects, object_cell, cells, parents


def _padded(rows: Sequence[Sequence[float]], width: int, fill: float) -> np.ndarray:
    out = np.full((len(rows), width), fill, dtype=np.float64)
    for i, row in enumerate(rows):
        out[i, : len(row)] = row
    return out


def _centre(chain: LodChain | CellChain) -> np.ndarray:
    return scene_points(chain, np.asarray(chain.center, dtype=np.float64)[None])[0]


def city_draw(items: Iterable[LodChain | CellChain]) -> CityDraw:
    """Flatten object chains and LOD parents (as :func:`~lodconvert.bakery.iter_chains`
    yields them) into a :class:`CityDraw`. Raises :class:`ValueError` for a city without
    objects."""
    objects, object_cell, cells, parents = _flatten(items)
    if not objects:
        raise ValueError("the city has no objects")
    world = np.array([_centre(chain) for chain in objects])
    origin = np.round((world.min(axis=0) + world.max(axis=0)) / 2.0)
    packer = _Packer(origin)
    levels = max(len(chain.levels) for chain in objects)
    level_first = np.zeros((len(objects), levels), dtype=np.int64)
    level_parts = np.zeros((len(objects), levels), dtype=np.int64)
    boxes = np.zeros((len(objects), 2, 3))
    for i, chain in enumerate(objects):
        for j, level in enumerate(chain.levels):
            level_first[i, j], level_parts[i, j], box = packer.level(chain, level)
            if j == 0:
                boxes[i] = box
    far = [packer.level(cell, cell.far)[0] for cell in cells]
    width = max(len(chain.cutoffs) for chain in objects)
    cell_centres = np.array([_centre(cell) for cell in cells]).reshape(-1, 3) - origin
    return CityDraw(
        origin=origin,
        geometry=packer.geometry(),
        centres=world - origin,
        radii=np.array([chain.alpha / 2.0 for chain in objects]),
        boxes=boxes,
        cutoffs=_padded([chain.cutoffs for chain in objects], max(width, 1), math.inf),
        level_first=level_first,
        level_parts=level_parts,
        object_cell=np.array(object_cell, dtype=np.int64),
        cell_centres=cell_centres,
        cell_radii=np.array([cell.alpha / 2.0 for cell in cells]),
        cell_cutoffs=_padded([cell.cutoffs[:2] for cell in cells], 2, math.inf),
        cell_far=np.array(far, dtype=np.int64),
        cell_parent=np.array(parents, dtype=np.int64),
        cell_tier=np.array([cell.tier for cell in cells], dtype=np.int64),
        cell_f=np.array([far_level_f(cell) for cell in cells]),
        cell_ids=[cell.cell_id for cell in cells],
    )


def far_level_f(cell: CellChain) -> float:
    """Silhouette F of ``cell``'s far level against its members at its switch-in distance, as
    the planner measured it (``facts["silhouette_f"]`` of ``facts["kind"]``; NaN if unknown)."""
    scores = cell.facts.get("silhouette_f", {})
    return float(scores.get(cell.facts.get("kind"), math.nan))


# --- cameras ------------------------------------------------------------------------------------


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


# --- one frame ----------------------------------------------------------------------------------


@dataclass
class Selection:
    """What one frame draws: its draw parts and the cells shown as their far level."""

    parts: np.ndarray
    far_cells: np.ndarray

    def vertices(self, city: CityDraw) -> int:
        """Vertices (mesh parts) plus points (point parts) submitted."""
        return int(city.geometry.size[self.parts].sum())

    @property
    def calls(self) -> int:
        """Draw calls: one per part."""
        return len(self.parts)


def _ranges(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """``starts[i] + k`` for k < ``counts[i]``, every i, concatenated."""
    total = int(counts.sum())
    before = np.cumsum(counts) - counts
    return np.repeat(starts - before, counts) + np.arange(total, dtype=np.int64)


def _open_cells(
    city: CityDraw, eye: np.ndarray, planes: np.ndarray | None, mode: Mode, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which cells open (members resolved) and which show their far level, tier by tier from
    the coarsest used down."""
    used = (city.cell_tier <= mode.tiers) & (mode.tiers > 0)
    shown = np.ones(len(city.cell_tier), dtype=bool)
    if planes is not None and len(shown):
        shown = spheres_in_frustum(city.cell_centres, city.cell_radii[:, None], planes)
    distance = np.linalg.norm(city.cell_centres - eye, axis=1) / scale
    far = distance >= city.cell_cutoffs[:, 0]
    gone = distance >= city.cell_cutoffs[:, 1]
    has_parent = city.cell_parent >= 0
    parent = np.where(has_parent, city.cell_parent, 0)
    opened = np.zeros(len(shown), dtype=bool)
    far_shown = np.zeros(len(shown), dtype=bool)
    for tier in range(mode.tiers, 0, -1):
        top = ~has_parent | ~used[parent]
        active = used & (city.cell_tier == tier) & (top | opened[parent])
        far_shown |= active & shown & far & ~gone
        opened |= active & shown & ~far
    return opened, far_shown


def select(city: CityDraw, camera: Camera, mode: Mode, scale: float = 1.0) -> Selection:
    """The draw parts of one frame seen by ``camera`` in ``mode``, cutoffs times ``scale``
    (module docstring)."""
    eye = np.asarray(camera.eye, dtype=np.float64)
    planes = frustum_planes(camera.view_proj(city.far_plane(eye))) if mode.culling else None
    opened, far_shown = _open_cells(city, eye, planes, mode, scale)
    candidates = np.arange(city.objects)
    if mode.tiers > 0:
        cell = np.maximum(city.object_cell, 0)
        # an object in no cell, or held directly by a tier above those in use, draws alone
        alone = (city.object_cell < 0) | (city.cell_tier[cell] > mode.tiers)
        candidates = candidates[alone | opened[cell]]
    if planes is not None:
        inside = spheres_in_frustum(city.centres[candidates], city.radii[candidates, None], planes)
        candidates = candidates[inside]
    cutoffs = city.cutoffs[candidates] * scale
    if not mode.lod:
        levels = np.zeros(len(candidates), dtype=np.int64)
    elif mode.switching == "prism":
        levels = prism_levels(eye, city.boxes[candidates], cutoffs)
    else:
        levels = range_levels(np.linalg.norm(city.centres[candidates] - eye, axis=1), cutoffs)
    drawn = levels < city.level_parts.shape[1]
    candidates, levels = candidates[drawn], levels[drawn]
    parts = _ranges(city.level_first[candidates, levels], city.level_parts[candidates, levels])
    far_cells = np.flatnonzero(far_shown)
    return Selection(np.concatenate([parts, city.cell_far[far_cells]]), far_cells)


# --- drawing ------------------------------------------------------------------------------------


class CityRenderer(GridRenderer):
    """Draws a :class:`CityDraw`'s selected parts, one draw call each, on the 1920×1080
    framebuffer of a :class:`~.bench.GridRenderer` (its program, unlit vertex colours, depth
    test, no face culling). Raises :class:`~lodconvert.errors.LodConvertError` when no EGL
    OpenGL 3.3 context can be made."""

    def __init__(self) -> None:
        super().__init__()
        self.city: CityDraw | None = None
        self._objects: list[Any] = []
        self._triangles: moderngl.VertexArray | None = None
        self._points: moderngl.VertexArray | None = None

    def load(self, city: CityDraw) -> None:
        """Upload ``city``'s geometry (freeing the previous city's)."""
        self.unload()
        g = city.geometry
        offset = self._buffer(np.zeros(3, dtype=np.float32))
        if len(g.triangle_indices):
            self._triangles = self._vertex_array(
                g.triangle_positions, g.triangle_colors, offset, g.triangle_indices
            )
        if len(g.point_positions):
            self._points = self._vertex_array(g.point_positions, g.point_colors, offset)
        self.city = city

    def unload(self) -> None:
        """Free the loaded city's buffers."""
        for gl_object in reversed(self._objects):
            gl_object.release()
        self._objects, self._triangles, self._points, self.city = [], None, None, None

    def _buffer(self, array: np.ndarray) -> moderngl.Buffer:
        buffer = self.ctx.buffer(np.ascontiguousarray(array).tobytes())
        self._objects.append(buffer)
        return buffer

    def _vertex_array(
        self,
        positions: np.ndarray,
        colors: np.ndarray,
        offset: moderngl.Buffer,
        indices: np.ndarray | None = None,
    ) -> moderngl.VertexArray:
        content = [
            (self._buffer(positions), "3f", "in_pos"),
            (self._buffer(colors), "4f1", "in_color"),
            (offset, "3f/i", "in_offset"),
        ]
        index = self._buffer(indices) if indices is not None else None
        vao = self.ctx.vertex_array(self.program, content, index_buffer=index, index_element_size=4)
        self._objects.append(vao)
        return vao

    def draw(self, selection: Selection, camera: Camera) -> float:
        """Clear and draw ``selection`` as ``camera`` sees it; the frame's seconds."""
        city = self.city
        if city is None:
            raise RuntimeError("no city loaded")
        g = city.geometry
        view_proj = camera.view_proj(city.far_plane(camera.eye))
        self.program["view_proj"].write(view_proj.T.astype(np.float32).tobytes())
        self.program["eye"].value = tuple(float(v) for v in camera.eye)
        self.program["max_point_size"].value = self.max_point_size
        parts = np.sort(selection.parts)
        points = g.points[parts]
        triangles, clouds = parts[~points], parts[points]
        self.ctx.finish()
        start = time.perf_counter()
        self.fbo.use()
        self.fbo.clear(0.6, 0.7, 0.8, 1.0)
        if self._triangles is not None and len(triangles):
            self.program["point_size"].value = 1.0
            self.program["design_distance"].value = 0.0
            render = self._triangles.render
            firsts, counts = g.first[triangles].tolist(), g.count[triangles].tolist()
            for first, count in zip(firsts, counts, strict=True):
                render(self.ctx.TRIANGLES, vertices=count, first=first, instances=1)
        if self._points is not None:
            for part in clouds.tolist():
                self.program["point_size"].value = float(g.point_size[part]) * camera.view_scale
                self.program["design_distance"].value = float(g.design_distance[part])
                self._points.render(
                    self.ctx.POINTS, vertices=int(g.count[part]), first=int(g.first[part]),
                    instances=1,
                )  # fmt: skip
        self.ctx.finish()
        return time.perf_counter() - start

    def release(self) -> None:
        """Free the city's buffers and the context."""
        self.unload()
        super().release()


# --- paths --------------------------------------------------------------------------------------


@dataclass
class PathStats:
    """One mode along one path: per frame the vertices + points and draw calls submitted, the
    frame times (with a renderer), and every cell shown as its far level at least once."""

    vertices: list[int] = field(default_factory=list)
    calls: list[int] = field(default_factory=list)
    frame_seconds: list[float] = field(default_factory=list)
    far_cells: set[int] = field(default_factory=set)

    @property
    def median_ms(self) -> float | None:
        """Median frame time in ms (None when not timed)."""
        return 1e3 * statistics.median(self.frame_seconds) if self.frame_seconds else None

    @property
    def low_ms(self) -> float | None:
        """The "5 % low" frame time in ms: the 95th percentile, which 5 % of frames exceed
        (the 5th percentile of the frame rate); None when not timed."""
        if not self.frame_seconds:
            return None
        return 1e3 * float(np.percentile(self.frame_seconds, 95))

    def record(self) -> dict[str, Any]:
        """Medians and maxima of the counts, the frame-time figures (JSON-able)."""
        return {
            "frames": len(self.calls),
            "vertices_median": statistics.median(self.vertices),
            "vertices_max": max(self.vertices),
            "calls_median": statistics.median(self.calls),
            "calls_max": max(self.calls),
            "median_ms": self.median_ms,
            "low_ms": self.low_ms,
        }


def walk(
    city: CityDraw,
    cameras: Sequence[Camera],
    modes: Sequence[Mode],
    scale: float = 1.0,
    renderer: CityRenderer | None = None,
) -> dict[str, PathStats]:
    """Every camera of a path in every mode (cutoffs times ``scale`` where the mode asks for
    the LOD scale), modes interleaved frame by frame with their order turning; with a
    ``renderer`` (``city`` loaded in it) each frame is drawn and timed after one untimed frame
    per mode. Returns the statistics per mode name."""
    stats = {mode.name: PathStats() for mode in modes}
    if renderer is not None and cameras:
        for mode in modes:
            renderer.draw(select(city, cameras[0], mode, _scale(mode, scale)), cameras[0])
    for k, camera in enumerate(cameras):
        turn = k % len(modes)
        for mode in [*modes[turn:], *modes[:turn]]:
            selection = select(city, camera, mode, _scale(mode, scale))
            entry = stats[mode.name]
            entry.vertices.append(selection.vertices(city))
            entry.calls.append(selection.calls)
            entry.far_cells.update(selection.far_cells.tolist())
            if renderer is not None:
                entry.frame_seconds.append(renderer.draw(selection, camera))
    return stats


def _scale(mode: Mode, scale: float) -> float:
    return scale if mode.los_scale else 1.0
