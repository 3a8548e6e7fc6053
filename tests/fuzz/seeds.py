"""Small valid files of every input suffix, generated here (no files checked in): a box as
OBJ, ASCII and binary PLY, ASCII and binary STL, OFF, GLB and glTF (buffer embedded)."""

from __future__ import annotations

import gzip
import json
from functools import cache
from pathlib import Path

import trimesh

from lodconvert.io import formats

SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def _box() -> trimesh.Trimesh:
    """A unit box with a vertex colour per corner (so colour paths are fuzzed too)."""
    mesh = trimesh.creation.box(extents=(1.0, 2.0, 0.5))
    mesh.visual.vertex_colors = [[40 * i, 255 - 30 * i, 128, 255] for i in range(8)]
    return mesh


@cache
def generated() -> dict[str, tuple[bytes, ...]]:
    """Seed contents by suffix."""
    mesh = _box()
    scene = trimesh.Scene()
    scene.add_geometry(mesh, node_name="box", geom_name="box")
    scene.add_geometry(mesh.copy().apply_translation((3, 0, 0)), node_name="b2", geom_name="b2")
    gltf = trimesh.exchange.gltf.export_gltf(scene, embed_buffers=True)
    obj = (
        "o first\n"
        + mesh.export(file_type="obj")
        + "o second\nv 5 5 5\nv 6 5 5\nv 5 6 5\nf 9 10 11\n"
    )
    return {
        ".obj": (obj.encode(),),
        ".ply": (mesh.export(file_type="ply", encoding="ascii"), mesh.export(file_type="ply")),
        ".stl": (mesh.export(file_type="stl_ascii").encode(), mesh.export(file_type="stl")),
        ".off": (mesh.export(file_type="off").encode(),),
        ".glb": (scene.export(file_type="glb"),),
        ".gltf": (json.dumps(json.loads(gltf["model.gltf"])).encode(),),
    }


def reader_suffixes() -> list[str]:
    """Every suffix the registry reads, each once (in registry order)."""
    suffixes = [s for f in formats() if f.read is not None for s in f.suffixes]
    return list(dict.fromkeys(suffixes))


def seeds_for(suffix: str) -> tuple[bytes, ...]:
    """Seeds of ``suffix``: generated ones, else the samples of that suffix, else every
    generated seed (a reader registered without seeds still meets mislabelled files)."""
    if suffix in generated():
        return generated()[suffix]
    found = tuple(p.read_bytes() for p in sorted(SAMPLES.glob(f"*{suffix}")) if p.is_file())
    return found or tuple(seed for group in generated().values() for seed in group)


def gzipped(data: bytes) -> bytes:
    """``data`` as a ``.gz`` (deterministic: no time stamp)."""
    return gzip.compress(data, mtime=0)
