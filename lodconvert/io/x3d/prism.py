"""Prism switching (ProxyPrismLOD's box regions): an object's levels drawn by nested ``Switch`` es
that ProximitySensor boxes set through a BooleanFilter and two IntegerTriggers each, without a
``Script``; box ``k`` is the finest level's bounding box grown by ``cutoffs[k]`` on every side.
The node layout and why it is so: ``docs/x3d.md``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model import LodChain
from ..numbers import format_exact
from .xmltext import XmlOut


@dataclass(frozen=True)
class Region:
    """DEFs of the nodes that switch an object's levels at one of its cutoffs (prism switching):
    the box's ``ProximitySensor``, the ``BooleanFilter`` splitting its ``isActive``, the
    ``IntegerTrigger`` s sending the near and the far choice, and the ``Switch`` they set."""

    sensor: str
    filter: str
    inside: str
    outside: str
    switch: str


NEAR_CHOICE, FAR_CHOICE = 0, 1
"""A prism Switch's choices: the level inside its box, and what shows outside it."""


def regions(base: str, count: int) -> list[Region]:
    """The DEFs of the first ``count`` regions of the object whose DEF base is ``base``."""
    roles = ("Prism", "Filter", "Inside", "Outside", "Switch")
    return [Region(*(f"{base}_{role}{k}" for role in roles)) for k in range(count)]


def hidden_name(base: str) -> str:
    """DEF of the ``Switch`` that holds the ``LOD`` of a prism-switched object, undrawn."""
    return f"{base}_levels"


def _finest_box(chain: LodChain) -> np.ndarray:
    """(2, 3) min and max corner of ``chain``'s finest level in its frame: the vertices its
    faces use, or its points; the chain centre (a box of no size) when it has neither."""
    finest = chain.levels[0]
    if finest.mesh is not None and finest.mesh.vertex_count:
        return finest.mesh.bounds
    if finest.points is not None and len(finest.points):
        positions = finest.points.positions
        return np.stack([positions.min(axis=0), positions.max(axis=0)])
    return np.stack([chain.center, chain.center]).astype(np.float64)


def prism_boxes(chain: LodChain) -> list[tuple[np.ndarray, np.ndarray]]:
    """Centre and size of each of ``chain``'s switching boxes, nearest first: its finest level's
    bounding box (:func:`_finest_box`) grown by each cutoff on every side."""
    low, high = _finest_box(chain)
    return [((low + high) / 2, high - low + 2 * cutoff) for cutoff in chain.cutoffs]


def write_prism(out: XmlOut, chain: LodChain, regions: list[Region], level_defs: list[str]) -> None:
    """The nodes that draw a chain's levels on boxes: the nested Switches, then each box's
    sensor, filter, triggers and the ROUTEs between them."""
    _write_switches(out, regions, level_defs)
    for region, (centre, size) in zip(regions, prism_boxes(chain), strict=True):
        box = {"center": format_exact(centre), "size": format_exact(size)}
        out.leaf("ProximitySensor", {"DEF": region.sensor, **box})
        out.leaf("BooleanFilter", {"DEF": region.filter})
        out.leaf("IntegerTrigger", {"DEF": region.inside, "integerKey": str(NEAR_CHOICE)})
        out.leaf("IntegerTrigger", {"DEF": region.outside, "integerKey": str(FAR_CHOICE)})
        for route in _routes(region):
            out.leaf("ROUTE", route)


def _write_switches(out: XmlOut, regions: list[Region], level_defs: list[str]) -> None:
    """One ``Switch`` per region, each holding the next: its near choice ``USE`` s the level
    inside its box, its far choice is the next Switch; past the last region, the remaining
    level (an empty ``Group`` when none remains: a culled chain). Each starts at its far choice."""
    if not regions:
        out.leaf("Group", {"USE": level_defs[0]} if level_defs else {})
        return
    with out.node("Switch", {"DEF": regions[0].switch, "whichChoice": str(FAR_CHOICE)}):
        out.leaf("Group", {"USE": level_defs[0]})
        _write_switches(out, regions[1:], level_defs[1:])


def _routes(region: Region) -> list[dict[str, str]]:
    """The ROUTEs of one region: ``isActive`` into the filter, its true and false outputs into
    the near and far triggers, and both triggers into the Switch's ``whichChoice``."""
    connections = (
        (region.sensor, "isActive", region.filter, "set_boolean"),
        (region.filter, "inputTrue", region.inside, "set_boolean"),
        (region.filter, "inputFalse", region.outside, "set_boolean"),
        (region.inside, "triggerValue", region.switch, "set_whichChoice"),
        (region.outside, "triggerValue", region.switch, "set_whichChoice"),
    )
    keys = ("fromNode", "fromField", "toNode", "toField")
    return [dict(zip(keys, connection, strict=True)) for connection in connections]
