"""The data model, free of file formats: Scene → Node (tree) → geometry parts; LodChain → Level."""

from .chain import (
    MESH_KINDS,
    BakeParams,
    CellChain,
    Level,
    LodChain,
    Numbers,
    Packed,
    as_numbers,
    from_numbers,
    in_scene,
)
from .geometry import GREY, TRAVELLING, WHITE, Mesh, PointCloud, Surface, travelling_tables
from .tree import Node, PackedNode, Scene, unpacked, with_geometry

__all__ = [
    "GREY",
    "MESH_KINDS",
    "TRAVELLING",
    "WHITE",
    "BakeParams",
    "CellChain",
    "Level",
    "LodChain",
    "Mesh",
    "Node",
    "Numbers",
    "Packed",
    "PackedNode",
    "PointCloud",
    "Scene",
    "Surface",
    "as_numbers",
    "from_numbers",
    "in_scene",
    "travelling_tables",
    "unpacked",
    "with_geometry",
]
