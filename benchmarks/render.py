"""Frame time of a grid of LOD instances against the same grid drawing the original mesh, on
the Stanford scans: the shape of the PCD paper's Tables 4–7 (``lodconvert bench``).

    python benchmarks/render.py              # writes results/render.md and prints it
    python benchmarks/render.py --models bunny_bun_zipper.ply --frames 5

Each model is converted with the default chain (:func:`lodconvert.convert.convert`) into a
temporary ``.glb``; then ``lodconvert bench FILE --json …`` runs in a child process per model
(with its own GL context) at the instance counts of :data:`PLAN`, two timed frames each. The
original grid's frame time grows with N × the mesh's triangles — on llvmpipe about 0.07 µs a
triangle when the machine is idle, so 4 to 7 minutes a frame for the full dragon at N = 6561 —
and the plan is sized for the script to end in under 20 minutes on an idle 2-core llvmpipe
machine: fewer N for heavier meshes. Counts that were not run are listed; nothing is
extrapolated.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tables import markdown_table

from lodconvert import convert
from lodconvert.analysis.bench import PAPER_INSTANCES
from lodconvert.cli.commands.bench import (
    bench_object_text,
    bench_table,
    bench_timing_text,
    bench_view_text,
    speedup_of,
)

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
STANFORD = Path(__file__).resolve().parents[2] / "shared/data/stanford"
PLAN: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("bunny_bun_zipper.ply", PAPER_INSTANCES),
    ("happy_buddha_100k.obj.gz", PAPER_INSTANCES),
    ("dragon_vrip_res2.ply.gz", (121, 441, 1681, 6561)),
    ("dragon_vrip.ply.gz", (121, 6561)),
)
"""Model file in STANFORD and the instance counts run."""
FRAMES = 2
"""Timed frames per grid."""
WARMUP = 0
"""Untimed full frames: none (each geometry is still drawn once before timing)."""
BUDGET_S = 1200.0
"""Longest frame allowed before a grid is reported over budget."""
PAPER = {"instances": 6561, "gpu": "GTX 1080 Ti", "original_fps": 8.0, "lod_fps": 22.0}
"""The paper's dragon at 6561 instances: 8 FPS original, 22 FPS with PCD LODs (2.75×)."""


def bench_command(glb: Path, instances: tuple[int, ...], frames: int, budget_s: float) -> list:
    """The ``lodconvert bench`` arguments run for one model."""
    return [
        "bench",
        str(glb),
        "--instances",
        ",".join(map(str, instances)),
        "--frames",
        str(frames),
        "--warmup",
        str(WARMUP),
        "--budget",
        f"{budget_s:g}",
        "--json",
    ]


def run_model(
    model: str, instances: tuple[int, ...], frames: int, budget_s: float, folder: Path
) -> dict[str, Any]:
    """Convert one model and benchmark it; the bench record plus the commands and timings."""
    source = STANFORD / model
    glb = folder / (model.split(".")[0] + ".glb")
    started = time.perf_counter()
    convert(source, glb)
    converted = time.perf_counter() - started
    args = bench_command(glb, instances, frames, budget_s)
    print(f"{model}: converted in {converted:.1f} s; lodconvert {shlex.join(args)}", flush=True)
    started = time.perf_counter()
    child = subprocess.run(
        [sys.executable, "-m", "lodconvert", *args, "--verbose"],
        stdout=subprocess.PIPE,
        text=True,
        check=False,
    )
    if child.returncode:
        raise SystemExit(f"lodconvert bench failed on {model} (exit {child.returncode})")
    record = json.loads(child.stdout)
    shown = [a if a != str(glb) else glb.name for a in args]
    record["commands"] = [
        f"lodconvert {os.path.relpath(source, ROOT)} -o {glb.name}",
        f"lodconvert {shlex.join(shown)}",
    ]
    record["seconds"] = {"convert": converted, "bench": time.perf_counter() - started}
    return record


def paper_comparison(records: dict[str, dict[str, Any]]) -> str:
    """The dragon at the paper's 6561 instances against the paper's 2.75×."""
    target = PAPER["lod_fps"] / PAPER["original_fps"]
    lines = [
        f"The paper ({PAPER['gpu']}): dragon at {PAPER['instances']} instances, "
        f"{PAPER['original_fps']:g} FPS original → {PAPER['lod_fps']:g} FPS with PCD levels, "
        f"a {target:.2f}× speed-up.",
        "",
    ]
    for model, record in records.items():
        if not model.startswith("dragon"):
            continue
        rows = [r for r in record["rows"] if r["instances"] == PAPER["instances"]]
        if not rows:
            lines.append(f"- {model}: N = {PAPER['instances']} was not run.")
            continue
        row = rows[0]
        lod, original = row["lod"], row["original"]
        speedup, bound = speedup_of(row)
        if speedup is None:
            lines.append(f"- {model}: not measured ({lod['status']}, {original['status']}).")
            continue
        verdict = "reaches" if speedup >= target else "does **not** reach"
        measured = (
            f"original over budget (its frame stopped after {original['stopped_after_s']:.0f} s):"
            " speed-up at least"
            if bound
            else f"original {original['median_s']:.1f} s a frame ({original['fps']:.3g} FPS):"
            " speed-up"
        )
        lines.append(
            f"- {model} ({record['reference']['count']:,} vertices): LOD grid "
            f"{lod['median_s']:.2f} s a frame ({lod['fps']:.3g} FPS, {lod['submitted']:,} "
            f"vertices + points submitted against {original['submitted']:,}); {measured} "
            f"**{speedup:.1f}×**, which {verdict} the paper's {target:.2f}× "
            f"({len(original['frame_seconds'])} timed original frame(s), "
            f"{len(lod['frame_seconds'])} LOD)."
        )
    return "\n".join(lines)


def not_run(records: dict[str, dict[str, Any]]) -> str:
    """Which of the paper's instance counts were not run, per model."""
    parts = []
    for model, record in records.items():
        ran = {row["instances"] for row in record["rows"]}
        missing = [n for n in PAPER_INSTANCES if n not in ran]
        if missing:
            parts.append(f"{model}: {', '.join(map(str, missing))}")
    return "; ".join(parts) or "none"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--models", nargs="+", help="files in STANFORD (default: the plan's four models)"
    )
    parser.add_argument("--frames", type=int, default=FRAMES, help="timed frames per grid")
    parser.add_argument("--budget", type=float, default=BUDGET_S, help="seconds a frame at most")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "render.md")
    args = parser.parse_args(argv)
    plan = [p for p in PLAN if args.models is None or p[0] in args.models]

    started = time.perf_counter()
    load_start = os.getloadavg()[0]
    date = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    records: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for model, instances in plan:
            if not (STANFORD / model).exists():
                print(f"skipping {model}: {STANFORD / model} is absent", file=sys.stderr)
                continue
            records[model] = run_model(model, instances, args.frames, args.budget, Path(tmp))
    if not records:
        print("no model was found", file=sys.stderr)
        return 1
    first = next(iter(records.values()))
    command = "python " + shlex.join([os.path.relpath(__file__, ROOT), *(argv or sys.argv[1:])])
    text = [
        "# Render speed: LOD grid against the original mesh",
        "",
        f"- Machine: {platform.platform()}, {os.cpu_count()} CPUs; load average (1 min) "
        f"{load_start:.1f} at the start, {os.getloadavg()[0]:.1f} at the end (the machine is "
        "shared: other processes ran beside the benchmark)",
        f"- GL renderer: {first['renderer']}",
        f"- Date: {date}",
        f"- Command: `{command}` ({time.perf_counter() - started:.0f} s)",
        f"- Setup: {bench_view_text(first)}.",
        "- Grid: N = k² instances on a square lattice on the ground, the camera fixed in front of"
        " the first row whatever N (its position and target in object diagonals α); each"
        " instance draws the level its LOD-centre distance selects with the file's cutoffs (the"
        " original grid draws the source mesh everywhere); instances whose bounding sphere is"
        " outside the view frustum are skipped in both grids. Points are drawn"
        " `point_size · design_distance / r` pixels wide as the files declare; no face culling.",
        "- Timing: wall clock from a finished pipeline through clear and draws to `ctx.finish()`,"
        " after drawing each geometry once; the median of the timed frames. *Submitted* ="
        " vertices (mesh) + points (point levels) sent per frame; speed-up = original median"
        " frame time / LOD median frame time.",
        f"- Instance counts of the paper not run (too slow for this machine's budget): "
        f"{not_run(records)}. Nothing is extrapolated.",
        "",
        "## The dragon at 6561 instances against the paper",
        "",
        paper_comparison(records),
        "",
    ]
    for model, record in records.items():
        header, rows = bench_table(record)
        text += [
            f"## {model}",
            "",
            f"{bench_object_text(record)}. Timing: {bench_timing_text(record)}. Converted in"
            f" {record['seconds']['convert']:.1f} s, benchmarked in"
            f" {record['seconds']['bench']:.0f} s:",
            "",
            *(f"    {c}" for c in record["commands"]),
            "",
            markdown_table(header, rows, 0),
            "",
        ]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(text), encoding="utf-8")
    print("\n".join(text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
