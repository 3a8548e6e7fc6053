"""3D Tiles output: speed, size and parents of a tileset, and the routes a GIS user has today.

Converts TUM Munich (1×, 10×, 100×: shifted copies made as ``benchmarks/city.py`` makes them)
and the CityJSON district of Delft into a tileset (``DIR/tileset.json``) with ``--hlod
250,1000``, each run a fresh child process (``scale.convert_once``: CPU seconds of the process
tree, peak RSS of its largest process), ``--workers 1`` and ``2`` and the single ``.glb`` of the
same input and options interleaved (1, 2, glb, 1, 2, glb, …):

    nice python benchmarks/tiles.py                       # writes results/tiles.md
    nice python benchmarks/tiles.py --factors 1,10,100 --factor-runs 2,2,1 --peers

Per input, medians of its runs: wall and CPU seconds, objects/s, peak RSS, whether every worker
count wrote the same bytes; tiles (GLB files), bytes of the tileset folder against the ``.glb``;
per tier of LOD parents, the far tiles' content (vertices + points, bytes) over the content of
the tiles they refine into (their children), and the silhouette F of the kept far levels (the
report's ``hlod.cells``); CesiumJS tiles selected and bytes requested from a near and a far
camera where ``cesium_metrics`` measures them.

``--peers`` also converts Delft with the routes a user has, each installed in a virtual
environment of its own (``--peers-venv``, default ``/tmp/lodconvert-peers``, never the
project's): cjio's ``export b3dm`` and py3dtiles's ``export -d`` of a folder of WKB
multipolygons (one per city object, its finest LoD, moved to the extent's centre and turned
y-up as py3dtiles's PostGIS route does), and again with each object's polygons split into
pieces of at most 255 distinct vertices (py3dtiles indexes a geometry's vertices in uint8 and
fails on more). For ours and each peer: CPU and wall seconds, what the
output keeps (city object ids and attribute names found in its bytes; whether features link
geometry to them), the official validator's errors, and positions: the distance from 1,000
source vertices (RD New + NAP, heights taken as ellipsoidal, to ECEF with pyproj in float64) to
the nearest vertex of the output placed as a 3D Tiles viewer places it (tile transforms, RTC,
glTF node matrices, y-up to z-up).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from city import DATA, TUM, Sample, Template, cityjson_sample, tum_document, write_district
from objects import ROOT
from scale import Run, convert_once
from tables import markdown_table, write_results

from lodconvert.io.gltf.binary import accessor_values as accessor
from lodconvert.io.gltf.binary import is_glb
from lodconvert.io.tiles.check import glb_parts

HERE = Path(__file__).resolve().parent
DELFT = DATA / "cityjson" / "delft.city.json"
HLOD = ("--hlod", "250,1000")
VALIDATOR = ROOT.parent / "shared" / "tools" / "3d-tiles-validator" / "validate.sh"
PEERS = ("cjio", "py3dtiles", "triangle")
Y_UP_TO_Z_UP = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)
"""glTF's y-up to 3D Tiles' z-up, as every 3D Tiles viewer applies it to tile content."""


CAMERAS = {"near": 300.0, "far": 4000.0}
"""Metres from the tileset's centre of the cameras CesiumJS is measured from (35° down)."""
TILES_DRIVER = ROOT / "tests" / "browser" / "tiles.mjs"


def cesium_metrics(tileset_path: Path) -> dict | None:
    """CesiumJS tiles selected and bytes requested from a near and a far camera
    (:data:`CAMERAS`): ``{"near": {"tiles": N, "bytes": B}, "far": {...}}``, measured by the
    browser tests' ``tiles.mjs cameras`` scenario in headless Chromium on lodconvert's tileset
    page, served from 127.0.0.1 with the npm package ``cesium``; None where node, Chromium or
    the package is absent."""
    from lodconvert.viewer import serve, write_page

    node, cesium = shutil.which("node"), ROOT / "node_modules" / "cesium" / "package.json"
    chromium = Path(os.environ.get("LODCONVERT_CHROMIUM", "/usr/bin/chromium"))
    if node is None or not cesium.is_file() or not chromium.exists():
        return None
    write_page(tileset_path, library="/node_modules/cesium")
    cameras = [{"name": name, "range": metres, "pitch": -35} for name, metres in CAMERAS.items()]
    params = {"page": f"{tileset_path.parent.name}/tileset.json.html", "cameras": cameras}
    mounts = {"/node_modules": ROOT / "node_modules"}
    with serve(tileset_path.parent.parent, mounts=mounts) as base:
        command = [node, str(TILES_DRIVER), "cameras", base, json.dumps(params)]
        done = subprocess.run(command, capture_output=True, text=True, check=False)
    out = json.loads(done.stdout.strip().splitlines()[-1]) if done.stdout.strip() else {}
    if not out.get("ok"):
        raise SystemExit(f"CesiumJS scenario failed: {out.get('error') or done.stderr[-2000:]}")
    return {
        seen["name"]: {"tiles": seen["tilesSelected"], "bytes": seen["bytes"]}
        for seen in out["result"]["cameras"]
    }


# --- a tileset's content ----------------------------------------------------------------------


@dataclass
class Content:
    """Vertices + points and bytes of a set of tiles."""

    vertices: int = 0
    bytes: int = 0

    def add(self, other: Content) -> None:
        self.vertices += other.vertices
        self.bytes += other.bytes


@dataclass
class Tileset:
    """What a tileset folder holds: tiles with content, bytes of every file, per tier of LOD
    parents the far tiles' content and that of their children."""

    tiles: int = 0
    bytes: int = 0
    far: dict[str, Content] = field(default_factory=dict)
    children: dict[str, Content] = field(default_factory=dict)


def glb_vertices(path: Path) -> int:
    """Vertices + points of every primitive of a GLB (its POSITION counts)."""
    document, _ = glb_parts(path.read_bytes())
    primitives = [p for mesh in document.get("meshes", []) for p in mesh["primitives"]]
    return sum(document["accessors"][p["attributes"]["POSITION"]]["count"] for p in primitives)


def tiles_of(node: dict, folder: Path) -> list[tuple[dict, Path]]:
    """``node``'s child tiles, an external tileset's root standing for the tile that names it."""
    children = []
    for child in node.get("children", []):
        uri = child.get("content", {}).get("uri", "")
        if uri.endswith(".json"):
            path = folder / uri
            children.append((json.loads(path.read_text())["root"], path.parent))
        else:
            children.append((child, folder))
    return children


def survey(tileset_json: Path) -> Tileset:
    """Tiles, bytes and per-tier content of a tileset of ours."""
    folder = tileset_json.parent
    result = Tileset(bytes=sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()))

    def content(node: dict, base: Path) -> Content:
        uri = node.get("content", {}).get("uri")
        if uri is None or uri.endswith(".json"):
            return Content()
        path = base / uri
        return Content(glb_vertices(path), path.stat().st_size)

    def walk(node: dict, base: Path) -> None:
        result.tiles += "content" in node and not node["content"]["uri"].endswith(".json")
        children = tiles_of(node, base)
        extras = node.get("extras", {})
        tier = tier_name(extras["tier"], extras.get("beside", False)) if "tier" in extras else None
        if tier is not None:
            result.far.setdefault(tier, Content()).add(content(node, base))
            below = result.children.setdefault(tier, Content())
            for child, child_base in children:
                below.add(content(child, child_base))
        for child, child_base in children:
            walk(child, child_base)

    walk(json.loads(tileset_json.read_text())["root"], folder)
    return result


def tier_name(tier: int, beside: bool) -> str:
    """A row's tier: its number, ``beside`` for the cells gathering what no cell admitted."""
    return f"{tier} beside" if beside else str(tier)


def silhouette_f(report: dict) -> dict[str, list[float]]:
    """Per tier, the silhouette F of each cell's kept far level (from the report)."""
    per_tier: dict[str, list[float]] = {}
    for cell in report.get("hlod", {}).get("cells", []):
        scores = cell.get("silhouette_f", {})
        if cell.get("kind") in scores:
            tier = tier_name(cell["tier"], cell.get("beside", False))
            per_tier.setdefault(tier, []).append(scores[cell["kind"]])
    return per_tier


# --- where an output puts its vertices --------------------------------------------------------


def node_matrices(document: dict) -> dict[int, np.ndarray]:
    """Each mesh's glTF node matrix (scene roots down; matrix and translation only)."""
    matrices: dict[int, np.ndarray] = {}

    def visit(index: int, parent: np.ndarray) -> None:
        node = document["nodes"][index]
        local = np.eye(4)
        if "matrix" in node:
            local = np.asarray(node["matrix"], float).reshape(4, 4).T
        elif "translation" in node:
            local[:3, 3] = node["translation"]
        matrix = parent @ local
        if "mesh" in node:
            matrices[node["mesh"]] = matrix
        for child in node.get("children", []):
            visit(child, matrix)

    scene = document.get("scenes", [{"nodes": list(range(len(document.get("nodes", []))))}])
    for root in scene[document.get("scene", 0)]["nodes"]:
        visit(root, np.eye(4))
    return matrices


def split_b3dm(data: bytes) -> tuple[dict, bytes]:
    """A b3dm's feature table JSON and its GLB; other content is its own GLB with no table."""
    if data[:4] != b"b3dm":
        return {}, data
    _, _, _, ft_json, ft_bin, bt_json, bt_bin = struct.unpack_from("<4s6I", data)
    glb = data[28 + ft_json + ft_bin + bt_json + bt_bin :]
    (length,) = struct.unpack_from("<I", glb, 8)
    return json.loads(data[28 : 28 + ft_json] or b"{}"), glb[:length]


def content_positions(data: bytes, transform: np.ndarray) -> np.ndarray:
    """The vertices of tile content (GLB or b3dm) placed by the tile's ``transform``, in ECEF."""
    table, glb = split_b3dm(data)
    rtc = np.asarray(table.get("RTC_CENTER", [0, 0, 0]), float)
    document, blob = glb_parts(glb)
    rtc = rtc + document.get("extensions", {}).get("CESIUM_RTC", {}).get("center", [0, 0, 0])
    placed = []
    for mesh, matrix in node_matrices(document).items():
        for primitive in document["meshes"][mesh]["primitives"]:
            local = accessor(document, blob, primitive["attributes"]["POSITION"]).astype(float)
            world = transform @ Y_UP_TO_Z_UP @ matrix
            placed.append(local @ world[:3, :3].T + world[:3, 3] + rtc)
    return np.concatenate(placed) if placed else np.zeros((0, 3))


def tileset_positions(tileset_json: Path) -> np.ndarray:
    """Every content vertex of a tileset, in ECEF, placed by the tiles' transforms."""
    placed = []

    def walk(node: dict, base: Path, parent: np.ndarray) -> None:
        transform = (
            parent @ np.asarray(node.get("transform", np.eye(4).T.ravel()), float).reshape(4, 4).T
        )
        uri = node.get("content", {}).get("uri")
        if uri and uri.endswith(".json"):
            walk(json.loads((base / uri).read_text())["root"], (base / uri).parent, transform)
        elif uri:
            placed.append(content_positions((base / uri).read_bytes(), transform))
        for child in node.get("children", []):
            walk(child, base, transform)

    walk(json.loads(tileset_json.read_text())["root"], tileset_json.parent, np.eye(4))
    return np.concatenate(placed)


def source_vertices(path: Path, count: int = 1000) -> np.ndarray:
    """``count`` vertices of the finest LoD of a CityJSON file's city objects, spread over its
    vertex list, in ECEF (float64): RD New + NAP, the heights taken as ellipsoidal (as our
    tileset states)."""
    from pyproj import Transformer

    model = json.loads(path.read_bytes())
    scale, translate = (np.asarray(model["transform"][k]) for k in ("scale", "translate"))
    finest = [
        max(o["geometry"], key=lambda g: float(g["lod"]))
        for o in model["CityObjects"].values()
        if o.get("geometry")
    ]
    used = sorted({v for g in finest for v in flatten(g["boundaries"])})
    vertices = np.asarray(model["vertices"], float)[used] * scale + translate
    chosen = vertices[np.linspace(0, len(vertices) - 1, count).astype(int)]
    lon, lat = Transformer.from_crs("EPSG:28992", "EPSG:4326", always_xy=True).transform(
        chosen[:, 0], chosen[:, 1]
    )
    ecef = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    return np.column_stack(ecef.transform(lon, lat, chosen[:, 2]))


def flatten(boundaries: list) -> list[int]:
    """The vertex indices of nested CityJSON boundaries."""
    if isinstance(boundaries, int):
        return [boundaries]
    return [v for part in boundaries for v in flatten(part)]


def position_error(placed: np.ndarray, source: np.ndarray) -> tuple[float, float]:
    """Median and largest distance (m) from each source vertex to the nearest placed vertex."""
    from scipy.spatial import cKDTree

    distances, _ = cKDTree(placed).query(source)
    return float(np.median(distances)), float(distances.max())


# --- our runs ---------------------------------------------------------------------------------


@dataclass
class Input:
    """One input's runs: per configuration (``tileset 1``, ``tileset 2``, ``glb 1``) its runs,
    and the first tileset and report written."""

    sample: Sample
    label: str
    runs: dict[str, list[Run]]
    tileset: Tileset
    glb_bytes: int
    f: dict[str, list[float]]
    cesium: dict | None


CONFIGS = (("tileset", 1), ("tileset", 2), ("glb", 1))


def measure(sample: Sample, label: str, runs: int, folder: Path) -> Input:
    """``runs`` interleaved rounds of every configuration on ``sample`` in ``folder``; the first
    tileset (workers 1) is kept in ``folder/kept``."""
    keep = folder / "kept"
    measured: dict[str, list[Run]] = {f"{fmt} {w}": [] for fmt, w in CONFIGS}
    first: tuple[Tileset, dict] | None = None
    for i in range(runs):
        for fmt, workers in CONFIGS:
            print(f"{label} → {fmt}, {workers} worker(s), run {i + 1}", flush=True)
            name = f"tiles_{workers}" if fmt == "tileset" else "district"
            output = folder / name / "tileset.json" if fmt == "tileset" else folder / f"{name}.glb"
            report = folder / f"{name}.report.json"
            measured[f"{fmt} {workers}"].append(
                convert_once(sample.path, output, str(workers), options=HLOD, report=report)
            )
            if fmt == "tileset" and first is None:
                first = survey(output), json.loads(report.read_text())
                shutil.copytree(output.parent, keep)
    assert first is not None
    tileset, report = first
    glb_bytes = (folder / "district.glb").stat().st_size
    cesium = cesium_metrics(keep / "tileset.json")
    return Input(sample, label, measured, tileset, glb_bytes, silhouette_f(report), cesium)


def speed_rows(item: Input) -> list[list[str]]:
    """Rows of the speed table for one input."""
    same = len({r.output for key in ("tileset 1", "tileset 2") for r in item.runs[key]}) == 1
    rows = []
    for key, runs in item.runs.items():
        wall = statistics.median(r.wall for r in runs)
        fmt, workers = key.split()
        rows.append(
            [
                item.label,
                "tileset" if fmt == "tileset" else ".glb",
                workers,
                f"{wall:.2f}",
                f"{statistics.median(r.cpu for r in runs):.2f}",
                f"{item.sample.objects / wall:,.0f}",
                f"{max(r.peak_mib for r in runs):.0f}",
                str(len(runs)),
                ("yes" if same else "**NO**") if fmt == "tileset" else "",
            ]
        )
    return rows


def cesium_cell(metrics: dict | None, key: str) -> str:
    """``near / far`` of one CesiumJS measure, or "not measured"."""
    if metrics is None:
        return "not measured"
    return " / ".join(f"{metrics[view][key]:,}" for view in ("near", "far"))


def size_row(item: Input) -> list[str]:
    """The row of the size table for one input."""
    tileset = item.tileset
    return [
        item.label,
        f"{tileset.tiles:,}",
        f"{tileset.bytes:,}",
        f"{item.glb_bytes:,}",
        f"{tileset.bytes / item.glb_bytes:.2f}",
        cesium_cell(item.cesium, "tiles"),
        cesium_cell(item.cesium, "bytes"),
    ]


def tier_rows(item: Input) -> list[list[str]]:
    """Per tier: far tiles' content against their children's, and F."""
    rows = []
    for tier in sorted(item.tileset.far):
        far, below = item.tileset.far[tier], item.tileset.children[tier]
        scores = item.f.get(tier, [])
        rows.append(
            [
                item.label,
                tier,
                str(len(scores)),
                f"{far.vertices:,} / {below.vertices:,}",
                f"{far.vertices / below.vertices:.2f}" if below.vertices else "–",
                f"{far.bytes:,} / {below.bytes:,}",
                f"{far.bytes / below.bytes:.2f}" if below.bytes else "–",
                f"{min(scores):.3f}" if scores else "–",
                f"{statistics.median(scores):.3f}" if scores else "–",
            ]
        )
    return rows


# --- peers ------------------------------------------------------------------------------------

WKB_SCRIPT = r"""
import json, struct, sys
from pathlib import Path
source, folder, most = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3])
model = json.load(open(source))
scale, translate = model["transform"]["scale"], model["transform"]["translate"]
points = [[c * s + t for c, s, t in zip(v, scale, translate)] for v in model["vertices"]]
lo = [min(p[i] for p in points) for i in range(3)]
hi = [max(p[i] for p in points) for i in range(3)]
centre = [(a + b) / 2 for a, b in zip(lo, hi)]
DEPTH = {"MultiSurface": 0, "CompositeSurface": 0, "Solid": 1, "MultiSolid": 2, "CompositeSolid": 2}
def surfaces(boundaries, depth):
    return boundaries if depth == 0 else [s for b in boundaries for s in surfaces(b, depth - 1)]
def ring(indices):
    xyz = [points[i] for i in indices + indices[:1]]
    # to the centre, then ST_RotateX(-pi/2): (x, y, z) -> (x, z, -y), as py3dtiles's PostGIS query
    xyz = [(x - centre[0], z - centre[2], -(y - centre[1])) for x, y, z in xyz]
    return struct.pack("<I", len(xyz)) + b"".join(struct.pack("<3d", *p) for p in xyz)
folder.mkdir()
for n, (name, obj) in enumerate(model["CityObjects"].items()):
    kept = [g for g in obj.get("geometry", []) if g["type"] in DEPTH]
    if not kept:
        continue
    finest = max(kept, key=lambda g: float(g["lod"]))
    pieces, seen = [[]], set()
    for p in (p for p in surfaces(finest["boundaries"], DEPTH[finest["type"]]) if p):
        more = {v for r in p for v in r} - seen
        if most and pieces[-1] and len(seen) + len(more) > most:
            pieces.append([])
            seen, more = set(), {v for r in p for v in r}
        pieces[-1].append(p)
        seen |= more
    for k, polygons in enumerate(pieces):
        body = b"".join(
            struct.pack("<BII", 1, 1003, len(p)) + b"".join(ring(r) for r in p) for p in polygons
        )
        head = struct.pack("<BII", 1, 1006, len(polygons))
        (folder / f"{n:05d}_{k:03d}.wkb").write_bytes(head + body)
print(*centre)
"""


@dataclass
class Route:
    """A tool's conversion of Delft: seconds, output and what it says."""

    name: str
    wall: float
    cpu: float
    output: Path
    """A ``tileset.json``, or the one content file the tool wrote."""
    failed: str = ""
    """Why the tool failed (the last line it wrote to stderr), if it did."""


class RouteFailed(Exception):
    """A peer's command exited non-zero; the message is its last line on stderr."""


def timed(command: list[str], **kwargs) -> tuple[float, float, str]:
    """Run ``command`` (niced): wall and CPU seconds (its process tree) and its stdout."""
    started = time.perf_counter()
    with tempfile.TemporaryFile("w+") as errors:
        child = subprocess.Popen(
            ["nice", *command], stdout=subprocess.PIPE, stderr=errors, text=True, **kwargs
        )
        out = child.stdout.read() if child.stdout else ""
        _, status, usage = os.wait4(child.pid, 0)
        if os.waitstatus_to_exitcode(status):
            errors.seek(0)
            lines = errors.read().strip().splitlines() or ["(nothing on stderr)"]
            raise RouteFailed(lines[-1])
    return time.perf_counter() - started, usage.ru_utime + usage.ru_stime, out


def peer_versions(venv: Path) -> str:
    """The peers' installed versions, as pip lists them."""
    _, _, out = timed([str(venv / "bin" / "python"), "-m", "pip", "list", "--format=json"])
    versions = {p["name"].lower(): p["version"] for p in json.loads(out)}
    return ", ".join(f"{name} {versions.get(name, '?')}" for name in PEERS)


def install_peers(venv: Path) -> None:
    """Make the peers' virtual environment (once)."""
    if not (venv / "bin" / "py3dtiles").is_file():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(venv / "bin" / "pip"), "install", "-q", *PEERS], check=True)


def run_peers(venv: Path, folder: Path) -> list[Route]:
    """cjio's b3dm export and py3dtiles's WKB export of Delft."""
    bin_ = venv / "bin"
    b3dm = folder / "cjio" / "delft.b3dm"
    b3dm.parent.mkdir()
    print("Delft → cjio export b3dm", flush=True)
    wall, cpu, _ = timed(
        [str(bin_ / "cjio"), "--suppress_msg", str(DELFT), "export", "b3dm", str(b3dm)]
    )
    routes = [Route("cjio `export b3dm`", wall, cpu, b3dm)]
    for most, name in ((0, "py3dtiles `export -d` (WKB)"), (255, "… objects split ≤ 255 vertices")):
        print(f"Delft → WKB → py3dtiles export ({name})", flush=True)
        wkb, out_dir = folder / f"wkb_{most}", folder / f"py3dtiles_{most}"
        script = [str(bin_ / "python"), "-c", WKB_SCRIPT, str(DELFT), str(wkb), str(most)]
        wall, cpu, out = timed(script)
        command = [str(bin_ / "py3dtiles"), "export", "-d", str(wkb), "-o", *out.split()]
        try:
            more_wall, more_cpu, _ = timed([*command, "-s", str(out_dir)], cwd=folder)
        except RouteFailed as error:
            routes.append(Route(name, wall, cpu, out_dir / "tileset.json", str(error)))
            continue
        routes.append(Route(name, wall + more_wall, cpu + more_cpu, out_dir / "tileset.json"))
    return routes


def validator_counts(path: Path) -> str:
    """The official validator's errors and warnings for a tileset or one content file."""
    if not VALIDATOR.is_file():
        return "validator absent"
    report = path.parent / f"{path.name}.validation.json"
    if path.name == "tileset.json":
        subprocess.run([str(VALIDATOR), str(path), str(report)], capture_output=True)
    else:
        home = Path(
            os.environ.get("TILES_VALIDATOR_HOME", Path.home() / ".cache/3d-tiles-validator")
        )
        command = ["node", str(home / "build" / "main"), "--tileContentFile", str(path)]
        subprocess.run([*command, "--reportFile", str(report)], capture_output=True)
    result = json.loads(report.read_text())
    report.unlink()
    kinds: set[str] = set()

    def collect(issues: list[dict]) -> None:
        for issue in issues:
            if issue["severity"] in ("ERROR", "WARNING"):
                kinds.add(issue["type"])
            collect(issue.get("causes", []))

    collect(result["issues"])
    found = f" ({', '.join(sorted(kinds))})" if kinds else ""
    return f"{result['numErrors']} errors, {result['numWarnings']} warnings{found}"


def content_files(output: Path) -> list[Path]:
    """The files a route wrote (a tileset's folder, or its one file)."""
    if output.name != "tileset.json":
        return [output]
    return sorted(p for p in output.parent.rglob("*") if p.is_file())


def linked(path: Path) -> bool:
    """Whether a content file's primitives carry feature ids (``_BATCHID`` or
    ``_FEATURE_ID_0``) linking their vertices to features."""
    _, glb = split_b3dm(path.read_bytes())
    if not is_glb(glb):
        return False
    document, _ = glb_parts(glb)
    names = {"_BATCHID", "_FEATURE_ID_0"}
    return any(
        names & set(p["attributes"]) for m in document.get("meshes", []) for p in m["primitives"]
    )


def keeps(route: Route, source: np.ndarray, our_glb_cpu: float) -> list[str]:
    """The peers-table row of a route."""
    if route.failed:
        return [route.name, "–", "–", "", "", "", "", "", "",
                "", f"failed: `{route.failed}`"]  # fmt: skip
    model = json.loads(DELFT.read_bytes())
    ids = list(model["CityObjects"])
    names = sorted({k for o in model["CityObjects"].values() for k in o.get("attributes", {})})
    files = content_files(route.output)
    blob = b"".join(p.read_bytes() for p in files)
    placed = (
        tileset_positions(route.output)
        if route.output.name == "tileset.json"
        else content_positions(route.output.read_bytes(), np.eye(4))
    )
    median, largest = position_error(placed, source)
    return [
        route.name,
        f"{route.cpu:.1f}",
        f"{route.wall:.1f}",
        f"{route.cpu / our_glb_cpu:.2f}×",
        f"{len(files)}",
        f"{sum(p.stat().st_size for p in files):,}",
        f"{sum(i.encode() in blob for i in ids)}/{len(ids)}",
        f"{sum(n.encode() in blob for n in names)}/{len(names)}",
        "yes" if any(linked(p) for p in files) else "no",
        validator_counts(route.output),
        f"{median:.3g} / {largest:.3g}",
    ]


# --- the results file -------------------------------------------------------------------------


def median_run(runs: list[Run]) -> tuple[float, float]:
    """Median wall and CPU seconds."""
    return statistics.median(r.wall for r in runs), statistics.median(r.cpu for r in runs)


def peers_section(delft: Input, args: argparse.Namespace, folder: Path) -> list[str]:
    """Delft through cjio and py3dtiles against our tileset, as a markdown section."""
    install_peers(args.peers_venv)
    routes = run_peers(args.peers_venv, folder)
    wall, cpu = median_run(delft.runs["tileset 1"])
    ours = Route(
        "lodconvert tileset (1 worker)", wall, cpu, folder / "delft" / "kept" / "tileset.json"
    )
    glb_cpu = median_run(delft.runs["glb 1"])[1]
    source = source_vertices(DELFT)
    rows = [keeps(route, source, glb_cpu) for route in [ours, *routes]]
    header = [
        "route", "CPU s", "wall s", "CPU / our .glb", "files", "bytes", "ids found",
        "attribute names found", "features linked", "3d-tiles-validator",
        "position m (median / max)",
    ]  # fmt: skip
    return [
        "## Peers on Delft",
        "",
        f"Versions: {peer_versions(args.peers_venv)} (own virtual environment); lodconvert's "
        f"figures are the medians above, the peers ran once each. Our .glb: {glb_cpu:.1f} CPU s.",
        "obj2tiles is a .NET tool (no `dotnet` here, nothing to install it from): not measured.",
        "",
        markdown_table(header, rows, 1),
        "",
        "Ids found: Delft's city object ids found in the output's bytes; attribute names: its "
        "attribute names found there; features linked: whether primitives carry `_BATCHID` / "
        "`_FEATURE_ID_0`, which tie each vertex to its feature (and so to its id and attributes: "
        "picking and styling). Position: 1,000 source vertices (RD New + NAP, heights taken as "
        "ellipsoidal, to ECEF with pyproj in float64) to the nearest output vertex as a 3D Tiles "
        "viewer places it (tile transforms, RTC_CENTER, glTF node matrices, y-up to z-up); cjio "
        "writes one `.b3dm` and no tileset, so its content is placed as a tile with no transform "
        "would be. Validator: CesiumGS 3d-tiles-validator 0.6.1 on the tileset (cjio: on its "
        "`.b3dm` alone, `--tileContentFile`), its finding types (a content's own findings are "
        "the causes of its CONTENT_VALIDATION_ERROR).",
        "",
    ]


def benchmark(args: argparse.Namespace) -> str:
    """Run every input and (with ``--peers``) the peers; the results file's text."""
    started, load = time.perf_counter(), os.getloadavg()[0]
    items: list[Input] = []
    peers: list[str] = []
    with tempfile.TemporaryDirectory(prefix="lodconvert-tiles-") as tmp:
        folder = Path(tmp)
        template = Template(tum_document())
        for factor, runs in zip(args.factors, args.factor_runs, strict=True):
            work = folder / f"tum_{factor}x"
            work.mkdir()
            sample = write_district(template, factor, work / "district.gml")
            label = f"{factor}× TUM ({sample.buildings:,} buildings)"
            items.append(measure(sample, label, runs, work))
            shutil.rmtree(work)
        work = folder / "delft"
        work.mkdir()
        sample = cityjson_sample(DELFT)
        label = f"Delft ({sample.objects} objects, {sample.buildings} buildings)"
        items.append(measure(sample, label, args.runs, work))
        if args.peers:
            peers = peers_section(items[-1], args, folder)
    speed_header = [
        "input", "output", "workers", "wall s", "CPU s", "objects/s", "peak RSS MiB", "runs",
        "same bytes (1, 2 workers)",
    ]  # fmt: skip
    size_header = [
        "input", "tiles", "tileset bytes", ".glb bytes", "tileset / .glb",
        "CesiumJS tiles selected (near / far)", "CesiumJS bytes requested (near / far)",
    ]  # fmt: skip
    tier_header = [
        "input", "tier", "cells", "far vertices + points / children's", "ratio",
        "far bytes / children's", "ratio", "min F", "median F",
    ]  # fmt: skip
    factors = ",".join(map(str, args.factors))
    runs = ",".join(map(str, args.factor_runs))
    cores = len(os.sched_getaffinity(0))
    return "\n".join(
        [
            "# 3D Tiles: tilesets of TUM Munich and Delft, and the routes a user has",
            "",
            f"Machine: {cores} cores usable (shared AMD EPYC, {os.uname().machine}, no GPU, Python "
            f"{sys.version.split()[0]}); load average {load:.1f} at the start, "
            f"{os.getloadavg()[0]:.1f} at the end; {time.perf_counter() - started:.0f} s in all.",
            f"Command: `nice python benchmarks/tiles.py --factors {factors} --factor-runs {runs} "
            f"--runs {args.runs}{' --peers' if args.peers else ''}`; every conversion with "
            "`--hlod 250,1000`, medians of interleaved runs (tileset with 1 worker, with 2, the "
            ".glb), CPU s of the whole process tree, peak RSS of its largest process.",
            "",
            "## Speed",
            "",
            markdown_table(speed_header, [r for item in items for r in speed_rows(item)], 3),
            "",
            "Objects/s: the input's top-level city objects (TUM: buildings) over the median wall "
            "time. Same bytes: every tileset run of the input, 1 and 2 workers, wrote the same "
            "files (paths and bytes).",
            "",
            "## Size",
            "",
            markdown_table(size_header, [size_row(item) for item in items], 1),
            "",
            "Tiles: GLB files of the tileset; tileset bytes: every file of its folder "
            "(`tileset.json`, external tilesets, GLBs); .glb: the single file of the same input "
            "and options. CesiumJS columns: from the browser scenario's `cesium_metrics` hook "
            "where it measures them.",
            "",
            "## LOD parents per tier",
            "",
            markdown_table(tier_header, [r for item in items for r in tier_rows(item)], 2),
            "",
            "Per tier of cells (1: 250 m, 2: 1000 m; `2 beside`: the cells gathering the "
            "buildings no cell admitted), the far tiles' content over that of the "
            "tiles they refine into (their children: finer cells' far tiles and the cells' LOD1 "
            "block tiles); vertices + points from the GLBs' POSITION counts, bytes of the GLB "
            "files. F: silhouette F of each cell's kept far level (`hlod.cells` of the report).",
            "",
            *peers,
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])

    def numbers(text: str) -> list[int]:
        return [int(part) for part in text.split(",")]

    parser.add_argument("--runs", type=int, default=3, help="runs of Delft (3)")
    parser.add_argument(
        "--factors", type=numbers, default=[1, 10], help="TUM district sizes in copies (1,10)"
    )
    parser.add_argument(
        "--factor-runs", type=numbers, default=[3, 2], help="runs of each district (3,2)"
    )
    parser.add_argument("--peers", action="store_true", help="also convert Delft with the peers")
    parser.add_argument("--peers-venv", type=Path, default=Path("/tmp/lodconvert-peers"))
    parser.add_argument("--out", type=Path, default=HERE / "results" / "tiles.md")
    args = parser.parse_args(argv)
    if len(args.factor_runs) != len(args.factors):
        parser.error("--factor-runs needs one count per factor")
    for path in (TUM, DELFT):
        if not path.is_file():
            raise SystemExit(f"{path} is absent")
    write_results(args.out, benchmark(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
