"""Bake speed and memory: per level, time (median of runs) and point count, numpy vs gl backend,
beside quadric decimation (fast-simplification) to the same vertex counts.

    python benchmarks/bake.py                 # bunny + full dragon, writes results/bake.md
    python benchmarks/bake.py --runs 5 --gl-runs 1

Runs pinned to one core (the target: the default 3-level bake of the full dragon in under 5 s
on one core, peak memory under 2 GB). Peak memory is measured in a fresh child process that
loads the mesh and bakes the default chain.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from lodconvert.bake import NumpyBackend, get_backend  # noqa: E402
from lodconvert.chain import ChainOptions  # noqa: E402
from lodconvert.io import read_scene  # noqa: E402
from lodconvert.plans import bake_chain  # noqa: E402

HERE = Path(__file__).resolve().parent
STANFORD = HERE.parents[1] / "shared" / "data" / "stanford"
MODELS = {"bunny": "bunny_bun_zipper.ply", "dragon": "dragon_vrip.ply.gz"}


def pin_one_core() -> str:
    """Pin this process to one CPU; return a description."""
    if hasattr(os, "sched_setaffinity"):
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return f"pinned to CPU {cpu}"
    return "not pinned (no sched_setaffinity)"


def bake_times(obj, backend, runs: int) -> tuple[list[dict], float]:
    """Bake the default chain ``runs`` times; per-level median seconds and counts, and the
    median of whole-chain times."""
    per_level: dict[str, list[float]] = {}
    totals, chain = [], None
    for _ in range(runs):
        fresh = type(obj)(obj.id, type(obj.geometry)(obj.geometry.vertices, obj.geometry.faces))
        start = time.perf_counter()
        chain = bake_chain(fresh, ChainOptions(), backend)
        totals.append(time.perf_counter() - start)
        for level in chain.levels[1:]:
            per_level.setdefault(level.name, []).append(level.bake_seconds)
    rows = [
        {
            "level": lv.name,
            "resolution": lv.params.resolution,
            "points": lv.count,
            "seconds": statistics.median(per_level[lv.name]),
        }
        for lv in chain.levels[1:]
    ]
    return rows, statistics.median(totals)


def decimation(obj, counts: list[int], runs: int) -> list[dict]:
    """Quadric decimation to each vertex count: median time and the count reached."""
    import fast_simplification

    v = obj.geometry.vertices.astype(np.float32)
    f = obj.geometry.faces.astype(np.int32)
    rows = []
    for target in counts:
        reduction = 1.0 - target / len(v)
        times = []
        for _ in range(runs):
            start = time.perf_counter()
            out_v, _ = fast_simplification.simplify(v, f, target_reduction=reduction)
            times.append(time.perf_counter() - start)
        rows.append({"target": target, "vertices": len(out_v), "seconds": statistics.median(times)})
    return rows


def peak_memory(path: Path) -> dict:
    """Peak RSS (MiB) of a fresh process that loads ``path`` and bakes the default chain."""
    code = (
        "import resource,sys,time;"
        "from lodconvert.io import read_scene;"
        "from lodconvert.chain import ChainOptions;from lodconvert.plans import bake_chain;"
        "from lodconvert.bake import NumpyBackend;"
        f"o=next(read_scene({str(path)!r}).with_geometry());"
        "base=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss;"
        "t=time.perf_counter();bake_chain(o,ChainOptions(),NumpyBackend());t=time.perf_counter()-t;"
        "peak=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss;"
        "print(base/1024,peak/1024,t)"
    )
    out = subprocess.run(
        ["taskset", "-c", "0", sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
    )
    base, peak, seconds = map(float, out.stdout.split())
    return {"after_load_mib": base, "peak_mib": peak, "seconds": seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="runs per numpy measurement")
    parser.add_argument("--gl-runs", type=int, default=1, help="runs per gl measurement")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "bake.md")
    args = parser.parse_args()
    pinned = pin_one_core()
    try:
        gl = get_backend("gl")
        renderer = gl.renderer
    except Exception as exc:  # no EGL here: report it and measure numpy alone
        gl, renderer = None, f"unavailable ({exc})"

    lines = [
        "# Bake benchmark",
        "",
        f"- date: {datetime.date.today().isoformat()}",
        f"- machine: {platform.platform()}, {os.cpu_count()} CPUs, {pinned}, Python "
        f"{platform.python_version()}, numpy {np.__version__}",
        f"- GL renderer: {renderer}",
        f"- command: `python benchmarks/bake.py --runs {args.runs} --gl-runs {args.gl_runs}`",
        "- default chain: LOD4 = source mesh, LOD3..LOD1 point clouds at the derived "
        "resolutions (γ = 10, 1.5 px spacing at switch-in, 1080 px / 45° reference view), "
        "median filter; times are medians, bake only (reading excluded)",
        "",
    ]
    summary = []
    for name, file in MODELS.items():
        path = STANFORD / file
        if not path.exists():
            lines += [f"## {name}: skipped ({path} absent)", ""]
            continue
        obj = next(read_scene(path).with_geometry())
        n_v, n_f = len(obj.geometry.vertices), len(obj.geometry.faces)
        numpy_rows, numpy_total = bake_times(obj, NumpyBackend(), args.runs)
        gl_rows, gl_total = bake_times(obj, gl, args.gl_runs) if gl else ([], float("nan"))
        dec = decimation(obj, [r["points"] for r in numpy_rows], args.runs)
        mem = peak_memory(path)
        lines += [
            f"## {name} ({n_v:,} vertices, {n_f:,} faces)",
            "",
            "| level | T3 | points (numpy) | numpy s | points (gl) | gl s | QEM vertices | QEM s |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for i, row in enumerate(numpy_rows):
            g = gl_rows[i] if i < len(gl_rows) else None
            gl_points = f"{g['points']:,}" if g else "–"
            gl_seconds = f"{g['seconds']:.3f}" if g else "–"
            lines.append(
                f"| {row['level']} | {row['resolution']} | {row['points']:,} "
                f"| {row['seconds']:.3f} | {gl_points} | {gl_seconds} "
                f"| {dec[i]['vertices']:,} | {dec[i]['seconds']:.3f} |"
            )
        lines += [
            "",
            f"Whole default chain: numpy {numpy_total:.2f} s (median of {args.runs}), "
            f"gl {gl_total:.2f} s (median of {args.gl_runs}); QEM to all three counts "
            f"{sum(d['seconds'] for d in dec):.2f} s.",
            f"Peak memory (fresh process, load + default bake): {mem['peak_mib']:.0f} MiB "
            f"({mem['after_load_mib']:.0f} MiB after loading); that run baked in "
            f"{mem['seconds']:.2f} s.",
            "",
        ]
        summary.append((name, numpy_total, mem["peak_mib"]))
    for name, seconds, peak in summary:
        if name == "dragon":
            verdict = "met" if seconds < 5 and peak < 2048 else "NOT met"
            lines.append(
                f"**Target** (full dragon, default 3-level bake < 5 s on one core, peak < 2 GB): "
                f"{verdict} — {seconds:.2f} s, {peak:.0f} MiB."
            )
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
