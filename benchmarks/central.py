"""The main process's CPU per building with workers: a district of N shifted copies of TUM
Munich (``benchmarks/city.py``, generated here and removed after) to X3D, glTF and a 3D Tiles
tileset with ``--workers W``, each in a fresh child process (``scale.convert_once``: the main
process's own CPU sampled every 50 ms, the tree's from ``wait4``), against the target of
0.25 ms a building (the most buildings a second any number of workers could then give is
4,000):

    python benchmarks/central.py                       # 100×, 2 workers: results/central.md
    python benchmarks/central.py --factor 10 --formats x3d
    python benchmarks/central.py --formats glb --baseline /tmp/base   # interleaved with a checkout
    python benchmarks/central.py --formats glb --baseline /tmp/base --runs 3   # medians of 3
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from city import Template, tum_document, write_district
from scale import ROOT, Run, convert_once
from tables import commit_of, machine_line, markdown_table, write_results

HERE = Path(__file__).resolve().parent
TARGET_MS = 0.25
"""Main-process CPU milliseconds per building aimed at."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--factor", type=int, default=100, help="copies of TUM Munich (100)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (2)")
    parser.add_argument("--formats", default="x3d,glb,tiles", help="x3d,glb,tiles")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "central.md")
    parser.add_argument(
        "--baseline", type=Path, help="a checkout to run before this one, format by format"
    )
    parser.add_argument(
        "--runs", type=int, default=1, help="runs of each, interleaved; medians reported (1)"
    )
    args = parser.parse_args()
    load, began = os.getloadavg()[0], time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory(prefix="central_") as tmp:
        folder = Path(tmp)
        district = write_district(Template(tum_document()), args.factor, folder / "tum.gml")
        roots = [(commit_of(ROOT), ROOT)]
        if args.baseline is not None:
            roots.insert(0, (commit_of(args.baseline), args.baseline.resolve()))
        for fmt in args.formats.split(","):
            out = folder / ("out/tileset.json" if fmt == "tiles" else f"out.{fmt}")
            runs: dict[str, list[Run]] = {name: [] for name, _ in roots}
            for _ in range(args.runs):
                for name, root in roots:
                    run = convert_once(
                        district.path, out, str(args.workers), root=root, report=folder / "r.json"
                    )
                    print(fmt, name, run, flush=True)
                    runs[name].append(run)
            for name, _ in roots:
                run = _median(runs[name])
                per = 1000 * run.main_cpu / district.buildings
                rows.append(
                    [
                        fmt if args.baseline is None else f"{fmt} ({name})",
                        f"{run.wall:.1f}",
                        f"{run.cpu:.1f}",
                        f"{run.main_cpu:.2f}",
                        f"{run.timings.get('validate', 0.0):.1f}",
                        f"{per:.3f}",
                        f"{district.buildings / run.main_cpu:,.0f}",
                        "yes" if per <= TARGET_MS else "no",
                        f"{run.peak_mib:,.0f}",
                    ]
                )
    header = ["output", "wall s", "CPU s (tree)", "main CPU s", "check s", "main ms/building"]
    header += ["buildings / main CPU s", f"≤ {TARGET_MS} ms", "peak RSS MiB (tree)"]
    text = "\n".join(
        [
            f"# Main-process CPU per building: {args.factor}× TUM Munich, {args.workers} workers",
            "",
            machine_line(load, time.perf_counter() - began),
            f"Command: `python benchmarks/central.py --factor {args.factor} --workers "
            f"{args.workers} --formats {args.formats}"
            + (f" --baseline {args.baseline}" if args.baseline is not None else "")
            + f"`; input: {district.buildings:,} LoD2 "
            f"buildings, {district.bytes / 1e9:.2f} GB of CityGML 2.0 (generated, removed "
            "after); "
            + ("one run each." if args.runs == 1 else f"medians of {args.runs} interleaved runs."),
            "",
            markdown_table(header, rows, 1),
            "",
            "Main CPU s: the main process's own (sampled every 50 ms); check s: the wall time of "
            "its check of the written output (the report's `validate` stage); buildings / main "
            "CPU s: "
            "the most buildings a second any number of workers could give while the main "
            "process does what it does.",
            "",
        ]
    )
    write_results(args.out, text)


def _median(runs: list[Run]) -> Run:
    """The median of each figure of ``runs`` (the first run's output digest and stage timings, but
    the median check time)."""
    check = statistics.median(run.timings.get("validate", 0.0) for run in runs)
    return Run(
        statistics.median(run.wall for run in runs),
        statistics.median(run.cpu for run in runs),
        statistics.median(run.peak_mib for run in runs),
        runs[0].output,
        {**runs[0].timings, "validate": check},
        statistics.median(run.main_cpu for run in runs),
    )


if __name__ == "__main__":
    main()
