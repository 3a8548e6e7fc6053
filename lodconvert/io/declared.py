"""What lodconvert declares in its own files, turned back into the model.

Both writers record, beside the geometry, each chain's switching data (``cutoffs``, ``alpha``,
``beta``, ``gamma``, ``xs``, ``culled``, ``center``) and each level's facts (``name``, ``kind``
and, for point levels, ``resolution``, ``slices``, ``point_size_px``, ``filter``, ``spacing``,
``design_distance``): glTF in ``extras.lodconvert``, X3D in ``MetadataSet name='lodconvert'``.
They also keep each object's ``attributes`` (``chain.metadata`` as converted: a city object's
id, type, name, address, generic attributes…): glTF as ``extras.attributes`` of the object's
root node, X3D as JSON text in the chain's ``MetadataString name='attributes'``.
The format modules read those facts; these functions build the chain from them.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from ..errors import InputError
from ..model import MESH_KINDS, BakeParams, Level, LodChain, PointCloud, Surface


def level_from_facts(
    facts: dict[str, Any],
    positions: np.ndarray,
    faces: np.ndarray | None,
    colors: np.ndarray | None,
    where: str,
) -> Level:
    """A :class:`Level` from its declared facts (name, kind, bake parameters) and geometry;
    :class:`InputError` naming ``where`` when they are incomplete."""
    name, kind = facts.get("name"), facts.get("kind")
    design = facts.get("design_distance")
    if kind in MESH_KINDS:
        if faces is None:
            faces = np.zeros((0, 3), dtype=np.int64)
        surface = Surface(positions, faces, vertex_colors=colors)
        return Level(name=name, kind=kind, mesh=surface, design_distance=design)
    if kind != "pcd":
        raise InputError(f"level {name!r} is of unknown kind {kind!r}", where)
    try:
        params = BakeParams(
            resolution=int(facts["resolution"]),
            slices=int(facts["slices"]),
            point_size=float(facts["point_size_px"]),
            filter=facts.get("filter", "median"),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"point level {name!r} lacks its bake parameters ({exc})", where) from None
    k = len(positions)
    cloud = PointCloud(
        positions=positions,
        colors=colors if colors is not None else np.full((k, 4), 255, dtype=np.uint8),
        normals=np.zeros((k, 3), dtype=np.float32),
    )
    return Level(
        name=name,
        kind="pcd",
        points=cloud,
        params=params,
        spacing=facts.get("spacing"),
        design_distance=design,
    )


def _attributes(declared: Any, where: str) -> dict[str, Any]:
    """The object's attributes as a file declares them: a JSON object, or its JSON text (X3D
    keeps them in a ``MetadataString``); none declared is ``{}``. :class:`InputError` naming
    ``where`` when they are not an object."""
    if declared is None:
        return {}
    if isinstance(declared, str):
        try:
            declared = json.loads(declared)
        except json.JSONDecodeError as exc:
            raise InputError(f"attributes are not JSON ({exc})", where) from None
    if not isinstance(declared, dict):
        raise InputError(f"attributes are a {type(declared).__name__}, not an object", where)
    return declared


def chain_from_facts(
    object_id: str, facts: dict[str, Any], levels: list[Level], origin: np.ndarray, where: str
) -> LodChain:
    """A :class:`LodChain` from the chain facts a file declares, its ``metadata`` the object's
    declared ``attributes``."""
    metadata = _attributes(facts.get("attributes"), where)
    try:
        return LodChain(
            object_id=object_id,
            levels=levels,
            cutoffs=[float(c) for c in facts["cutoffs"]],
            origin=np.asarray(origin, dtype=np.float64),
            center=np.asarray(facts.get("center", np.zeros(3)), dtype=np.float64).reshape(3),
            alpha=float(facts["alpha"]),
            beta=float(facts["beta"]),
            gamma=float(facts["gamma"]),
            xs=[float(x) for x in facts["xs"]],
            culled=bool(facts.get("culled", False)),
            metadata=metadata,
            transform=(
                np.asarray(facts["transform"], dtype=np.float64).reshape(4, 4)
                if facts.get("transform") is not None
                else None
            ),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"object {object_id!r} lacks its switching data ({exc})", where) from None
