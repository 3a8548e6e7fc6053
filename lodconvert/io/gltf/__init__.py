"""glTF 2.0 (``.glb`` and self-contained ``.gltf``): the writer (:mod:`.writer`), the read-back
of our own files (:mod:`.reader`) and the structural checks (:mod:`.check`), declared as one
registry entry each for ``.glb`` and ``.gltf``."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ...model import LodChain
from ...sinks import FileSink
from .. import Format, OutputInfo
from .reader import GltfLevel, GltfObject, read_back, read_lod_gltf
from .writer import (
    GLB_BIN,
    GLB_JSON,
    GLB_MAGIC,
    MSFT_LOD,
    SRGB_TO_LINEAR,
    linear_rgba,
    srgb_rgba,
    write_glb,
    write_gltf,
)


def write(chains: Iterable[LodChain], sink: FileSink, info: OutputInfo) -> None:
    """Write ``chains`` into ``sink``: GLB or ``.gltf`` with an embedded buffer, by suffix."""
    stream = write_gltf if sink.path.suffix.lower() == ".gltf" else write_glb
    with sink.open() as handle:
        stream(chains, handle, info)


def check(path: Path, findings: Any, schema: Any = None) -> None:
    """Structural checks of a glTF file lodconvert wrote (GLB framing, accessors, MSFT_lod)."""
    from .check import check_gltf

    check_gltf(path, findings, schema)


FORMAT = Format(
    name="gltf",
    suffixes=(".glb", ".gltf"),
    write=write,
    read_back=read_back,
    check=check,
)

__all__ = [
    "FORMAT",
    "GLB_BIN",
    "GLB_JSON",
    "GLB_MAGIC",
    "MSFT_LOD",
    "SRGB_TO_LINEAR",
    "GltfLevel",
    "GltfObject",
    "linear_rgba",
    "read_back",
    "read_lod_gltf",
    "srgb_rgba",
    "write_glb",
    "write_gltf",
]
