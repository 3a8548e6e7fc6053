"""Silhouette F-measure of the default chain per hole filter (median, gaussian, none) on the
Stanford scans, as in the PCD paper's Table 12.

    python benchmarks/filters.py              # writes results/filters.md and prints it
    python benchmarks/filters.py --views 16 --size 256 --models bunny_bun_zipper.ply

Every point level of the default chain (``ChainOptions(filter=f)``, numpy backend) is rendered
with its declared point sizes (:func:`lodconvert.evaluate.point_pixel_size`: the 1080-pixel
reference view's sizes, scaled to the render) from Fibonacci views at 4, 8 and 16 bounding-box
diagonals and at its own switch-in distance, against the source mesh.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import statistics
import sys
import time
from pathlib import Path

from lodconvert.bake import NumpyBackend
from lodconvert.chain import ChainOptions, bake_chain
from lodconvert.evaluate import DistanceScore, LevelScores, SilhouetteRenderer, evaluate_chain
from lodconvert.io.mesh import read_mesh
from lodconvert.ranges import REFERENCE_VIEW

HERE = Path(__file__).resolve().parent
STANFORD = Path(__file__).resolve().parents[2] / "shared/data/stanford"
MODELS = ("bunny_bun_zipper.ply", "dragon_vrip_res2.ply.gz", "happy_buddha_100k.obj.gz")
FILTERS = ("median", "gaussian", "none")
DISTANCES = (4, 8, 16)
# Mean-F differences below this are reported as a practical tie.
TIE = 0.001


def evaluate_model(
    path: Path, filters: tuple[str, ...], renderer: SilhouetteRenderer, views: int
) -> tuple[list[list[str]], dict[str, float], list[DistanceScore]]:
    """Table rows of every point level per filter, each filter's mean F over point levels ×
    distances, and those scores."""
    obj = read_mesh(path).objects[0]
    rows: list[list[str]] = []
    means: dict[str, float] = {}
    scored: list[DistanceScore] = []
    for name in filters:
        start = time.perf_counter()
        chain = bake_chain(obj, ChainOptions(filter=name), NumpyBackend())
        baked = time.perf_counter() - start
        start = time.perf_counter()
        scores = evaluate_chain(
            None, chain, DISTANCES, views, renderer=renderer, at_design_distance=True
        )
        points = [
            (lv, row) for lv, row in zip(chain.levels, scores, strict=True) if lv.kind == "pcd"
        ]
        level_scores = [s for _, row in points for s in row.scores]
        scored += level_scores
        means[name] = statistics.fmean(s.f for s in level_scores)
        print(
            f"{path.name} {name}: bake {baked:.1f} s, evaluate {time.perf_counter() - start:.1f} s,"
            f" mean F {means[name]:.4f}",
            file=sys.stderr,
        )
        rows += [level_row(path.name, name, lv.params.resolution, row) for lv, row in points]
    return rows, means, scored


def level_row(model: str, filter_name: str, resolution: int, row: LevelScores) -> list[str]:
    """One table row: counts, declared size, F per distance and at switch-in, drawn sizes, mean
    precision and recall over the distances."""
    design = row.at_design
    drawn = [s.pixel_size for s in row.scores] + ([design.pixel_size] if design else [])
    return [
        model,
        filter_name,
        row.name,
        f"{row.count:,}",
        str(resolution),
        f"{row.point_size:.2f}",
        *(f"{s.f:.4f}" for s in row.scores),
        f"{design.f:.4f} @ {design.diagonals:.1f}" if design else "–",
        " / ".join(f"{p:.2f}" for p in drawn),
        f"{statistics.fmean(s.precision for s in row.scores):.4f}",
        f"{statistics.fmean(s.recall for s in row.scores):.4f}",
    ]


def markdown_table(header: list[str], rows: list[list[str]], text_columns: int) -> str:
    """A markdown table; the columns after the first ``text_columns`` right-aligned."""
    align = ["---" if i < text_columns else "---:" for i in range(len(header))]
    lines = [header, align, *rows]
    return "\n".join("| " + " | ".join(line) + " |" for line in lines)


def conclusion(
    means: dict[str, dict[str, float]], filters: tuple[str, ...], scored: list[DistanceScore]
) -> str:
    """Which filter scores best on average over the models, by how much, and per model; and
    whether precision or recall limits F."""
    average = {f: statistics.fmean(m[f] for m in means.values()) for f in filters}
    ranked = sorted(filters, key=average.get, reverse=True)
    best = ranked[0]
    text = (
        f"Averaged over {len(means)} model(s), **{best}** scores best (mean F {average[best]:.4f}"
    )
    if len(ranked) > 1:
        gaps = ", ".join(f"{average[best] - average[f]:+.5f} over {f}" for f in ranked[1:])
        text += f"; {gaps}"
    text += ")."
    tied = [f for f in ranked[1:] if average[best] - average[f] < TIE]
    if tied:
        text += (
            f" The margin over {' and '.join(tied)} is under {TIE} F: on this measure"
            f" {'the filters are' if len(tied) > 1 else 'the two are'} practically tied."
        )
    winners = [f"{model}: {max(m, key=m.get)}" for model, m in means.items()]
    text += " Best per model — " + "; ".join(winners) + "."
    precision = statistics.fmean(s.precision for s in scored)
    recall = statistics.fmean(s.recall for s in scored)
    text += (
        f" Over all point levels, filters and distances, mean precision is {precision:.4f} and"
        f" mean recall {recall:.4f} (lowest {min(s.recall for s in scored):.4f}): "
    )
    if recall > precision:
        text += (
            "the points already cover the silhouette, and F is limited by points drawn past it,"
            " which the cells that hole filling adds can only increase."
        )
    else:
        text += "F is limited by gaps in the silhouette, which hole filling is meant to close."
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=64, help="Fibonacci views per distance")
    parser.add_argument("--size", type=int, default=512, help="render width and height (px)")
    parser.add_argument("--models", nargs="+", default=list(MODELS), help="files in STANFORD")
    parser.add_argument("--filters", nargs="+", default=list(FILTERS), choices=FILTERS)
    parser.add_argument("--out", type=Path, default=HERE / "results" / "filters.md")
    args = parser.parse_args(argv)
    filters = tuple(args.filters)

    renderer = SilhouetteRenderer(args.size)
    started = time.perf_counter()
    rows: list[list[str]] = []
    means: dict[str, dict[str, float]] = {}
    scored: list[DistanceScore] = []
    try:
        for model in args.models:
            path = STANFORD / model
            if not path.exists():
                print(f"skipping {model}: {path} is absent", file=sys.stderr)
                continue
            model_rows, means[model], model_scores = evaluate_model(
                path, filters, renderer, args.views
            )
            rows += model_rows
            scored += model_scores
    finally:
        gl_renderer = renderer.renderer_name
        renderer.release()

    dist_cols = [f"F @{d}α" for d in DISTANCES]
    header = [
        "Model",
        "Filter",
        "Level",
        "Points",
        "T3",
        "Declared px",
        *dist_cols,
        "F @ switch-in (d/α)",
        "px drawn (4/8/16/switch-in)",
        "P̄",
        "R̄",
    ]
    summary_rows = [[m, *(f"{means[m][f]:.4f}" for f in filters)] for m in means]
    if means:
        summary_rows.append(
            [
                "**mean**",
                *(f"{statistics.fmean(m[f] for m in means.values()):.4f}" for f in filters),
            ]
        )
    scale = renderer.focal_px / REFERENCE_VIEW.focal_px
    command = "python " + " ".join([os.path.relpath(__file__), *(argv or sys.argv[1:])])
    text = "\n".join(
        [
            "# Silhouette F-measure per hole filter",
            "",
            f"- Machine: {platform.platform()}, {os.cpu_count()} CPUs, GL renderer: {gl_renderer}",
            f"- Date: {datetime.datetime.now().astimezone().isoformat(timespec='seconds')}",
            f"- Command: `{command}` ({time.perf_counter() - started:.0f} s)",
            f"- Views: {args.views} Fibonacci directions per distance, {args.size}×{args.size} px,"
            f" perspective {renderer.fov_y_deg:g}° vertical FOV, cameras looking at the"
            " bounding-box centre from 4, 8 and 16 diagonals (α) and from each level's switch-in"
            " distance.",
            "- Chains: default `ChainOptions(filter=…)`, numpy backend; LOD4 (the source mesh) is"
            " the reference and scores 1.",
            f"- Point size drawn: clamp(point_size · design_distance / r · {scale:.4f}, 1, 255) px"
            f" — the declared size at the {REFERENCE_VIEW.height_px}-px reference view scaled to"
            f" this {args.size}-px render (same footprint on the object).",
            "- P̄ and R̄: mean precision and recall over the three distances.",
            "",
            "## Per level",
            "",
            markdown_table(header, rows, 3),
            "",
            "## Mean F over point levels × {4, 8, 16} α",
            "",
            markdown_table(["Model", *filters], summary_rows, 1),
            "",
            "## Conclusion",
            "",
            conclusion(means, filters, scored) if means else "No model was found.",
            "",
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
