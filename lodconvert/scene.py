"""The data model: Scene → SceneObject → LodChain → Level.

Readers yield :class:`SceneObject` s whose :class:`Surface` is in world coordinates (float64,
instance transforms already applied, georeferenced values kept as they are). Baking turns each
object into a :class:`LodChain` whose levels are stored relative to ``chain.origin`` (the
bounding-box centre) so that float32 output buffers keep their precision; writers put the origin
back as a parent transform / node translation.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

GREY = np.array([204, 204, 204, 255], dtype=np.uint8)
WHITE = np.array([255, 255, 255, 255], dtype=np.uint8)


@dataclass
class Surface:
    """A triangle mesh with optional per-vertex colours, UVs + texture, and a base colour.

    ``vertices`` (n, 3) float64, ``faces`` (m, 3) int64. ``vertex_colors`` (n, 4) uint8 RGBA,
    ``uv`` (n, 2) float64 with ``texture`` (h, w, 4) uint8 RGBA, ``base_color`` (4,) uint8 or
    None when the source names none (then :attr:`material_color` picks a neutral one).
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_colors: np.ndarray | None = None
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    base_color: np.ndarray | None = None
    # Arrays derived from the geometry (bounds, per-face tables), computed once per Surface.
    # Not an init field, so ``dataclasses.replace`` starts a fresh cache for new geometry.
    _derived: dict[str, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def derived(self, key: str, compute: Callable[[], Any]) -> Any:
        """``compute()`` once per surface and key; later calls return the stored value.
        The geometry arrays must not be modified in place after the first call."""
        if key not in self._derived:
            self._derived[key] = compute()
        return self._derived[key]

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) array: min and max corner of the vertices used by faces."""

        def compute() -> np.ndarray:
            used = np.zeros(len(self.vertices), dtype=bool)
            used[self.faces.ravel()] = True
            v = self.vertices[used] if used.any() else self.vertices
            return np.stack([v.min(axis=0), v.max(axis=0)])

        return self.derived("bounds", compute)

    @property
    def triangles(self) -> np.ndarray:
        """Corner positions (m, 3, 3) of every face."""
        return self.derived("triangles", lambda: self.vertices[self.faces])

    @property
    def material_color(self) -> np.ndarray:
        """The base colour in effect: the source's, else white under vertex colours or a
        texture (which then carry the colour), else light grey."""
        if self.base_color is not None:
            return self.base_color
        return WHITE if self.vertex_colors is not None or self.texture is not None else GREY

    def face_normals(self, face_ids: np.ndarray) -> np.ndarray:
        """Unit normals (k, 3) float32 of the given faces; degenerate faces get +z."""
        tri = self.vertices[self.faces[face_ids]]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(n, axis=1)
        ok = length > 0
        n[ok] /= length[ok, None]
        n[~ok] = (0.0, 0.0, 1.0)
        return n.astype(np.float32)

    def barycentric(self, face_ids: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Barycentric coordinates (k, 3) of ``points`` projected onto their faces' planes,
        clipped into the triangle so that colours never extrapolate."""
        tri = self.vertices[self.faces[face_ids]]
        v0 = tri[:, 1] - tri[:, 0]
        v1 = tri[:, 2] - tri[:, 0]
        v2 = points - tri[:, 0]
        d00 = np.einsum("ij,ij->i", v0, v0)
        d01 = np.einsum("ij,ij->i", v0, v1)
        d11 = np.einsum("ij,ij->i", v1, v1)
        d20 = np.einsum("ij,ij->i", v2, v0)
        d21 = np.einsum("ij,ij->i", v2, v1)
        denom = d00 * d11 - d01 * d01
        safe = np.where(np.abs(denom) > 0, denom, 1.0)
        b1 = np.where(np.abs(denom) > 0, (d11 * d20 - d01 * d21) / safe, 1 / 3)
        b2 = np.where(np.abs(denom) > 0, (d00 * d21 - d01 * d20) / safe, 1 / 3)
        bary = np.stack([1.0 - b1 - b2, b1, b2], axis=1)
        bary = np.clip(bary, 0.0, 1.0)
        return bary / bary.sum(axis=1, keepdims=True)

    def colors_at(self, face_ids: np.ndarray, points: np.ndarray) -> np.ndarray:
        """RGBA uint8 (k, 4) of the surface at ``points`` lying on faces ``face_ids``.

        Texture colours (nearest texel, UV wrapped) win over vertex colours, which win over the
        base colour; texture and vertex colours are modulated by the base colour as in glTF.
        """
        k = len(face_ids)
        if k == 0:
            return np.zeros((0, 4), dtype=np.uint8)
        base = self.material_color
        textured = self.texture is not None and self.uv is not None
        if not textured and self.vertex_colors is None:
            return np.repeat(base[None, :], k, axis=0)
        bary = self.barycentric(face_ids, points)
        corners = self.faces[face_ids]
        if textured:
            uv = np.einsum("ij,ijk->ik", bary, self.uv[corners])
            h, w = self.texture.shape[:2]
            x = np.floor((uv[:, 0] % 1.0) * w).astype(np.int64).clip(0, w - 1)
            y = np.floor((1.0 - (uv[:, 1] % 1.0)) * h).astype(np.int64).clip(0, h - 1)
            rgba = self.texture[y, x].astype(np.float64)
        else:
            rgba = np.einsum("ij,ijk->ik", bary, self.vertex_colors[corners].astype(np.float64))
        rgba = rgba * (base.astype(np.float64) / 255.0)
        return np.clip(np.rint(rgba), 0, 255).astype(np.uint8)


@dataclass
class SceneObject:
    """One object of a scene: a surface in world coordinates plus identity and metadata."""

    id: str
    surface: Surface
    metadata: dict[str, Any] = field(default_factory=dict)


@dataclass
class Scene:
    """What a reader produced: objects plus scene-wide facts (source, CRS, units)."""

    source: str
    objects: list[SceneObject] = field(default_factory=list)
    crs: str | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __iter__(self) -> Iterator[SceneObject]:
        return iter(self.objects)


@dataclass
class PointCloud:
    """Baked points relative to the chain origin: positions (k, 3) float64, colors (k, 4) uint8,
    normals (k, 3) float32 unit vectors."""

    positions: np.ndarray
    colors: np.ndarray
    normals: np.ndarray

    def __len__(self) -> int:
        return len(self.positions)


@dataclass(frozen=True)
class BakeParams:
    """The paper's per-level parameters: T3 resolution (cells along the longest side), T1 slices
    (slabs along the longest side), T2 point size in pixels at the level's switch-in distance at
    the reference view, and the hole filter."""

    resolution: int
    slices: int
    point_size: float
    filter: Literal["median", "gaussian", "none"] = "median"


@dataclass
class Level:
    """One level of a chain. ``kind`` is "mesh" (``mesh`` set) or "pcd" (``points`` set).

    ``spacing`` is the grid pitch of a point level in scene units; ``design_distance`` the
    distance (from the chain centre) its resolution and point size were chosen for: where it
    first shows, or α·β for a baked finest level. At that distance, at the reference view, its
    points are ``params.point_size`` pixels wide; viewers scale them with 1/distance.
    ``bake_seconds`` is the time spent baking it. Geometry is relative to the chain's origin.
    """

    name: str
    kind: Literal["mesh", "pcd"]
    mesh: Surface | None = None
    points: PointCloud | None = None
    params: BakeParams | None = None
    spacing: float | None = None
    design_distance: float | None = None
    bake_seconds: float = 0.0

    @property
    def count(self) -> int:
        """Vertices of a mesh level, points of a point level."""
        if self.kind == "mesh":
            assert self.mesh is not None
            return len(self.mesh.vertices)
        assert self.points is not None
        return len(self.points)


@dataclass
class LodChain:
    """All levels of one object, finest first, and the distances at which they switch.

    ``cutoffs[i]`` is the distance (scene units, from ``center``) beyond which ``levels[i+1]``
    replaces ``levels[i]``. With culling, ``len(cutoffs) == len(levels)`` and the last cutoff is
    where the object disappears; otherwise ``len(cutoffs) == len(levels) - 1``.
    ``origin`` is the world position that level geometry is relative to; ``center`` the
    bounding-box centre relative to that origin (zero unless a writer re-bases it).
    """

    object_id: str
    levels: list[Level]
    cutoffs: list[float]
    origin: np.ndarray
    center: np.ndarray
    alpha: float
    beta: float
    gamma: float
    xs: list[float]
    culled: bool = False
    metadata: dict[str, Any] = field(default_factory=dict)
