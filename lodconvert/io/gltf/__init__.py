"""glTF 2.0 (``.glb`` and self-contained ``.gltf``): the writer (:mod:`.writer`), the read-back
of our own files (:mod:`.reader`) and the structural checks (:mod:`.check`), declared as one
registry entry each for ``.glb`` and ``.gltf``. The package's modules: ``docs/gltf.md``."""

from __future__ import annotations

from .. import Format, streamed
from .chain_part import chain_parts
from .check import check_gltf
from .lod import MSFT_LOD
from .reader import GltfLevel, GltfObject, read_back, read_cells, read_frame, read_lod_gltf
from .writer import write_glb, write_gltf

FORMAT = Format(
    name="gltf",
    suffixes=(".glb", ".gltf"),
    write=streamed({".glb": write_glb, ".gltf": write_gltf}),
    read_back=read_back,
    read_cells=read_cells,
    read_frame=read_frame,
    check=check_gltf,
    viewer="gltf",
    formatter=chain_parts,
    write_options=("compress", "texture_format"),
)

__all__ = [
    "FORMAT",
    "MSFT_LOD",
    "GltfLevel",
    "GltfObject",
    "read_back",
    "read_cells",
    "read_frame",
    "read_lod_gltf",
    "write_glb",
    "write_gltf",
]
