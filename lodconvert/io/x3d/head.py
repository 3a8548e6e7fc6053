"""The ``X3D`` root element's fields (profile per switching mode, schema) and the document's
``head``: the components needed beyond the profile and the ``meta`` entries that say what the
file holds and how to read it (generator, source, CRS, reference view, switching, ranges)."""

from __future__ import annotations

import json

from .. import OutputInfo
from .xmltext import XmlOut

XSI = "http://www.w3.org/2001/XMLSchema-instance"
SCHEMA_URL = "https://www.web3d.org/specifications/x3d-4.0.xsd"
COMPONENTS = (("Navigation", 2), ("Rendering", 4), ("Shape", 5))
"""Beyond the Interchange profile: LOD needs Navigation 2, ColorRGBA alpha is guaranteed from
Rendering 4, PointProperties needs Shape 5."""

SWITCHING_MODES = ("lod", "prism")
"""How levels switch: ``lod``, by distance from the object's centre (an X3D ``LOD``); ``prism``,
on boxes around the object (:mod:`.prism`)."""
PROFILES = {"lod": "Interchange", "prism": "Interactive"}
"""The X3D profile per switching mode. Prism switching's ProximitySensor, BooleanFilter and
IntegerTrigger are in Interactive (EnvironmentalSensor 1, EventUtilities 1), which holds all of
Interchange. A profile, not component statements: a script adding a component the scene
already declares fails in X_ITE (lodconvert's viewer page adds EnvironmentalSensor)."""

_PRISM_TEXT = (
    "each object's levels switch on nested ProximitySensor boxes, the finest level's bounding "
    "box grown by each LOD range on every side, driving Switch nodes through BooleanFilter and "
    "IntegerTrigger; the LOD inside a Switch with whichChoice -1 lists the levels and is not drawn"
)


def root_fields(switching: str) -> dict[str, str]:
    """The ``X3D`` element's fields for levels switching as ``switching`` says."""
    return {
        "xmlns:xsd": XSI,
        "profile": PROFILES[switching],
        "version": "4.0",
        "xsd:noNamespaceSchemaLocation": SCHEMA_URL,
    }


def write_head(out: XmlOut, info: OutputInfo, switching: str) -> None:
    """The ``head``: :data:`COMPONENTS`, then a ``meta`` per fact of ``info`` and per rule a
    reader needs (switching, LOD ranges, point sizes)."""
    view = info.view
    meta = [
        ("generator", info.generator),
        ("source", info.source),
        *([("crs", info.crs)] if info.crs else []),
        *([("vertical-reference", info.vertical)] if info.vertical else []),
        (
            "reference-view",
            f"{view.height_px} px high viewport, {view.fov_y_deg:g} degree vertical field of "
            f"view (focal length {view.focal_px:.2f} px)",
        ),
        ("switching", switching),
        *([("prism-switching", _PRISM_TEXT)] if switching == "prism" else []),
        (
            "lod-ranges",
            "LOD range values are distances in scene units from the LOD center at which the next "
            "coarser child takes over: Y = alpha * beta * gamma^x (alpha = bounding-box "
            "diagonal); after the last range of a culled object an empty Group shows nothing",
        ),
        (
            "point-size",
            "PointSet points are point_size_px pixels wide at design_distance in the reference "
            "view and scale with 1/distance (PointProperties attenuation 0 b 0)",
        ),
        *(
            [("options", json.dumps(info.options, sort_keys=True, default=str))]
            if info.options
            else []
        ),
    ]
    with out.node("head"):
        for name, level in COMPONENTS:
            out.leaf("component", {"name": name, "level": str(level)})
        for name, content in meta:
            out.leaf("meta", {"name": name, "content": content})
