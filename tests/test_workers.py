"""Baking in worker processes (``--workers N``): the same bytes as in one process, broken objects
reported the same, a killed worker's batch retried once and then reported, no process a run
started outliving it (an interrupted run leaving nothing)."""

from __future__ import annotations

import ast
import contextlib
import json
import multiprocessing
import os
import pickle
import re
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from lodconvert import spool
from lodconvert.bake import get_backend
from lodconvert.bakery import iter_chains
from lodconvert.chain import ChainOptions
from lodconvert.context import RunContext
from lodconvert.inputs import read_inputs
from lodconvert.io import output_format
from lodconvert.model import Node, PackedNode, Scene
from lodconvert.pipeline import RunOptions, _output_info, convert
from lodconvert.report import chain_record
from lodconvert.tasks import (
    INPUT_BYTES_PER_WORKER,
    PoolExecutor,
    SerialExecutor,
    default_workers,
)

from .conftest import ROOT, SHARED, shared_data, surface_of
from .test_cityjson import _features
from .test_cli import assert_one_line_error
from .test_cli import run as run_cli
from .test_imports import NUMBA_SCIPY
from .worker_probe import imported_by_workers

TUM = SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip"
CITIES = {
    "kit": SHARED / "data" / "citygml" / "kit_testcases_lod2_100bldg_v3.gml",
    "plateau": SHARED / "data" / "citygml" / "plateau_53394517_bldg_lod012_v3.gml",
    "potsdam": SHARED / "data" / "citygml" / "potsdam_lod1_v1.gml",
    "sig3d": SHARED / "data" / "citygml" / "sig3d_house_lod0-4" / "Building_LOD4-EPSG25832.gml",
    "delft": SHARED / "data" / "cityjson" / "delft.city.json",
    "multi_lod": SHARED / "data" / "cityjson" / "multi_lod_10bldg.city.json",
}
"""Real cities, CityGML and CityJSON, read by workers as by one process, beside TUM."""


def _lodconvert(*args: object) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "lodconvert", *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, cwd=ROOT, check=False)


@pytest.fixture(scope="module")
def mixed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A GLB of several objects: a box, a sphere placed by three nodes (one geometry), a ring,
    and one without area that the reader skips."""
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box(extents=(1, 2, 3)), node_name="box", geom_name="box")
    flat = trimesh.Trimesh([[1, 1, 1]] * 3, [[0, 1, 2]], process=False)
    scene.add_geometry(flat, node_name="broken", geom_name="flat")
    scene.add_geometry(trimesh.creation.icosphere(3), node_name="ball0", geom_name="ball")
    for i in (1, 2):
        matrix = trimesh.transformations.translation_matrix([10.0 * i, 0, 0])
        scene.graph.update(
            frame_to=f"ball{i}", frame_from=scene.graph.base_frame, matrix=matrix, geometry="ball"
        )
    scene.add_geometry(trimesh.creation.torus(2, 0.5), node_name="ring", geom_name="ring")
    path = tmp_path_factory.mktemp("mixed") / "mixed.glb"
    scene.export(path)
    return path


def _untimed(report: dict[str, Any]) -> dict[str, Any]:
    """``report`` without what measures time (the stages' and each point level's seconds) or
    names the output."""
    report = {k: v for k, v in report.items() if k not in ("timings", "output")}
    for record in report["objects"]:
        for level in record["levels"]:
            level.pop("bake_seconds", None)
    return report


def _messages(stderr: str) -> list[str]:
    """The lines of a run's stderr that do not tell time (warnings, objects, cells)."""
    return [line for line in stderr.splitlines() if "(" not in line or "warning" in line]


CASES = [
    pytest.param("tum", ".x3d", (), id="tum-x3d", marks=pytest.mark.slow),
    pytest.param("tum", ".glb", (), id="tum-glb", marks=pytest.mark.slow),
    pytest.param("tum", ".x3d", ("--hlod", "250"), id="tum-hlod-250", marks=pytest.mark.slow),
    pytest.param(
        "kit", ".glb", ("--hlod", "50,200"), id="kit-hlod-two-tiers", marks=pytest.mark.slow
    ),
    pytest.param("tum", ".x3d", ("--switching", "prism"), id="tum-prism", marks=pytest.mark.slow),
    pytest.param("mixed", ".x3d", (), id="mesh-x3d"),
    pytest.param("mixed", ".glb", (), id="mesh-glb"),
    pytest.param("kit", ".x3d", (), id="kit-x3d", marks=pytest.mark.slow),
    pytest.param("kit", ".glb", ("--plot-radius", "12"), id="kit-plot-radius"),
    pytest.param("kit", ".x3d", ("--crs", "EPSG:25833"), id="kit-crs", marks=pytest.mark.slow),
    pytest.param(
        "sequence", ".glb", ("--hlod", "250"), id="cityjsonseq-hlod-250", marks=pytest.mark.slow
    ),
    pytest.param("plateau", ".glb", (), id="plateau-glb", marks=pytest.mark.slow),
    pytest.param(
        "potsdam", ".x3d", ("--switching", "prism"), id="potsdam-prism", marks=pytest.mark.slow
    ),
    pytest.param("sig3d", ".glb", (), id="sig3d-glb", marks=pytest.mark.slow),
    pytest.param("delft", ".x3d", (), id="delft-x3d", marks=pytest.mark.slow),
    pytest.param(
        "delft",
        ".glb",
        ("--crs", "EPSG:28992", "--hlod", "250"),
        id="delft-crs-hlod",
        marks=pytest.mark.slow,
    ),
    pytest.param("multi_lod", ".glb", (), id="multi-lod-glb", marks=pytest.mark.slow),
]


@pytest.mark.parametrize(("source", "suffix", "options"), CASES)
def test_two_workers_write_the_bytes_of_one(
    source: str, suffix: str, options: tuple[str, ...], mixed: Path, tmp_path: Path
) -> None:
    paths = {"tum": TUM, "mixed": mixed, **CITIES}
    path = _sequence(tmp_path) if source == "sequence" else paths[source]
    if not path.exists():
        pytest.skip(f"{path} is not here")
    runs = {}
    for workers in (1, 2):
        out, report = tmp_path / f"w{workers}{suffix}", tmp_path / f"w{workers}.json"
        run = _lodconvert(path, "-o", out, "--report", report, "--workers", workers, *options)
        assert run.returncode == 0, run.stderr
        runs[workers] = (out.read_bytes(), json.loads(report.read_text()), run.stderr)
    assert runs[2][0] == runs[1][0]
    assert _untimed(runs[2][1]) == _untimed(runs[1][1])
    assert _messages(runs[2][2]) == _messages(runs[1][2])
    timings = runs[2][1]["timings"]
    assert list(timings) == ["read", "plan", "execute", "assemble", "write", "validate"]


@pytest.mark.parametrize("switching", ["lod", "prism"])
def test_objects_whose_names_clash_get_the_names_of_one_worker(
    tmp_path: Path, switching: str
) -> None:
    """Workers write each chain's X3D text for whatever names the main process gives it; where
    an object before it took those its id gives, it gets the names it gets with one worker."""
    scene = trimesh.Scene()
    for i, name in enumerate(["a b", "a_b", "a_b_2", "a_b_2_LOD4"]):
        box = trimesh.creation.box(extents=(1, 1 + i, 2))
        box.apply_translation([3.0 * i, 0, 0])
        scene.add_geometry(box, node_name=name, geom_name=f"g{i}")
    path = tmp_path / "clash.glb"
    scene.export(path)
    written = []
    for workers in (1, 2):
        out = tmp_path / f"w{workers}.x3d"
        run = _lodconvert(path, "-o", out, "--workers", workers, "--switching", switching)
        assert run.returncode == 0, run.stderr
        written.append(out.read_bytes())
    assert written[1] == written[0]
    defs = re.findall(rb'<Transform DEF="([^"]+)"', written[1])
    assert defs == [b"a_b", b"a_b_2", b"a_b_2_2", b"a_b_2_LOD4_2"]  # a level's name


def _sequence(tmp_path: Path) -> Path:
    """Delft as a CityJSONSeq file: a header, then one feature a line."""
    source = CITIES["delft"]
    if not source.exists():
        pytest.skip(f"{source} is not here")
    document = json.loads(source.read_text())
    header = {key: document[key] for key in ("type", "version", "transform", "metadata")}
    lines = [json.dumps({**header, "CityObjects": {}, "vertices": []})]
    lines += [json.dumps(feature) for feature in _features(document)]
    path = tmp_path / "delft.city.jsonl"
    path.write_text("\n".join(lines) + "\n")
    return path


class _KillsItsWorker:
    """An attribute whose unpickling kills the process doing it: a worker taking the task."""

    def __reduce__(self) -> tuple[Any, tuple[int]]:
        return signal.raise_signal, (signal.SIGKILL,)


def _scene(broken: str | None = None, killer: str | None = None) -> Scene:
    """Eight small objects (``broken``: one with a NaN vertex; ``killer``: one that kills the
    worker that takes it)."""
    nodes = []
    for i in range(8):
        mesh = trimesh.creation.icosphere(2, radius=1.0 + i / 8)
        node = Node(f"obj{i}", surface_of(mesh), origin=np.array([5.0 * i, 0.0, 0.0]))
        if node.id == broken:
            node.geometry.vertices[0, 0] = np.nan
        if node.id == killer:
            node.attributes["trap"] = _KillsItsWorker()
        nodes.append(node)
    return Scene("test scene", nodes)


def _baked(scene: Scene, workers: int) -> tuple[list[Any], list[str], list[dict[str, str]]]:
    """The chains, warnings and skipped objects of ``scene`` baked by ``workers`` processes."""
    warnings: list[str] = []
    skipped: list[dict[str, str]] = []
    backend = get_backend("numpy")
    executor = SerialExecutor(backend) if workers == 1 else PoolExecutor(workers, "numpy")
    with executor:
        chains = list(
            iter_chains(
                scene,
                ChainOptions(),
                RunContext(executor, backend, warn=warnings.append, skipped=skipped),
            )
        )
    return chains, warnings, skipped


def test_a_broken_object_in_a_batch_is_reported_as_with_one_worker() -> None:
    one = _baked(_scene(broken="obj5"), 1)
    two = _baked(_scene(broken="obj5"), 2)
    assert [c.object_id for c in two[0]] == [c.object_id for c in one[0]]
    assert len(two[0]) == 7
    assert two[1] == one[1] and any("obj5" in w and "skipped" in w for w in two[1])
    assert (
        two[2]
        == one[2]
        == [{"id": "obj5", "reason": "obj5: has NaN or infinite vertex coordinates"}]
    )


def test_a_batch_whose_worker_is_killed_twice_is_reported_and_the_rest_convert() -> None:
    chains, warnings, skipped = _baked(_scene(killer="obj0"), 2)
    assert [c.object_id for c in chains] == [f"obj{i}" for i in range(1, 8)]
    assert [entry["id"] for entry in skipped] == ["obj0"]
    assert "died twice (signal SIGKILL)" in skipped[0]["reason"]
    assert any("obj0" in w and "skipped" in w for w in warnings)


def _rebuilt(made_in: int, number: int) -> _Numbered:
    """A :class:`_Numbered` task unpickled: only in the process that made it (a worker whose
    modules changed under it fails here alike)."""
    if os.getpid() != made_in:
        raise AttributeError("module 'lodconvert' has no attribute 'moved'")
    return _Numbered(number)


@dataclass(frozen=True)
class _Numbered:
    """A task that gives back its number, and that no worker can unpickle."""

    number: int

    def __reduce__(self) -> tuple[Any, tuple[int, int]]:
        return _rebuilt, (os.getpid(), self.number)

    def run(self, backend: Any = None, progress: Any = None) -> int:
        return self.number

    def failed(self, reason: str) -> int:
        return -1


def test_a_task_a_worker_cannot_unpickle_is_run_here_not_waited_for_forever() -> None:
    with PoolExecutor(2, "numpy") as executor:
        assert list(executor.results(_Numbered(i) for i in range(6))) == list(range(6))


def _children_of(pid: int) -> list[int]:
    """The processes ``pid`` started that are still there."""
    children = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(FileNotFoundError):  # a thread that ended meanwhile
            children += [int(c) for c in (task / "children").read_text().split()]
    return children


def _workers_of(pid: int) -> list[int]:
    """The worker processes ``pid`` started (spawned by multiprocessing)."""
    return [
        child
        for child in _children_of(pid)
        if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes()
    ]


@pytest.mark.parametrize(
    ("sig", "code"),
    [(None, 0), (signal.SIGTERM, 143), (signal.SIGINT, 130)],
    ids=["exit", "sigterm", "sigint"],
)
def test_no_process_a_run_started_outlives_it(
    mixed: Path, tmp_path: Path, sig: signal.Signals | None, code: int
) -> None:
    """Its two workers, the check of its X3D and multiprocessing's resource tracker have all
    ended when the run exits, however it ends (the tracker outlived it, reparented); an
    interrupted run leaves nothing."""
    out = tmp_path / "out" / "mixed.x3d"
    out.parent.mkdir()
    slow = ("--resolution", "1024,512,256", "--no-mesh", "--levels", "3") if sig else ()
    command = [
        *(sys.executable, "-m", "lodconvert", str(mixed), "-o", str(out), "-v"),
        *("--workers", "2", *slow),
    ]
    with subprocess.Popen(command, stderr=subprocess.PIPE, text=True, cwd=ROOT) as run:
        assert run.stderr is not None
        seen: list[str] = []
        while not any("baking" in line for line in seen[-1:]):  # a worker is baking
            line = run.stderr.readline()
            assert line, "".join(seen)
            seen.append(line)
        started = _children_of(run.pid)
        if sig is not None:
            run.send_signal(sig)
        rest = run.stderr.read()
        assert run.wait() == code, rest
    assert len(started) == 4, started  # the tracker, the workers, the check
    assert [pid for pid in started if Path(f"/proc/{pid}").exists()] == []
    assert list(out.parent.iterdir()) == ([] if sig else [out])


def test_workers_below_one_is_a_usage_error(mixed: Path, tmp_path: Path) -> None:
    run = _lodconvert(mixed, "-o", tmp_path / "out.glb", "--workers", "0")
    assert run.returncode == 2
    assert run.stderr.strip().splitlines()[-1].endswith("--workers must be at least 1, got 0")
    assert list(tmp_path.iterdir()) == []


def test_default_workers_are_one_per_share_of_input_up_to_the_cores() -> None:
    cores = len(os.sched_getaffinity(0))
    assert default_workers(0) == 1
    assert default_workers(INPUT_BYTES_PER_WORKER) == 1
    assert default_workers(INPUT_BYTES_PER_WORKER + 1) == min(2, cores)
    assert default_workers(10**15) == cores


@pytest.mark.slow
def test_without_workers_given_a_small_city_is_converted_here_and_a_large_one_by_workers(
    tmp_path: Path,
) -> None:
    """KIT's 0.7 MB take 0.6 s in one process and 1 s with two workers, whose start costs
    more than they save; TUM's zip holds 12 MB of CityGML, which workers convert faster."""
    kit = shared_data(CITIES["kit"])
    small = _lodconvert(kit, "-o", tmp_path / "kit.x3d", "-v")
    assert small.returncode == 0, small.stderr
    assert "worker processes" not in small.stderr
    given = _lodconvert(kit, "-o", tmp_path / "kit2.x3d", "-v", "--workers", "2")
    assert given.returncode == 0, given.stderr
    assert _said(given.stderr, "2 worker processes")
    large = _lodconvert(shared_data(TUM), "-o", tmp_path / "tum.x3d", "-v")
    assert large.returncode == 0, large.stderr
    workers = min(2, len(os.sched_getaffinity(0)))
    assert _said(large.stderr, "2 worker processes") == (workers == 2)


def _said(stderr: str, message: str) -> bool:
    """Whether ``message`` is a line of ``stderr`` (after its time, with ``-v``)."""
    return any(line.endswith(f"s {message}") for line in stderr.splitlines())


def test_workers_that_read_and_bake_a_city_never_import_scipy(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A worker process starts by importing what it needs; scipy took the most of that (0.25 s
    of CPU per worker and run, for the connected parts of a footprint), so a worker that read,
    baked and formatted TUM's buildings must not have imported more of it than numba loads by
    itself to run the guard's loops (its BLAS bindings)."""
    imported = imported_by_workers(monkeypatch, shared_data(TUM), tmp_path / "tum.x3d")
    assert {"lodconvert.io.citygml.parallel", "lodconvert.city.prisms"} <= set(imported)
    alone = subprocess.run([sys.executable, "-c", NUMBA_SCIPY], capture_output=True, text=True)
    by_numba = set(ast.literal_eval(alone.stdout.strip()))
    assert {name for name in imported if name.split(".")[0] == "scipy"} <= by_numba


@pytest.mark.parametrize(
    "text",
    [
        '<?xml version="1.0"?>\n<CityModel xmlns="http://www.opengis.net/citygml/2.0">'
        "<cityObjectMember><Building></cityObjectMember></CityModel>",
        "<?xml version='1.0'?>\n<NotACity/>",
    ],
    ids=["broken-first-member", "not-citygml"],
)
def test_a_city_that_cannot_be_read_by_workers_fails_in_one_line_and_stops_them(
    tmp_path: Path, text: str
) -> None:
    """The workers start before the city is opened: a city that cannot be read still gives
    one line, writes nothing, and leaves no worker running."""
    path = tmp_path / "bad.gml"
    path.write_text(text, encoding="utf-8")
    out = tmp_path / "out" / "bad.x3d"
    out.parent.mkdir()
    result = run_cli(path, "-o", out, "--workers", "2", "-q")
    assert_one_line_error(result, 1, str(path))
    assert list(out.parent.iterdir()) == []
    assert multiprocessing.active_children() == []


@pytest.mark.parametrize("suffix", [".x3d", ".glb"])
def test_chains_whose_output_workers_made_come_back_without_their_geometry(suffix: str) -> None:
    """Where workers make each chain's piece of the output and nothing else needs its meshes
    (a plain ``.x3d`` or ``.glb``), a chain comes back with its levels' counts in place of their
    geometry: a fraction of the bytes to send, and the same report record as with one worker."""
    source = shared_data(CITIES["kit"])
    backend = get_backend("numpy")
    chains = {}
    for workers in (1, 2):
        scene, crs = read_inputs([source])
        info = _output_info([source], scene, crs, ChainOptions())
        executor = SerialExecutor(backend) if workers == 1 else PoolExecutor(workers, "numpy")
        pieces = output_format(f"kit{suffix}").pieces(info, {}) if workers == 2 else None
        with executor:
            chains[workers] = list(
                iter_chains(scene, ChainOptions(), RunContext(executor, backend), pieces=pieces)
            )
    assert [chain_record(c) for c in chains[2]] == [chain_record(c) for c in chains[1]]
    assert all(lv.mesh is lv.points is None for c in chains[2] for lv in c.levels)
    assert all(lv.mesh is not None or lv.points is not None for c in chains[1] for lv in c.levels)
    sizes = {w: sum(len(pickle.dumps(c)) for c in found) for w, found in chains.items()}
    assert sizes[2] < sizes[1] / 3  # KIT's houses keep their LoD2 alone: little geometry


@pytest.mark.parametrize("city", ["kit", "delft"])
def test_what_workers_read_goes_to_be_baked_unopened(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, city: str
) -> None:
    """The objects workers read (CityGML members, CityJSON objects without parts) come back
    packed and go to the workers that bake them as they came: the main process never
    unpickles their geometry (nor pickles it again), which took a fifth of its CPU."""
    parked: list[str] = []
    opened: list[str] = []
    add, node = spool.NodeSpool.add, PackedNode.node

    def noted_add(self: spool.NodeSpool, found: Node | PackedNode) -> None:
        parked.append(type(found).__name__)
        add(self, found)

    def noted_node(self: PackedNode) -> Node:
        opened.append(self.id)
        return node(self)

    monkeypatch.setattr(spool.NodeSpool, "add", noted_add)
    monkeypatch.setattr(PackedNode, "node", noted_node)
    report = convert(shared_data(CITIES[city]), tmp_path / "city.x3d", RunOptions(workers=2))
    assert len(report["objects"]) == len(parked) > 50
    assert parked.count("PackedNode") >= 0.9 * len(parked)  # all but what this process read
    assert opened == []
