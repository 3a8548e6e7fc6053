"""What the CesiumJS page of a 3D Tiles tileset needs to know, read from the tileset lodconvert
wrote (its ``asset.extras.lodconvert``): the ``maximumScreenSpaceError`` its geometricError is
made for (``--sse``), the ``pointCloudShading`` that sizes its point tiles as baked (absent
without point tiles), the reference view, its CRS and how its heights were taken.

Raises :class:`~lodconvert.errors.InputError` for a tileset lodconvert did not write, and for
one the page's browser should not be sent into: every tileset JSON is read and walked as
``lodconvert validate`` reads it (:mod:`lodconvert.io.tiles.tree`), and the first file over
the run's limits or not JSON, content URI that names no file inside the tileset's folder (a
link out of it, ``../``, an absolute path, a URL) or cycle of external tilesets refuses it in
one line naming the file and the tile.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.tiles import written_by_lodconvert
from ..io.tiles.tree import Problem, walk
from ..limits import DEFAULT_LIMITS, Limits


def _refuse(problem: Problem) -> None:
    raise problem.error()


def _extras(document: Any) -> dict[str, Any] | None:
    """``asset.extras.lodconvert`` of a tileset JSON lodconvert wrote, else ``None``."""
    asset = document.get("asset") if isinstance(document, dict) else None
    if not isinstance(asset, dict) or not written_by_lodconvert(asset.get("generator")):
        return None
    extras = asset.get("extras")
    extras = extras.get("lodconvert") if isinstance(extras, dict) else None
    return extras if isinstance(extras, dict) and {"sse", "view"} <= extras.keys() else None


def tileset_config(path: Path, limits: Limits = DEFAULT_LIMITS) -> dict[str, Any]:
    """The page's configuration of the tileset ``path`` (without the asset URL)."""
    path = Path(path)
    extras: dict[str, Any] | None = None
    for tile in walk(path, _refuse, limits):
        if extras is None:  # the top file's root comes first: a stranger's is not walked
            extras = _extras(tile.tileset)
            if extras is None:
                raise InputError(
                    "is not a tileset lodconvert wrote (its asset.generator)", str(path)
                )
    assert extras is not None  # the walk yields the top root or raises
    return {
        "format": "tiles",
        "sse": extras["sse"],
        "pointCloudShading": extras.get("point_cloud_shading"),
        "view": extras["view"],
        "crs": extras.get("crs"),
        "heights": extras.get("heights"),
    }
