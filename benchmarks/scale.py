"""Conversion with worker processes: ``--workers 1`` against ``--workers 2``, end to end.

Converts TUM Munich (1×, unzipped) and a 10× district of shifted copies of it (made as
``benchmarks/city.py`` makes them) into X3D and into glTF with the CLI, each run in a fresh
child process (not pinned: the workers need the cores), the worker counts interleaved (1, 2, 1,
2, …) so that load on a shared machine falls on both alike:

    python benchmarks/scale.py                    # writes results/scale.md
    python benchmarks/scale.py --runs 3 --factors 1,10

Per configuration, medians of ``--runs`` runs: wall seconds, CPU seconds of the whole process
tree (the child's ``wait4`` rusage, which holds its workers': it waits for each), buildings/s,
the peak RSS of the largest single process, and the speed-up of 2 workers over 1 (wall). Each
pair of outputs is compared byte for byte (they must be the same).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from city import TUM, Template, tum_document, write_district
from objects import ROOT
from tables import markdown_table, write_results

HERE = Path(__file__).resolve().parent
LODCONVERT = [sys.executable, "-m", "lodconvert"]
FORMATS = ("x3d", "glb")
WORKERS = (1, 2)


@dataclass
class Run:
    """One conversion: wall and CPU seconds, peak RSS (MiB), the digest of its output and the stage
    timings of its report."""

    wall: float
    cpu: float
    peak_mib: float
    output: bytes
    """SHA-256 of the output (``output_digest``)."""
    timings: dict[str, float]

    @property
    def main_only(self) -> float:
        """Seconds of the stages only the main process works in (all but ``execute``)."""
        return sum(v for k, v in self.timings.items() if k != "execute")


def output_digest(output: Path) -> bytes:
    """SHA-256 of an output file; of a tileset (``DIR/tileset.json``), of every file of DIR,
    each preceded by its path in DIR."""
    digest = hashlib.sha256()
    files = sorted(p for p in output.parent.rglob("*") if p.is_file())
    for path in files if output.name == "tileset.json" else [output]:
        digest.update(str(path.relative_to(output.parent)).encode())
        digest.update(path.read_bytes())
    return digest.digest()


def convert_once(
    source: Path,
    output: Path,
    workers: int,
    options: tuple[str, ...] = (),
    report: Path | None = None,
) -> Run:
    """Convert ``source`` into ``output`` (a tileset: its folder removed first) with
    ``--workers`` and further CLI ``options`` in a child process; its report is ``report``
    (default: ``output`` with the suffix ``.json``)."""
    if output.name == "tileset.json":
        shutil.rmtree(output.parent, ignore_errors=True)
    output.unlink(missing_ok=True)
    report = report or output.with_suffix(".json")
    command = [*LODCONVERT, str(source), "-o", str(output), "-qq", "--workers", str(workers)]
    command += ["--report", str(report), *options]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    started = time.perf_counter()
    child = subprocess.Popen(command, env=env, cwd=ROOT)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - started
    if os.waitstatus_to_exitcode(status):
        raise SystemExit(f"{' '.join(command)} failed")
    cpu = usage.ru_utime + usage.ru_stime
    timings = json.loads(report.read_text())["timings"]
    return Run(wall, cpu, usage.ru_maxrss / 1024, output_digest(output), timings)


def benchmark(args: argparse.Namespace) -> str:
    """Run every configuration, interleaved; the results file's text."""
    started = time.perf_counter()
    load = os.getloadavg()[0]
    template = Template(tum_document())
    rows = []
    with tempfile.TemporaryDirectory(prefix="lodconvert-scale-") as tmp:
        folder = Path(tmp)
        for factor in args.factors:
            sample = write_district(template, factor, folder / f"tum_{factor}x.gml")
            for fmt in FORMATS:
                runs: dict[int, list[Run]] = {w: [] for w in WORKERS}
                for i in range(args.runs):
                    for workers in WORKERS:
                        print(f"{factor}× → {fmt}, {workers} worker(s), run {i + 1}", flush=True)
                        out = folder / f"out_{workers}.{fmt}"
                        runs[workers].append(convert_once(sample.path, out, workers))
                same = len({run.output for w in WORKERS for run in runs[w]}) == 1
                one = statistics.median(r.wall for r in runs[1])
                for workers in WORKERS:
                    wall = statistics.median(r.wall for r in runs[workers])
                    rows.append(
                        [
                            f"{factor}× TUM ({sample.buildings:,} buildings)",
                            fmt,
                            str(workers),
                            f"{wall:.2f}",
                            f"{statistics.median(r.cpu for r in runs[workers]):.2f}",
                            f"{sample.buildings / wall:,.0f}",
                            f"{max(r.peak_mib for r in runs[workers]):.0f}",
                            f"{statistics.median(r.main_only for r in runs[workers]):.2f}",
                            f"{statistics.median(r.timings['execute'] for r in runs[workers]):.2f}",
                            f"{one / wall:.2f}×",
                            "yes" if same else "**NO**",
                        ]
                    )
            sample.path.unlink()
    header = [
        "input", "format", "workers", "wall s", "CPU s", "buildings/s", "peak RSS MiB",
        "main-only s", "execute s", "speed-up", "same bytes",
    ]  # fmt: skip
    cores = len(os.sched_getaffinity(0))
    return "\n".join(
        [
            "# Worker processes: --workers 1 vs 2",
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
            " workers can shorten only `execute`: the main-only part bounds the speed-up.",
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
