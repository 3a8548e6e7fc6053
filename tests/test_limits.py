"""The baker's memory follows what a file holds, not what it claims; options past the checks are
usage errors; grids beyond ``grid_cells`` are refused or made coarser.

Peak memory is measured in a child process (``ru_maxrss`` of its children, reported by a fresh
interpreter so that no earlier child counts)."""

from __future__ import annotations

import itertools
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from lodconvert.bake import NumpyBackend, bake_points
from lodconvert.chain import ChainOptions
from lodconvert.errors import UsageError
from lodconvert.limits import Limits
from lodconvert.model import BakeParams, Node, Surface
from lodconvert.plans import bake_chain
from lodconvert.ranges import MAX_ALPHA, cutoff

from .test_cli import assert_one_line_error, run

PEAK_LIMIT_BYTES = 2 << 30
MEASURE = """
import resource, subprocess, sys
done = subprocess.run(sys.argv[1:], capture_output=True, text=True)
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
print(peak, done.returncode)
sys.stderr.write(done.stderr)
"""


def peak_rss(*args: str | Path) -> tuple[int, int, str]:
    """Peak resident bytes, exit code and stderr of ``lodconvert ARGS`` in a child process."""
    argv = [sys.executable, "-c", MEASURE, sys.executable, "-m", "lodconvert", *map(str, args)]
    done = subprocess.run(argv, capture_output=True, text=True, check=True)
    peak, code = done.stdout.split()
    return int(peak), int(code), done.stderr


def repeated_triangle(path: Path, times: int) -> Path:
    """One triangle written ``times`` times over (80 KB for 10,000)."""
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + "f 1 2 3\n" * times)
    return path


@pytest.mark.parametrize("times", [10_000, 100_000])
def test_a_repeated_triangle_bakes_in_little_memory(tmp_path: Path, times: int) -> None:
    source = repeated_triangle(tmp_path / "tri.obj", times)
    peak, code, err = peak_rss(
        source, "-o", tmp_path / "out.x3d", "--backend", "numpy", "--no-mesh"
    )
    assert code == 0, err
    assert peak < PEAK_LIMIT_BYTES


@pytest.mark.slow
def test_overlapping_distinct_faces_cost_time_not_memory(tmp_path: Path) -> None:
    """2,000 triangles, each a hair apart (no two alike), over the same pixels."""
    lines = ["v 0 0 0", "v 1 0 0", "v 0 1 0"]
    lines += [f"v {i * 1e-9:.9f} 1 0" for i in range(1, 2000)]
    lines += ["f 1 2 3"] + [f"f 1 2 {i + 3}" for i in range(1, 2000)]
    source = tmp_path / "fan.obj"
    source.write_text("\n".join(lines) + "\n")
    peak, code, err = peak_rss(
        source, "-o", tmp_path / "out.x3d", "--backend", "numpy", "--no-mesh", "--limit",
        "memory_bytes=64M",
    )  # fmt: skip
    assert code == 0, err
    assert peak < 1 << 30


@pytest.mark.slow
def test_a_fine_grid_on_a_small_sphere_stays_within_memory(tmp_path: Path) -> None:
    source = tmp_path / "sphere.obj"
    trimesh.creation.icosphere(1).export(source)
    peak, code, err = peak_rss(
        source, "-o", tmp_path / "out.x3d", "--backend", "numpy", "--resolution", "1024,1024,1024"
    )
    assert code == 0, err
    assert peak < PEAK_LIMIT_BYTES


def test_chunked_baking_gives_the_same_points(torus: Node) -> None:
    params = BakeParams(resolution=48, slices=40, point_size=2.0, filter="median")
    whole, _ = bake_points(torus.geometry, params, NumpyBackend())
    chunked, _ = bake_points(torus.geometry, params, NumpyBackend(), memory_bytes=1 << 16)
    for field in ("positions", "colors", "normals"):
        np.testing.assert_array_equal(getattr(chunked, field), getattr(whole, field))


def test_repeated_faces_bake_like_one(torus: Node) -> None:
    surface = torus.geometry
    doubled = Surface(surface.vertices, np.r_[surface.faces, surface.faces], surface.vertex_colors)
    params = BakeParams(resolution=32, slices=32, point_size=2.0, filter="gaussian")
    once, _ = bake_points(surface, params, NumpyBackend())
    twice, _ = bake_points(doubled, params, NumpyBackend())
    for field in ("positions", "colors", "normals"):
        np.testing.assert_array_equal(getattr(twice, field), getattr(once, field))


def test_an_explicit_resolution_over_the_grid_limit_is_refused(torus: Node) -> None:
    opts = ChainOptions(resolutions=(64, 32, 16))
    with pytest.raises(UsageError, match="grid_cells limit") as caught:
        bake_chain(torus, opts, NumpyBackend(), limits=Limits(grid_cells=10_000))
    assert caught.value.field == "resolutions"


def test_a_default_resolution_over_the_grid_limit_is_lowered(torus: Node) -> None:
    warnings: list[str] = []
    chain = bake_chain(
        torus,
        ChainOptions(levels=2, keep_mesh=False),
        NumpyBackend(),
        warn=warnings.append,
        limits=Limits(grid_cells=4_000),
    )
    level = chain.levels[0]
    assert level.params is not None
    extent = np.ptp(torus.geometry.bounds, axis=0)
    cells = math.prod(max(1, math.ceil(e / level.spacing - 1e-9)) for e in extent)
    assert cells <= 4_000
    assert any("grid_cells" in w for w in warnings)


def test_grid_limit_on_the_command_line(tmp_path: Path) -> None:
    source = tmp_path / "sphere.obj"
    trimesh.creation.icosphere(1).export(source)
    result = run(
        source, "-o", tmp_path / "o.x3d", "--backend", "numpy", "--resolution", "64,32,16",
        "--limit", "grid_cells=1000",
    )  # fmt: skip
    assert_one_line_error(result, 2, "--resolution 64", "grid_cells")


@pytest.mark.parametrize(
    ("option", "flag"),
    [
        (("--resolution", "inf"), "--resolution"),
        (("--resolution", "nan"), "--resolution"),
        (("--resolution", "1e400"), "--resolution"),
        (("--slices", "1e400"), "--slices"),
        (("--x", "1e300,1e301,1e302"), "--x"),
        (("--cull", "1e300"), "--cull"),
        (("--beta", "1e-320"), "--beta"),
        (("--beta", "1e308"), "--beta"),
        (("--plot-radius", "1e308"), "--plot-radius"),
        (("--plot-radius", "1.0000000000000002"), "--plot-radius"),
        (("--x", "0.33,0.66,0.6600000000000001"), "--x"),
    ],
)
def test_options_past_the_checks_are_usage_errors(
    tmp_path: Path, option: tuple[str, str], flag: str
) -> None:
    source = tmp_path / "sphere.obj"
    trimesh.creation.icosphere(1).export(source)
    result = run(source, "-o", tmp_path / "o.x3d", "--backend", "numpy", *option)
    assert_one_line_error(result, 2, flag)
    ranges = run("ranges", source, *option)
    if flag not in ("--resolution", "--slices"):
        assert_one_line_error(ranges, 2, flag)


@pytest.mark.parametrize("beta", [1e-280, 0.5, 3.0, 1e200])
@pytest.mark.parametrize("gamma", [1.000001, 10.0, 1e30])
@pytest.mark.parametrize("xs", [(0.33, 0.66, 1.0), (0.5, 3.0, 7.0), (1e-6, 2e-6, 3e-6)])
def test_accepted_ranges_give_finite_increasing_cutoffs(
    beta: float, gamma: float, xs: tuple[float, ...]
) -> None:
    try:
        ChainOptions(beta=beta, gamma=gamma, xs=xs, cull=xs[-1] + 1).check()
    except UsageError:
        return
    for alpha in (1e-8, 1.0, 1e15, MAX_ALPHA):
        ys = [cutoff(alpha, beta, gamma, x) for x in (0.0, *xs, xs[-1] + 1)]
        assert all(math.isfinite(y) and y > 0 for y in ys)
        assert all(b > a for a, b in itertools.pairwise(ys))


def test_ranges_json_stays_finite(tmp_path: Path) -> None:
    source = tmp_path / "sphere.obj"
    trimesh.creation.icosphere(1).export(source)
    result = run("ranges", source, "--json", "--beta", "1e-280", "--cull", "50")
    assert result.returncode == 0, result.stderr
    rows = json.loads(result.stdout)
    assert all(math.isfinite(y) for y in rows[0]["cutoffs"])
