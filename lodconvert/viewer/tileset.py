"""What the CesiumJS page of a 3D Tiles tileset needs to know, read from the tileset lodconvert
wrote (its ``asset.extras.lodconvert``): the ``maximumScreenSpaceError`` its geometricError is
made for (``--sse``), the ``pointCloudShading`` that sizes its point tiles as baked (absent
without point tiles), the reference view, its CRS and how its heights were taken.

Raises :class:`~lodconvert.errors.InputError` for a tileset lodconvert did not write.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.tiles import written_by_lodconvert


def tileset_config(path: Path) -> dict[str, Any]:
    """The page's configuration of the tileset ``path`` (without the asset URL)."""
    try:
        asset = json.loads(Path(path).read_bytes()).get("asset", {})
    except FileNotFoundError:
        raise InputError("no such file", str(path)) from None
    except (OSError, ValueError, AttributeError) as error:
        raise InputError(f"is not a tileset lodconvert can read ({error})", str(path)) from None
    extras = asset.get("extras", {}).get("lodconvert") if isinstance(asset, dict) else None
    if not written_by_lodconvert(asset.get("generator")) or not isinstance(extras, dict):
        raise InputError("is not a tileset lodconvert wrote (its asset.generator)", str(path))
    return {
        "format": "tiles",
        "sse": extras["sse"],
        "pointCloudShading": extras.get("point_cloud_shading"),
        "view": extras["view"],
        "crs": extras.get("crs"),
        "heights": extras.get("heights"),
    }
