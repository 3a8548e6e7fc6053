"""The taken-over half of a scale rehearsal, on a district ``rehearsal.py`` generated (its
``--folder`` kept): the tileset run killed (SIGKILL, the whole tree) once half its tiles are
staged, then run again, which takes the staged folder over; the second run's wall and CPU
seconds, main-process CPU and the process tree's peak RSS (sampled every 50 ms):

    python benchmarks/rehearsal_resume.py /tmp/rehearsal_XXXX     # results/rehearsal_resume.md

The staged folder may hold tiles of an earlier run of the same command already (a killed
straight run): the first run takes those over too before it is killed.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from rehearsal import MEMORY_LIMIT_MIB, ROOT, interrupted
from scale import Run, convert_once
from tables import machine_line, markdown_table, write_results

HERE = Path(__file__).resolve().parent
TILES = 41_681
"""The tiles of the 1000× district's tileset (``results/rehearsal.md``)."""


def results(folder: Path, ran: float, run: Run, load: float, seconds: float) -> str:
    """The results file's text."""
    buildings = 290_000
    rows = [[
        "taken over after the kill", f"{run.wall:.0f}", f"{run.cpu:.0f}", f"{run.main_cpu:.0f}",
        f"{1000 * run.main_cpu / buildings:.2f}", f"{run.peak_mib:,.0f}",
        "yes" if run.peak_mib <= MEMORY_LIMIT_MIB else "no",
    ]]  # fmt: skip
    header = ["run", "wall s", "CPU s", "main CPU s", "main ms/building", "peak RSS MiB (tree)",
              f"≤ {MEMORY_LIMIT_MIB} MiB"]  # fmt: skip
    return "\n".join(
        [
            "# Scale rehearsal taken over: 1000× TUM Munich killed at half its tiles, run again",
            "",
            machine_line(load, seconds),
            f"Command: `python benchmarks/rehearsal_resume.py {folder}`; the district of "
            "`rehearsal.py` (290,000 buildings, 12.1 GB); `--workers 2`; killed after "
            f"{ran:.0f} s with half the {TILES:,} tiles staged.",
            "",
            markdown_table(header, rows, 1),
            "",
            f"Stage timings (s): {json.dumps({k: round(v, 1) for k, v in run.timings.items()})}",
            "",
        ]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="a rehearsal folder holding district.gml")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "rehearsal_resume.md")
    args = parser.parse_args()
    load, began = os.getloadavg()[0], time.perf_counter()
    source, output = args.folder / "district.gml", args.folder / "tiles" / "tileset.json"
    ran = interrupted(source, output, 2, TILES, 0.5)
    run = convert_once(source, output, "2", root=ROOT, report=args.folder / "report.json")
    write_results(args.out, results(args.folder, ran, run, load, time.perf_counter() - began))


if __name__ == "__main__":
    main()
