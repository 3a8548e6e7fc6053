"""The glTF writer streams: writing many chains does not hold their buffer or JSON in memory,
and the ``.gltf`` data URI, encoded block by block, holds exactly the ``.glb``'s BIN chunk."""

from __future__ import annotations

import base64
import json
import struct
import tracemalloc
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

from lodconvert.io import OutputInfo
from lodconvert.io.gltf import write_glb, write_gltf
from lodconvert.model import Level, LodChain, PointCloud, Surface

INFO = OutputInfo(generator="lodconvert tests", source="streaming", crs="EPSG:25832")
WRITE = {".glb": write_glb, ".gltf": write_gltf}
POINTS = 20_000
"""Points of each chain's coarse level (640 kB of buffer)."""


def _chain(points: int) -> LodChain:
    """A textured box (a mesh level) and ``points`` random coloured points (a point level)."""
    rng = np.random.default_rng(0)
    box = trimesh.creation.box().subdivide()
    texture = rng.integers(0, 256, (8, 8, 4), dtype=np.uint8)
    surface = Surface(
        vertices=box.vertices,
        faces=box.faces.astype(np.int64),
        uv=box.vertices[:, :2] + 0.5,
        texture=texture,
    )
    cloud = PointCloud(
        positions=rng.uniform(-0.5, 0.5, (points, 3)),
        colors=rng.integers(0, 256, (points, 4), dtype=np.uint8),
        normals=rng.normal(size=(points, 3)).astype(np.float32),
    )
    return LodChain(
        object_id="block",
        levels=[Level("LOD2", "mesh", mesh=surface), Level("LOD1", "pcd", points=cloud)],
        cutoffs=[40.0],
        origin=np.array([691000.25, 5336000.5, 520.0]),
        center=np.zeros(3),
        alpha=2.0,
        beta=3.0,
        gamma=10.0,
        xs=[1.0],
        metadata={"function": "office"},
    )


def _copies(chain: LodChain, count: int) -> Iterator[LodChain]:
    """``count`` objects with ``chain``'s geometry, made one at a time (each written in full)."""
    for i in range(count):
        yield replace(
            chain, object_id=f"block{i}", origin=chain.origin + np.array([100.0 * i, 0.0, 0.0])
        )


def _instances(chain: LodChain) -> list[LodChain]:
    """Two placements of one geometry, which the writer stores once (turned in place: a
    georeferenced instance stays near the data)."""
    turned = trimesh.transformations.rotation_matrix(0.5, [0, 0, 1], point=chain.origin)
    return [
        replace(chain, object_id="twin0", transform=np.eye(4)),
        replace(chain, object_id="twin1", transform=turned),
    ]


def _write(path: Path, chains: Iterator[LodChain] | list[LodChain]) -> Path:
    with path.open("wb") as handle:
        WRITE[path.suffix](iter(chains), handle, INFO)
    return path


def _glb_chunks(data: bytes) -> tuple[bytes, bytes]:
    """The JSON and BIN chunks of a GLB (BIN empty when there is none)."""
    magic, version, total = struct.unpack_from("<4sII", data)
    assert (magic, version, total) == (b"glTF", 2, len(data))
    chunks = {}
    at = 12
    while at < len(data):
        length, kind = struct.unpack_from("<I4s", data, at)
        assert length % 4 == 0
        chunks[kind] = data[at + 8 : at + 8 + length]
        at += 8 + length
    assert at == len(data)
    return chunks[b"JSON"], chunks.get(b"BIN\x00", b"")


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_writing_many_chains_does_not_hold_the_output_in_memory(
    tmp_path: Path, suffix: str
) -> None:
    chain = _chain(POINTS)
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        path = _write(tmp_path / f"city{suffix}", _copies(chain, 60))
        peak = tracemalloc.get_traced_memory()[1] - start
    finally:
        tracemalloc.stop()
    size = path.stat().st_size
    assert size > 35 * 2**20
    # One chain's arrays and the writer's in-memory spool share, not the file's 35+ MiB.
    assert peak < size / 4, f"peak {peak / 2**20:.1f} MiB writing {size / 2**20:.1f} MiB"


@pytest.mark.parametrize("count", [0, 3])
def test_gltf_data_uri_holds_the_glb_bin_chunk(tmp_path: Path, count: int) -> None:
    chain = _chain(POINTS)
    chains = [*_copies(chain, count), *(_instances(chain) if count else [])]
    glb = _write(tmp_path / "city.glb", chains).read_bytes()
    text = _write(tmp_path / "city.gltf", chains).read_text(encoding="ascii")
    json_chunk, bin_chunk = _glb_chunks(glb)
    from_glb = json.loads(json_chunk)
    from_gltf = json.loads(text)
    # Laid out exactly as json.dumps lays out the parsed document.
    compact = json.dumps(from_glb, separators=(",", ":")).encode()
    assert json_chunk == compact + b" " * (-len(compact) % 4)
    assert text == json.dumps(from_gltf, indent=1, separators=(",", ": ")) + "\n"
    buffers = from_gltf.pop("buffers", [])
    assert [{"byteLength": b["byteLength"]} for b in buffers] == from_glb.pop("buffers", [])
    assert from_gltf == from_glb
    if not count:
        assert not buffers and not bin_chunk
        return
    (buffer,) = buffers
    prefix = "data:application/octet-stream;base64,"
    assert buffer["uri"].startswith(prefix)
    blob = base64.b64decode(buffer["uri"][len(prefix) :], validate=True)
    assert len(blob) == buffer["byteLength"] > 2 * 2**20  # several copy blocks
    assert bin_chunk[: len(blob)] == blob
    assert set(bin_chunk[len(blob) :]) <= {0} and len(bin_chunk) - len(blob) < 4
