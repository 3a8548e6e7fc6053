"""Geometry of the model: :class:`Surface` (one part: triangles with its own colours or
texture), :class:`Mesh` (the parts of one node or level, baked and measured as one) and
:class:`PointCloud` (a baked point level).

Coordinates are float64. No file format is known here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

import numpy as np

TRAVELLING = ("bounds", "block-footprint-")
"""Tables derived from a mesh that travel with it to another process (:meth:`Mesh.shipped`):
a few numbers each, one of them (a block footprint) slow to find; the others (per face and
vertex, several times the geometry's bytes) are found again where they are needed."""
GREY = np.array([204, 204, 204, 255], dtype=np.uint8)
WHITE = np.array([255, 255, 255, 255], dtype=np.uint8)


@dataclass
class Surface:
    """A triangle mesh with optional per-vertex colours, UVs + texture, and a base colour.

    ``vertices`` (n, 3) float64, ``faces`` (m, 3) int64. ``vertex_colors`` (n, 4) uint8 RGBA,
    ``uv`` (n, 2) float64 with ``texture`` (h, w, 4) uint8 RGBA, ``base_color`` (4,) uint8 or
    None when the source names none (then :attr:`material_color` picks a neutral one);
    ``photographic``: the texture is a photograph, which a lossy encoding suits (the source
    gave it so).
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_colors: np.ndarray | None = None
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    base_color: np.ndarray | None = None
    photographic: bool = False
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

    def translated(self, offset: np.ndarray) -> Surface:
        """This surface moved by ``offset`` (sharing colours, texture and UVs), its bounds
        moved along where they are known."""
        moved = replace(self, vertices=self.vertices + offset)
        _move_bounds(self._derived, moved._derived, offset)
        return moved

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

    def colors_at(
        self, face_ids: np.ndarray, points: np.ndarray | None, weights: np.ndarray | None = None
    ) -> np.ndarray:
        """RGBA uint8 (k, 4) of the surface at ``points`` lying on faces ``face_ids`` (their
        barycentric coordinates ``weights`` where already known, else found; ``points`` may be
        None where they are known).

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
        corners = self.faces[face_ids]
        if textured:
            if weights is None:
                assert points is not None
                weights = self.barycentric(face_ids, points)
            uv = np.einsum("ij,ijk->ik", weights, self.uv[corners])
            h, w = self.texture.shape[:2]
            x = np.floor((uv[:, 0] % 1.0) * w).astype(np.int64).clip(0, w - 1)
            y = np.floor((1.0 - (uv[:, 1] % 1.0)) * h).astype(np.int64).clip(0, h - 1)
            if (base == 255).all():  # white modulates nothing
                return self.texture[y, x]
            rgba = self.texture[y, x].astype(np.float64)
        else:
            rgba = _interpolated(self, face_ids, points, self.vertex_colors[corners], weights)
        rgba = rgba * (base.astype(np.float64) / 255.0)
        return np.clip(np.rint(rgba), 0, 255).astype(np.uint8)

    def face_colors(self, face_ids: np.ndarray) -> np.ndarray:
        """The mean RGBA uint8 (k, 4) of faces ``face_ids``: of a textured surface, the
        texture's over each face (:data:`FACE_SAMPLES` points spread evenly over it); else the
        colour at its centroid."""
        triangles = self.vertices[self.faces[face_ids]]
        if self.texture is None or self.uv is None or not len(face_ids):
            return self.colors_at(face_ids, triangles.mean(axis=1))
        points = np.einsum("sj,kjd->ksd", FACE_SAMPLES, triangles).reshape(-1, 3)
        seen = self.colors_at(np.repeat(face_ids, len(FACE_SAMPLES)), points)
        mean = seen.reshape(len(face_ids), len(FACE_SAMPLES), 4).mean(axis=1)
        return np.rint(mean).astype(np.uint8)

    def baked_colors(self) -> np.ndarray:
        """RGBA uint8 (n, 4) per vertex with the texture baked in: its vertex colours, else
        its material colour; a textured surface's vertex takes the texture's mean over a face
        that uses it (:meth:`face_colors`)."""
        if self.vertex_colors is not None:
            return self.vertex_colors
        colors = np.repeat(self.material_color[None], len(self.vertices), axis=0)
        if self.texture is not None and self.uv is not None and len(self.faces):
            means = self.face_colors(np.arange(len(self.faces)))
            for corner in range(3):
                colors[self.faces[:, corner]] = means
        return colors


def _face_samples(n: int) -> np.ndarray:
    """Barycentric coordinates (n², 3) of the centroids of the n² equal triangles that
    dividing a triangle's sides into ``n`` makes."""
    rows = []
    for a in range(n):
        for b in range(n - a):
            rows.append(((a + 1 / 3) / n, (b + 1 / 3) / n))
            if a + b < n - 1:
                rows.append(((a + 2 / 3) / n, (b + 2 / 3) / n))
    ab = np.array(rows)
    return np.column_stack([1.0 - ab.sum(axis=1), ab])


FACE_SAMPLES = _face_samples(4)
"""Where a face's mean texture colour is sampled: 16 points, each the centre of an equal
share of its area."""


def _interpolated(
    surface: Surface,
    face_ids: np.ndarray,
    points: np.ndarray | None,
    colors: np.ndarray,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """The colours (k, 4) float64 at ``points`` on faces ``face_ids`` of ``surface`` whose
    corners have ``colors`` ((k, 3, 4) uint8), interpolated across each face (by the points'
    barycentric coordinates ``weights`` where given, ``points`` then unused); a face whose
    corners share one colour has it, as interpolating gives it within a few ulps (which no
    rounding to bytes, after any base colour, can tell: a byte times a byte over 255 is never
    within 1/510 of a half)."""
    rgba = colors[:, 0].astype(np.float64)
    mixed = np.flatnonzero((colors != colors[:, :1]).any(axis=(1, 2)))
    if len(mixed):
        if weights is None:
            assert points is not None
            bary = surface.barycentric(face_ids[mixed], points[mixed])
        else:
            bary = weights[mixed]
        rgba[mixed] = np.einsum("ij,ijk->ik", bary, colors[mixed].astype(np.float64))
    return rgba


def _move_bounds(derived: dict[str, Any], moved: dict[str, Any], offset: np.ndarray) -> None:
    """Put the bounds in ``derived``, if any, moved by ``offset``, into ``moved``: rounding
    keeps the order of coordinates, so the moved vertices' extremes are the extremes moved."""
    if "bounds" in derived:
        moved["bounds"] = derived["bounds"] + offset


@dataclass
class PointCloud:
    """Baked points relative to the chain origin: positions (k, 3) float64, colors (k, 4) uint8,
    normals (k, 3) float32 unit vectors."""

    positions: np.ndarray
    colors: np.ndarray
    normals: np.ndarray

    def __len__(self) -> int:
        return len(self.positions)


def _parts_bounds(parts: Sequence[Surface]) -> np.ndarray:
    boxes = np.stack([part.bounds for part in parts])
    return np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])


class Mesh:
    """The triangle parts of one node or level, seen as one surface.

    Each part keeps its own colours, UVs and texture (a building's walls and roof, a model's
    materials); the baker, the planner and the evaluators see the concatenated ``vertices`` and
    ``faces``, and :meth:`colors_at` asks the part a face belongs to. A single-part mesh shares
    that part's arrays and derived tables.
    """

    def __init__(self, parts: Sequence[Surface]) -> None:
        if not parts:
            raise ValueError("a mesh needs at least one part")
        self.parts: tuple[Surface, ...] = tuple(parts)
        self._derived: dict[str, Any] = {}
        if len(self.parts) == 1:
            self._derived = self.parts[0]._derived

    @classmethod
    def of(cls, geometry: Mesh | Surface) -> Mesh:
        """``geometry`` as a mesh (a surface becomes a one-part mesh)."""
        return geometry if isinstance(geometry, Mesh) else cls([geometry])

    def derived(self, key: str, compute: Callable[[], Any]) -> Any:
        """``compute()`` once per mesh and key (see :meth:`Surface.derived`)."""
        if key not in self._derived:
            self._derived[key] = compute()
        return self._derived[key]

    @property
    def single(self) -> Surface | None:
        """The only part, or ``None`` when there are several."""
        return self.parts[0] if len(self.parts) == 1 else None

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float64 vertices of all parts, in part order."""
        if self.single is not None:
            return self.single.vertices
        return self.derived("vertices", lambda: np.concatenate([p.vertices for p in self.parts]))

    @property
    def faces(self) -> np.ndarray:
        """(m, 3) int64 faces of all parts, indexing :attr:`vertices`."""
        if self.single is not None:
            return self.single.faces
        return self.derived("faces", self._concatenated_faces)

    def _concatenated_faces(self) -> np.ndarray:
        offsets = np.cumsum([0] + [len(p.vertices) for p in self.parts[:-1]])
        return np.concatenate([p.faces + o for p, o in zip(self.parts, offsets, strict=True)])

    @property
    def vertex_colors(self) -> np.ndarray | None:
        """(n, 4) uint8 RGBA per vertex when a part has vertex colours (other parts give their
        material colour), else ``None``."""
        if all(p.vertex_colors is None for p in self.parts):
            return None
        return np.concatenate(
            [
                p.vertex_colors
                if p.vertex_colors is not None
                else np.repeat(p.material_color[None], len(p.vertices), axis=0)
                for p in self.parts
            ]
        )

    @property
    def face_part(self) -> np.ndarray:
        """(m,) index of the part each face belongs to."""
        return self.derived(
            "face-part",
            lambda: np.repeat(np.arange(len(self.parts)), [len(p.faces) for p in self.parts]),
        )

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) min and max corner of the vertices used by faces, over all parts."""
        if self.single is not None:
            return self.single.bounds
        return self.derived("bounds", lambda: _parts_bounds(self.parts))

    @property
    def triangles(self) -> np.ndarray:
        """Corner positions (m, 3, 3) of every face."""
        return self.derived("triangles", lambda: self.vertices[self.faces])

    @property
    def vertex_count(self) -> int:
        """Vertices over all parts."""
        return sum(len(p.vertices) for p in self.parts)

    @property
    def face_count(self) -> int:
        """Triangles over all parts."""
        return sum(len(p.faces) for p in self.parts)

    def face_normals(self, face_ids: np.ndarray) -> np.ndarray:
        """Unit normals (k, 3) float32 of the given faces; degenerate faces get +z."""
        if self.single is not None:
            return self.single.face_normals(face_ids)
        return Surface(self.vertices, self.faces).face_normals(face_ids)

    def colors_at(
        self, face_ids: np.ndarray, points: np.ndarray | None, weights: np.ndarray | None = None
    ) -> np.ndarray:
        """RGBA uint8 (k, 4) at ``points`` lying on faces ``face_ids`` (barycentric
        coordinates ``weights`` where known: then ``points`` may be None), each from its
        part."""
        if weights is None:
            return self._by_part(face_ids, points, Surface.colors_at)
        return self._by_part(
            face_ids, weights, lambda part, faces, at: part.colors_at(faces, None, at)
        )

    def baked_colors(self) -> np.ndarray:
        """RGBA uint8 (n, 4) per vertex of every part, textures baked in
        (:meth:`Surface.baked_colors`)."""
        return np.concatenate([part.baked_colors() for part in self.parts])

    def face_colors(self, face_ids: np.ndarray) -> np.ndarray:
        """The mean RGBA uint8 (k, 4) of faces ``face_ids`` (:meth:`Surface.face_colors`)."""
        return self._by_part(face_ids, None, lambda part, faces, _: part.face_colors(faces))

    def _by_part(
        self,
        face_ids: np.ndarray,
        points: np.ndarray | None,
        colors: Callable[[Surface, np.ndarray, Any], np.ndarray],
    ) -> np.ndarray:
        """``colors(part, faces, points)`` of each face's part, for faces ``face_ids``."""
        if self.single is not None:
            return colors(self.single, face_ids, points)
        out = np.zeros((len(face_ids), 4), dtype=np.uint8)
        if not len(face_ids):
            return out
        part_of = self.face_part[face_ids]
        if all(p.vertex_colors is None and p.texture is None for p in self.parts):
            return np.stack([p.material_color for p in self.parts])[part_of]  # plain colours
        first_face = np.cumsum([0] + [len(p.faces) for p in self.parts[:-1]])
        order = np.argsort(part_of, kind="stable")  # each part's faces together: one pass
        indices, starts = np.unique(part_of[order], return_index=True)
        for index, run in zip(indices, np.split(order, starts[1:]), strict=True):
            local = face_ids[run] - first_face[index]
            out[run] = colors(self.parts[index], local, None if points is None else points[run])
        return out

    def translated(self, offset: np.ndarray) -> Mesh:
        """This mesh moved by ``offset`` (new parts sharing colours, texture and UVs), its
        bounds moved along where they are known."""
        moved = Mesh([p.translated(offset) for p in self.parts])
        if self.single is None:
            _move_bounds(self._derived, moved._derived, offset)
        return moved

    def shipped(self) -> Mesh:
        """This mesh with parts sharing its arrays, keeping only the derived tables that
        :data:`TRAVELLING` names (what is pickled for another process)."""
        shipped = Mesh([_travelling(part, replace(part)) for part in self.parts])
        return _travelling(self, shipped)


T = TypeVar("T", Mesh, Surface)


def travelling_tables(source: Mesh | Surface) -> dict[str, Any]:
    """The tables derived from ``source`` that :data:`TRAVELLING` names."""
    return {k: v for k, v in source._derived.items() if k.startswith(TRAVELLING)}


def _travelling(source: T, copy: T) -> T:
    """``copy`` given the derived tables of ``source`` that :data:`TRAVELLING` names."""
    copy._derived.update(travelling_tables(source))
    return copy
