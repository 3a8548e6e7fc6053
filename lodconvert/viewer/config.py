"""What the viewer page needs to know about an output, read back by the output's own format
(:func:`lodconvert.io.read_chains`, without geometry, and the format's ``read_cells``): per
object its id, attributes, centre, diagonal, cutoffs, levels and point sizes, its cell and the
nodes the page drives; per cell its tier, centre, cutoffs, members and far level. Centres are
in the file's scene coordinates, where the page draws (:mod:`lodconvert.io.frame`), and the
first view stands along +z, tilted :data:`PITCH_DEG` up for a y-up city. Each field:
``docs/viewer.md``.

Raises :class:`~lodconvert.errors.InputError` for files lodconvert did not write.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..io import own_format, read_chains
from ..io.frame import ROTATION
from ..model import LodChain
from ..ranges import REFERENCE_VIEW

FORMAT_KINDS = {"x3d": "x3d", "gltf": "gltf"}
"""Registry format name → the page script that shows it."""
PITCH_DEG = 35.0
"""How far above the horizon the page first views a georeferenced (y-up) scene."""


def _point_size(px: float | None, distance: float | None) -> dict[str, float] | None:
    """How the page sizes a point level: ``px`` pixels wide at ``distance``; ``None`` for a
    mesh level (no point size) or one without a design distance."""
    return {"px": px, "distance": distance} if px is not None and distance else None


def _object(chain: LodChain, fmt: str) -> dict[str, Any]:
    """The viewer entry of one chain read back by the format named ``fmt``, whose
    ``read_back`` keeps where the chain lies in the file under ``chain.metadata[fmt]``, beside
    the object's attributes."""
    entry: dict[str, Any] = {
        "id": chain.object_id,
        "attributes": {k: v for k, v in chain.metadata.items() if k != fmt},
        "center": (chain.origin + chain.center).tolist(),
        "local_center": np.asarray(chain.center, dtype=np.float64).tolist(),
        "alpha": chain.alpha,
        "cutoffs": list(chain.cutoffs),
        "culled": chain.culled,
        "levels": [level.name for level in chain.levels],
        "points": [
            _point_size(level.params.point_size if level.params else None, level.design_distance)
            for level in chain.levels
        ],
        "cell": None,
    }
    entry.update(chain.metadata.get(fmt, {}))
    return entry


def _cell(cell: dict[str, Any], fmt: str) -> dict[str, Any]:
    """The viewer entry of one LOD parent as the format named ``fmt`` reads it
    (``read_cells``, which keeps where the cell lies in the file under ``cell[fmt]``)."""
    far = cell["far"]
    entry: dict[str, Any] = {
        "id": cell["cell_id"],
        "tier": cell["tier"],
        "center": [float(v) for v in cell["center"]],
        "cutoffs": list(cell["cutoffs"]),
        "culled": cell["culled"],
        "members": list(cell["members"]),
        "kind": cell["facts"].get("kind"),
        "points": _point_size(far.get("point_size_px"), far.get("design_distance")),
        "parent": None,
    }
    entry.update(cell[fmt])
    return entry


def _finer_cell(
    cells: list[dict[str, Any]], by_id: dict[str, int], holder: int, member: str
) -> int | None:
    """The index of the cell that ``member`` of cell ``holder`` is: one of a lower tier named
    so; ``None`` for an object."""
    index = by_id.get(member)
    return index if index is not None and cells[index]["tier"] < cells[holder]["tier"] else None


def _members(
    cells: list[dict[str, Any]], by_id: dict[str, int], holders: list[int]
) -> Iterator[tuple[int, str, int | None]]:
    """Each member of the cells ``holders`` and of the finer cells among their members, in
    document order: the index of the cell holding it, its id and, for a finer cell, its index."""
    for holder in holders:
        for member in cells[holder]["members"]:
            finer = _finer_cell(cells, by_id, holder, member)
            yield holder, member, finer
            if finer is not None:
                yield from _members(cells, by_id, [finer])


def _link(objects: list[dict[str, Any]], cells: list[dict[str, Any]], path: Path) -> None:
    """Set each cell's ``parent`` and each object's ``cell``: the index of the cell that holds
    it as a member (``None`` for one that no cell holds). Objects and cells are in document
    order, so an object member is the next object of its id."""
    by_id = {cell["id"]: i for i, cell in enumerate(cells)}
    held = {
        _finer_cell(cells, by_id, holder, member)
        for holder, cell in enumerate(cells)
        for member in cell["members"]
    }
    outermost = [i for i in range(len(cells)) if i not in held]
    following = 0  # the objects before it are placed
    for holder, member, cell in _members(cells, by_id, outermost):
        if cell is not None:
            cells[cell]["parent"] = holder
            continue
        found = next(
            (k for k in range(following, len(objects)) if objects[k]["id"] == member), None
        )
        if found is None:
            message = f"cell {cells[holder]['id']!r} names a member {member!r} it does not hold"
            raise InputError(message, str(path))
        objects[found]["cell"] = holder
        following = found + 1


def page_config(path: Path) -> dict[str, Any]:
    """The page's configuration (without the asset URL): format, reference view, objects and
    cells (none for a file without LOD parents)."""
    path = Path(path)
    entry = own_format(path)
    kind = FORMAT_KINDS.get(entry.name)
    if kind is None:
        raise InputError("has no viewer page", str(path))
    if not path.is_file():
        raise InputError("no such file", str(path))
    objects = [_object(chain, entry.name) for chain in read_chains(path, geometry=False)]
    if not objects:
        raise InputError("holds no LOD chain written by lodconvert", str(path))
    found = entry.read_cells(path) if entry.read_cells is not None else []
    cells = [_cell(cell, entry.name) for cell in found]
    _link(objects, cells, path)
    frame = entry.read_frame(path) if entry.read_frame is not None else None
    rotation, direction = np.eye(3), [0.0, 0.0, 1.0]
    if frame is not None:
        rotation, pitch = ROTATION, np.radians(PITCH_DEG)
        direction = [0.0, float(np.sin(pitch)), float(np.cos(pitch))]
        for placed in (*objects, *cells):
            placed["center"] = (ROTATION @ (np.asarray(placed["center"]) - frame.origin)).tolist()
    view = {
        "height_px": REFERENCE_VIEW.height_px,
        "fov_y_deg": REFERENCE_VIEW.fov_y_deg,
        "direction": direction,
    }
    return {
        "format": kind,
        "view": view,
        "rotation": rotation.tolist(),
        "objects": objects,
        "cells": cells,
    }
