r"""Reading back the ``.glb``/``.gltf``/``.x3d`` files lodconvert wrote, as :class:`LodChain`\ s.

Geometry comes from :func:`~lodconvert.io.gltf.read_lod_gltf` and
:func:`~lodconvert.io.x3d.read_x3d_points`; the chain and level parameters from what lodconvert
declares alongside: the glTF ``extras.lodconvert`` of the object and level nodes, or the X3D
lodconvert ``MetadataSet`` of the object's ``Transform`` (in older files: of the ``LOD``) and of
each level ``Group``. Used by ``lodconvert evaluate`` and ``lodconvert bench``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from ..errors import InputError
from ..model import MESH_KINDS, BakeParams, Level, LodChain, PointCloud, Surface
from .gltf import GltfObject, read_lod_gltf
from .x3d import METADATA_SET, read_x3d_points, x3d_read_errors


def read_chains(path: str | Path) -> list[LodChain]:
    """The chains of a ``.glb``, ``.gltf`` or ``.x3d`` file lodconvert wrote, with the level
    geometry (relative to each chain's origin) and the parameters the file declares.

    Raises :class:`InputError` for another suffix, an unreadable file, or one lodconvert did
    not write.
    """
    suffix = Path(path).suffix.lower()
    if suffix in (".glb", ".gltf"):
        return [_gltf_chain(obj, path) for obj in read_lod_gltf(path)]
    if suffix == ".x3d":
        return _x3d_chains(path)
    raise InputError("is not a .glb, .gltf or .x3d file written by lodconvert", str(path))


def _level_from(
    facts: dict[str, Any],
    positions: np.ndarray,
    faces: np.ndarray | None,
    colors: np.ndarray | None,
    where: str,
) -> Level:
    """A :class:`Level` from its declared facts (name, kind, bake parameters) and geometry."""
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


def _chain_from(
    object_id: str, facts: dict[str, Any], levels: list[Level], origin: np.ndarray, where: str
) -> LodChain:
    """A :class:`LodChain` from the chain facts a file declares."""
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
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"object {object_id!r} lacks its switching data ({exc})", where) from None


def _gltf_chain(obj: GltfObject, path: str | Path) -> LodChain:
    where = f"{path}: object {obj.object_id!r}"
    levels = [_level_from(lv.extras, lv.positions, lv.faces, lv.colors, where) for lv in obj.levels]
    return _chain_from(obj.object_id, obj.extras, levels, obj.origin, where)


_MFSTRING = re.compile(r'"((?:[^"\\]|\\.)*)"')


def _metadata_values(element: etree._Element) -> dict[str, Any]:
    """The entries of a ``MetadataSet``: single values as scalars, several as lists."""
    facts: dict[str, Any] = {}
    for child in element:
        name, text = child.get("name"), child.get("value") or ""
        if child.tag == "MetadataString":
            values: list[Any] = [
                re.sub(r"\\(.)", r"\1", m.group(1)) for m in _MFSTRING.finditer(text)
            ]
        elif child.tag == "MetadataBoolean":
            values = [v == "true" for v in text.replace(",", " ").split()]
        elif child.tag == "MetadataInteger":
            values = [int(v) for v in text.replace(",", " ").split()]
        elif child.tag == "MetadataDouble":
            values = [float(v) for v in text.replace(",", " ").split()]
        else:
            continue
        facts[name] = values if len(values) != 1 or name in ("xs", "cutoffs") else values[0]
    return facts


def _vector(text: str | None) -> np.ndarray:
    values = np.array((text or "").replace(",", " ").split(), dtype=np.float64)
    return values[:3] if len(values) >= 3 else np.zeros(3)


def _x3d_facts(path: str | Path) -> list[dict[str, Any]]:
    """Per ``LOD`` node carrying lodconvert metadata: its origin (the enclosing translations),
    centre, chain facts (from the ``MetadataSet`` of its ``Transform``, or of the LOD itself)
    and, per level ``Group``, its DEF and facts. Shapes are skipped."""
    objects: list[dict[str, Any]] = []
    transforms: list[dict[str, Any]] = []  # open Transforms: translation and metadata
    for event, element in etree.iterparse(str(path), events=("start", "end")):
        tag = element.tag
        if event == "start":
            if tag == "Transform":
                transforms.append({"offset": _vector(element.get("translation")), "facts": {}})
            elif tag == "LOD":
                offsets = [t["offset"] for t in transforms]
                objects.append(
                    {
                        "origin": np.sum(offsets, axis=0) if offsets else np.zeros(3),
                        "center": _vector(element.get("center")),
                        "facts": dict(transforms[-1]["facts"]) if transforms else {},
                        "levels": [],
                        "element": element,
                    }
                )
            elif tag == "Group" and objects and element.getparent() is objects[-1]["element"]:
                objects[-1]["levels"].append({"def": element.get("DEF"), "facts": {}})
            continue
        if tag == "Transform":
            transforms.pop()
        elif tag == "Shape":
            element.clear()
        elif tag == "MetadataSet" and element.get("name") == METADATA_SET:
            parent = element.getparent()
            lod = objects[-1]["element"] if objects else None
            if parent.tag == "Transform" and transforms:
                transforms[-1]["facts"] = _metadata_values(element)
            elif parent is lod:
                objects[-1]["facts"] = _metadata_values(element)
            elif objects[-1:] and objects[-1]["levels"] and parent.getparent() is lod:
                objects[-1]["levels"][-1]["facts"] = _metadata_values(element)
    return [obj for obj in objects if obj["facts"]]


def _x3d_chains(path: str | Path) -> list[LodChain]:
    with x3d_read_errors(path, "metadata"):
        objects = _x3d_facts(path)
    if not objects:
        raise InputError("is not an X3D file written by lodconvert (no lodconvert LOD)", str(path))
    geometry = read_x3d_points(path)
    chains = []
    for obj in objects:
        object_id = obj["facts"].get("object_id", "")
        where = f"{path}: object {object_id!r}"
        levels = []
        for entry in obj["levels"]:
            facts = {"name": entry["facts"].get("level"), **entry["facts"]}
            shapes = geometry.get(entry["def"])
            positions = shapes.coordinates if shapes is not None else np.zeros((0, 3))
            faces = shapes.index if shapes is not None else None
            colors = shapes.colors if shapes is not None else None
            levels.append(_level_from(facts, positions, faces, colors, where))
        chain_facts = {**obj["facts"], "center": obj["center"]}
        chains.append(_chain_from(object_id, chain_facts, levels, obj["origin"], where))
    return chains
