"""Where a tileset's content lies on the globe: scene coordinates (metres in the scene's CRS, or
in the local frame a geographic CRS was projected onto) → ECEF (EPSG:4978) with pyproj, vertex
by vertex in float64, and the east-north-up frame of each tile at its origin.

No projected offset is taken for metres east or north: a tile's frame is the ENU frame at its
origin's ECEF position, and each vertex is its own ECEF position expressed in that frame.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from ...errors import LodConvertError
from ..crs import NOT_DECLARED, frame_pipeline, vertical_reference

ECEF = "EPSG:4978"
GEODETIC = "EPSG:4979"
UNDECLARED = "heights of no declared vertical CRS"


class Placement:
    """Scene coordinates of one georeferenced scene → ECEF, and ENU frames there."""

    def __init__(self, georef: Any, crs_name: str | None, source: str) -> None:
        """``georef``: the scene's :class:`~lodconvert.reproject.Georef` (``None`` where it has
        none, or one pyproj does not know: ``crs_name`` then says which). Raises a one-line
        :class:`LodConvertError` naming ``source`` where the scene cannot be placed."""
        import pyproj

        if georef is None:
            reason = (
                "declares no CRS, so it cannot be placed on the globe (--crs EPSG:… names it)"
                if crs_name is None
                else f"its CRS {crs_name} is no CRS pyproj knows: it cannot be placed on the globe"
            )
            raise LodConvertError(f"{reason}; a 3D Tiles tileset needs one", source)
        self.source = source
        self.label = georef.label
        self.back = frame_pipeline(georef.frame) if georef.frame else None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # pyproj's own warning of missing grids
                self.transformer = pyproj.Transformer.from_crs(georef.crs, ECEF, always_xy=True)
                group = pyproj.transformer.TransformerGroup(georef.crs, ECEF, always_xy=True)
        except pyproj.exceptions.ProjError as exc:
            reason = str(exc).splitlines()[0].split("Internal Proj Error: ")[-1].rstrip(")")
            raise self._refused(reason.removeprefix("proj_create_operations: ")) from None
        self.geodetic = pyproj.Transformer.from_crs(ECEF, GEODETIC, always_xy=True)
        self.ballpark_heights = bool(group.transformers) and all(
            "ballpark vertical" in t.description.lower() for t in group.transformers
        )
        self.vertical = _vertical(georef.crs)

    def _refused(self, reason: str) -> LodConvertError:
        """The one-line error of a CRS that cannot be placed in ECEF, for ``reason``."""
        return LodConvertError(
            f"its CRS {self.label} cannot be placed on the globe (ECEF, {ECEF}): {reason}",
            self.source,
        )

    def ecef(self, points: np.ndarray) -> np.ndarray:
        """``points`` (n, 3) scene coordinates as ECEF metres (float64)."""
        x, y, z = (np.array(points[:, k], dtype=np.float64) for k in range(3))
        if self.back is not None:
            x, y = self.back.transform(x, y, direction="INVERSE")
        x, y, z = self.transformer.transform(x, y, z)
        out = np.stack([x, y, z], axis=1)
        if not np.isfinite(out).all():
            raise self._refused("some coordinates lie outside the area where it is defined")
        return out

    def enu_frame(self, ecef_origin: np.ndarray) -> np.ndarray:
        """The 4×4 east-north-up frame at ``ecef_origin`` (columns: east, north, up, origin)."""
        lon, lat, _ = self.geodetic.transform(*(float(v) for v in ecef_origin))
        lam, phi = math.radians(lon), math.radians(lat)
        sin_l, cos_l, sin_p, cos_p = math.sin(lam), math.cos(lam), math.sin(phi), math.cos(phi)
        frame = np.eye(4)
        frame[:3, 0] = (-sin_l, cos_l, 0.0)
        frame[:3, 1] = (-sin_p * cos_l, -sin_p * sin_l, cos_p)
        frame[:3, 2] = (cos_p * cos_l, cos_p * sin_l, sin_p)
        frame[:3, 3] = ecef_origin
        return frame

    def heights(self) -> str:
        """What the tileset says of its heights (``asset.extras``)."""
        if self.ballpark_heights:
            return (
                f"{self.vertical}: taken as heights above the WGS 84 ellipsoid (PROJ has "
                "no geoid grid here): content sits lower or higher by the geoid undulation"
            )
        if self.vertical == UNDECLARED:
            return f"{UNDECLARED}, taken as heights above the ellipsoid"
        return f"{self.vertical}, converted to ECEF by PROJ"


def _vertical(crs: Any) -> str:
    """The vertical reference of a pyproj CRS's heights, as the tileset names it."""
    found = vertical_reference(crs)
    return UNDECLARED if found == NOT_DECLARED else found


def world_to_frame(frame: np.ndarray, ecef: np.ndarray) -> np.ndarray:
    """ECEF points (n, 3) in the coordinates of ``frame`` (4×4, orthonormal)."""
    return (ecef - frame[:3, 3]) @ frame[:3, :3]
