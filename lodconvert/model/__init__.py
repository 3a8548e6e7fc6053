"""The data model, free of file formats: Scene → Node (tree) → geometry parts; LodChain → Level."""

from .chain import MESH_KINDS, BakeParams, CellChain, Level, LodChain
from .geometry import GREY, WHITE, Mesh, PointCloud, Surface
from .tree import Node, PackedNode, Scene, unpacked, with_geometry

__all__ = [
    "GREY",
    "MESH_KINDS",
    "WHITE",
    "BakeParams",
    "CellChain",
    "Level",
    "LodChain",
    "Mesh",
    "Node",
    "PackedNode",
    "PointCloud",
    "Scene",
    "Surface",
    "unpacked",
    "with_geometry",
]
