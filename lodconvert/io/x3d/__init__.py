"""X3D 4.0: the writer (:mod:`.writer`, with the document's head and metadata, DEF names, prism
switching, geometry Shapes and XML text in modules of their own), the read-back of our own files
(:mod:`.reader`) and the structural checks (:mod:`.check`), declared as one registry entry."""

from __future__ import annotations

from .. import Format, streamed
from .check import check_x3d
from .head import SWITCHING_MODES
from .metadata import METADATA_SET
from .prism import prism_boxes
from .reader import (
    X3DLevel,
    read_back,
    read_cells,
    read_frame,
    read_x3d_points,
    x3d_read_errors,
)
from .shapes import point_properties, vertex_colors
from .writer import chain_texts, write_x3d

FORMAT = Format(
    name="x3d",
    suffixes=(".x3d",),
    write=streamed({".x3d": write_x3d}),
    read_back=read_back,
    read_cells=read_cells,
    read_frame=read_frame,
    check=check_x3d,
    checked_as_streamed=True,
    viewer="x3d",
    formatter=chain_texts,
    write_options=("switching",),
)

__all__ = [
    "FORMAT",
    "METADATA_SET",
    "SWITCHING_MODES",
    "X3DLevel",
    "point_properties",
    "prism_boxes",
    "read_back",
    "read_cells",
    "read_frame",
    "read_x3d_points",
    "vertex_colors",
    "write_x3d",
    "x3d_read_errors",
]
