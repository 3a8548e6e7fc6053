"""The scene frame of georeferenced output: glTF and X3D are +Y up, and engines hold node
matrices in float32, so a city model's scene (with or without a CRS) or one with a CRS is
written turned z-up → y-up about one scene origin.

Scene (file) coordinates are ``ROTATION · (source − origin)``: ``ROTATION`` maps the source's
(x, y, z) to (x, z, −y), so east stays +x, up becomes +y and north −z. ``origin`` is the input's
first object's bounding-box centre rounded to whole metres (float64, recorded with the CRS), so
offsets stay small and two outputs of one input (with and without LOD parents) share it; source
coordinates come back as ``origin + ROTATIONᵀ · scene``. Plain meshes without a CRS
get no frame: their own axes and coordinates are kept.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import LodConvertError, UsageError
from ..model import CellChain, LodChain

ROTATION = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""Source z-up axes → scene y-up axes: (x, y, z) ↦ (x, z, −y), a turn of −90° about x."""
UP_AXES = ("x", "y", "z", "-x", "-y", "-z")
"""The up axes a mesh may be read with (``--up``)."""
_TO_Y_UP = {
    "x": [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],  # (x, y, z) ↦ (−y, x, z)
    "y": np.eye(3),
    "z": ROTATION,
    "-x": [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],  # (x, y, z) ↦ (y, −x, z)
    "-y": np.diag([1.0, -1.0, -1.0]),  # (x, y, z) ↦ (x, −y, −z)
    "-z": [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],  # (x, y, z) ↦ (x, −z, y)
}
AXES = "source (x, y, z) -> scene (x, z, -y): y up, north -z"
MEANING = "source = origin + rotation^T * scene (rotation row-major; scene = file coordinates)"
MAX_OFFSET = 1e5
"""Largest magnitude of a node offset from the scene origin (float32 keeps 8 mm there)."""


def y_up(up: str) -> np.ndarray:
    """The rotation (3, 3) turning axis ``up`` (one of :data:`UP_AXES`) to +y, glTF's and X3D's
    up: a quarter or half turn about x or z (``z`` is :data:`ROTATION`, as for a city)."""
    if up not in _TO_Y_UP:
        raise UsageError(f"must be one of {', '.join(UP_AXES)}, got {up!r}", "up")
    return np.array(_TO_Y_UP[up], dtype=np.float64)


@dataclass(frozen=True)
class SceneFrame:
    """Where a georeferenced scene's coordinates start (``origin``, float64, source CRS) and how
    its axes are turned (:data:`ROTATION`)."""

    origin: np.ndarray

    def offset(self, point: np.ndarray, what: str) -> np.ndarray:
        """``point`` (source coordinates) less the origin, still in source axes;
        :class:`LodConvertError` naming ``what`` when it is :data:`MAX_OFFSET` or farther."""
        offset = np.asarray(point, dtype=np.float64) - self.origin
        largest = float(np.abs(offset).max())
        if not largest < MAX_OFFSET:
            raise LodConvertError(
                f"{what} lies {largest / 1000:.0f} km from the scene origin "
                f"{_metres(self.origin)}: glTF node offsets stay within "
                f"{MAX_OFFSET / 1000:.0f} km of it (float32 precision); convert such a region "
                "in parts"
            )
        return offset

    def record(self) -> dict[str, Any]:
        """What a file records of the frame (JSON-able): origin, rotation, axes, the formula."""
        return {
            "origin": [float(v) for v in self.origin],
            "rotation": ROTATION.tolist(),
            "axes": AXES,
            "meaning": MEANING,
        }


def _metres(point: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.0f}" for v in point) + ")"


def item_origin(item: LodChain | CellChain) -> np.ndarray:
    """Where a chain or a LOD parent lies: its origin (an instance's: placed by its matrix)."""
    if isinstance(item, CellChain):
        return np.asarray(item.origin, dtype=np.float64)
    origin = np.asarray(item.origin, dtype=np.float64)
    if item.transform is None:
        return origin
    return item.transform[:3, :3] @ origin + item.transform[:3, 3]


def scene_frame(
    framed: bool, first: LodChain | CellChain, at: np.ndarray | None = None
) -> SceneFrame | None:
    """The frame of a scene whose first item is ``first``: its origin ``at`` (where the input's
    first object lies, :attr:`~lodconvert.io.OutputInfo.origin`: the same whatever groups the
    objects into LOD parents) or else ``first``'s, rounded to whole metres; ``None`` where the
    scene is not ``framed`` (a plain mesh keeps its axes)."""
    if not framed:
        return None
    origin = item_origin(first) if at is None else np.asarray(at, dtype=np.float64)
    return SceneFrame(np.round(origin) + 0.0)  # + 0.0: no negative zero


def frame_from_record(record: Any) -> SceneFrame | None:
    """The frame a file recorded (:meth:`SceneFrame.record`); ``None`` for none. ``ValueError``
    for a record that is not one."""
    if record is None:
        return None
    origin = np.asarray(record["origin"], dtype=np.float64)
    if origin.shape != (3,) or not np.isfinite(origin).all():
        raise ValueError(f"scene frame origin {record['origin']!r} is not 3 finite numbers")
    if not np.array_equal(np.asarray(record.get("rotation"), dtype=np.float64), ROTATION):
        raise ValueError(f"scene frame rotation {record.get('rotation')!r} is not z-up to y-up")
    return SceneFrame(origin)
