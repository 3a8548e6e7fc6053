"""A scale rehearsal: a district of N shifted copies of TUM Munich (``benchmarks/city.py``'s
``write_district``, generated here and removed after) to a 3D Tiles tileset with ``--workers``
worker processes, twice: once straight through, and once killed (SIGKILL, the whole process
tree) when a share of its tiles are written and run again, which takes the staged folder over
(docs/3d-tiles.md); both must end byte for byte alike. From the straight run's costs per
building it models 10⁷ buildings on 16, 64 and 256 workers beside pg2b3dm's published figures:

    python benchmarks/rehearsal.py                      # 1000×: writes results/rehearsal.md
    python benchmarks/rehearsal.py --factor 100 --workers 2

Measured per run: wall and CPU seconds of the process tree (the child's ``wait4`` rusage, its
workers' included), the main process's own CPU seconds (sampled), the peak RSS of the whole
tree (sampled every 50 ms) and the report's stage timings. The model: a run of N buildings on
W workers takes N × max(main CPU s per building, worker CPU s per building / W) plus the
straight run's fixed start, each worker on a core of this machine's speed; it assumes the
main process and the workers scale as measured here (reading spread over the workers, the
main process assembling and writing).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil
from city import Template, tum_document, write_district
from scale import LODCONVERT, Run, convert_once
from tables import machine_line, markdown_table, write_results

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PG2B3DM = ((9_700_000, 114 * 60), (46_000_000, 202 * 60))
"""pg2b3dm's published runs: buildings and seconds (one thread, from PostGIS, no levels)."""
TARGET = 10_000_000
MEMORY_LIMIT_MIB = 2048


def staged(output: Path) -> list[Path]:
    """The staged folders of tileset ``output`` (``.DIR.KEY.tmp`` beside DIR)."""
    folder = output.parent
    return sorted(folder.parent.glob(f".{folder.name}.*.tmp"))


def interrupted(source: Path, output: Path, workers: int, tiles: int, share: float) -> float:
    """Start the conversion and kill its process tree (SIGKILL) once ``share`` of ``tiles``
    tiles lie in its staged folder; the seconds it ran."""
    command = [*LODCONVERT, str(source), "-o", str(output), "-qq", "--workers", str(workers)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    started = time.perf_counter()
    child = subprocess.Popen(command, env=env, cwd=ROOT)
    process = psutil.Process(child.pid)
    while child.poll() is None:
        written = sum(len(list((f / "tiles").glob("*"))) for f in staged(output))
        if written >= share * tiles:
            for member in [*process.children(recursive=True), process]:
                member.send_signal(signal.SIGKILL)
            break
        time.sleep(0.5)
    child.wait()
    if child.returncode == 0:
        raise SystemExit("the run ended before it could be killed: give a smaller --kill-at")
    return time.perf_counter() - started


def model_rows(run: Run, buildings: int) -> list[list[str]]:
    """10⁷ buildings on 16, 64 and 256 workers from ``run``'s costs per building."""
    main = run.main_cpu / buildings
    work = (run.cpu - run.main_cpu) / buildings
    rows = []
    for workers in (16, 64, 256):
        seconds = TARGET * max(main, work / workers)
        bound = "main process" if main >= work / workers else "workers"
        rows.append([f"{workers}", f"{seconds / 3600:.1f} h", f"{TARGET / seconds:,.0f}", bound])
    for count, seconds in PG2B3DM:
        rows.append(
            [
                f"pg2b3dm, 1 thread ({count / 1e6:g} M buildings)",
                f"{seconds / 3600:.1f} h",
                f"{count / seconds:,.0f}",
                "published; no levels of detail",
            ]
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--factor", type=int, default=1000, help="copies of TUM Munich (1000)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (2)")
    parser.add_argument("--kill-at", type=float, default=0.5, help="share of tiles (0.5)")
    parser.add_argument("--folder", type=Path, default=None, help="where to write (a temp dir)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "rehearsal.md")
    args = parser.parse_args()
    load, began = os.getloadavg()[0], time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="rehearsal_", dir=args.folder) as tmp:
        folder = Path(tmp)
        sample = write_district(Template(tum_document()), args.factor, folder / "district.gml")
        size = sample.path.stat().st_size
        output = folder / "tiles" / "tileset.json"
        report = folder / "report.json"
        straight = convert_once(sample.path, output, str(args.workers), root=ROOT, report=report)
        tiles = len(list((output.parent / "tiles").glob("*")))
        ran = interrupted(sample.path, output, args.workers, tiles, args.kill_at)
        resumed = convert_once(sample.path, output, str(args.workers), root=ROOT, report=report)
    buildings = sample.buildings
    same = resumed.output == straight.output
    rows = []
    for name, run in (("straight", straight), ("resumed after the kill", resumed)):
        rows.append(
            [
                name,
                f"{run.wall:.0f}",
                f"{run.cpu:.0f}",
                f"{run.main_cpu:.0f}",
                f"{buildings / run.wall:,.0f}",
                f"{buildings / run.cpu:,.0f}",
                f"{1000 * run.main_cpu / buildings:.2f}",
                f"{run.peak_mib:,.0f}",
                "yes" if run.peak_mib <= MEMORY_LIMIT_MIB else "no",
            ]
        )
    stages = [[name, f"{seconds:.1f}"] for name, seconds in straight.timings.items()]
    model_header = ["workers", "time", "buildings/s", "bound by"]
    header = ["run", "wall s", "CPU s", "main CPU s", "buildings/s", "buildings/CPU s"]
    header += ["main ms/building", "peak RSS MiB (tree)", f"≤ {MEMORY_LIMIT_MIB} MiB"]
    text = "\n".join(
        [
            f"# Scale rehearsal: {args.factor}× TUM Munich to a tileset",
            "",
            machine_line(load, time.perf_counter() - began),
            f"Command: `{' '.join([sys.executable.split('/')[-1], *sys.argv])}`; input: "
            f"{buildings:,} LoD2 buildings, {size / 1e9:.2f} GB of CityGML 2.0 (generated, "
            f"removed after); `--workers {args.workers}`, LOD parents `auto`.",
            "",
            markdown_table(header, rows, 1),
            "",
            f"Killed (SIGKILL, the whole tree) after {ran:.0f} s with {args.kill_at:.0%} of the "
            f"{tiles:,} tiles written, then run again: the same bytes as the straight run: "
            f"{'yes' if same else 'NO'}.",
            "",
            "Stage timings of the straight run (its report; wall seconds of the main process):",
            "",
            markdown_table(["stage", "s"], stages, 1),
            "",
            f"Model: {TARGET:,} buildings at this run's costs per building (main process "
            f"{1000 * straight.main_cpu / buildings:.2f} ms, workers "
            f"{1000 * (straight.cpu - straight.main_cpu) / buildings:.2f} ms of CPU), a core "
            "each:",
            "",
            markdown_table(model_header, model_rows(straight, buildings), 1),
            "",
        ]
    )
    write_results(args.out, text)
    if not same:
        raise SystemExit("the resumed tileset differs from the straight run's")


if __name__ == "__main__":
    main()
