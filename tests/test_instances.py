"""Shared geometry: a mesh placed by several scene-graph nodes is baked once and written once
(X3D ``LOD`` DEF/USE, glTF mesh reuse), each instance keeping its placement."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh
from lxml import etree

from lodconvert import convert
from lodconvert.io import read_chains

PLACEMENTS = [
    trimesh.transformations.translation_matrix([0, 0, 0]),
    trimesh.transformations.translation_matrix([10, 0, 0])
    @ trimesh.transformations.rotation_matrix(0.5, [0, 0, 1])
    @ np.diag([2.0, 2.0, 2.0, 1.0]),
    trimesh.transformations.translation_matrix([30, 5, 0]) @ np.diag([1.0, 3.0, 1.0, 1.0]),
]


@pytest.fixture(scope="module")
def instanced(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A GLB whose one sphere mesh is placed by three nodes."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    scene = trimesh.Scene()
    scene.add_geometry(sphere, node_name="ball0", geom_name="ball")
    for i, matrix in enumerate(PLACEMENTS):
        scene.graph.update(
            frame_to=f"ball{i}", frame_from=scene.graph.base_frame, matrix=matrix, geometry="ball"
        )
    path = tmp_path_factory.mktemp("instances") / "balls.glb"
    scene.export(path)
    return path


def _glb_json(path: Path) -> dict:
    data = path.read_bytes()
    (length,) = struct.unpack_from("<I", data, 12)
    return json.loads(data[20 : 20 + length])


@pytest.mark.parametrize("suffix", [".x3d", ".glb"])
def test_instances_are_baked_once_and_keep_their_placement(
    instanced: Path, tmp_path: Path, suffix: str, schema: etree.XMLSchema
) -> None:
    out = tmp_path / f"balls{suffix}"
    report = convert(instanced, out)
    counts = {tuple(lv["count"] for lv in obj["levels"]) for obj in report["objects"]}
    assert len(report["objects"]) == 3 and len(counts) == 1  # one bake, three instances
    chains = read_chains(out)
    sphere = trimesh.creation.icosphere(subdivisions=3).vertices
    for chain, matrix in zip(chains, PLACEMENTS, strict=True):
        placement = np.eye(4) if chain.transform is None else chain.transform
        local = chain.levels[0].mesh.vertices + chain.origin
        world = local @ placement[:3, :3].T + placement[:3, 3]
        expected = sphere @ matrix[:3, :3].T + matrix[:3, 3]
        np.testing.assert_allclose(np.sort(world, axis=0), np.sort(expected, axis=0), atol=1e-5)
    if suffix == ".x3d":
        document = etree.parse(str(out))
        schema.assertValid(document)
        assert len(document.findall(".//LOD[@DEF]")) == 1
        assert len(document.findall(".//LOD[@USE]")) == 2
    else:
        doc = _glb_json(out)
        assert len(doc["meshes"]) == len(chains[0].levels)  # level meshes written once
        roots = [doc["nodes"][i] for i in doc["scenes"][0]["nodes"]]
        assert sum("matrix" in root for root in roots) == 2  # the identity needs none
