"""Compressed glTF geometry (``--compress``, docs/compression.md): meshoptimizer's bitstreams
written byte for byte as its own encoder writes them and read back, tilesets (meshopt by
default) and ``.glb`` files that pass the official validators with the same geometry within
the error they state, and a wrong ``--compress`` refused in one line."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from lodconvert.io.gltf.binary import accessor_values, pack_glb
from lodconvert.io.gltf.compression import POSITION_STEPS, POSITION_TOLERANCE
from lodconvert.io.gltf.meshopt import (
    MeshoptError,
    decode_indices,
    decode_vertices,
    encode_sequence,
    encode_triangles,
    encode_vertices,
    exponential,
    from_exponential,
    from_octahedral,
    octahedral,
)
from lodconvert.io.gltf.reader import read_lod_gltf
from lodconvert.io.tiles.check import read_glb

from .conftest import ROOT, SHARED, require
from .test_cli import assert_one_line_error, run
from .test_tiles import official

TUM = SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip"
BUNNY = SHARED / "data" / "stanford"
REFERENCE = ROOT / "node_modules" / "meshoptimizer" / "index.js"
MESHOPT = "EXT_meshopt_compression"
QUANTIZATION = "KHR_mesh_quantization"
_SCRIPT = """
import {{ MeshoptEncoder, MeshoptDecoder }} from {module};
import fs from 'fs';
await MeshoptEncoder.ready; await MeshoptDecoder.ready;
const [what, file, count, size] = process.argv.slice(2);
const b = fs.readFileSync(file);
const src = new Uint8Array(b.buffer, b.byteOffset, b.length);
let out;
if (what === 'vertices') out = MeshoptEncoder.encodeVertexBufferLevel(src, +count, +size, 2, 0);
else if (what === 'sequence') out = MeshoptEncoder.encodeIndexSequence(src, +count, +size);
else if (what === 'triangles') out = MeshoptEncoder.encodeIndexBuffer(src, +count, +size);
else if (what === 'exponential') out = MeshoptEncoder.encodeFilterExp(
  new Float32Array(b.buffer, b.byteOffset, b.length / 4), +count, +size, 24, 'SharedComponent');
else if (what === 'octahedral') out = MeshoptEncoder.encodeFilterOct(
  new Float32Array(b.buffer, b.byteOffset, b.length / 4), +count, +size, 8);
else {{
  out = new Uint8Array(+count * +size);
  MeshoptDecoder.decodeGltfBuffer(out, +count, +size, src, what);
}}
process.stdout.write(Buffer.from(out).toString('base64'));
"""


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """meshoptimizer's own encoders and decoder (its npm package, run by node): a function
    of (what, bytes, count, size) giving the bytes it makes."""
    node = shutil.which("node")
    require(node is not None, "node is not on PATH (meshoptimizer's reference encoder)")
    require(REFERENCE.exists(), f"{REFERENCE} is absent (scripts/test.sh installs it)")
    folder = tmp_path_factory.mktemp("meshopt")
    script = folder / "reference.mjs"
    script.write_text(_SCRIPT.format(module=json.dumps(REFERENCE.as_uri())))

    def make(what: str, data: bytes, count: int, size: int) -> bytes:
        source = folder / "in.bin"
        source.write_bytes(data)
        done = subprocess.run(
            [node, str(script), what, str(source), str(count), str(size)],
            capture_output=True, text=True, timeout=120, check=True,
        )  # fmt: skip
        import base64

        return base64.b64decode(done.stdout)

    return make


RNG = np.random.default_rng(7)
SHAPES = [(1, 4), (5, 12), (300, 12), (1000, 36), (4000, 8), (17, 256), (0, 12)]


@pytest.mark.parametrize(("count", "stride"), SHAPES)
def test_vertex_data_is_what_meshoptimizer_writes(reference, count, stride):
    smooth = np.cumsum(RNG.integers(-3, 4, size=(count, stride // 4)), axis=0)
    rows = smooth.astype(np.float32).view(np.uint8).reshape(count, stride)
    assert encode_vertices(rows) == reference("vertices", rows.tobytes(), count, stride)
    noise = RNG.integers(0, 256, size=(count, stride), dtype=np.uint8)
    packed = encode_vertices(noise)
    assert packed == reference("vertices", noise.tobytes(), count, stride)
    assert np.array_equal(decode_vertices(packed, count, stride), noise)


MESHES = {
    "box": trimesh.creation.box().faces,
    "sphere": trimesh.creation.icosphere(3).faces,
    "two boxes (a reset)": np.vstack([trimesh.creation.box().faces] * 2),
    "random": RNG.integers(0, 100_000, size=(1000, 3)),
}


@pytest.mark.parametrize("name", MESHES)
def test_index_data_is_what_meshoptimizer_writes(reference, name):
    indices = np.asarray(MESHES[name], dtype=np.uint32).ravel()
    raw = indices.tobytes()
    triangles = encode_triangles(indices)
    assert triangles == reference("triangles", raw, len(indices), 4)
    sequence = encode_sequence(indices)
    assert sequence == reference("sequence", raw, len(indices), 4)
    assert np.array_equal(decode_indices(sequence, len(indices), "INDICES"), indices)
    # the triangle codec may start a triangle at another corner: as meshoptimizer decodes it
    decoded = decode_indices(triangles, len(indices), "TRIANGLES")
    theirs = reference("TRIANGLES", triangles, len(indices), 4)
    assert decoded.tobytes() == theirs
    assert sorted(map(_turned, decoded.reshape(-1, 3))) == sorted(
        map(_turned, indices.reshape(-1, 3))
    )


def _turned(triangle: np.ndarray) -> tuple[int, ...]:
    """A triangle from its least corner, keeping its winding."""
    k = int(np.argmin(triangle))
    return tuple(int(v) for v in np.roll(triangle, -k))


def test_the_exponential_filter_is_meshoptimizers_and_within_half_a_float32_step(reference):
    for scale in (1e-3, 1.0, 300.0):
        values = (RNG.normal(size=(500, 3)) * scale).astype(np.float32)
        values[5] = 0.0
        words = exponential(values)
        theirs = reference("exponential", values.tobytes(), 500, 12)
        assert words.tobytes() == theirs
        back = from_exponential(words)
        largest = np.abs(values).max(axis=0)
        assert (np.abs(back - values) <= np.spacing(largest)).all()
        # with a tolerance: every value within it, or within float32's step where it is finer
        fewer = exponential(values, 1e-4 * scale)
        bound = np.maximum(1e-4 * scale, np.spacing(largest))
        assert (np.abs(from_exponential(fewer) - values) <= bound).all()
        assert (fewer >> 24 != words >> 24).all()  # coarser steps: other exponents


def test_the_octahedral_filter_is_meshoptimizers_within_a_degree(reference):
    normals = RNG.normal(size=(2000, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    normals[:3] = [[0, 0, 1], [0, 0, -1], [1, 0, 0]]
    source = np.zeros((len(normals), 4), np.float32)
    source[:, :3] = normals
    words = octahedral(normals)
    assert words.tobytes() == reference("octahedral", source.tobytes(), len(normals), 4)
    packed = encode_vertices(words.view(np.uint8))
    theirs = reference("ATTRIBUTES", packed, len(normals), 4)  # decoded without the filter
    assert theirs == words.tobytes()
    back = from_octahedral(words)[:, :3] / 127.0
    cosine = (back * normals).sum(axis=1) / np.linalg.norm(back, axis=1)
    assert np.degrees(np.arccos(np.clip(cosine, -1, 1))).max() <= 1.01


@pytest.mark.parametrize(
    "damage", ["truncated", "wrong header", "garbage", "empty"], ids=lambda d: d
)
def test_malformed_meshopt_data_is_refused_not_crashed_on(damage):
    rows = RNG.integers(0, 256, size=(300, 12), dtype=np.uint8)
    good = {"vertices": encode_vertices(rows), "triangles": encode_triangles(MESHES["sphere"])}
    count = MESHES["sphere"].size
    for what, data in good.items():
        bad = {
            "truncated": data[: len(data) // 2],
            "wrong header": b"\x00" + data[1:],
            "garbage": RNG.integers(0, 256, size=len(data), dtype=np.uint8).tobytes(),
            "empty": b"",
        }[damage]
        with pytest.raises(MeshoptError):
            if what == "vertices":
                decode_vertices(bad, 300, 12)
            else:
                decode_indices(bad, count, "TRIANGLES")


@pytest.fixture(scope="module")
def tum_tilesets(tmp_path_factory) -> dict[str, Path]:
    """TUM Munich as a tileset three ways: ``none``, the default (``meshopt``), ``quantize``."""
    require(TUM.exists(), f"{TUM} is absent (shared data not checked out)")
    out = tmp_path_factory.mktemp("compressed")
    made = {}
    for how in ("none", None, "quantize"):
        name = how or "default"
        extra = ["--compress", how] if how else []
        result = run(TUM, "-o", out / name / "tileset.json", "-q", *extra)
        assert result.returncode == 0, result.stderr
        made[name] = out / name / "tileset.json"
    return made


def _positions(tileset: Path) -> dict[str, tuple[np.ndarray, np.ndarray, dict]]:
    """Every tile's content positions (the node's transform applied), feature ids and asset
    extras, by file name."""
    found = {}
    for path in sorted((tileset.parent / "tiles").glob("*.glb")):
        document, blob = read_glb(path)
        node = document["nodes"][0]
        points, ids = [], []
        for primitive in document["meshes"][0]["primitives"]:
            steps = accessor_values(document, blob, primitive["attributes"]["POSITION"])
            scale = np.asarray(node.get("scale", [1.0] * 3))
            points.append(steps * scale + np.asarray(node.get("translation", [0.0] * 3)))
            if "_FEATURE_ID_0" in primitive["attributes"]:
                feature = accessor_values(document, blob, primitive["attributes"]["_FEATURE_ID_0"])
                ids.append(feature.astype(np.int64))
        extras = document["asset"].get("extras", {}).get("lodconvert", {})
        found[path.name] = (np.vstack(points), np.concatenate(ids) if ids else None, extras)
    return found


def _same_geometry(plain: Path, packed: Path) -> float:
    """Assert the two tilesets' tiles hold the same vertices (in any order: each has one of
    the other's within the packed tile's stated error per coordinate) and feature ids; the
    largest error stated."""
    ours, theirs = _positions(plain), _positions(packed)
    assert ours.keys() == theirs.keys()
    largest = 0.0
    for name, (points, ids, _) in ours.items():
        packed_points, packed_ids, extras = theirs[name]
        error = extras["position_error"]
        largest = max(largest, error)
        assert len(points) == len(packed_points), name
        for a, b in ((points, packed_points), (packed_points, points)):
            gap = cKDTree(a).query(b, p=np.inf)[0].max()
            assert gap <= error + 1e-9, (name, gap, error)
        if ids is not None:
            assert sorted(ids.tolist()) == sorted(packed_ids.tolist())
    return largest


def test_a_tileset_is_meshopt_compressed_by_default_to_under_half_the_bytes(tum_tilesets):
    plain, packed = tum_tilesets["none"], tum_tilesets["default"]
    sizes = {
        name: sum(f.stat().st_size for f in (path.parent / "tiles").glob("*.glb"))
        for name, path in tum_tilesets.items()
    }
    assert sizes["default"] <= 0.42 * sizes["none"], sizes
    assert sizes["quantize"] < sizes["none"], sizes
    packed_bytes = 0
    for path in (packed.parent / "tiles").glob("*.glb"):
        document, _ = read_glb(path)
        views = [v for v in document["bufferViews"] if MESHOPT in v.get("extensions", {})]
        assert (MESHOPT in document.get("extensionsRequired", [])) == bool(views)
        packed_bytes += path.stat().st_size if views else 0
    assert packed_bytes >= 0.95 * sizes["default"]  # only views too small to gain stay plain
    # leaves within 0.05 mm (TUM's tiles lie within 512 m of their centres: float32 holds
    # that), coarser tiles within a thousandth of their geometric error, 1 mm at most
    least, most = POSITION_TOLERANCE
    assert 0 < _same_geometry(plain, packed) <= most
    errors = {name: extras["position_error"] for name, (*_, extras) in _positions(packed).items()}
    assert all(error <= least for name, error in errors.items() if "_finest" in name), errors
    assert max(errors.values()) > least  # the far levels' coarser steps


def test_quantized_tiles_keep_their_stated_error_within_a_step_of_their_extent(tum_tilesets):
    plain = tum_tilesets["none"]
    largest = _same_geometry(plain, tum_tilesets["quantize"])
    assert 0 < largest < 0.01  # TUM's tiles are under 600 m across: half a step < 5 mm
    for name, (points, _, extras) in _positions(tum_tilesets["quantize"]).items():
        extent = float((points.max(axis=0) - points.min(axis=0)).max())
        assert extras["position_error"] <= extent / POSITION_STEPS / 2 * 1.01 + 1e-9, name


@pytest.mark.parametrize("how", ["default", "quantize"])
def test_compressed_tilesets_pass_the_official_validator(tum_tilesets, how, tmp_path):
    tileset = tum_tilesets[how]
    report = official(tileset, tmp_path / "report.json")
    assert report["numErrors"] == 0 and report["numWarnings"] == 0, report["issues"][:3]
    assert run("validate", tileset).returncode == 0


@pytest.mark.parametrize("how", ["meshopt", "quantize"])
def test_a_compressed_glb_passes_the_khronos_validator_with_the_same_levels(
    how, tmp_path, gltf_validator
):
    bunny = sorted(BUNNY.glob("bunny*"))
    require(bool(bunny), f"{BUNNY} holds no bunny (shared data not checked out)")
    made = {}
    for name in ("none", how):
        out = tmp_path / f"{name}.glb"
        assert run(bunny[0], "-o", out, "--compress", name, "-q").returncode == 0
        made[name] = out
    assert made[how].stat().st_size < 0.7 * made["none"].stat().st_size
    report = gltf_validator(made[how])
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0
    used = {
        m["message"] for m in report["issues"]["messages"] if m["code"] == "UNSUPPORTED_EXTENSION"
    }
    assert used <= {
        f"Cannot validate an extension as it is not supported by the validator: '{name}'."
        for name in ("MSFT_lod", MESHOPT)
    }
    plain, packed = read_lod_gltf(made["none"]), read_lod_gltf(made[how])
    document, _ = read_glb(made[how])
    error = document["asset"]["extras"]["lodconvert"]["position_error"]
    assert error > 0
    for ours, theirs in zip(plain, packed, strict=True):
        for level, packed_level in zip(ours.levels, theirs.levels, strict=True):
            gap = np.abs(level.positions - packed_level.positions).max(initial=0.0)
            assert gap <= error + 1e-9, (level.name, gap, error)
    assert run("validate", made[how]).returncode == 0


def test_a_wrong_compress_is_a_one_line_usage_error_that_writes_nothing(tmp_path):
    cube = tmp_path / "cube.obj"
    trimesh.creation.box().export(cube)
    result = run(cube, "-o", tmp_path / "out.glb", "--compress", "zstd")
    assert_one_line_error(result, 2, "--compress", "zstd")
    result = run(cube, "-o", tmp_path / "out.x3d", "--compress", "meshopt")
    assert_one_line_error(result, 2, "--compress", "out.x3d")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cube.obj"]


def test_a_meshopt_packed_glb_is_read_as_input_and_a_filter_it_lacks_is_one_line(tmp_path):
    """lodconvert reads a GLB whose views are packed (its own, here) as it reads the plain
    one; a view under a filter it does not decode (octahedral) is refused in one line that
    names the file, and nothing is written."""
    bunny = sorted(BUNNY.glob("bunny*"))
    require(bool(bunny), f"{BUNNY} holds no bunny (shared data not checked out)")
    made = {}
    for how in ("none", "meshopt"):
        made[how] = tmp_path / f"{how}.glb"
        assert run(bunny[0], "-o", made[how], "--compress", how, "-q").returncode == 0
    reports = {}
    for how, source in made.items():
        report = tmp_path / f"{how}.json"
        result = run(source, "-o", tmp_path / f"again_{how}.x3d", "--report", report, "-q")
        assert result.returncode == 0, result.stderr
        reports[how] = json.loads(report.read_text())["objects"]
    counts = [[level["count"] for level in obj["levels"]] for obj in reports["none"]]
    assert counts == [[level["count"] for level in obj["levels"]] for obj in reports["meshopt"]]
    document, blob = read_glb(made["meshopt"])
    filtered = [
        view["extensions"][MESHOPT]
        for view in document["bufferViews"]
        if view.get("extensions", {}).get(MESHOPT, {}).get("filter")
    ]
    assert filtered
    filtered[0]["filter"] = "OCTAHEDRAL"
    octahedral = tmp_path / "octahedral.glb"
    with octahedral.open("wb") as handle:
        pack_glb(handle, json.dumps(document).encode(), blob)
    result = run(octahedral, "-o", tmp_path / "never.x3d")
    assert_one_line_error(result, 1, "octahedral.glb", "OCTAHEDRAL")
    assert not (tmp_path / "never.x3d").exists()


def _packed_bunny(tmp_path: Path) -> tuple[dict, bytes]:
    """The bunny as a meshopt-packed GLB's document and binary chunk."""
    bunny = sorted(BUNNY.glob("bunny*"))
    require(bool(bunny), f"{BUNNY} holds no bunny (shared data not checked out)")
    packed = tmp_path / "packed.glb"
    assert run(bunny[0], "-o", packed, "--compress", "meshopt", "-q").returncode == 0
    return read_glb(packed)


def _written(path: Path, document: dict, blob: bytes) -> Path:
    with path.open("wb") as handle:
        pack_glb(handle, json.dumps(document).encode(), blob)
    return path


@pytest.mark.parametrize("claim", ["count", "limit"])
def test_a_packed_view_that_claims_more_than_it_may_is_refused_in_one_line(tmp_path, claim):
    """A view claiming 10⁹ vertices from its few bytes is refused before anything is
    allocated; views that would decode past ``--limit decompressed_bytes`` likewise."""
    document, blob = _packed_bunny(tmp_path)
    extra: tuple[str, ...] = ()
    if claim == "count":
        view = next(v for v in document["bufferViews"] if MESHOPT in v.get("extensions", {}))
        view["extensions"][MESHOPT]["count"] = 10**9
        words = ("claims",)
    else:
        extra, words = ("--limit", "decompressed_bytes=100K"), ("limit",)
    source = _written(tmp_path / "claims.glb", document, blob)
    result = run(source, "-o", tmp_path / "never.x3d", *extra)
    assert_one_line_error(result, 1, "claims.glb", *words)
    assert not (tmp_path / "never.x3d").exists()
    assert run("validate", source).returncode != 0 or claim == "limit"


_FUZZ = """
import numpy as np, trimesh
from lodconvert.io.gltf.meshopt import (MeshoptError, decode_indices, decode_vertices,
    encode_sequence, encode_triangles, encode_vertices)
rng = np.random.default_rng(11)
rows = np.cumsum(rng.integers(-3, 4, size=(700, 3)), axis=0).astype(np.float32)
faces = trimesh.creation.icosphere(2).faces.astype(np.uint32).ravel()
cases = [
    (encode_vertices(rows.view(np.uint8).reshape(700, 12)), lambda d: decode_vertices(d, 700, 12)),
    (encode_triangles(faces), lambda d: decode_indices(d, len(faces), "TRIANGLES")),
    (encode_sequence(faces), lambda d: decode_indices(d, len(faces), "INDICES")),
]
decoded = refused = 0
for good, decode in cases:
    for _ in range(700):
        data = bytearray(good)
        for _ in range(int(rng.integers(1, 9))):
            data[int(rng.integers(0, len(data)))] = int(rng.integers(0, 256))
        cut = int(rng.integers(0, len(data) + 1)) if rng.random() < 0.3 else len(data)
        try:
            decode(bytes(data[:cut]))
            decoded += 1
        except MeshoptError:
            refused += 1
print(decoded, refused)
"""


def test_damaged_meshopt_data_never_reads_outside_its_bytes(tmp_path):
    """2,100 damaged encodings (bytes changed, cut short) decoded with numba's bounds checks
    on: each decodes or is refused, none reads or writes outside its arrays (an IndexError
    there), whatever the damage."""
    script = tmp_path / "fuzz.py"
    script.write_text(_FUZZ)
    env = {**os.environ, "NUMBA_BOUNDSCHECK": "1", "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, env=env, check=False
    )
    assert done.returncode == 0, done.stderr[-3000:]
    decoded, refused = map(int, done.stdout.split())
    assert decoded + refused == 2100 and refused > 0
