"""Quadric edge-collapse decimation (``fast-simplification``) as a level kind.

A ``qem`` level is the source mesh decimated to a target vertex count: a mesh level, drawn as
triangles, where a ``pcd`` level would be drawn as points. ``fast-simplification`` targets a
face count; the vertex count that comes out is checked and the face target lowered until it
is at most the vertex target. Colours (vertex colours or texture, modulated by the base colour)
are sampled from the source surface at each new vertex, on a face of a source vertex that
collapsed into it; the texture itself is not kept.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from ..errors import LodConvertError
from ..model import Mesh, Surface

PIP_INSTALL = "pip install fast-simplification"
# Face targets tried before giving up on reaching the vertex target.
MAX_TRIES = 6
AIM = 0.99


def _simplifier() -> ModuleType:
    try:
        import fast_simplification
    except ImportError as exc:
        raise LodConvertError(
            f"--level-kind qem needs fast-simplification ({exc}); run: {PIP_INSTALL}"
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
    _, _, mapping = fs.replay_simplification(surface.vertices, surface.faces, collapses)
    # A source face for each new vertex: one that uses a source vertex collapsed into it.
    corners = surface.faces.ravel()
    face_of_new = np.zeros(len(points), dtype=np.int64)
    face_of_new[mapping[corners]] = np.arange(len(corners)) // 3
    colors = surface.colors_at(face_of_new, points)
    return Surface(points, faces, vertex_colors=colors)
