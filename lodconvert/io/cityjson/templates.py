"""Geometry templates and their instances: each template read once into a :class:`Mesh` that
its ``GeometryInstance`` nodes share, placed by the instance's transform."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import InputError
from ...model import Mesh, Node
from .geometry import SURFACE_DEPTH, lod_label, read_lod
from .jsonkind import json_shown
from .source import Context
from .triangulation import triangulate_batch
from .vertices import check_used

_IGNORED = frozenset({"MultiPoint", "MultiLineString"})
"""Template types that are no surfaces: their instances are ignored, as such geometry is."""


def _mesh(
    geometries: list[dict[str, Any]], vertices: np.ndarray, ctx: Context, where: str, kind: str
) -> tuple[Mesh | None, int]:
    """The Mesh of ``geometries`` (of one LoD) indexing ``vertices``, one part per semantic
    class and material, and how many faces were dropped (degenerate polygons, triangles
    without area). Raises :class:`InputError` for bad indices or boundaries."""
    lod = read_lod("", geometries, vertices, ctx, where, kind)
    triangulate_batch([lod])
    return lod.mesh, lod.dropped


def template_mesh(index: Any, ctx: Context, where: str, kind: str) -> tuple[str, Mesh] | None:
    """Template ``index`` as its (LoD label, Mesh), read once per file (coloured for the
    type ``kind`` of the first object using it)."""
    if type(index) is not int or not 0 <= index < len(ctx.templates):
        raise InputError(f"uses template {index!r}; the file has {len(ctx.templates)}", where)
    if index not in ctx.shared:
        template = ctx.templates[index]
        kind_of_template = template.get("type") if isinstance(template, dict) else None
        if kind_of_template not in SURFACE_DEPTH and kind_of_template not in _IGNORED:
            raise InputError(
                f"uses template {index}, whose type {json_shown(kind_of_template)} is not that "
                "of a surface, point or line geometry",
                where,
            )
        if kind_of_template in _IGNORED:
            ctx.shared[index] = None
        else:
            mesh, dropped = _mesh([template], ctx.template_vertices, ctx, where, kind)
            ctx.tally.dropped_faces += dropped
            label = lod_label(template.get("lod", ""))
            ctx.shared[index] = (label, mesh) if mesh is not None else None
    return ctx.shared[index]


def placement(geometry: dict[str, Any], ctx: Context, where: str) -> np.ndarray:
    """An instance's 4×4 transform: its ``transformationMatrix`` moved to its reference
    point (a vertex that exists, whose coordinates are finite)."""
    try:
        values = geometry.get("transformationMatrix", np.eye(4).ravel().tolist())
        if not isinstance(values, list) or not set(map(type, values)) <= {int, float}:
            raise ValueError("its transformationMatrix is not a list of 16 numbers")
        matrix = np.array(values, dtype=np.float64).reshape(4, 4)
        (point,) = geometry["boundaries"]
    except (TypeError, ValueError, KeyError, OverflowError) as exc:
        raise InputError(f"has a malformed GeometryInstance ({exc})", where) from None
    if type(point) is not int or not 0 <= point < len(ctx.vertices):
        raise InputError(
            f"has a GeometryInstance whose reference point {json_shown(point)} is not one of "
            f"the {len(ctx.vertices):,} vertices",
            where,
        )
    check_used(ctx.vertices, np.array([point]), where)
    matrix[:3, 3] += ctx.vertices[point]
    if not np.isfinite(matrix).all():
        raise InputError("has a GeometryInstance with a non-finite transformationMatrix", where)
    return matrix


def world_bounds(mesh: Mesh, transform: np.ndarray | None) -> np.ndarray:
    """(2, 3) bounds of ``mesh`` placed by ``transform``."""
    if transform is None:
        return mesh.bounds
    corners = np.array(np.meshgrid(*mesh.bounds.T)).reshape(3, -1).T
    placed = corners @ transform[:3, :3].T + transform[:3, 3]
    return np.stack([placed.min(axis=0), placed.max(axis=0)])


def instance_nodes(node: Node, placed: list[tuple[tuple[str, Mesh], np.ndarray]]) -> None:
    """Give ``node`` its geometry instances: placing the node itself when it has one and no
    geometry of its own, else as child nodes ``<id>-instance<k>``."""
    if len(placed) == 1 and node.geometry is None:
        (label, mesh), node.transform = placed[0]
        node.geometry, node.lods = mesh, {label: mesh}
        return
    for k, ((label, mesh), transform) in enumerate(placed, start=1):
        child_id = f"{node.id}-instance{k}"
        node.children.append(
            Node(
                id=child_id,
                geometry=mesh,
                type=node.type,
                attributes={**node.attributes, "id": child_id},
                crs=node.crs,
                transform=transform,
                lods={label: mesh},
            )
        )
