"""A cell's far level as one merged mesh: what it replaces (finer cells' far meshes, objects'
coarsest mesh levels) or its objects' levels, finer where the coarsest lose the silhouette,
without floors on the ground, as one part with vertex colours, then simplified by quadric edge
collapse to within a few pixels at the switch distance (:func:`mesh_level`); and the mesh helpers
the other far levels share."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from ..bake.qem import simplify_within
from ..chain import ChainOptions
from ..model import WHITE, CellChain, Level, LodChain, Mesh, Surface
from .far_choice import MIN_CELL_F, silhouette_f
from .hlod import Member

DOWN = -0.99
"""Unit normal z below which a face looks straight down."""
FLOOR_MARGIN = 0.01
"""Metres above an object's lowest point within which a face looking down is its floor on the
ground, left out of far meshes."""
MERGED_FROM = ("finer cells' far levels", "objects' levels")
"""What a merged far mesh is made of: what it replaces (a coarser tier's), or its objects'
levels."""
SIMPLIFY_PX = (8.0, 4.0, 2.0, 1.0)
"""Tolerances tried for a far mesh's simplification, coarsest first: pixels at the cell's
switch distance in the reference view (one pixel at d is 2·d·tan(fov/2)/height_px metres:
0.77 m at 1 km, 1080 px, 45°), all within half the 16 px screen-space error at which CesiumJS
refines a tile by default (a tile's geometric error is 16 px at its switch)."""


def _placed(chain: LodChain, mesh: Mesh) -> Mesh:
    """``mesh`` (a level of ``chain``) in scene coordinates."""
    return chain.in_scene(mesh)


def finest_mesh(chain: LodChain) -> Mesh:
    """The finest mesh level of ``chain`` in scene coordinates."""
    level = next(lv for lv in chain.levels if lv.mesh is not None)
    assert level.mesh is not None
    return _placed(chain, level.mesh)


def mesh_level(
    members: list[Member],
    objects: list[LodChain],
    origin: np.ndarray,
    source: Mesh,
    distance: float,
    options: ChainOptions,
) -> tuple[Level, float, dict[str, Any]]:
    """A cell's simplified merged far mesh (:func:`_simplified`), from what it replaces where
    it has finer cells (:func:`far_meshes` of every member merged, kept where its silhouette
    F against ``source`` from ``distance`` reaches :data:`MIN_CELL_F`) and from its objects'
    levels (:func:`merged_level`): the one with fewer vertices of those whose F reaches it,
    else the most faithful. Its level, F and facts (what it was merged from, the levels finer
    than the objects' coarsest it took, the simplification)."""
    merges = []
    if any(isinstance(m, CellChain) and m.far.mesh is not None for m in members):
        parts = [mesh for m in members for mesh in far_meshes(m)]
        level = Level(name="FAR", kind="merged", mesh=one_part(merge(parts).translated(-origin)))
        f = silhouette_f(source, level, distance, options)
        if f >= MIN_CELL_F:
            merges.append((MERGED_FROM[0], 0, level, f))
    level, f, finer = merged_level(objects, origin, source, distance, options)
    merges.append((MERGED_FROM[1], finer, level, f))
    made = []
    for made_from, finer, merged, f in merges:
        level, after, simplified = _simplified(merged, f, source, distance, options)
        facts = {"merged_from": made_from, "mesh_levels_finer": finer, "simplified": simplified}
        made.append((level, after, facts))
    faithful = [m for m in made if m[1] >= MIN_CELL_F]
    if faithful:
        return min(faithful, key=lambda m: m[0].count)
    return max(made, key=lambda m: m[1])


def merged_level(
    objects: list[LodChain],
    origin: np.ndarray,
    source: Mesh,
    distance: float,
    options: ChainOptions,
) -> tuple[Level, float, int]:
    """The objects' coarsest mesh levels (without their floors, :func:`floorless`) merged into
    one far level, or, where its silhouette
    F against ``source`` (the objects' finest geometry about ``origin``) from ``distance``
    stays below :data:`MIN_CELL_F`, their next finer mesh levels in turn (their finest at
    most); the level, its F and how many levels finer than the coarsest it took."""
    meshes = [
        [lv.mesh for lv in reversed(chain.levels) if lv.mesh is not None] for chain in objects
    ]
    depth = max(len(levels) for levels in meshes)
    for finer in range(depth):
        merged = merge(
            [
                floorless(_placed(chain, levels[min(finer, len(levels) - 1)]))
                for chain, levels in zip(objects, meshes, strict=True)
            ]
        )
        level = Level(name="FAR", kind="merged", mesh=one_part(merged.translated(-origin)))
        last = finer == depth - 1  # whose F is given back, whatever it is
        f = silhouette_f(source, level, distance, options, 0.0 if last else MIN_CELL_F)
        if f >= MIN_CELL_F:
            break
    return level, f, finer


def far_meshes(member: Member) -> list[Mesh]:
    """A member's far content in scene coordinates: a finer cell's far mesh (its objects'
    coarsest mesh levels where it is points), an object's coarsest mesh level, without
    floors."""
    if isinstance(member, CellChain) and member.far.mesh is not None:
        return [member.far.mesh.translated(member.origin)]
    chains = member.objects()
    coarsest = (next(lv.mesh for lv in reversed(c.levels) if lv.mesh is not None) for c in chains)
    return [floorless(_placed(c, mesh)) for c, mesh in zip(chains, coarsest, strict=True)]


def _simplified(
    merged: Level, f: float, source: Mesh, distance: float, options: ChainOptions
) -> tuple[Level, float, dict[str, float | int | bool]]:
    """``merged`` (a far mesh of silhouette F ``f`` against ``source``) simplified to within the
    coarsest tolerance of :data:`SIMPLIFY_PX` at ``distance`` whose F reaches
    :data:`MIN_CELL_F` or is no lower than ``f``; ``merged`` itself when none does. The level
    kept, its F, and the tolerance, counts and F before and after (of the last tried)."""
    assert merged.mesh is not None
    floor = min(MIN_CELL_F, f)
    for px in SIMPLIFY_PX:
        tolerance = px * distance / options.view.focal_px
        mesh = Mesh([simplify_within(merged.mesh, tolerance, source)])
        level = Level(name="FAR", kind="merged", mesh=mesh)
        stop = 0.0 if px == SIMPLIFY_PX[-1] else floor  # the last one's F is stated
        after = silhouette_f(source, level, distance, options, stop) if level.count else 0.0
        if after >= floor:
            break
    kept = after >= floor
    facts = {
        "tolerance_px": px,
        "tolerance_m": round(tolerance, 4),
        "vertices_before": merged.count,
        "vertices_after": level.count,
        "silhouette_f_before": round(f, 4),
        "silhouette_f_after": round(after, 4),
        "kept": kept,
    }
    return (level, after, facts) if kept else (merged, f, facts)


def floorless(mesh: Mesh) -> Mesh:
    """``mesh`` (an object's level, z up) without its floor on the ground: the faces looking
    straight down (:data:`DOWN`) that lie within :data:`FLOOR_MARGIN` of its lowest point,
    which no viewpoint above the ground sees; ``mesh`` itself when that is all of it."""
    low = mesh.bounds[0, 2] + FLOOR_MARGIN
    parts = []
    for part in mesh.parts:
        faces = np.arange(len(part.faces))
        floor = (part.face_normals(faces)[:, 2] < DOWN) & (
            part.triangles[:, :, 2].max(axis=1) <= low
        )
        if not floor.any():
            parts.append(part)
        elif not floor.all():
            parts.append(_with_faces(part, faces[~floor]))
    return Mesh(parts) if parts else mesh


def _with_faces(part: Surface, faces: np.ndarray) -> Surface:
    """``part`` with only the given faces and the vertices they use."""
    used, corners = np.unique(part.faces[faces], return_inverse=True)
    return replace(
        part,
        vertices=part.vertices[used],
        faces=corners.reshape(-1, 3),
        vertex_colors=None if part.vertex_colors is None else part.vertex_colors[used],
        uv=None if part.uv is None else part.uv[used],
    )


def merge(meshes: Sequence[Mesh]) -> Mesh:
    """One mesh of every part of ``meshes``."""
    return Mesh([part for mesh in meshes for part in mesh.parts])


def one_part(mesh: Mesh) -> Mesh:
    """``mesh`` as one part (one draw call): parts' colours become vertex colours (on a white
    base colour, which glTF multiplies them by); a texture is baked into its vertices' colours
    (:meth:`~lodconvert.model.Mesh.baked_colors`)."""
    colors = mesh.baked_colors()
    return Mesh([Surface(mesh.vertices, mesh.faces, vertex_colors=colors, base_color=WHITE.copy())])
