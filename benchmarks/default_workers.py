"""The default ``--workers`` against ``--workers 1`` and one worker per core, end to end on the
shared cities (small) and TUM Munich districts (large): whether its choice (one worker for each
``INPUT_BYTES_PER_WORKER`` of input, up to the cores) is as fast as the better of the two.

Each run is a fresh CLI process converting to X3D, the set-ups interleaved (1, cores, default,
1, …) after one untimed conversion (which leaves the bytecode, as :mod:`scale` does):

    python benchmarks/default_workers.py            # writes results/default_workers.md
    python benchmarks/default_workers.py --runs 5 --factors 1,2,10

Per input, medians of ``--runs`` runs: wall seconds and CPU seconds of the process tree; the
default's wall over the faster of the other two. Outputs are compared byte for byte.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from city import DATA, TUM, Template, tum_document, write_district
from scale import Run, convert_once
from tables import machine_line, markdown_table, write_results

from lodconvert.io.archive import inflated_size
from lodconvert.tasks import INPUT_BYTES_PER_WORKER, default_workers

HERE = Path(__file__).resolve().parent
CITIES = [
    DATA / "citygml" / "kit_testcases_lod2_100bldg_v3.gml",
    DATA / "citygml" / "plateau_53394517_bldg_lod012_v3.gml",
    DATA / "citygml" / "potsdam_lod1_v1.gml",
    DATA / "cityjson" / "delft.city.json",
    TUM,
]
"""The shared cities converted as they are (TUM Munich zipped: 0.9 MB holding 12 MB)."""


def inputs(factors: list[int], folder: Path) -> list[Path]:
    """The shared cities that are here, then a TUM district of each of ``factors``."""
    districts = [
        write_district(Template(tum_document()), factor, folder / f"tum_{factor}x.gml").path
        for factor in factors
    ]
    return [path for path in CITIES if path.is_file()] + districts


def benchmark(args: argparse.Namespace) -> str:
    """Run every input in each set-up, interleaved; the results file's text."""
    started, load = time.perf_counter(), os.getloadavg()[0]
    cores = len(os.sched_getaffinity(0))
    setups = ["1", str(cores), "default"]
    rows = []
    with tempfile.TemporaryDirectory(prefix="lodconvert-default-workers-") as tmp:
        folder = Path(tmp)
        for source in inputs(args.factors, folder):
            convert_once(source, folder / "warm_up.x3d", "1")
            runs: dict[str, list[Run]] = {setup: [] for setup in setups}
            for i in range(args.runs):
                for setup in setups:
                    run = convert_once(source, folder / f"out_{setup}.x3d", setup)
                    runs[setup].append(run)
                    print(f"{source.name} {setup} run {i + 1}: {run.wall:.2f} s", flush=True)
            wall = {s: statistics.median(r.wall for r in runs[s]) for s in setups}
            cpu = {s: statistics.median(r.cpu for r in runs[s]) for s in setups}
            size = inflated_size(source)
            same = len({r.output for each in runs.values() for r in each}) == 1
            rows.append(
                [
                    source.name,
                    f"{size / 2**20:.1f}",
                    str(default_workers(size)),
                    *(f"{wall[s]:.2f} ({cpu[s]:.2f})" for s in setups),
                    f"{wall['default'] / min(wall['1'], wall[str(cores)]):.2f}",
                    "yes" if same else "**NO**",
                ]
            )
    header = [
        "input", "MiB (inflated)", "default workers", "1 worker: wall s (CPU s)",
        f"{cores} workers", "default", "default / faster", "same bytes",
    ]  # fmt: skip
    command = " ".join(["python", "benchmarks/default_workers.py", *sys.argv[1:]])
    return "\n".join(
        [
            "# The default --workers: one per "
            f"{INPUT_BYTES_PER_WORKER / 2**20:.0f} MiB of input, up to the cores",
            "",
            machine_line(load, time.perf_counter() - started),
            f"Command: `{command}`; medians of {args.runs} interleaved runs each, to X3D.",
            "",
            markdown_table(header, rows, 1),
            "",
            "Wall s and, in brackets, CPU s of the whole process tree (workers and the check's"
            " process included). Default / faster: the default's wall over the faster of 1"
            f" worker and {cores}; above 1 where its choice lost time.",
            "",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="runs per set-up (5)")
    parser.add_argument(
        "--factors",
        type=lambda text: [int(part) for part in text.split(",") if part],
        default=[2, 10],
        help="TUM district sizes besides the shared cities (default 2,10)",
    )
    parser.add_argument("--out", type=Path, default=HERE / "results" / "default_workers.md")
    args = parser.parse_args(argv)
    write_results(args.out, benchmark(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
