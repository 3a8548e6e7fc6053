"""Silhouette F-measure against the point size: which multiple of the projected grid pitch
should points be drawn at?

    python benchmarks/point_size.py        # writes results/point_size.md

Each model's default chain is baked once per filter; every point level is then scored with
its points drawn at ``factor × projected pitch`` at its switch-in distance (shrinking with
1/distance as the files declare), for several factors, at 4, 8 and 16 diagonals and at the
level's switch-in distance (64 Fibonacci views, 512×512 px, 45°).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import platform
import statistics
import sys
import time
from pathlib import Path

from filters import DISTANCES, MODELS, STANFORD, markdown_table

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions, bake_chain
from lodconvert.evaluate import SilhouetteRenderer, evaluate_chain
from lodconvert.io.mesh import read_mesh
from lodconvert.ranges import projected_px

HERE = Path(__file__).resolve().parent
FACTORS = (0.7, 0.85, 1.0, 1.2, 1.414)


def sweep(path: Path, filter_name: str, renderer: SilhouetteRenderer, views: int) -> list[list]:
    """Rows (factor, mean F over levels × distances, mean F at switch-in, per-level means)."""
    chain = bake_chain(read_mesh(path).objects[0], ChainOptions(filter=filter_name), NumpyBackend())
    rows = []
    for factor in FACTORS:
        for level in chain.levels[1:]:
            pitch_px = projected_px(level.spacing, level.design_distance)
            level.params = dataclasses.replace(level.params, point_size=max(1.0, factor * pitch_px))
        scores = evaluate_chain(
            None, chain, DISTANCES, views, renderer=renderer, at_design_distance=True
        )
        points = scores[1:]
        mean_f = statistics.fmean(s.f for row in points for s in row.scores)
        switch_in = statistics.fmean(row.at_design.f for row in points)
        per_level = [statistics.fmean(s.f for s in row.scores) for row in points]
        rows.append([factor, mean_f, switch_in, per_level])
        print(f"{path.name} {filter_name} ×{factor}: mean F {mean_f:.4f}", file=sys.stderr)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=64)
    parser.add_argument("--filters", nargs="+", default=["median", "none"])
    parser.add_argument("--out", type=Path, default=HERE / "results" / "point_size.md")
    args = parser.parse_args()
    renderer = SilhouetteRenderer(512)
    started = time.perf_counter()
    table: list[list[str]] = []
    best: dict[float, list[float]] = {}
    try:
        for model in MODELS:
            path = STANFORD / model
            if not path.exists():
                print(f"skipping {model}: {path} is absent", file=sys.stderr)
                continue
            for filter_name in args.filters:
                rows = sweep(path, filter_name, renderer, args.views)
                for factor, mean_f, switch_in, per_level in rows:
                    best.setdefault(factor, []).append(mean_f)
                    levels = " / ".join(f"{f:.4f}" for f in per_level)
                    cells = [f"{factor:g}", f"{mean_f:.4f}", f"{switch_in:.4f}", levels]
                    table.append([model, filter_name, *cells])
    finally:
        gl_renderer = renderer.renderer_name
        renderer.release()
    averages = {factor: statistics.fmean(values) for factor, values in best.items()}
    winner = max(averages, key=averages.get) if averages else None
    text = "\n".join(
        [
            "# Silhouette F-measure against point size",
            "",
            f"- Machine: {platform.platform()}, {os.cpu_count()} CPUs, GL renderer: {gl_renderer}",
            f"- Date: {datetime.datetime.now().astimezone().isoformat(timespec='seconds')}",
            f"- Command: `python benchmarks/point_size.py` ({time.perf_counter() - started:.0f} s)",
            f"- {args.views} Fibonacci views, 512×512 px, 45°; distances 4, 8, 16 α and each"
            " level's switch-in distance; points drawn at factor × the projected grid pitch at"
            " switch-in, shrinking with 1/distance, at least 1 px.",
            "",
            markdown_table(
                [
                    "Model",
                    "Filter",
                    "Factor",
                    "Mean F (4/8/16 α)",
                    "Mean F at switch-in",
                    "Per level LOD3 / LOD2 / LOD1",
                ],
                table,
                3,
            ),
            "",
            "## Conclusion",
            "",
            "Mean F over models, filters, levels and distances per factor: "
            + ", ".join(f"×{k:g} {v:.4f}" for k, v in averages.items())
            + (f". Best: **×{winner:g}**." if winner is not None else "."),
            "",
        ]
    )
    args.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
