"""What the viewer page needs to know about an output, read from the file itself: per object its
centre, diagonal α, cutoffs, level names and (glTF) level nodes and point sizes.

Only the structure is read: the X3D document is streamed with its ``Shape`` s cleared, the glTF
buffer is not decoded. Raises :class:`~lodconvert.errors.InputError` for files lodconvert did not
write.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from ..errors import InputError
from ..io.gltf import MSFT_LOD
from ..io.gltf import _parse as parse_gltf_bytes
from ..ranges import REFERENCE_VIEW

NOTHING = "nothing"
"""Level name of the empty child that a culled chain shows beyond its last cutoff."""
_MFSTRING = re.compile(r'^\s*"((?:[^"\\]|\\.)*)"')


def _first_string(value: str) -> str:
    """The first value of X3D MFString text (``"a" "b"`` → ``a``), unescaped."""
    match = _MFSTRING.match(value)
    return re.sub(r"\\(.)", r"\1", match.group(1)) if match else value


def _metadata(node: etree._Element) -> dict[str, str]:
    """name → value of the metadata entries in ``node``'s ``MetadataSet`` (for a chain, on the
    ``LOD`` or on the ``Transform`` around it)."""
    meta = node.find("MetadataSet")
    return {} if meta is None else {m.get("name"): m.get("value", "") for m in meta}


def _floats(text: str | None) -> list[float]:
    return [float(v) for v in (text or "").replace(",", " ").split()]


def _x3d_object(lod: etree._Element, translation: np.ndarray) -> dict[str, Any]:
    parent = lod.getparent()
    meta = _metadata(lod) or (_metadata(parent) if parent is not None else {})
    levels = []
    for child in lod:
        if not isinstance(child.tag, str) or child.tag.startswith("Metadata"):
            continue
        name = _metadata(child).get("level")
        levels.append(_first_string(name) if name else child.get("DEF") or NOTHING)
    cutoffs = _floats(lod.get("range"))
    culled = levels[-1:] == [NOTHING]
    center = translation + np.array(_floats(lod.get("center")) or [0.0, 0.0, 0.0])
    return {
        "id": _first_string(meta["object_id"]) if "object_id" in meta else lod.get("DEF"),
        "lod": lod.get("DEF"),
        "center": center.tolist(),
        "alpha": float(meta.get("alpha", 1.0)),
        "cutoffs": cutoffs,
        "culled": culled,
        "levels": levels[:-1] if culled else levels,
    }


def x3d_objects(path: Path) -> list[dict[str, Any]]:
    """One entry per DEF'd ``LOD`` of an X3D file, with its world centre (the enclosing
    ``Transform`` translations added)."""
    objects, offsets = [], [np.zeros(3)]
    try:
        events = etree.iterparse(str(path), events=("start", "end"), resolve_entities=False)
        for event, element in events:
            if element.tag == "Transform":
                if event == "start":
                    shift = _floats(element.get("translation")) or [0.0, 0.0, 0.0]
                    offsets.append(offsets[-1] + np.array(shift))
                else:
                    offsets.pop()
            elif event == "end" and element.tag == "LOD" and element.get("DEF"):
                objects.append(_x3d_object(element, offsets[-1]))
            elif event == "end" and element.tag == "Shape":
                element.clear()
    except (etree.XMLSyntaxError, ValueError) as exc:
        raise InputError(f"is not a well-formed X3D file ({exc})", str(path)) from None
    return objects


def _gltf_object(doc: dict[str, Any], root_index: int) -> dict[str, Any] | None:
    """The viewer entry of a scene root written by lodconvert (``None`` for other roots)."""
    nodes = doc["nodes"]
    root = nodes[root_index]
    if not root.get("children"):
        return None
    finest_index = root["children"][0]
    finest = nodes[finest_index]
    facts = finest.get("extras", {}).get("lodconvert")
    if not isinstance(facts, dict):
        return None
    origin = np.array(root.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
    local = np.array(facts.get("center", [0.0, 0.0, 0.0]), dtype=np.float64)
    levels = facts["levels"]
    return {
        "id": root.get("name", f"node {root_index}"),
        "node": finest_index,
        "ids": finest.get("extensions", {}).get(MSFT_LOD, {}).get("ids", []),
        "center": (origin + local).tolist(),
        "local_center": local.tolist(),
        "alpha": facts.get("alpha", 1.0),
        "cutoffs": facts.get("cutoffs", []),
        "culled": bool(facts.get("culled")),
        "levels": [level["name"] for level in levels],
        "points": [
            {"px": level["point_size_px"], "distance": level["design_distance"]}
            if level.get("point_size_px") and level.get("design_distance")
            else None
            for level in levels
        ],
    }


def gltf_objects(path: Path) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The objects of a glTF file lodconvert wrote and its reference view."""
    try:
        doc, _ = parse_gltf_bytes(path.read_bytes())
        scene = doc["scenes"][doc.get("scene", 0)]
        found = [_gltf_object(doc, i) for i in scene.get("nodes", [])]
        view = doc["asset"].get("extras", {}).get("lodconvert", {}).get("reference_view")
    except InputError as exc:
        raise InputError(str(exc), str(path)) from None
    except (ValueError, KeyError, IndexError, TypeError, AttributeError, struct.error) as exc:
        raise InputError(f"is not a glTF file lodconvert wrote ({exc})", str(path)) from None
    return [o for o in found if o is not None], view or _reference_view()


def _reference_view() -> dict[str, Any]:
    return {"height_px": REFERENCE_VIEW.height_px, "fov_y_deg": REFERENCE_VIEW.fov_y_deg}


def page_config(path: Path) -> dict[str, Any]:
    """The page's configuration (without the asset URL): format, reference view, objects."""
    suffix = path.suffix.lower()
    if suffix not in (".x3d", ".glb", ".gltf"):
        raise InputError(f"no viewer page for {suffix or 'files without suffix'} files", str(path))
    if not path.is_file():
        raise InputError("no such file", str(path))
    if suffix == ".x3d":
        kind, objects, view = "x3d", x3d_objects(path), _reference_view()
    else:
        kind, (objects, view) = "gltf", gltf_objects(path)
    if not objects:
        raise InputError("holds no LOD chain written by lodconvert", str(path))
    return {"format": kind, "view": view, "objects": objects}
