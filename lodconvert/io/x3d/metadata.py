"""The ``MetadataSet`` s an X3D file carries for its readers (:mod:`.reader`): the scene frame's
origin and rotation, and per chain, level and LOD parent what a reader needs to rebuild it (ids,
α, β, γ, cutoffs, counts, bake parameters, attributes, a cell's facts)."""

from __future__ import annotations

import json

from ...model import CellChain, Level, LodChain
from ..frame import ROTATION, SceneFrame
from ..numbers import format_exact
from .xmltext import XmlOut, mfstring

METADATA_SET = "lodconvert"
"""Name of the ``MetadataSet`` of a chain, a level or a LOD parent."""
FRAME_METADATA = "lodconvert_frame"
"""Name of the scene frame Transform's ``MetadataSet``: the scene origin and rotation."""

Metadata = tuple[str, str, str]
"""One metadata entry: node type (``MetadataDouble`` …), name, value as X3D field text."""


def frame_metadata(out: XmlOut, frame: SceneFrame) -> None:
    """The scene frame's ``MetadataSet``: its origin (float64), rotation (row-major), axes and
    how to get source coordinates back."""
    record = frame.record()
    with out.node("MetadataSet", {"name": FRAME_METADATA, "containerField": "metadata"}):
        out.leaf("MetadataDouble", {"name": "origin", "value": format_exact(frame.origin)})
        out.leaf("MetadataDouble", {"name": "rotation", "value": format_exact(ROTATION.ravel())})
        for name in ("axes", "meaning"):
            out.leaf("MetadataString", {"name": name, "value": mfstring([record[name]])})


def metadata_set(out: XmlOut, entries: list[Metadata]) -> None:
    """A ``MetadataSet`` named :data:`METADATA_SET` holding ``entries``."""
    with out.node("MetadataSet", {"name": METADATA_SET, "containerField": "metadata"}):
        for tag, name, value in entries:
            out.leaf(tag, {"name": name, "value": value})


def _switching_metadata(item: LodChain | CellChain) -> list[Metadata]:
    """α, β, γ, exponents, cutoffs and culling of a chain or a LOD parent."""
    return [
        ("MetadataDouble", "alpha", format_exact([item.alpha])),
        ("MetadataDouble", "beta", format_exact([item.beta])),
        ("MetadataDouble", "gamma", format_exact([item.gamma])),
        ("MetadataDouble", "xs", format_exact(item.xs)),
        ("MetadataDouble", "cutoffs", format_exact(item.cutoffs)),
        ("MetadataBoolean", "culled", "true" if item.culled else "false"),
    ]


def chain_metadata(chain: LodChain) -> list[Metadata]:
    """A chain's id, switching, placement (an instance's) and attributes."""
    entries = [
        ("MetadataString", "object_id", mfstring([chain.object_id])),
        *_switching_metadata(chain),
    ]
    if chain.transform is not None:
        entries.append(("MetadataDouble", "transform", format_exact(chain.transform.ravel())))
    if chain.metadata:
        attributes = json.dumps(chain.metadata, sort_keys=True, default=str, ensure_ascii=False)
        entries.append(("MetadataString", "attributes", mfstring([attributes])))
    return entries


def level_metadata(level: Level, switch_in: float, switch_out: float | None) -> list[Metadata]:
    """A level's name, kind, counts, the distances it shows between and how it was baked."""
    entries = [
        ("MetadataString", "level", mfstring([level.name])),
        ("MetadataString", "kind", mfstring([level.kind])),
        ("MetadataInteger", "count", str(level.count)),
        ("MetadataDouble", "switch_in", format_exact([switch_in])),
    ]
    if switch_out is not None:
        entries.append(("MetadataDouble", "switch_out", format_exact([switch_out])))
    if level.mesh is not None:
        entries.append(("MetadataInteger", "triangles", str(len(level.mesh.faces))))
    if level.params is not None:
        entries += [
            ("MetadataInteger", "resolution", str(level.params.resolution)),
            ("MetadataInteger", "slices", str(level.params.slices)),
            ("MetadataDouble", "point_size_px", format_exact([level.params.point_size])),
            ("MetadataString", "filter", mfstring([level.params.filter])),
        ]
    if level.spacing is not None:
        entries.append(("MetadataDouble", "spacing", format_exact([level.spacing])))
    if level.design_distance is not None:
        entries.append(("MetadataDouble", "design_distance", format_exact([level.design_distance])))
    return entries


def cell_metadata(cell: CellChain) -> list[Metadata]:
    """A LOD parent's id, tier, grid cell, switching, members and facts."""
    facts = json.dumps(cell.facts, sort_keys=True, default=str, ensure_ascii=False)
    return [
        ("MetadataString", "cell_id", mfstring([cell.cell_id])),
        ("MetadataInteger", "tier", str(cell.tier)),
        ("MetadataDouble", "size", format_exact([cell.size])),
        ("MetadataInteger", "key", " ".join(map(str, cell.key))),
        *_switching_metadata(cell),
        ("MetadataString", "members", mfstring(cell.member_ids())),
        ("MetadataString", "facts", mfstring([facts])),
    ]
