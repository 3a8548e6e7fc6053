"""Many-object conversion speed and memory of the CLI, end to end on one core.

Converts a generated town of N low-poly buildings (boxes and gabled houses, 12–40 triangles
each) with ``lodconvert`` in a fresh child process per run, into X3D and into glTF:

    python benchmarks/objects.py                  # N = 1,000 and 10,000, writes results/objects.md
    python benchmarks/objects.py --counts 1000 --runs 3 --max-seconds 600
    python benchmarks/objects.py --profile        # cProfile of the 1,000-object x3d and glb runs
    python benchmarks/objects.py --commit HEAD    # lodconvert/ as committed, not the working tree

Each scene is written to a GLB (one glTF node + mesh + primitive per building, placed by the
node's translation and yaw, y-up, metres, centred on the origin; deterministic from ``--seed``)
in a temporary folder, then converted with ``lodconvert scene.glb -o out.x3d`` and
``-o out.glb`` in a child process pinned to CPU 0 (``taskset -c 0``). Per run: wall time of the
child from spawn to exit (interpreter start and imports included), its CPU time and peak RSS
(``wait4`` rusage of that child alone) and the output's size; the table gives medians of
``--runs`` runs. A
run past ``--max-seconds`` is killed and recorded as over budget (the configuration's remaining
runs are skipped). A small ``--baseline`` scene is converted the same way to take the fixed cost
(interpreter, imports) out of the memory check. ``--commit REV`` measures ``lodconvert/`` as
committed at REV (a ``git archive`` snapshot on PYTHONPATH), for numbers that edits in progress
in the working tree cannot disturb.

Target: ≥ 1,000 objects/s end to end on one core, and peak memory growing no faster than the
output: (peak RSS − baseline peak) ≤ (output size − baseline output size).

``--profile`` instead runs the ``--profile-count``-object x3d and glb conversions in this process
under cProfile (``lodconvert.cli.main([...])``, pinned to one core, after an unprofiled warm-up
on a one-object scene and an unprofiled run of the same scene) and prints the top functions by
cumulative and by total time; it writes no results file.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import datetime
import hashlib
import importlib.metadata
import io
import json
import math
import os
import platform
import pstats
import resource
import shlex
import shutil
import signal
import statistics
import subprocess
import sys
import tarfile
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import pygltflib  # noqa: E402
from tables import markdown_table, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
LODCONVERT = Path(sys.executable).with_name("lodconvert")
"""The console script of the interpreter running this file (``.venv/bin/lodconvert``)."""
FORMATS = ("x3d", "glb")
TARGET_OBJECTS_PER_S = 1000.0
NOISE_MIB = 2.0
"""Peak-RSS growth within this of the output's growth still meets the memory target (run-to-run
jitter of the peak RSS of the same conversion is about 1 MiB)."""
MIB = 1024 * 1024
PHASES = (("read", "plan"), ("execute", "assemble", "write"), ("validate",))
"""The report's stages summed into the read, bake+write and validate columns."""

LOT = 16.0
"""Lot pitch in metres (each building stands in its own lot)."""
BLOCK = 4
"""Lots along each side of a block; blocks are separated by streets."""
STREET = 12.0
"""Street width in metres."""
KINDS: dict[str, float] = {
    "block": 0.30,  # flat-roofed box, 12 triangles
    "stepped": 0.10,  # box with a set-back upper box, 24
    "hipped": 0.05,  # box under a pyramid roof, 14
    "house": 0.25,  # gabled house, 16
    "house_chimney": 0.20,  # gabled house with a chimney, 28
    "house_annex": 0.10,  # gabled house with a chimney and a flat-roofed annex, 40
}
"""Building kinds and their shares of the town."""
COLORS = (
    (0.85, 0.80, 0.70, 1.0),  # plaster
    (0.65, 0.33, 0.25, 1.0),  # brick
    (0.60, 0.60, 0.62, 1.0),  # concrete
    (0.90, 0.88, 0.82, 1.0),  # whitewash
    (0.45, 0.40, 0.35, 1.0),  # timber
)
"""Base colours of the materials (one material per building)."""


# --- the town ---------------------------------------------------------------------------


@dataclass
class Building:
    """One building in its own frame (y-up, footprint centred on the origin, ground at y = 0),
    placed by ``translation`` and a rotation of ``yaw`` radians about y."""

    name: str
    kind: str
    vertices: np.ndarray
    faces: np.ndarray
    translation: tuple[float, float, float]
    yaw: float
    material: int


@dataclass
class Part:
    """A convex piece of a building: vertices and triangles (oriented outwards by :func:`merge`)."""

    vertices: list[tuple[float, float, float]] = field(default_factory=list)
    faces: list[tuple[int, int, int]] = field(default_factory=list)


def _outward(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Flip the triangles of a convex part whose normal points towards the part's centre."""
    centre = vertices.mean(axis=0)
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    inward = np.einsum("ij,ij->i", normal, tri.mean(axis=1) - centre) < 0
    faces = faces.copy()
    faces[inward] = faces[inward][:, ::-1]
    return faces


def box(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float, top: bool = True) -> Part:
    """An axis-aligned box: 12 triangles (10 without its top)."""
    v = [(x, y, z) for y in (y0, y1) for z in (z0, z1) for x in (x0, x1)]
    # corners: bottom 0..3, top 4..7; index = 4·(y is y1) + 2·(z is z1) + (x is x1)
    quads = [(0, 1, 3, 2), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    if top:
        quads.append((4, 5, 7, 6))
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return Part(v, faces)


def gabled(w: float, d: float, eave: float, ridge: float) -> Part:
    """A gabled house, ridge along x: floor 2, long walls 4, gable ends 6, roof 4 triangles."""
    x, z = w / 2, d / 2
    v = [
        (-x, 0, -z), (x, 0, -z), (x, 0, z), (-x, 0, z),  # ground 0..3
        (-x, eave, -z), (x, eave, -z), (x, eave, z), (-x, eave, z),  # eaves 4..7
        (-x, ridge, 0), (x, ridge, 0),  # ridge 8, 9
    ]  # fmt: skip
    faces = [
        (0, 1, 2), (0, 2, 3),  # floor
        (0, 1, 5), (0, 5, 4), (3, 2, 6), (3, 6, 7),  # long walls
        (0, 3, 7), (0, 7, 4), (4, 7, 8),  # gable end at -x
        (1, 2, 6), (1, 6, 5), (5, 6, 9),  # gable end at +x
        (4, 5, 9), (4, 9, 8), (7, 6, 9), (7, 9, 8),  # roof planes
    ]  # fmt: skip
    return Part(v, faces)


def hipped(w: float, d: float, eave: float, apex: float) -> Part:
    """A box without top under a pyramid roof: 14 triangles."""
    part = box(-w / 2, w / 2, 0.0, eave, -d / 2, d / 2, top=False)
    part.vertices.append((0.0, apex, 0.0))
    part.faces += [(4, 5, 8), (5, 7, 8), (7, 6, 8), (6, 4, 8)]
    return part


def merge(parts: list[Part]) -> tuple[np.ndarray, np.ndarray]:
    """One vertex and face array from convex parts, each part's triangles oriented outwards."""
    vertices, faces, base = [], [], 0
    for part in parts:
        v = np.asarray(part.vertices, dtype=np.float64)
        vertices.append(v)
        faces.append(_outward(v, np.asarray(part.faces, dtype=np.int64)) + base)
        base += len(v)
    return np.concatenate(vertices), np.concatenate(faces)


def building(kind: str, rng: np.random.Generator) -> list[Part]:
    """The parts of one building of ``kind``, sizes drawn from ``rng`` (metres)."""
    w, d = rng.uniform(5.0, 11.0), rng.uniform(5.0, 11.0)
    if kind == "block":
        h = rng.choice([rng.uniform(3.0, 9.0), rng.uniform(9.0, 30.0)], p=[0.7, 0.3])
        return [box(-w / 2, w / 2, 0.0, h, -d / 2, d / 2)]
    if kind == "stepped":
        h1, h2 = rng.uniform(4.0, 12.0), rng.uniform(3.0, 15.0)
        s = rng.uniform(0.55, 0.8)
        return [
            box(-w / 2, w / 2, 0.0, h1, -d / 2, d / 2),
            box(-w * s / 2, w * s / 2, h1, h1 + h2, -d * s / 2, d * s / 2),
        ]
    if kind == "hipped":
        eave = rng.uniform(3.0, 8.0)
        apex = eave + min(w, d) / 2 * math.tan(math.radians(rng.uniform(25.0, 45.0)))
        return [hipped(w, d, eave, apex)]
    eave = rng.uniform(2.8, 7.0)
    pitch = math.radians(rng.uniform(15.0, 55.0))
    ridge = eave + d / 2 * math.tan(pitch)
    parts = [gabled(w, d, eave, ridge)]
    if kind in ("house_chimney", "house_annex"):
        cx = rng.uniform(-0.35, 0.35) * w
        cz = rng.choice([-1.0, 1.0]) * rng.uniform(0.1, 0.3) * d
        half = rng.uniform(0.3, 0.5)
        roof_at = ridge - (ridge - eave) * (abs(cz) + half) / (d / 2)
        parts.append(box(cx - half, cx + half, roof_at - 0.2, ridge + rng.uniform(0.5, 1.5),
                         cz - half, cz + half))  # fmt: skip
    if kind == "house_annex":
        aw, ad = rng.uniform(0.3, 0.6) * w, rng.uniform(2.0, 3.5)
        ax = rng.uniform(-(w - aw) / 2, (w - aw) / 2)
        parts.append(box(ax - aw / 2, ax + aw / 2, 0.0, rng.uniform(2.4, eave),
                         d / 2, d / 2 + ad))  # fmt: skip
    return parts


def town(count: int, seed: int) -> list[Building]:
    """``count`` buildings on a square grid of lots in blocks of BLOCK × BLOCK lots with streets
    between blocks, centred on the origin (x east, z south, y up)."""
    rng = np.random.default_rng(seed)
    kinds = list(KINDS)
    shares = np.array(list(KINDS.values()))
    side = math.ceil(math.sqrt(count))
    extent = side * LOT + (side - 1) // BLOCK * STREET
    out = []
    for i in range(count):
        row, col = divmod(i, side)
        x = col * LOT + col // BLOCK * STREET + LOT / 2 - extent / 2
        z = row * LOT + row // BLOCK * STREET + LOT / 2 - extent / 2
        kind = kinds[rng.choice(len(kinds), p=shares / shares.sum())]
        vertices, faces = merge(building(kind, rng))
        yaw = rng.integers(4) * math.pi / 2 + math.radians(rng.uniform(-8.0, 8.0))
        jitter = rng.uniform(-0.5, 0.5, size=2)
        out.append(
            Building(
                name=f"bldg_{i:05d}",
                kind=kind,
                vertices=vertices,
                faces=faces,
                translation=(float(x + jitter[0]), 0.0, float(z + jitter[1])),
                yaw=float(yaw),
                material=int(rng.integers(len(COLORS))),
            )
        )
    return out


def write_glb(buildings: list[Building], path: Path) -> dict[str, Any]:
    """Write the town as a GLB (one node, mesh and primitive per building; positions float32,
    indices uint16, two buffer views shared by all) and return a summary."""
    positions = io.BytesIO()
    indices = io.BytesIO()
    gltf = pygltflib.GLTF2(
        asset=pygltflib.Asset(version="2.0", generator="lodconvert benchmarks/objects.py"),
        scene=0,
        materials=[
            pygltflib.Material(
                name=f"colour_{i}",
                pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
                    baseColorFactor=list(c), metallicFactor=0.0, roughnessFactor=0.9
                ),
            )
            for i, c in enumerate(COLORS)
        ],
    )
    for i, b in enumerate(buildings):
        v = b.vertices.astype(np.float32)
        f = b.faces.astype(np.uint16).ravel()
        bounds = {"min": v.min(axis=0).tolist(), "max": v.max(axis=0).tolist()}
        gltf.accessors += [
            pygltflib.Accessor(
                bufferView=view,
                byteOffset=stream.tell(),
                componentType=kind,
                count=count,
                type=shape,
                **extra,
            )
            for view, stream, kind, count, shape, extra in (
                (0, positions, pygltflib.FLOAT, len(v), pygltflib.VEC3, bounds),
                (1, indices, pygltflib.UNSIGNED_SHORT, len(f), pygltflib.SCALAR, {}),
            )
        ]
        positions.write(v.tobytes())
        indices.write(f.tobytes())
        gltf.meshes.append(
            pygltflib.Mesh(
                name=b.name,
                primitives=[
                    pygltflib.Primitive(
                        attributes=pygltflib.Attributes(POSITION=2 * i),
                        indices=2 * i + 1,
                        material=b.material,
                    )
                ],
            )
        )
        half = b.yaw / 2
        gltf.nodes.append(
            pygltflib.Node(
                name=b.name,
                mesh=i,
                translation=list(b.translation),
                rotation=[0.0, math.sin(half), 0.0, math.cos(half)],
            )
        )
    gltf.scenes = [pygltflib.Scene(nodes=list(range(len(buildings))))]
    pos, idx = positions.getvalue(), indices.getvalue()
    blob = pos + idx + b"\0" * (-len(idx) % 4)
    gltf.bufferViews = [
        pygltflib.BufferView(
            buffer=0, byteOffset=0, byteLength=len(pos), byteStride=12, target=34962
        ),
        pygltflib.BufferView(buffer=0, byteOffset=len(pos), byteLength=len(idx), target=34963),
    ]
    gltf.buffers = [pygltflib.Buffer(byteLength=len(blob))]
    gltf.set_binary_blob(blob)
    gltf.save_binary(str(path))
    triangles = [len(b.faces) for b in buildings]
    return {
        "objects": len(buildings),
        "triangles": int(sum(triangles)),
        "min_triangles": min(triangles),
        "max_triangles": max(triangles),
        "kinds": {k: sum(b.kind == k for b in buildings) for k in KINDS},
        "bytes": path.stat().st_size,
    }


# --- measuring ------------------------------------------------------------------------------


@dataclass
class Run:
    """One child conversion: wall and CPU seconds, peak RSS (MiB), output size (MiB), status
    (``ok``, ``over budget`` or ``failed (exit N)``), with the phase timings of its report."""

    status: str
    seconds: float
    peak_mib: float
    cpu_seconds: float = float("nan")
    output_mib: float = float("nan")
    timings: dict[str, float] = field(default_factory=dict)
    stderr: str = ""


def pin_prefix() -> list[str]:
    """``taskset -c 0`` where taskset exists, else nothing."""
    return ["taskset", "-c", "0"] if shutil.which("taskset") else []


def child_env(pythonpath: Path | None) -> dict[str, str]:
    """The environment of the conversions: ours, with ``pythonpath`` first on PYTHONPATH (the
    editable install's finder comes after sys.path, so a copy there shadows the working tree)."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(pythonpath), env.get("PYTHONPATH", "")) if p
        )
    return env


def convert_once(glb: Path, output: Path, max_seconds: float, pythonpath: Path | None) -> Run:
    """Convert ``glb`` into ``output`` with the CLI in a child process (own session, pinned);
    kill it after ``max_seconds``. Peak RSS is the child's own ``wait4`` rusage."""
    output.unlink(missing_ok=True)
    report = output.with_suffix(output.suffix + ".report.json")
    command = [*pin_prefix(), str(LODCONVERT), str(glb), "-o", str(output), "-q"]
    command += ["--report", str(report)]
    with tempfile.TemporaryFile() as err:
        started = time.perf_counter()
        child = subprocess.Popen(
            command,
            stdout=subprocess.DEVNULL,
            stderr=err,
            start_new_session=True,
            env=child_env(pythonpath),
        )
        reaped = threading.Event()
        killed = threading.Event()

        def kill() -> None:
            if not reaped.is_set():
                killed.set()
                os.killpg(child.pid, signal.SIGKILL)

        timer = threading.Timer(max_seconds, kill)
        timer.start()
        _, status, usage = os.wait4(child.pid, 0)
        seconds = time.perf_counter() - started
        reaped.set()
        timer.cancel()
        child.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        stderr = err.read().decode(errors="replace")
    peak = usage.ru_maxrss / 1024  # KiB on Linux
    cpu = usage.ru_utime + usage.ru_stime
    if killed.is_set():
        return Run("over budget", seconds, peak, cpu, stderr=stderr)
    if child.returncode:
        return Run(f"failed (exit {child.returncode})", seconds, peak, cpu, stderr=stderr)
    timings = json.loads(report.read_text())["timings"] if report.exists() else {}
    return Run("ok", seconds, peak, cpu, output.stat().st_size / MIB, timings)


@dataclass
class Row:
    """The median of a configuration's runs."""

    count: int
    fmt: str
    runs: list[Run]

    @property
    def ok(self) -> list[Run]:
        """The runs that finished."""
        return [r for r in self.runs if r.status == "ok"]

    @property
    def status(self) -> str:
        """``ok`` when every run finished, else the first other status."""
        return next((r.status for r in self.runs if r.status != "ok"), "ok")

    @property
    def seconds(self) -> float:
        """Median wall seconds of the finished runs (nan when none finished)."""
        return statistics.median(r.seconds for r in self.ok) if self.ok else float("nan")

    @property
    def cpu_seconds(self) -> float:
        """Median CPU seconds (user + system) of the finished runs."""
        return statistics.median(r.cpu_seconds for r in self.ok) if self.ok else float("nan")

    @property
    def rate(self) -> float:
        """Objects per second at the median time."""
        return self.count / self.seconds if self.ok else float("nan")

    @property
    def peak_mib(self) -> float:
        """Median peak RSS of the finished runs."""
        return statistics.median(r.peak_mib for r in self.ok) if self.ok else float("nan")

    @property
    def output_mib(self) -> float:
        """Output size (the same every run)."""
        return self.ok[0].output_mib if self.ok else float("nan")

    def phase(self, *stages: str) -> float:
        """Median seconds of one phase of the report: the sum of its ``stages``."""
        values = [sum(r.timings.get(s, float("nan")) for s in stages) for r in self.ok]
        return statistics.median(values) if values else float("nan")


def measure(
    count: int,
    fmt: str,
    glb: Path,
    folder: Path,
    runs: int,
    max_seconds: float,
    pythonpath: Path | None,
) -> Row:
    """``runs`` conversions of one scene into one format (stopping at the first that fails or
    runs over budget)."""
    done: list[Run] = []
    for i in range(runs):
        run = convert_once(glb, folder / f"out_{count}.{fmt}", max_seconds, pythonpath)
        done.append(run)
        head = f"  N={count:,} {fmt} run {i + 1}/{runs}: {run.status}"
        if run.status != "ok":
            print(f"{head}, killed or ended after {run.seconds:.1f} s", flush=True)
            if run.stderr.strip():
                print("    last stderr line: " + run.stderr.strip().splitlines()[-1], flush=True)
            break
        print(
            f"{head}, {run.seconds:.2f} s ({run.cpu_seconds:.2f} s CPU), "
            f"{count / run.seconds:,.1f} objects/s, peak {run.peak_mib:.0f} MiB, "
            f"output {run.output_mib:.2f} MiB",
            flush=True,
        )
    return Row(count, fmt, done)


def verdict(row: Row, base: Row | None, max_seconds: float) -> tuple[str, str]:
    """Speed and memory verdicts of a row against the target (memory growth over the baseline
    scene's run in the same format against the output's growth)."""
    if row.status == "over budget":
        rate = row.count / max_seconds
        return f"NOT met (< {rate:,.1f} objects/s: over {max_seconds:g} s)", "not measured"
    if row.status != "ok":
        return f"not measured ({row.status})", "not measured"
    speed = "met" if row.rate >= TARGET_OBJECTS_PER_S else "NOT met"
    speed += f" ({row.rate:,.1f} objects/s; {row.count / row.cpu_seconds:,.1f} per CPU second)"
    if base is None or base.status != "ok":
        return speed, "no baseline"
    grew, out = row.peak_mib - base.peak_mib, row.output_mib - base.output_mib
    memory = "met" if grew <= out + NOISE_MIB else "NOT met"
    return speed, f"{memory} (peak {grew:+.1f} MiB vs output {out:+.2f} MiB)"


# --- report ---------------------------------------------------------------------------------


def cpu_model() -> str:
    """The CPU's model name (from /proc/cpuinfo, else platform)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def versions() -> str:
    """Python and the versions of the packages the conversion leans on."""
    parts = [f"Python {platform.python_version()}"]
    for name in ("numpy", "scipy", "trimesh", "pygltflib", "lxml", "lodconvert"):
        with contextlib.suppress(importlib.metadata.PackageNotFoundError):
            parts.append(f"{name} {importlib.metadata.version(name)}")
    return ", ".join(parts)


def package_dir(pythonpath: Path | None) -> Path:
    """The lodconvert package the conversions import."""
    return (pythonpath or ROOT) / "lodconvert"


def tree_digest(folder: Path) -> str:
    """A short digest of the package's Python sources (to notice edits during a run)."""
    digest = hashlib.sha1()
    for path in sorted(folder.rglob("*.py")):
        digest.update(str(path.relative_to(folder)).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:12]


def snapshot(rev: str, folder: Path) -> str:
    """Extract ``lodconvert/`` of commit ``rev`` into ``folder`` (``git archive``; the working
    tree and the index are not touched) and return the commit's short hash."""
    short = subprocess.run(
        ["git", "rev-parse", "--short", f"{rev}^{{commit}}"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    archive = subprocess.run(
        ["git", "archive", "--format=tar", short, "lodconvert"],
        cwd=ROOT,
        capture_output=True,
        check=True,
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(folder, filter="data")
    return short


def imported_from(pythonpath: Path | None) -> Path:
    """The lodconvert package a child with :func:`child_env` really imports."""
    out = subprocess.run(
        [sys.executable, "-c", "import lodconvert; print(lodconvert.__file__)"],
        cwd=tempfile.gettempdir(),
        env=child_env(pythonpath),
        capture_output=True,
        text=True,
        check=True,
    )
    return Path(out.stdout.strip()).parent


def source_state(pythonpath: Path | None, commit: str | None) -> str:
    """Where lodconvert comes from: a commit's snapshot (``--commit``), another folder
    (``--pythonpath``), or the working tree at its commit, with or without uncommitted changes
    in lodconvert/."""
    if commit is not None:
        return f"commit {commit} (`git archive` snapshot of lodconvert/, working tree unused)"
    if pythonpath is not None:
        return f"lodconvert imported from {imported_from(pythonpath)}"
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "lodconvert"],
            cwd=ROOT,
            capture_output=True,
            text=True,
        ).stdout.strip()
    except OSError:
        return "unknown"
    return f"working tree at {head}{' + uncommitted changes in lodconvert/' if dirty else ''}"


def add_source_options(parser: argparse.ArgumentParser) -> None:
    """The mutually exclusive ``--commit REV`` and ``--pythonpath DIR`` options (where the
    measured lodconvert comes from; see :func:`lodconvert_source`)."""
    source = parser.add_mutually_exclusive_group()
    source.add_argument(
        "--commit",
        metavar="REV",
        help="measure lodconvert/ as committed at REV (a `git archive` snapshot) instead of "
        "the working tree, which other people may be editing",
    )
    source.add_argument(
        "--pythonpath",
        type=Path,
        metavar="DIR",
        help="import lodconvert from DIR/lodconvert instead of the working tree",
    )


@contextlib.contextmanager
def lodconvert_source(args: argparse.Namespace) -> Iterator[None]:
    """Within: with ``--commit``, ``args.commit`` is the short hash and ``args.pythonpath`` a
    snapshot of its lodconvert/ (removed on leaving); exits unless the children would import
    lodconvert from ``package_dir(args.pythonpath)``."""
    with tempfile.TemporaryDirectory(prefix="lodconvert-src-") as src:
        if args.commit:
            args.commit = snapshot(args.commit, Path(src))
            args.pythonpath = Path(src)
        if imported_from(args.pythonpath) != package_dir(args.pythonpath):
            raise SystemExit(f"lodconvert is not imported from {package_dir(args.pythonpath)}")
        yield


def preamble(
    title: str,
    args: argparse.Namespace,
    command: str,
    load: tuple[float, float],
    elapsed: float,
    digests: tuple[str, str],
) -> list[str]:
    """The title, date, machine, software and command lines of a results file."""
    pinned = "pinned to CPU 0 with `taskset -c 0`" if pin_prefix() else "not pinned (no taskset)"
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return [
        f"# {title}",
        "",
        f"- Date: {datetime.datetime.now().astimezone().isoformat(timespec='seconds')}",
        f"- Machine: {cpu_model()}, {os.cpu_count()} CPUs ({cores} usable), "
        f"{platform.platform()}; each conversion {pinned}; load average (1 min) {load[0]:.1f} "
        f"at the start, {load[1]:.1f} at the end",
        f"- Software: {versions()}; source: {source_state(args.pythonpath, args.commit)}, "
        "package digest "
        + (
            f"{digests[0]} (unchanged during the run)"
            if digests[0] == digests[1]
            else f"{digests[0]} at the start, {digests[1]} at the end (edited during the run)"
        ),
        f"- Command: `{command}` ({elapsed:.0f} s)",
    ]


def run_facts(
    script: str,
    argv: list[str],
    started: float,
    load_start: float,
    digest_start: str,
    pythonpath: Path | None,
) -> tuple[str, tuple[float, float], float, tuple[str, str]]:
    """At the end of a benchmark: its command line, load averages (start, end), elapsed seconds
    and package digests (start, end), for :func:`preamble`."""
    command = "python " + shlex.join([os.path.relpath(script, ROOT), *argv])
    load = (load_start, os.getloadavg()[0])
    digests = (digest_start, tree_digest(package_dir(pythonpath)))
    return command, load, time.perf_counter() - started, digests


def results_text(
    rows: list[Row],
    bases: dict[str, Row],
    scenes: dict[int, dict[str, Any]],
    args: argparse.Namespace,
    command: str,
    load: tuple[float, float],
    elapsed: float,
    digests: tuple[str, str],
) -> str:
    """The results markdown."""
    lines = [
        *preamble("Many-object conversion benchmark", args, command, load, elapsed, digests),
        f"- Scenes: a town of N buildings, seed {args.seed}: boxes, stepped and hipped blocks and"
        " gabled houses (some with chimneys and annexes), 12–40 triangles each, on"
        f" {LOT:g} m lots in blocks of {BLOCK}×{BLOCK} lots with {STREET:g} m streets, centred"
        " on the origin (y up); one glTF node + mesh + primitive per building, placed by"
        " translation and yaw.",
        "- Conversion: `lodconvert scene.glb -o out.FMT -q --report out.json` with default"
        " options, in a fresh child process per run; time = wall clock from spawn to exit"
        " (interpreter start and imports included), CPU = its user + system time (less disturbed"
        " than wall time when other processes share the core); peak = the child's max RSS"
        " (`wait4`); objects/s and ms/object from the wall time;"
        f" medians of {args.runs} runs (a run over {args.max_seconds:g} s is killed and the"
        " configuration's remaining runs skipped).",
        f"- Target: ≥ {TARGET_OBJECTS_PER_S:,.0f} objects/s end to end on one core; peak memory"
        f" growing no faster than the output, measured against a {args.baseline}-object baseline"
        " scene in the same format: (peak − baseline peak) ≤ (output − baseline output).",
        "",
        "| scene | objects | triangles | triangles/object | GLB MiB |",
        "|---|---:|---:|---:|---:|",
    ]
    for count, s in sorted(scenes.items()):
        lines.append(
            f"| {'baseline' if count == args.baseline else 'town'} | {count:,} | "
            f"{s['triangles']:,} | {s['min_triangles']}–{s['max_triangles']} | "
            f"{s['bytes'] / MIB:.2f} |"
        )
    header = ["N", "format", "status", "median s", "CPU s", "objects/s", "ms/object", "peak MiB"]
    header += ["output MiB", "read s", "bake+write s", "validate s", "target"]
    table, verdicts = [], []
    for role, row in [*(("baseline", b) for b in bases.values()), *(("town", r) for r in rows)]:
        target = "(baseline)"
        if role == "town":
            speed, memory = verdict(row, bases.get(row.fmt), args.max_seconds)
            target = "met" if speed.startswith("met") and memory.startswith("met") else "NOT met"
            verdicts.append(f"- N = {row.count:,} → {row.fmt}: speed {speed}; memory {memory}.")
        if row.status == "ok":
            cells = [
                f"{row.seconds:.2f}",
                f"{row.cpu_seconds:.2f}",
                f"{row.rate:,.1f}",
                f"{1000 * row.seconds / row.count:.2f}",
                f"{row.peak_mib:.0f}",
                f"{row.output_mib:.2f}",
                *(f"{row.phase(*p):.2f}" for p in PHASES),
            ]
        elif row.status == "over budget":
            limit = args.max_seconds
            cells = [f"> {limit:g}", "–", f"< {row.count / limit:,.1f}"]
            cells += [f"> {1000 * limit / row.count:.2f}", *["–"] * 5]
        else:
            cells = ["–"] * 9
        table.append([f"{row.count:,}", row.fmt, row.status, *cells, target])
    lines += ["", markdown_table(header, table, 3), "", *verdicts, ""]
    lines += [
        "Read, bake+write and validate: medians of the stages the CLI's `--report` times (read:"
        " `read` + `plan`, where a streamed reader does its work; bake+write: `execute` +"
        " `assemble` + `write`); the rest of the wall time is interpreter start, imports, option"
        " checks and the report.",
    ]
    return "\n".join(lines) + "\n"


def benchmark(args: argparse.Namespace, argv: list[str]) -> int:
    """Generate the scenes, convert each in each format ``runs`` times, write the results."""
    started = time.perf_counter()
    load_start = os.getloadavg()[0]
    digest_start = tree_digest(package_dir(args.pythonpath))
    rows: list[Row] = []
    bases: dict[str, Row] = {}
    scenes: dict[int, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory(prefix="lodconvert-objects-") as tmp:
        folder = Path(tmp)
        for count in [args.baseline, *args.counts]:
            glb = folder / f"town_{count}.glb"
            made = time.perf_counter()
            scenes[count] = write_glb(town(count, args.seed), glb)
            s = scenes[count]
            print(
                f"N={count:,}: {s['triangles']:,} triangles, {s['bytes'] / MIB:.2f} MiB GLB "
                f"(generated in {time.perf_counter() - made:.1f} s)",
                flush=True,
            )
            for fmt in FORMATS:
                row = measure(count, fmt, glb, folder, args.runs, args.max_seconds, args.pythonpath)
                if count == args.baseline:
                    bases[fmt] = row
                else:
                    rows.append(row)
    command, load, elapsed, digests = run_facts(
        __file__, argv, started, load_start, digest_start, args.pythonpath
    )
    text = results_text(rows, bases, scenes, args, command, load, elapsed, digests)
    write_results(args.out, text)
    for row in rows:
        speed, memory = verdict(row, bases.get(row.fmt), args.max_seconds)
        meets = speed.startswith("met") and memory.startswith("met")
        print(
            f"N={row.count:,} {row.fmt}: {'MEETS' if meets else 'does NOT meet'} the target — "
            f"speed {speed}; memory {memory}"
        )
    return 0


# --- profile --------------------------------------------------------------------------------


def cpu_call(fn: Any, *a: Any) -> tuple[Any, float, float]:
    """``fn(*a)``, its wall and its CPU seconds."""
    started, cpu_started = time.perf_counter(), time.process_time()
    result = fn(*a)
    return result, time.perf_counter() - started, time.process_time() - cpu_started


def profile(args: argparse.Namespace) -> int:
    """Run the x3d and glb conversions of the ``profile_count``-object town in this process
    under cProfile; print the top functions by cumulative and by total time.

    Each format is first converted once from a one-object scene (imports, lazy imports and
    caches: the fixed cost of a process, kept out of the profile) and once from the town
    without the profiler (the in-process time the profile inflates)."""
    if args.pythonpath is not None:
        sys.path.insert(0, str(args.pythonpath))
    import lodconvert
    from lodconvert.cli import main as lodconvert_main

    print(f"profiling {Path(lodconvert.__file__).parent}", flush=True)
    if args.commit:
        print(f"(commit {args.commit})", flush=True)

    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    count = args.profile_count
    with tempfile.TemporaryDirectory(prefix="lodconvert-objects-") as tmp:
        folder = Path(tmp)
        glb = folder / f"town_{count}.glb"
        write_glb(town(count, args.seed), glb)
        one = folder / "town_1.glb"
        write_glb(town(1, args.seed), one)
        for fmt in FORMATS:
            out = folder / f"out_{count}.{fmt}"
            _, wall, cpu = cpu_call(lodconvert_main, [str(one), "-o", str(out), "-q"])
            print(f"\n{fmt}: one-object warm-up {wall:.2f} s wall, {cpu:.2f} s CPU", flush=True)
            _, wall, cpu = cpu_call(lodconvert_main, [str(glb), "-o", str(out), "-q"])
            print(
                f"{fmt}: N={count:,} without profiler {wall:.2f} s wall, {cpu:.2f} s CPU "
                f"({1000 * cpu / count:.3f} ms CPU a object)",
                flush=True,
            )
            profiler = (
                cProfile.Profile(time.process_time)
                if args.profile_timer == "cpu"
                else cProfile.Profile()
            )
            code, seconds, cpu = cpu_call(
                profiler.runcall, lodconvert_main, [str(glb), "-o", str(out), "-q"]
            )
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            print(
                f"\n=== N={count:,} → {fmt}: exit {code}, {seconds:.1f} s wall, {cpu:.1f} s CPU "
                f"under cProfile ({args.profile_timer} timer; {1000 * seconds / count:.1f} ms "
                f"wall, {1000 * cpu / count:.1f} ms CPU a object), "
                f"process peak so far {peak:.0f} MiB ===",
                flush=True,
            )
            if args.profile_dir:
                args.profile_dir.mkdir(parents=True, exist_ok=True)
                profiler.dump_stats(args.profile_dir / f"objects_{count}_{fmt}.prof")
            for key in ("cumulative", "tottime"):
                print(f"\n--- top {args.profile_top} by {key} ---")
                stream = io.StringIO()
                stats = pstats.Stats(profiler, stream=stream).strip_dirs().sort_stats(key)
                stats.print_stats(args.profile_top)
                print(stream.getvalue(), flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--counts",
        type=lambda s: [int(c) for c in s.split(",") if c.strip()],
        default=[1000, 10000],
        metavar="N,..",
        help="objects per scene (default 1000,10000)",
    )
    parser.add_argument("--runs", type=int, default=3, help="runs per configuration (median)")
    parser.add_argument(
        "--max-seconds", type=float, default=600.0, help="kill a run after this long (default 600)"
    )
    parser.add_argument(
        "--baseline", type=int, default=10, help="objects of the memory baseline scene (10)"
    )
    parser.add_argument("--seed", type=int, default=1, help="town generator seed (default 1)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "objects.md")
    parser.add_argument(
        "--profile", action="store_true", help="profile in-process instead (no results file)"
    )
    parser.add_argument("--profile-count", type=int, default=1000, help="objects when profiling")
    parser.add_argument("--profile-top", type=int, default=25, help="functions listed per sort")
    parser.add_argument("--profile-dir", type=Path, help="also save the raw .prof stats here")
    parser.add_argument(
        "--profile-timer",
        choices=("cpu", "wall"),
        default="cpu",
        help="cProfile clock: process CPU time (default; robust on a shared core) or wall",
    )
    add_source_options(parser)
    args = parser.parse_args(argv)
    if args.baseline in args.counts:
        parser.error("--baseline must differ from the counts")
    with lodconvert_source(args):
        return profile(args) if args.profile else benchmark(args, argv)


if __name__ == "__main__":
    sys.exit(main())
