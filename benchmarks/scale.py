"""Conversion with worker processes and on a dask cluster, end to end: ``--workers 1`` against
``--workers N`` and against an N-worker dask ``LocalCluster`` (``--scheduler``).

Converts TUM Munich (1×, unzipped), districts of shifted copies of it (made as
``benchmarks/city.py`` makes them) and a district of shifted copies of Delft's CityJSON (with
``--sequence``, as CityJSONSeq too) into X3D and into glTF with the CLI, each run in a fresh
child process (not pinned: the workers need the cores), the set-ups interleaved (1, 2, cluster,
1, …) so that load on a shared machine falls on all alike, after one untimed conversion of 1×
TUM in each (which also leaves the modules' bytecode, as an installed package has it, where
``PYTHONDONTWRITEBYTECODE`` kept it from a checkout). The cluster (worker processes of one
thread on 127.0.0.1) is started once, in a process of its own as a cluster's scheduler runs
apart from its clients, and serves every run:

    python benchmarks/scale.py                    # writes results/scale.md
    python benchmarks/scale.py --runs 3 --factors 1,10,100 --delft 10
    python benchmarks/scale.py --workers 1,2,4,8,16 --cluster 16 --formats x3d --out many_cores.md
    python benchmarks/scale.py --factors "" --delft 10 --sequence --baseline CHECKOUT

Per configuration, medians of ``--runs`` runs: wall seconds, CPU seconds of the whole process
tree (the child's ``wait4`` rusage, which holds its workers': it waits for each; with the
cluster, plus what its scheduler, nannies and workers spent meanwhile), buildings/s, the peak
RSS of the whole process tree (sampled every 50 ms; the cluster's processes: their peak so far,
added), the speed-up over 1 worker (wall) and the
cluster's wall time over the pool's of as many workers. The outputs of each input and format
are compared byte for byte (they must be the same).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import psutil
from city import DATA, TUM, Template, tum_document, write_district
from objects import ROOT
from tables import machine_line, markdown_table, write_results

HERE = Path(__file__).resolve().parent
DELFT = DATA / "cityjson" / "delft.city.json"
LODCONVERT = [sys.executable, "-m", "lodconvert"]
FORMATS = ("x3d", "glb")
SAMPLE_SECONDS = 0.05
"""How often the process tree's memory is sampled."""


@dataclass
class Run:
    """One conversion: wall and CPU seconds (the tree's, and the main process's own), peak RSS
    of the tree (MiB), the digest of its output (:func:`output_digest`) and the stage timings
    of its report."""

    wall: float
    cpu: float
    peak_mib: float
    output: bytes
    timings: dict[str, float]
    main_cpu: float

    @property
    def reading(self) -> float:
        """Seconds of the ``read`` and ``plan`` stages: the main process reading the city (or
        taking what workers read) and parking it."""
        return self.timings["read"] + self.timings["plan"]

    @property
    def main_only(self) -> float:
        """Seconds of the stages only the main process works in (all but ``execute``)."""
        return sum(v for k, v in self.timings.items() if k != "execute")


@dataclass(frozen=True)
class Input:
    """A district to convert: its file, its name in the table and its buildings."""

    path: Path
    name: str
    buildings: int


class Cluster:
    """A dask LocalCluster on 127.0.0.1 (worker processes of one thread each) served by a
    process of its own (``process``: its scheduler and nannies, as ``dask scheduler`` and
    ``dask worker`` would run apart from the client), and the CPU seconds and peak memory of
    the processes it runs in."""

    def __init__(self, process: subprocess.Popen[str], address: str, workers: int) -> None:
        self.process = process
        self.address = address
        self.size = workers
        host = psutil.Process(process.pid)
        self.processes = [host, *host.children(recursive=True)]

    def cpu(self) -> float:
        """CPU seconds of its scheduler, nannies and workers so far."""
        return sum(sum(p.cpu_times()[:2]) for p in self.processes)

    def peak_mib(self) -> float:
        """The sum of its processes' peak RSS (``VmHWM``) so far, in MiB."""
        total = 0.0
        for process in self.processes:
            status = Path(f"/proc/{process.pid}/status").read_text()
            line = next(line for line in status.splitlines() if line.startswith("VmHWM:"))
            total += int(line.split()[1]) / 1024
        return total


SERVE_CLUSTER = """
import sys
from distributed import Client, LocalCluster

with LocalCluster(
    processes=True, n_workers={workers}, threads_per_worker=1, host="127.0.0.1",
    dashboard_address=":0",
) as local, Client(local) as client:
    client.wait_for_workers({workers})
    print(local.scheduler_address, flush=True)
    sys.stdin.read()  # until the benchmark closes it
"""
"""What the cluster's own process runs: a LocalCluster that serves until its stdin closes."""


@contextmanager
def local_cluster(workers: int, root: Path = ROOT) -> Iterator[Cluster | None]:
    """A :class:`Cluster` of ``workers`` running the lodconvert of checkout ``root`` for the
    length of the benchmark (none for 0)."""
    if workers == 0:
        yield None
        return
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
    }
    code = SERVE_CLUSTER.format(workers=workers)
    with subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        env=env, cwd=root,
    ) as process:  # fmt: skip
        assert process.stdin is not None and process.stdout is not None
        address = process.stdout.readline().strip()
        if not address:
            raise SystemExit("the LocalCluster did not start")
        try:
            yield Cluster(process, address, workers)
        finally:
            process.stdin.close()


def _tree_rss(root: psutil.Process) -> int:
    """Bytes resident in ``root`` and its descendants now (0 for those already gone)."""
    total = 0
    try:
        processes = [root, *root.children(recursive=True)]
    except psutil.NoSuchProcess:
        return 0
    for process in processes:
        with suppress(psutil.NoSuchProcess):
            total += process.memory_info().rss
    return total


def output_digest(output: Path) -> bytes:
    """SHA-256 of an output file (not of its name, which differs between set-ups); of a
    tileset (``DIR/tileset.json``), of every file of DIR, each preceded by its path in DIR."""
    if output.name != "tileset.json":
        return hashlib.sha256(output.read_bytes()).digest()
    digest = hashlib.sha256()
    for path in sorted(p for p in output.parent.rglob("*") if p.is_file()):
        digest.update(str(path.relative_to(output.parent)).encode())
        digest.update(path.read_bytes())
    return digest.digest()


def convert_once(
    source: Path,
    output: Path,
    setup: str,
    cluster: Cluster | None = None,
    root: Path = ROOT,
    options: tuple[str, ...] = (),
    report: Path | None = None,
    prefix: tuple[str, ...] = (),
) -> Run:
    """Convert ``source`` into ``output`` (a tileset: its folder removed first) in a child
    process by the lodconvert of checkout ``root``: with ``--workers setup``, its default
    (``setup`` ``default``), or on ``cluster`` (``setup`` ``cluster``), and further CLI
    ``options``, the command run through ``prefix`` (e.g. ``taskset -c 0``); its report is
    ``report`` (default: ``output`` with the suffix ``.json``)."""
    if output.name == "tileset.json":
        shutil.rmtree(output.parent, ignore_errors=True)
    output.unlink(missing_ok=True)
    report = report or output.with_suffix(".json")
    if setup == "cluster":
        assert cluster is not None
        where = ["--scheduler", cluster.address]
    else:  # "default": as many as lodconvert picks
        where = [] if setup == "default" else ["--workers", setup]
    command = [*prefix, *LODCONVERT, str(source), "-o", str(output), "-qq", *where]
    command += ["--report", str(report), *options]
    env = {
        **{k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"},
        "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
    }  # bytecode written once (by the warm-up) and then read, as an installed package has it
    before = cluster.cpu() if cluster is not None and setup == "cluster" else 0.0
    started = time.perf_counter()
    child = subprocess.Popen(command, env=env, cwd=root)
    peak = [0]
    main_cpu = [0.0]
    done = threading.Event()

    def sample() -> None:
        process = psutil.Process(child.pid)
        while not done.wait(SAMPLE_SECONDS):
            peak[0] = max(peak[0], _tree_rss(process))
            with suppress(psutil.NoSuchProcess):
                times = process.cpu_times()
                main_cpu[0] = times.user + times.system

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - started
    done.set()
    sampler.join()
    if os.waitstatus_to_exitcode(status):
        raise SystemExit(f"{' '.join(command)} failed")
    cpu = usage.ru_utime + usage.ru_stime
    peak_mib = peak[0] / (1 << 20)  # wait4's maxrss counts the forked copy of this process
    if cluster is not None and setup == "cluster":
        cpu += cluster.cpu() - before
        peak_mib += cluster.peak_mib()
    timings = json.loads(report.read_text())["timings"]
    return Run(wall, cpu, peak_mib, output_digest(output), timings, main_cpu[0])


def write_delft_district(factor: int, path: Path) -> Input:
    """``factor`` copies of Delft's CityJSON on a near-square grid as one CityJSON file: each
    copy's objects renamed ``ID_k`` and its vertices shifted by whole extents."""
    document = json.loads(DELFT.read_text(encoding="utf-8"))
    vertices = document["vertices"]
    scale = document["transform"]["scale"]
    xs = [v[0] for v in vertices]
    ys = [v[1] for v in vertices]
    extent = (max(xs) - min(xs) + int(10 / scale[0]), max(ys) - min(ys) + int(10 / scale[1]))
    columns = math.ceil(math.sqrt(factor))
    objects: dict[str, Any] = {}
    all_vertices: list[list[int]] = []
    for k in range(factor):
        row, column = divmod(k, columns)
        dx, dy, base = column * extent[0], row * extent[1], len(all_vertices)
        all_vertices += [[x + dx, y + dy, z] for x, y, z in vertices]
        suffix = f"_{k}" if k else ""
        for name, obj in document["CityObjects"].items():
            copy = json.loads(json.dumps(obj))
            for key in ("parents", "children"):
                if key in copy:
                    copy[key] = [ref + suffix for ref in copy[key]]
            for geometry in copy.get("geometry", []):
                geometry["boundaries"] = _renumbered(geometry["boundaries"], base.__add__)
            objects[name + suffix] = copy
    document["CityObjects"], document["vertices"] = objects, all_vertices
    path.write_text(json.dumps(document), encoding="utf-8")
    buildings = sum(o["type"] == "Building" for o in objects.values())
    return Input(path, f"{factor}× Delft CityJSON", buildings)


def _renumbered(boundaries: Any, change: Callable[[int], int]) -> Any:
    """CityJSON ``boundaries`` with each vertex index ``i`` replaced by ``change(i)``."""
    if isinstance(boundaries, list):
        return [_renumbered(part, change) for part in boundaries]
    return change(boundaries)


def write_sequence(district: Input, path: Path) -> Input:
    """``district`` (a CityJSON file whose objects have neither parents nor children) as a
    CityJSONSeq file: its header, then each object as a feature of the vertices it uses."""
    document = json.loads(district.path.read_text(encoding="utf-8"))
    header = {key: document[key] for key in ("type", "version", "transform", "metadata")}
    lines = [json.dumps({**header, "CityObjects": {}, "vertices": []})]
    for key, obj in document["CityObjects"].items():
        used = sorted({i for g in obj.get("geometry", []) for i in _indices(g["boundaries"])})
        index = {old: new for new, old in enumerate(used)}
        for geometry in obj.get("geometry", []):
            geometry["boundaries"] = _renumbered(geometry["boundaries"], index.__getitem__)
        vertices = [document["vertices"][i] for i in used]
        feature = {"type": "CityJSONFeature", "id": key, "CityObjects": {key: obj}}
        lines.append(json.dumps({**feature, "vertices": vertices}))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return Input(path, district.name.replace("CityJSON", "CityJSONSeq"), district.buildings)


def _indices(boundaries: Any) -> Iterator[int]:
    """The vertex indices of CityJSON ``boundaries``."""
    if isinstance(boundaries, list):
        for part in boundaries:
            yield from _indices(part)
    else:
        yield boundaries


def inputs(args: argparse.Namespace, folder: Path) -> Iterator[Input]:
    """The districts to convert, each written when its turn comes (and removed after)."""
    template = Template(tum_document())
    for factor in args.factors:
        sample = write_district(template, factor, folder / f"tum_{factor}x.gml")
        yield Input(sample.path, f"{factor}× TUM", sample.buildings)
        sample.path.unlink()
    if args.delft and DELFT.is_file():
        district = write_delft_district(args.delft, folder / f"delft_{args.delft}x.city.json")
        yield district
        if args.sequence:
            sequence = write_sequence(district, folder / f"delft_{args.delft}x.city.jsonl")
            yield sequence
            sequence.path.unlink()
        district.path.unlink()


def warm_up(
    configurations: list[tuple[str, str]],
    clusters: dict[str, Cluster | None],
    baseline: Path | None,
    folder: Path,
) -> None:
    """Convert 1× TUM once in each configuration, untimed, so that no timed run pays for cold
    caches or for a cluster still starting."""
    sample = write_district(Template(tum_document()), 1, folder / "warm_up.gml")
    for setup, code in configurations:
        root = baseline if code and baseline is not None else ROOT
        convert_once(sample.path, folder / "warm_up.x3d", setup, clusters[code], root)
    sample.path.unlink()


def benchmark(args: argparse.Namespace) -> str:
    """Run every configuration, interleaved; the results file's text."""
    started = time.perf_counter()
    load = os.getloadavg()[0]
    rows = []
    setups = [str(w) for w in args.workers] + (["cluster"] if args.cluster else [])
    codes = ["", "before"] if args.baseline is not None else [""]
    configurations = [(s, c) for c in codes for s in setups]
    with (
        tempfile.TemporaryDirectory(prefix="lodconvert-scale-") as tmp,
        local_cluster(args.cluster) as cluster,
        local_cluster(args.cluster if args.baseline else 0, args.baseline or ROOT) as before,
    ):
        clusters = {"": cluster, "before": before}
        folder = Path(tmp)
        warm_up(configurations, clusters, args.baseline, folder)
        for sample in inputs(args, folder):
            for fmt in args.formats:
                runs: dict[tuple[str, str], list[Run]] = {c: [] for c in configurations}
                for i in range(args.runs):
                    for setup, code in configurations:
                        print(f"{sample.name} → {fmt}, {setup} {code}, run {i + 1}", flush=True)
                        out = folder / f"out_{setup}{code}.{fmt}"
                        root = args.baseline if code else ROOT
                        run = convert_once(sample.path, out, setup, clusters[code], root)
                        runs[setup, code].append(run)
                        print(
                            f"  wall {run.wall:.2f} s, CPU {run.cpu:.2f} s,"
                            f" main CPU {run.main_cpu:.2f} s, peak {run.peak_mib:.0f} MiB",
                            flush=True,
                        )
                same = len({run.output for each in runs.values() for run in each}) == 1
                walls = {c: statistics.median(r.wall for r in runs[c]) for c in configurations}
                for setup, code in configurations:
                    each, wall = runs[setup, code], walls[setup, code]
                    main_cpu = statistics.median(r.main_cpu for r in each)
                    one = walls["1", code] if ("1", code) in walls else float("nan")
                    versus = ""
                    if setup == "cluster" and (str(args.cluster), code) in walls:
                        versus = f"{wall / walls[str(args.cluster), code]:.2f}"
                    label = f"{args.cluster} (LocalCluster)" if setup == "cluster" else setup
                    rows.append(
                        [
                            f"{sample.name} ({sample.buildings:,} buildings)",
                            fmt,
                            label + (f" ({code})" if code else ""),
                            f"{wall:.2f}",
                            f"{statistics.median(r.cpu for r in each):.2f}",
                            f"{main_cpu:.2f}",
                            f"{sample.buildings / wall:,.0f}",
                            f"{sample.buildings / main_cpu:,.0f}",
                            f"{max(r.peak_mib for r in each):.0f}",
                            f"{statistics.median(r.reading for r in each):.2f}",
                            f"{statistics.median(r.main_only for r in each):.2f}",
                            f"{statistics.median(r.timings['execute'] for r in each):.2f}",
                            f"{one / wall:.2f}×",
                            versus,
                            "yes" if same else "**NO**",
                        ]
                    )
    header = [
        "input", "format", "workers", "wall s", "CPU s", "main CPU s", "buildings/s",
        "buildings / main CPU s", "peak RSS MiB (tree)",
        "read+plan s", "main-only s", "execute s", "speed-up", "cluster / pool", "same bytes",
    ]  # fmt: skip
    return results_text(args, header, rows, load, time.perf_counter() - started)


def results_text(
    args: argparse.Namespace, header: list[str], rows: list[list[str]], load: float, took: float
) -> str:
    """The results file: machine, command, table and what the columns mean."""
    command = " ".join(["python", "benchmarks/scale.py", *sys.argv[1:]])
    return "\n".join(
        [
            "# Worker processes and a dask cluster: --workers 1 vs N vs --scheduler",
            "",
            machine_line(load, took),
            f"Command: `{command}`; medians of {args.runs} interleaved runs each.",
            "",
            markdown_table(header, rows, 3),
            "",
            "CPU s: the whole process tree's (the cluster's: its workers' and scheduler's too);"
            " main CPU s: the main process's own (sampled every 50 ms, so up to 50 ms short);"
            " buildings / main CPU s: the most buildings/s that any number of workers could give"
            " while the main process does what it does;"
            " peak RSS: the whole tree's, sampled every 50 ms (the peaks of the cluster's"
            " processes added: its scheduler and nannies run in a process of their own)."
            " Read+plan s: the main process reading the city (with workers: cutting it into runs"
            " of members and taking what the workers read) and parking it; main-only"
            " s: that and the other stages only the main process works in (`assemble`, `write`,"
            " `validate`); execute s: the time it spent baking (1 worker) or waiting for the"
            " workers' results. Speed-up: wall of 1 worker over this row's, same code. Cluster /"
            " pool: the LocalCluster's wall time over as many worker processes' (its workers are"
            " started once, before the first run; the pool's with each run)."
            + (
                f" Rows marked (before): the checkout at `{args.baseline}`, run interleaved with"
                " this one's."
                if args.baseline is not None
                else ""
            ),
            "",
        ]
    )


def _numbers(text: str) -> list[int]:
    return [int(part) for part in text.split(",") if part]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2, help="runs per configuration (2)")
    parser.add_argument(
        "--factors", type=_numbers, default=[1, 10], help="TUM district sizes (default 1,10)"
    )
    parser.add_argument(
        "--delft",
        type=int,
        default=10,
        help="copies of Delft (10; 0: none)",
    )
    parser.add_argument(
        "--sequence",
        action="store_true",
        help="convert the Delft district as CityJSONSeq too (one feature a line)",
    )
    parser.add_argument(
        "--workers", type=_numbers, default=[1, 2], help="worker counts to run (default 1,2)"
    )
    parser.add_argument(
        "--cluster", type=int, default=2, help="LocalCluster workers (default 2; 0: none)"
    )
    parser.add_argument(
        "--formats",
        type=lambda text: text.split(","),
        default=list(FORMATS),
        help="output formats (default x3d,glb)",
    )
    parser.add_argument("--out", type=Path, default=HERE / "results" / "scale.md")
    parser.add_argument(
        "--baseline",
        type=Path,
        help="another checkout of lodconvert whose runs are interleaved with these (before)",
    )
    args = parser.parse_args(argv)
    if not TUM.is_file():
        raise SystemExit(f"{TUM} is absent")
    if 1 not in args.workers:
        raise SystemExit("--workers must include 1 (the speed-up's reference)")
    write_results(args.out, benchmark(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
