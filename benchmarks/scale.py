"""Conversion with worker processes: ``--workers 1`` against ``--workers 2`` and against a
2-worker dask ``LocalCluster`` (``--scheduler``), end to end.

Converts TUM Munich (1×, unzipped) and a 10× district of shifted copies of it (made as
``benchmarks/city.py`` makes them) into X3D and into glTF with the CLI, each run in a fresh
child process (not pinned: the workers need the cores), the three set-ups interleaved (1, 2,
cluster, 1, …) so that load on a shared machine falls on all alike. The cluster (two worker
processes of one thread on 127.0.0.1) is started by the script once and serves every run, as a
cluster would:

    python benchmarks/scale.py                    # writes results/scale.md
    python benchmarks/scale.py --runs 3 --factors 1,10

Per configuration, medians of ``--runs`` runs: wall seconds, CPU seconds of the whole process
tree (the child's ``wait4`` rusage, which holds its workers': it waits for each; with the
cluster, plus what its worker processes and this one, where its scheduler runs, spent
meanwhile), buildings/s, the peak RSS of the largest single process (the cluster's workers:
their peak so far), the speed-up over 1 worker (wall) and the cluster's wall time over the
pool's. The outputs of each input and format are compared byte for byte (they must be the
same).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import psutil
from city import TUM, Template, tum_document, write_district
from distributed import Client, LocalCluster
from objects import ROOT
from tables import markdown_table, write_results

HERE = Path(__file__).resolve().parent
LODCONVERT = [sys.executable, "-m", "lodconvert"]
FORMATS = ("x3d", "glb")
SETUPS = ("1", "2", "cluster")
"""``--workers 1``, ``--workers 2``, ``--scheduler`` of the 2-worker LocalCluster."""


@dataclass
class Run:
    """One conversion: wall and CPU seconds, peak RSS (MiB), the output's bytes and the stage
    timings of its report."""

    wall: float
    cpu: float
    peak_mib: float
    output: bytes
    timings: dict[str, float]

    @property
    def main_only(self) -> float:
        """Seconds of the stages only the main process works in (all but ``execute``)."""
        return sum(v for k, v in self.timings.items() if k != "execute")


class Cluster:
    """A 2-worker dask LocalCluster on 127.0.0.1 (worker processes of one thread each) and the
    CPU seconds and peak memory of the processes it runs in."""

    def __init__(self, local: Any) -> None:
        self.address = local.scheduler_address
        with Client(local) as client:
            pids = client.run(os.getpid)
        self.workers = [psutil.Process(pid) for pid in pids.values()]

    def cpu(self) -> float:
        """CPU seconds of its workers and of this process (its scheduler and nannies) so far."""
        own = resource.getrusage(resource.RUSAGE_SELF)
        times = [worker.cpu_times() for worker in self.workers]
        return own.ru_utime + own.ru_stime + sum(t.user + t.system for t in times)

    def peak_mib(self) -> float:
        """The largest peak RSS (``VmHWM``) of its workers so far, in MiB."""
        peaks = []
        for worker in self.workers:
            status = Path(f"/proc/{worker.pid}/status").read_text()
            line = next(line for line in status.splitlines() if line.startswith("VmHWM:"))
            peaks.append(int(line.split()[1]) / 1024)
        return max(peaks)


@contextmanager
def local_cluster() -> Iterator[Cluster]:
    """A :class:`Cluster` for the length of the benchmark."""
    sys.path.insert(0, str(ROOT))  # the workers (spawned) import this lodconvert
    with LocalCluster(
        processes=True, n_workers=2, threads_per_worker=1, host="127.0.0.1",
        dashboard_address=":0",
    ) as local:  # fmt: skip
        yield Cluster(local)


def convert_once(source: Path, output: Path, setup: str, cluster: Cluster) -> Run:
    """Convert ``source`` into ``output`` in a child process, by ``setup`` (:data:`SETUPS`)."""
    output.unlink(missing_ok=True)
    report = output.with_suffix(".json")
    where = ["--scheduler", cluster.address] if setup == "cluster" else ["--workers", setup]
    command = [*LODCONVERT, str(source), "-o", str(output), "-qq", *where]
    command += ["--report", str(report)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    before = cluster.cpu() if setup == "cluster" else 0.0
    started = time.perf_counter()
    child = subprocess.Popen(command, env=env, cwd=ROOT)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - started
    if os.waitstatus_to_exitcode(status):
        raise SystemExit(f"{' '.join(command)} failed")
    cpu = usage.ru_utime + usage.ru_stime
    peak = usage.ru_maxrss / 1024
    if setup == "cluster":
        cpu += cluster.cpu() - before
        peak = max(peak, cluster.peak_mib())
    timings = json.loads(report.read_text())["timings"]
    return Run(wall, cpu, peak, output.read_bytes(), timings)


def benchmark(args: argparse.Namespace) -> str:
    """Run every configuration, interleaved; the results file's text."""
    started = time.perf_counter()
    load = os.getloadavg()[0]
    template = Template(tum_document())
    rows = []
    with (
        tempfile.TemporaryDirectory(prefix="lodconvert-scale-") as tmp,
        local_cluster() as cluster,
    ):
        folder = Path(tmp)
        for factor in args.factors:
            sample = write_district(template, factor, folder / f"tum_{factor}x.gml")
            for fmt in FORMATS:
                runs: dict[str, list[Run]] = {setup: [] for setup in SETUPS}
                for i in range(args.runs):
                    for setup in SETUPS:
                        print(f"{factor}× → {fmt}, {setup}, run {i + 1}", flush=True)
                        out = folder / f"out_{setup}.{fmt}"
                        runs[setup].append(convert_once(sample.path, out, setup, cluster))
                same = len({run.output for s in SETUPS for run in runs[s]}) == 1
                walls = {s: statistics.median(r.wall for r in runs[s]) for s in SETUPS}
                for setup in SETUPS:
                    rows.append(
                        [
                            f"{factor}× TUM ({sample.buildings:,} buildings)",
                            fmt,
                            "2 (LocalCluster)" if setup == "cluster" else setup,
                            f"{walls[setup]:.2f}",
                            f"{statistics.median(r.cpu for r in runs[setup]):.2f}",
                            f"{sample.buildings / walls[setup]:,.0f}",
                            f"{max(r.peak_mib for r in runs[setup]):.0f}",
                            f"{statistics.median(r.main_only for r in runs[setup]):.2f}",
                            f"{statistics.median(r.timings['execute'] for r in runs[setup]):.2f}",
                            f"{walls['1'] / walls[setup]:.2f}×",
                            f"{walls['cluster'] / walls['2']:.2f}" if setup == "cluster" else "",
                            "yes" if same else "**NO**",
                        ]
                    )
            sample.path.unlink()
    header = [
        "input", "format", "workers", "wall s", "CPU s", "buildings/s", "peak RSS MiB",
        "main-only s", "execute s", "speed-up", "cluster / pool", "same bytes",
    ]  # fmt: skip
    cores = len(os.sched_getaffinity(0))
    return "\n".join(
        [
            "# Worker processes: --workers 1 vs 2 vs a 2-worker dask LocalCluster",
            "",
            f"Machine: {cores} cores usable ({os.uname().machine}, Python "
            f"{sys.version.split()[0]}), shared; load average {load:.1f} at the start, "
            f"{os.getloadavg()[0]:.1f} at the end; {time.perf_counter() - started:.0f} s in all.",
            f"Command: `python benchmarks/scale.py --runs {args.runs} --factors "
            f"{','.join(map(str, args.factors))}`; medians of {args.runs} interleaved runs each, "
            "CPU s of the whole process tree, peak RSS of the largest process.",
            "",
            markdown_table(header, rows, 3),
            "",
            "Main-only s: the report's stages that only the main process works in (reading and"
            " parking the city: `read` + `plan`; `assemble`, `write`, `validate`); execute s: the"
            " time it spent baking (1 worker) or waiting for the workers' results (2). Baking in"
            " workers can shorten only `execute`: the main-only part bounds the speed-up."
            " Cluster / pool: the LocalCluster's wall time over 2 worker processes' (its workers"
            " are started once, before the first run; the pool's with each run).",
            "",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2, help="runs per configuration (2)")
    parser.add_argument(
        "--factors",
        type=lambda text: [int(part) for part in text.split(",")],
        default=[1, 10],
        help="district sizes in copies of TUM Munich (default 1,10)",
    )
    parser.add_argument("--out", type=Path, default=HERE / "results" / "scale.md")
    args = parser.parse_args(argv)
    if not TUM.is_file():
        raise SystemExit(f"{TUM} is absent")
    write_results(args.out, benchmark(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
