"""X3D 4.0: the writer (:mod:`.writer`), the read-back of our own files (:mod:`.reader`) and the
structural checks (:mod:`.check`), declared as one registry entry."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ...model import LodChain
from ...sinks import FileSink
from .. import Format, OutputInfo
from .reader import X3DLevel, read_back, read_x3d_points, x3d_read_errors
from .writer import METADATA_SET, point_properties, vertex_colors, write_x3d


def write(chains: Iterable[LodChain], sink: FileSink, info: OutputInfo) -> None:
    """Write ``chains`` into ``sink`` as one X3D document (see :mod:`.writer`)."""
    with sink.open() as handle:
        write_x3d(chains, handle, info)


def check(path: Path, findings: Any, schema: Any = None) -> None:
    """Structural checks of an X3D file lodconvert wrote (and the official XSD when given)."""
    from .check import check_x3d

    check_x3d(path, findings, schema)


FORMAT = Format(
    name="x3d",
    suffixes=(".x3d",),
    write=write,
    read_back=read_back,
    check=check,
)

__all__ = [
    "FORMAT",
    "METADATA_SET",
    "X3DLevel",
    "point_properties",
    "read_back",
    "read_x3d_points",
    "vertex_colors",
    "write_x3d",
    "x3d_read_errors",
]
