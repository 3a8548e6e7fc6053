"""What dask's worker profiler costs a ``--scheduler`` run: a 2-worker LocalCluster as dask
starts it against one whose workers' statistical profiler is off
(``DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED=False``, as ``dask worker`` takes it from the
environment), and the process pool of as many workers, on 10× TUM Munich to X3D.

Each round starts one cluster, converts once untimed, then ``--runs`` timed; then the other
cluster; then the pool once, so that load falls on all alike (an idle cluster costs CPU, so only
one runs at a time):

    python benchmarks/cluster_profiler.py            # writes results/cluster_profiler.md
    python benchmarks/cluster_profiler.py --rounds 3 --runs 2

Medians over all rounds: wall s, CPU s of the tree (the cluster's processes included), and each
set-up's wall over the pool's. Outputs are compared byte for byte.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from city import Template, tum_document, write_district
from scale import Run, convert_once, local_cluster
from tables import machine_line, markdown_table, write_results

HERE = Path(__file__).resolve().parent
PROFILER = "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED"
SETUPS = {"profiler on (dask's default)": None, "profiler off": "False"}
"""Each cluster set-up and the value of :data:`PROFILER` its processes get (``None``: unset)."""


def benchmark(args: argparse.Namespace) -> str:
    """Run the rounds; the results file's text."""
    started, load = time.perf_counter(), os.getloadavg()[0]
    runs: dict[str, list[Run]] = {name: [] for name in [*SETUPS, "pool"]}
    with tempfile.TemporaryDirectory(prefix="lodconvert-cluster-profiler-") as tmp:
        folder = Path(tmp)
        source = write_district(Template(tum_document()), args.factor, folder / "tum.gml").path
        sample = write_district(Template(tum_document()), 1, folder / "warm_up.gml").path
        for round_ in range(args.rounds):
            for name, value in SETUPS.items():
                if value is None:
                    os.environ.pop(PROFILER, None)
                else:
                    os.environ[PROFILER] = value
                with local_cluster(2) as cluster:
                    convert_once(sample, folder / "warm_up.x3d", "cluster", cluster)
                    for _ in range(args.runs):
                        run = convert_once(source, folder / "out.x3d", "cluster", cluster)
                        runs[name].append(run)
                        print(f"round {round_ + 1}, {name}: {run.wall:.2f} s", flush=True)
            os.environ.pop(PROFILER, None)
            run = convert_once(source, folder / "out.x3d", "2")
            runs["pool"].append(run)
            print(f"round {round_ + 1}, pool: {run.wall:.2f} s", flush=True)
    pool = statistics.median(r.wall for r in runs["pool"])
    same = len({r.output for each in runs.values() for r in each}) == 1
    rows = [
        [
            name if name == "pool" else f"2-worker LocalCluster, {name}",
            str(len(each)),
            f"{statistics.median(r.wall for r in each):.2f}",
            f"{statistics.median(r.cpu for r in each):.2f}",
            f"{statistics.median(r.wall for r in each) / pool:.2f}",
        ]
        for name, each in runs.items()
    ]
    header = ["set-up", "runs", "wall s", "CPU s (tree)", "wall / pool"]
    command = " ".join(["python", "benchmarks/cluster_profiler.py", *sys.argv[1:]])
    return "\n".join(
        [
            "# dask's worker profiler and a --scheduler run",
            "",
            machine_line(load, time.perf_counter() - started),
            f"Command: `{command}`; {args.factor}× TUM Munich to X3D; medians over"
            f" {args.rounds} rounds. Same bytes in every run: {'yes' if same else '**NO**'}.",
            "",
            markdown_table(header, rows, 1),
            "",
            "CPU s: the lodconvert process tree's and, for a cluster, what its scheduler,"
            " nannies and workers spent meanwhile. Wall / pool: the median wall over the process"
            " pool's (`--workers 2`).",
            "",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="rounds (3)")
    parser.add_argument("--runs", type=int, default=2, help="timed runs per cluster and round")
    parser.add_argument("--factor", type=int, default=10, help="TUM district size (10)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "cluster_profiler.md")
    args = parser.parse_args(argv)
    write_results(args.out, benchmark(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
