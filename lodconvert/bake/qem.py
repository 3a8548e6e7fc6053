"""Quadric edge-collapse decimation (``fast-simplification``): to a vertex count, as a level
kind (``qem``: the source decimated, colours sampled from the source surface at each new
vertex), or within a distance (:func:`simplify_within`, Garland & Heckbert's quadrics bounding
the error), for LOD parents' far meshes. How the targets are met: ``docs/baking.md``.
"""

from __future__ import annotations

import math
import threading
from types import ModuleType

import numpy as np

from ..errors import LodConvertError
from ..model import WHITE, Mesh, Surface

PIP_INSTALL = "pip install fast-simplification"
# Face targets tried before giving up on reaching the vertex target.
MAX_TRIES = 6
AIM = 0.99
PASSES = 100
"""Collapse passes of ``fast-simplification`` (its ``Simplify.h``)."""
THRESHOLD_SCALE = 1e-9
"""Factor of its pass thresholds (squared metres for a mesh in metres)."""
NEAREST = 32
"""Faces (nearest by centre) among which a point's face is found."""
ONE_AT_A_TIME = threading.Lock()
"""Held around each use of ``fast-simplification``: it keeps the mesh it works on in module
state between calls, so threads baking at once would mix their meshes."""


def _simplifier(user: str = "--level-kind qem") -> ModuleType:
    try:
        import fast_simplification
    except ImportError as exc:
        raise LodConvertError(
            f"{user} needs fast-simplification ({exc}); run: {PIP_INSTALL}"
        ) from exc
    return fast_simplification


def decimate(surface: Mesh, vertices: int) -> Surface:
    """``surface`` (all its parts as one) decimated to at most ``vertices`` vertices (when the
    face targets tried allow it). Vertices used by no face are dropped; a target of a few
    vertices can leave none."""
    fs = _simplifier()
    points = np.asarray(surface.vertices, dtype=np.float64)
    faces = np.asarray(surface.faces, dtype=np.int64)
    used = len(np.unique(faces))
    # A closed mesh has about two faces per vertex; aim a little low, the count overshoots.
    target_faces = max(1, int(len(faces) * vertices / max(used, 1) * AIM))
    for _ in range(MAX_TRIES):
        with ONE_AT_A_TIME:
            out_points, out_faces, collapses = fs.simplify(
                points, faces, target_count=min(target_faces, len(faces)), return_collapses=True
            )
        if len(out_points) <= vertices or target_faces == 1:
            break
        target_faces = max(1, int(target_faces * vertices / len(out_points) * 0.98))
    return _coloured(surface, fs, collapses, out_points, out_faces.astype(np.int64))


def _coloured(
    surface: Mesh, fs: ModuleType, collapses: np.ndarray, points: np.ndarray, faces: np.ndarray
) -> Surface:
    """The decimated mesh with the source's colours sampled at its vertices (one base colour
    when the source is a single part with nothing beyond it)."""
    single = surface.single
    if single is not None and single.texture is None and single.vertex_colors is None:
        return Surface(points, faces, base_color=single.base_color)
    face_of_new = _source_faces(fs, surface.vertices, surface.faces, collapses, len(points))
    colors = surface.colors_at(face_of_new, points)
    return Surface(points, faces, vertex_colors=colors)


def _source_faces(
    fs: ModuleType, vertices: np.ndarray, faces: np.ndarray, collapses: np.ndarray, count: int
) -> np.ndarray:
    """For each of the ``count`` new vertices, a face of (``vertices``, ``faces``) that uses a
    source vertex collapsed into it."""
    corners = faces.ravel()
    face_of_new = np.zeros(count, dtype=np.int64)
    face_of_new[_new_vertex_of(fs, vertices, faces, collapses)[corners]] = (
        np.arange(len(corners)) // 3
    )
    return face_of_new


def _new_vertex_of(
    fs: ModuleType, vertices: np.ndarray, faces: np.ndarray, collapses: np.ndarray
) -> np.ndarray:
    """The new vertex each source vertex collapsed into."""
    with ONE_AT_A_TIME:
        _, _, mapping = fs.replay_simplification(vertices, faces, collapses)
    return mapping


def simplify_within(surface: Mesh, tolerance: float, colours: Mesh | None = None) -> Surface:
    """``surface`` (all its parts as one) simplified while each vertex stays within
    ``tolerance`` of the planes of the source faces it stands for: vertices at one position are
    welded first (so that separate polygons of one solid collapse together), faces of no area
    left out. Open borders stay as they are: the quadrics hold a vertex to its faces' planes,
    not to a border's line, along which it would slide. Each face takes the colour (at its
    centre) of the source face facing most nearly its way of those within ``tolerance`` of the
    nearest to its centre (:func:`_most_facing`), of ``colours`` where given (the geometry that
    ``surface`` stands for, in the same frame, so that colours do not drift tier by tier) else
    of ``surface``, so that a wall's face collapsed into a roof's place takes the roof's colour
    and a wall keeps its own up to the eaves; as vertex colours on a white base, a vertex where
    faces of different colours meet one per colour, so that no colour runs across an edge."""
    fs = _simplifier("a simplified far mesh")
    points, corners = np.unique(surface.vertices, axis=0, return_inverse=True)
    welded = corners.reshape(-1)[surface.faces]
    tri = points[welded]
    kept = np.flatnonzero(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).any(axis=1))
    welded = welded[kept]
    if not len(welded):
        return Surface(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    agg = max(0.0, math.log(tolerance**2 / THRESHOLD_SCALE) / math.log(PASSES + 2))
    with ONE_AT_A_TIME:
        out_points, out_faces = fs.simplify(
            points, welded, target_count=0, agg=agg, preserve_border=True
        )
    out_faces = out_faces.astype(np.int64)
    normals = Surface(out_points, out_faces).face_normals(np.arange(len(out_faces)))
    centres = out_points[out_faces].mean(axis=1)
    reference = colours if colours is not None else surface
    faces = np.arange(reference.face_count) if colours is not None else kept
    near = _most_facing(reference.triangles[faces], reference.face_normals(faces), centres,
                        normals, tolerance)  # fmt: skip
    source = faces[near]
    colors = reference.face_colors(source)
    return _split_by_colour(out_points, out_faces, colors)


def _most_facing(
    triangles: np.ndarray,
    normals: np.ndarray,
    points: np.ndarray,
    directions: np.ndarray,
    within: float,
) -> np.ndarray:
    """For each of ``points`` (unit normals ``directions``), the face of ``triangles`` (unit
    ``normals``) facing most nearly its way of those no more than ``within`` farther from it
    than the nearest, among the :data:`NEAREST` nearest by centre."""
    near, distance = _near(triangles, points)
    close = distance <= distance.min(axis=1, keepdims=True) + within
    cosine = np.einsum("nkj,nj->nk", normals[near], directions)
    best = np.where(close, cosine, -np.inf).argmax(axis=1)
    return near[np.arange(len(points)), best]


def _near(triangles: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``points``, the :data:`NEAREST` faces of ``triangles`` nearest by centre
    and the distance from it to each."""
    from scipy.spatial import cKDTree

    from .closest import distances  # numba: loaded where a far mesh is coloured

    k = min(NEAREST, len(triangles))
    _, near = cKDTree(triangles.mean(axis=1)).query(points, k=k)
    near = np.asarray(near, dtype=np.int64).reshape(len(points), k)
    triangles = np.ascontiguousarray(triangles, dtype=np.float64)
    return near, distances(triangles, near, np.ascontiguousarray(points, dtype=np.float64))


def _split_by_colour(points: np.ndarray, faces: np.ndarray, colors: np.ndarray) -> Surface:
    """A surface of ``faces`` over ``points``, each face of its own colour (``colors``, RGBA
    per face): a vertex for each point and colour of the faces around it."""
    rgba = np.repeat(np.ascontiguousarray(colors, dtype=np.uint8), 3, axis=0)
    keys = np.column_stack([faces.ravel(), rgba.view(np.uint32).ravel()])
    unique, first, corners = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return Surface(
        points[unique[:, 0]],
        corners.reshape(-1, 3),
        vertex_colors=rgba[first],
        base_color=WHITE.copy(),
    )
