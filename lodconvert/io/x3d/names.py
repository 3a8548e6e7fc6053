"""DEF names: each object gets a base made an XML NCName from its id, numbered where another
object has it, and every node of the object is named from that base (its LOD, level Groups and
their Appearances, and with prism switching its Switches, sensors and triggers)."""

from __future__ import annotations

import re
from dataclasses import astuple

from ...model import Level
from .prism import hidden_name, regions

_NOT_NCNAME = re.compile(r"[^A-Za-z0-9_.\-]")


def appearance_name(level_def: str) -> str:
    """DEF of the ``Appearance`` shared by the Shapes of the level ``Group`` ``level_def``."""
    return f"{level_def}_Appearance"


def _ncname(object_id: str) -> str:
    """``object_id`` made an XML NCName: the DEF base it gets when no other object has it."""
    base = _NOT_NCNAME.sub("_", object_id) or "_"
    return base if base[0].isalpha() or base[0] == "_" else "_" + base


def derived_names(
    candidate: str, levels: list[Level], region_count: int | None
) -> tuple[list[str], list[str]]:
    """The level DEFs of an object whose DEF base is ``candidate``, and every name that base
    takes (itself, LOD, level Groups and their Appearances; with prism switching, the Switch
    hiding the LOD and the nodes of ``region_count`` regions)."""
    level_defs = [f"{candidate}_{lv.name}" for lv in levels]
    names = [
        candidate,
        f"{candidate}_LOD",
        f"{candidate}_instance",
        *level_defs,
        *map(appearance_name, level_defs),
    ]
    if region_count is not None:
        names.append(hidden_name(candidate))
        names += [name for region in regions(candidate, region_count) for name in astuple(region)]
    return level_defs, names


def unique_names(
    object_id: str, used: set[str], levels: list[Level], region_count: int | None = None
) -> tuple[str, list[str]]:
    """A DEF base (an XML NCName) for ``object_id`` whose derived names
    (:func:`derived_names`) are not yet in ``used``, and the level DEFs; all are added to
    ``used``."""
    base = _ncname(object_id)
    candidate, n = base, 1
    while True:
        level_defs, names = derived_names(candidate, levels, region_count)
        if not used.intersection(names):
            used.update(names)
            return candidate, level_defs
        n += 1
        candidate = f"{base}_{n}"
