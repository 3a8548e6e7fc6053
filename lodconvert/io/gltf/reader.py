"""Reading back the glTF files lodconvert wrote: per root node its levels in ``MSFT_lod`` order
(:func:`read_lod_gltf`), chains with the facts of ``extras.lodconvert`` (:func:`read_back`) and
LOD parents (:func:`read_cells`). Origins and centres come back in the source's coordinates:
the scene frame of a georeferenced file (``asset.extras.lodconvert.frame``, see
:mod:`lodconvert.io.frame`) is undone."""

from __future__ import annotations

import base64
import binascii
import contextlib
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...colors import normalized, srgb_rgba
from ...errors import InputError
from ...model import LodChain
from ..declared import chain_from_facts, level_from_facts
from ..frame import SceneFrame, frame_from_record
from .binary import GlbError, accessor_values, is_glb, split_glb
from .lod import MSFT_LOD

# --- reading our own output ---------------------------------------------------------------------


@dataclass
class GltfLevel:
    """One level as stored: geometry relative to the object's origin, sRGB colours.

    ``positions`` (k, 3) float64 (the float32 buffer values), ``colors`` (k, 4) uint8 or
    ``None``, ``normals`` (k, 3) float32 or ``None``, ``faces`` (m, 3) int64 for a mesh level,
    ``extras`` the level's facts from the finest node's ``extras.lodconvert.levels``.
    """

    name: str
    kind: str
    positions: np.ndarray
    colors: np.ndarray | None
    normals: np.ndarray | None
    faces: np.ndarray | None
    extras: dict[str, Any]


@dataclass
class GltfObject:
    """One object (root node): id, float64 origin (source coordinates), levels finest first,
    coverage thresholds, the finest node's ``extras.lodconvert``, its node index, its
    ``MSFT_lod`` ids and the root node's ``extras.attributes`` as stored (``None`` without
    any)."""

    object_id: str
    origin: np.ndarray
    levels: list[GltfLevel]
    screen_coverage: list[float]
    extras: dict[str, Any]
    node: int
    ids: list[int]
    attributes: Any = None


def read_lod_gltf(path: str | Path, geometry: bool = True) -> list[GltfObject]:
    """Read a ``.glb``/``.gltf`` that lodconvert wrote: one :class:`GltfObject` per root node,
    with levels in ``MSFT_lod`` order.

    Raises :class:`InputError` when the file cannot be read, is truncated or malformed, or was
    not written by lodconvert.
    """
    with _read_errors(path):
        obj, blob = _load(Path(path))
        frame = scene_frame_of(obj)
        roots = _object_roots(obj["nodes"], _scene_roots(obj))
        return [_read_object(obj, blob, i, frame, geometry) for i in roots]


def read_frame(path: str | Path) -> SceneFrame | None:
    """The scene frame of a ``.glb``/``.gltf`` lodconvert wrote (``None``: none, the file is in
    source coordinates). Raises :class:`InputError` as :func:`read_lod_gltf` does."""
    with _read_errors(path):
        obj, _ = _load(Path(path))
        return scene_frame_of(obj)


def read_cells(path: str | Path) -> list[dict[str, Any]]:
    """The LOD parents of a ``.glb``/``.gltf`` lodconvert wrote, coarsest first in document
    order (see :mod:`lodconvert.io`): the ``extras.lodconvert`` of each cell's near node,
    ``far`` (the far node's ``extras.lodconvert``) and, under ``"gltf"``, the indices of the
    near and far nodes. Raises :class:`InputError` as :func:`read_lod_gltf` does."""
    with _read_errors(path):
        obj, _ = _load(Path(path))
        nodes = obj["nodes"]
        cells = []
        for near in _cell_nears(nodes, _scene_roots(obj)):
            (far,) = nodes[near]["extensions"][MSFT_LOD]["ids"]
            facts = nodes[near]["extras"]["lodconvert"]
            where = {"near": near, "far": far}
            cells.append({**facts, "far": nodes[far]["extras"]["lodconvert"], "gltf": where})
        return cells


@contextlib.contextmanager
def _read_errors(path: str | Path) -> Iterator[None]:
    """Turn what reading a glTF file can raise into an :class:`InputError` naming ``path``."""
    try:
        yield
    except (InputError, GlbError) as exc:
        raise InputError(str(exc), str(path)) from None
    except (ValueError, KeyError, IndexError, TypeError, AttributeError) as exc:
        raise InputError(f"malformed glTF ({type(exc).__name__}: {exc})", str(path)) from None
    except RecursionError:  # JSON, or LOD parents, nested past Python's recursion limit
        raise InputError("malformed glTF (nested too deeply)", str(path)) from None


def _load(path: Path) -> tuple[dict[str, Any], bytes]:
    """JSON object and binary buffer of a glTF lodconvert wrote; :class:`InputError` for a file
    that cannot be read or that lodconvert did not write."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}") from None
    obj, blob = _parse(data)
    if not isinstance(obj.get("asset", {}).get("extras", {}).get("lodconvert"), dict):
        raise InputError("not a glTF written by lodconvert (no asset.extras.lodconvert)")
    return obj, blob


def scene_frame_of(obj: dict[str, Any]) -> SceneFrame | None:
    """The scene frame a glTF's JSON object records (``None``: no frame, source coordinates)."""
    return frame_from_record(obj["asset"]["extras"]["lodconvert"].get("frame"))


def _scene_roots(obj: dict[str, Any]) -> list[int]:
    """The root nodes of the glTF's objects and LOD parents: its scene's, or the children of
    the scene's one frame node."""
    roots = obj["scenes"][obj.get("scene", 0)].get("nodes", [])
    if scene_frame_of(obj) is None:
        return roots
    (frame_node,) = roots
    return obj["nodes"][frame_node].get("children", [])


def _cell_near(nodes: list[dict[str, Any]], index: int) -> int | None:
    """The near node of the LOD parent whose root is node ``index`` (its first child, whose
    ``extras.lodconvert`` names a ``cell_id``); ``None`` when node ``index`` is no cell."""
    children = nodes[index].get("children", [])
    if children and "cell_id" in nodes[children[0]].get("extras", {}).get("lodconvert", {}):
        return children[0]
    return None


def _object_roots(nodes: list[dict[str, Any]], indices: list[int]) -> Iterator[int]:
    """The root nodes of objects among ``indices``, looking inside LOD parents (their members
    are their near node's children)."""
    for index in indices:
        near = _cell_near(nodes, index)
        if near is None:
            yield index
        else:
            yield from _object_roots(nodes, nodes[near].get("children", []))


def _cell_nears(nodes: list[dict[str, Any]], indices: list[int]) -> Iterator[int]:
    """The near nodes of the LOD parents among ``indices`` and inside them, coarsest first."""
    for index in indices:
        near = _cell_near(nodes, index)
        if near is not None:
            yield near
            yield from _cell_nears(nodes, nodes[near].get("children", []))


def _parse(data: bytes) -> tuple[dict[str, Any], bytes]:
    """JSON object and binary buffer of GLB or glTF-with-data-URI bytes."""
    if not is_glb(data):
        obj = json.loads(data.decode("utf-8"))
        buffers = obj.get("buffers", [])
        if not buffers:
            return obj, b""
        uri = buffers[0].get("uri", "")
        if not uri.startswith("data:") or "," not in uri:
            raise InputError("buffer is not an embedded data URI")
        try:
            return obj, base64.b64decode(uri.split(",", 1)[1], validate=True)
        except binascii.Error as exc:
            raise InputError(f"bad base64 buffer ({exc})") from None
    text, blob = split_glb(data)
    return json.loads(bytes(text).decode("utf-8")), bytes(blob)


def _primitive(obj: dict[str, Any], blob: bytes, primitive: dict[str, Any]) -> dict[str, Any]:
    """Positions (float64), sRGB colours, normals and faces of one primitive (``None`` where
    absent)."""
    attributes = primitive["attributes"]
    out: dict[str, Any] = {
        "positions": accessor_values(obj, blob, attributes["POSITION"]).astype(np.float64),
        "colors": None,
        "normals": None,
        "faces": None,
    }
    if "COLOR_0" in attributes:
        linear = normalized(accessor_values(obj, blob, attributes["COLOR_0"]))
        if linear.shape[1] == 3:
            linear = np.column_stack([linear, np.ones(len(linear))])
        out["colors"] = srgb_rgba(linear)
    if "NORMAL" in attributes:
        out["normals"] = normalized(accessor_values(obj, blob, attributes["NORMAL"]))
    if "indices" in primitive:
        indices = accessor_values(obj, blob, primitive["indices"])
        out["faces"] = indices.astype(np.int64).reshape(-1, 3)
    return out


def _read_level(obj: dict[str, Any], blob: bytes, node: dict[str, Any], facts: dict) -> GltfLevel:
    """One level node's geometry: its mesh's primitives (one per part) joined in order, the
    node's scale and translation (of quantized positions) applied."""
    positions = np.zeros((0, 3))
    colors = normals = faces = None
    if "mesh" in node:
        parts = [_primitive(obj, blob, p) for p in obj["meshes"][node["mesh"]]["primitives"]]
        scale = np.asarray(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)
        translation = np.asarray(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
        positions = np.concatenate([p["positions"] for p in parts]) * scale + translation
        if any(p["colors"] is not None for p in parts):
            colors = np.concatenate(
                [
                    p["colors"]
                    if p["colors"] is not None
                    else np.full((len(p["positions"]), 4), 255, dtype=np.uint8)
                    for p in parts
                ]
            )
        if all(p["normals"] is not None for p in parts):
            normals = np.concatenate([p["normals"] for p in parts])
        if all(p["faces"] is not None for p in parts):
            starts = np.cumsum([0, *(len(p["positions"]) for p in parts[:-1])])
            faces = np.concatenate([p["faces"] + s for p, s in zip(parts, starts, strict=True)])
    return GltfLevel(
        name=facts["name"],
        kind=facts["kind"],
        positions=positions,
        colors=colors,
        normals=normals,
        faces=faces,
        extras=facts,
    )


def _read_object(
    obj: dict[str, Any],
    blob: bytes,
    root_index: int,
    frame: SceneFrame | None,
    geometry: bool = True,
) -> GltfObject:
    nodes = obj["nodes"]
    root = nodes[root_index]
    finest_index = root["children"][0]
    finest = nodes[finest_index]
    extras = finest.get("extras", {})
    facts = extras["lodconvert"]
    ids = finest.get("extensions", {}).get(MSFT_LOD, {}).get("ids", [])
    level_nodes = [finest, *(nodes[i] for i in ids)]
    if len(level_nodes) != len(facts["levels"]):
        raise InputError(
            f"{root.get('name')!r}: {len(level_nodes)} level nodes but "
            f"{len(facts['levels'])} levels in extras"
        )
    if "origin" in facts:  # an instance's, declared in source coordinates
        origin = np.array(facts["origin"], dtype=np.float64)
    else:
        origin = np.array(root.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
        if frame is not None:
            origin = frame.origin + origin
    return GltfObject(
        object_id=root["name"],
        origin=origin,
        levels=[
            _read_level(obj, blob, node if geometry else {}, level)
            for node, level in zip(level_nodes, facts["levels"], strict=True)
        ],
        screen_coverage=list(extras.get("MSFT_screencoverage", [])),
        extras=facts,
        node=finest_index,
        ids=list(ids),
        attributes=root.get("extras", {}).get("attributes"),
    )


def read_back(path: Path, geometry: bool = True) -> list[LodChain]:
    """The chains of a ``.glb``/``.gltf`` lodconvert wrote, with the facts of
    ``extras.lodconvert`` and (unless ``geometry`` is false) the level geometry, relative to
    each chain's origin. ``chain.metadata`` holds the object's attributes (its root node's
    ``extras.attributes``) and, under ``"gltf"`` (in place of an attribute of that name), the
    finest level's node index and the ``MSFT_lod`` ids."""
    chains = []
    for obj in read_lod_gltf(path, geometry):
        where = f"{path}: object {obj.object_id!r}"
        levels = [
            level_from_facts(lv.extras, lv.positions, lv.faces, lv.colors, where)
            for lv in obj.levels
        ]
        facts = {**obj.extras, "attributes": obj.attributes}
        chain = chain_from_facts(obj.object_id, facts, levels, obj.origin, where)
        chain.metadata["gltf"] = {"node": obj.node, "ids": obj.ids}
        chains.append(chain)
    return chains
