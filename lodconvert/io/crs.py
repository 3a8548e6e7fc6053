"""Coordinate reference systems of city models: the declared EPSG CRS, the local metric frame
that geographic coordinates (latitude, longitude, height) are projected into, the pyproj CRS a
name stands for, and which vertical reference the heights are in."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import LodConvertError, UsageError

_EPSG = re.compile(r"(?:EPSG(?:/[\d.]+/|:[\d.]*:|:)|(?<=\d)\+)(\d+)", re.IGNORECASE)
"""EPSG codes in a URN, URL or ``EPSG:code`` name (``EPSG:h+v`` names a vertical CRS too)."""
_CODE_DIGITS = 9
"""Digits of the longest EPSG code read as one; a name with a longer one is no EPSG name."""
_SHOWN = 80
"""Characters of a CRS name a message shows."""


NOT_DECLARED = "as in the source, not declared"
"""The vertical reference of heights whose CRS says none (a 2-D CRS, or no CRS)."""


class CrsError(LodConvertError):
    """Coordinates that the CRS they are declared in cannot hold, or that cannot be transformed
    into the output's CRS: the whole input is wrong, not one object (exit code 1)."""


@dataclass(frozen=True)
class LocalFrame:
    """A transverse Mercator centred on geographic data (``lat0``, ``lon0`` in degrees) on the
    source's ellipsoid: metres east, north and the source's height."""

    source_crs: str
    lat0: float
    lon0: float
    semi_major: float
    inverse_flattening: float
    lat_axis: int
    lon_axis: int

    @property
    def proj(self) -> str:
        """The frame's PROJ definition."""
        return (
            f"+proj=tmerc +lat_0={self.lat0:.9f} +lon_0={self.lon0:.9f} +k=1 +x_0=0 +y_0=0 "
            f"+a={self.semi_major!r} +rf={self.inverse_flattening!r} +units=m +no_defs"
        )

    def record(self) -> dict[str, Any]:
        """What the scene's attributes keep of the frame (JSON-able)."""
        return {"proj": self.proj, "source_crs": self.source_crs, "center": [self.lat0, self.lon0]}

    def project(self, points: np.ndarray) -> np.ndarray:
        """``points`` (n, 3) in the source's axis order, in this frame's metres."""
        x, y = frame_pipeline(self.proj).transform(
            points[:, self.lon_axis], points[:, self.lat_axis]
        )
        return np.stack([x, y, points[:, 2]], axis=1)


def frame_pipeline(proj: str) -> Any:
    """The local frame of PROJ definition ``proj`` (:attr:`LocalFrame.proj`) as a pyproj
    transformer from longitude, latitude in degrees to its metres east and north."""
    import pyproj

    return pyproj.Transformer.from_pipeline(
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
        f"+step {proj.replace(' +units=m +no_defs', '')}"
    )


@dataclass
class Crs:
    """The document's CRS: its EPSG name (horizontal part), vertical part, and the local frame
    geographic coordinates are projected into (set from the first object's coordinates)."""

    name: str | None = None
    vertical: str | None = None
    geographic: Any = None
    frame: LocalFrame | None = None
    where: str = ""
    """The file whose coordinates these are (named by messages)."""

    @classmethod
    def of(cls, srs_name: str, where: str = "") -> Crs:
        codes = _EPSG.findall(srs_name)
        if not codes or max(len(code) for code in codes) > _CODE_DIGITS:
            return cls(name=srs_name, where=where)
        vertical = f"EPSG:{codes[1]}" if len(codes) > 1 else None
        crs = cls(name=f"EPSG:{codes[0]}", vertical=vertical, where=where)
        crs.geographic = _geographic(int(codes[0]))
        return crs

    @property
    def scene_crs(self) -> str | None:
        """What outputs record: the local frame's PROJ definition, else the EPSG name."""
        return self.frame.proj if self.frame is not None else self.name

    def to_metric(self, points: np.ndarray, first: int | None = None) -> np.ndarray:
        """``points`` in metres: projected onto the local frame when geographic (the frame is
        centred on the first call's points, or on its first ``first`` of them, those within
        range: :meth:`beyond_range`; :class:`CrsError` where most are not, as the CRS is then
        not the one they are in). A point beyond range becomes infinite."""
        if self.geographic is None or not len(points):
            return points
        if self.frame is None:
            lat_axis, lon_axis = self.geographic["axes"]
            centred = points[:first] if first else points
            inside = centred[~self._beyond(centred)]
            if 2 * len(inside) < len(centred):
                center = (centred.min(axis=0) + centred.max(axis=0)) / 2.0
                raise CrsError(
                    f"its coordinates are not latitude and longitude, as {self.name} has them "
                    f"(the first object lies at {center[lat_axis]:.6g}, {center[lon_axis]:.6g}); "
                    "the CRS declared or given with --crs is not the one they are in",
                    self.where or None,
                )
            center = (inside.min(axis=0) + inside.max(axis=0)) / 2.0
            self.frame = LocalFrame(
                self.name or "",
                float(np.round(center[lat_axis], 6)),
                float(np.round(center[lon_axis], 6)),
                self.geographic["a"],
                self.geographic["rf"],
                lat_axis,
                lon_axis,
            )
        return self.frame.project(points)

    def beyond_range(self, points: np.ndarray) -> str | None:
        """For a geographic CRS, why ``points`` ((n, 3) in its axis order) are not latitude and
        longitude in it: the first beyond ±90° latitude or ±180° longitude, named; else None."""
        if self.geographic is None or not len(points):
            return None
        beyond = self._beyond(points)
        if not beyond.any():
            return None
        point = points[int(np.argmax(beyond))]
        lat_axis, lon_axis = self.geographic["axes"]
        if abs(point[lat_axis]) > 90.0:
            return f"has latitude {point[lat_axis]:.6g}, beyond ±90° ({self.name})"
        return f"has longitude {point[lon_axis]:.6g}, beyond ±180° ({self.name})"

    def _beyond(self, points: np.ndarray) -> np.ndarray:
        """Which of ``points`` lie beyond ±90° latitude or ±180° longitude (a geographic CRS)."""
        lat_axis, lon_axis = self.geographic["axes"]
        return (np.abs(points[:, lat_axis]) > 90.0) | (np.abs(points[:, lon_axis]) > 180.0)


def _geographic(code: int) -> dict[str, Any] | None:
    """For a geographic (or geographic + vertical) EPSG CRS: the latitude and longitude axis
    indices and its ellipsoid; None for any other (or an unknown) code."""
    import pyproj

    try:
        crs = pyproj.CRS.from_epsg(code)
    except pyproj.exceptions.CRSError:
        return None
    horizontal = crs.sub_crs_list[0] if crs.is_compound else crs
    if not horizontal.is_geographic or horizontal.ellipsoid is None:
        return None
    directions = [axis.direction for axis in horizontal.axis_info]
    return {
        "axes": (directions.index("north"), directions.index("east")),
        "a": horizontal.ellipsoid.semi_major_metre,
        "rf": horizontal.ellipsoid.inverse_flattening,
    }


def crs_attributes(crs: Crs | None) -> dict[str, Any]:
    """What a scene's attributes record of its CRS beyond its name: the vertical CRS and the
    local frame of a geographic CRS, where there are."""
    attributes: dict[str, Any] = {}
    if crs is not None and crs.vertical:
        attributes["vertical_crs"] = crs.vertical
    if crs is not None and crs.frame is not None:
        attributes["local_frame"] = crs.frame.record()
    return attributes


def pyproj_crs(name: str, vertical: str | None = None) -> Any:
    """The pyproj CRS that ``name`` (with the vertical CRS ``vertical``, where given) stands
    for; raises pyproj's ``CRSError`` where it knows none."""
    import pyproj

    crs = pyproj.CRS.from_user_input(name)
    if vertical is None:
        return crs
    height = pyproj.CRS.from_user_input(vertical)
    try:
        return pyproj.crs.CompoundCRS(f"{crs.name} + {height.name}", [crs, height])
    except pyproj.exceptions.CRSError:
        raise pyproj.exceptions.CRSError(
            f"proj_create: {name} + {vertical} is no compound CRS: {vertical} is not vertical "
            f"or {name} has heights of its own"
        ) from None


def checked_crs_option(text: str) -> str:
    """``text``, the CRS a user names (``--crs``), when pyproj knows it; :class:`UsageError`
    otherwise."""
    import pyproj

    crs = Crs.of(text)
    try:
        pyproj_crs(crs.name or text, crs.vertical)
    except pyproj.exceptions.CRSError as exc:
        reason = str(exc).split("proj_create: ")[-1].rstrip(")") or "unknown"
        raise UsageError(
            f"{_shortened(text)!r} names no CRS that pyproj knows ({_shortened(reason)})", "crs"
        ) from None
    return text


def _shortened(text: str) -> str:
    """``text``, cut to :data:`_SHOWN` characters."""
    return text if len(text) <= _SHOWN else text[: _SHOWN - 1] + "…"


def vertical_reference(crs: Any) -> str:
    """Which heights a pyproj CRS (or None) holds: its vertical CRS's name and code where it is
    compound, ``ellipsoidal (<ellipsoid>)`` for a 3-D geographic or projected CRS, else
    :data:`NOT_DECLARED`."""
    if crs is None:
        return NOT_DECLARED
    if crs.is_compound:
        height = crs.sub_crs_list[-1]
        code = height.to_authority()
        return f"{height.name} ({':'.join(code)})" if code else height.name
    if len(crs.axis_info) == 3 and crs.ellipsoid is not None:
        return f"ellipsoidal ({crs.ellipsoid.name})"
    return NOT_DECLARED
