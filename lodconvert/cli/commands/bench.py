"""``lodconvert bench OUT``: frame time of a grid of LOD instances against the original mesh."""

from __future__ import annotations

import argparse
import json
import os
import platform
from typing import Any

from ...analysis.bench import (
    DEFAULT_BUDGET_S,
    DEFAULT_FRAMES,
    DEFAULT_WARMUP,
    GRID_SPACING,
    PAPER_INSTANCES,
    BenchObject,
    BenchRow,
    BenchSettings,
    GridRenderer,
    level_kind,
    level_triangles,
    read_object,
    run_bench,
)
from ...io.frame import UP_AXES
from ..console import Console
from ..options import EXIT_OK, parse_list

DESCRIPTION = (
    "Render a k×k grid of instances of an object from a fixed camera, each drawing the level its "
    "distance selects, against the same grid drawing the original mesh (offscreen OpenGL); print "
    "per N the median frame time, vertices + points submitted per frame and the speed-up."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``lodconvert bench``."""
    parser.add_argument("input", metavar="OUT", help=".glb, .gltf or .x3d written by lodconvert")
    parser.add_argument(
        "--instances",
        metavar="N1,N2,..",
        default=",".join(map(str, PAPER_INSTANCES)),
        help="grid sizes, perfect squares (default: the paper's %(default)s)",
    )
    parser.add_argument(
        "--frames",
        type=int,
        default=DEFAULT_FRAMES,
        help="timed frames per grid (default %(default)s)",
    )
    parser.add_argument(
        "--warmup",
        type=int,
        default=DEFAULT_WARMUP,
        help="untimed frames first (default %(default)s)",
    )
    parser.add_argument(
        "--budget",
        type=float,
        default=DEFAULT_BUDGET_S,
        metavar="SECONDS",
        help="stop a frame after this long and report the grid over budget (default %(default)s)",
    )
    parser.add_argument(
        "--spacing",
        type=float,
        default=GRID_SPACING,
        help="distance between instances in object diagonals α (default %(default)s)",
    )
    parser.add_argument(
        "--reference", metavar="MESH", help="original mesh (needed when LOD4 is a point cloud)"
    )
    parser.add_argument("--object", metavar="ID", help="object to instance (default: the first)")
    parser.add_argument(
        "--up",
        choices=UP_AXES,
        default="y",
        help="the model's up axis (default y, as glTF; a negative one as --up=-z)",
    )
    parser.add_argument(
        "--no-frustum-culling",
        action="store_true",
        help="submit instances outside the view too (default: skip them in both grids)",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress messages")
    parser.add_argument("-v", "--verbose", action="store_true", help="print every step")


def run(args: argparse.Namespace, console: Console) -> int:
    """Run the benchmark and print its table (or JSON) on stdout."""
    settings = BenchSettings(
        instances=parse_list(args.instances, int, "--instances"),
        frames=args.frames,
        warmup=args.warmup,
        budget_s=args.budget,
        spacing=args.spacing,
        frustum_culling=not args.no_frustum_culling,
        up=args.up,
    )
    settings.check()
    console.progress(f"reading {args.input}")
    target = read_object(args.input, args.object, args.reference)
    with GridRenderer() as renderer:
        rows = run_bench(target, settings, renderer, console.progress)
        record = bench_record(args.input, target, settings, rows, renderer.renderer_name)
    console.clear()
    print(json.dumps(record, indent=2) if args.json else bench_text(record))
    return EXIT_OK


def bench_record(
    path: str, target: BenchObject, settings: BenchSettings, rows: list[BenchRow], renderer: str
) -> dict[str, Any]:
    """What a run measured, as the JSON that ``--json`` prints."""
    chain, reference = target.chain, target.reference
    return {
        "file": str(path),
        "object": chain.object_id,
        "objects_in_file": target.objects,
        "alpha": chain.alpha,
        "cutoffs": list(chain.cutoffs),
        "levels": [
            {"name": lv.name, "kind": level_kind(lv), "count": lv.count} for lv in chain.levels
        ],
        "reference": {"count": reference.count, "triangles": level_triangles(reference)},
        "renderer": renderer,
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
        "settings": settings.record(),
        "rows": [row.record() for row in rows],
    }


def _ms(grid: dict[str, Any]) -> str:
    if grid["status"] == "over budget":
        return f"> {grid['stopped_after_s'] * 1000:,.0f} (over budget)"
    if grid["median_s"] is None:
        return grid["status"]
    return f"{grid['median_s'] * 1000:,.1f}"


def speedup_of(row: dict[str, Any]) -> tuple[float | None, bool]:
    """(speed-up, whether it is a lower bound) of a row of :func:`bench_record`: the measured
    ratio, or when the original frame was stopped over budget, the bound its partial time gives
    (None when neither exists)."""
    if row["speedup"] is not None:
        return row["speedup"], False
    lod, original = row["lod"], row["original"]
    if lod["median_s"] and original["status"] == "over budget":
        return original["stopped_after_s"] / lod["median_s"], True
    return None, False


def _speedup(row: dict[str, Any]) -> str:
    value, bound = speedup_of(row)
    if value is None:
        return "–"
    return f"> {value:.1f}× (original over budget)" if bound else f"{value:.2f}×"


def _fps(grid: dict[str, Any]) -> str:
    return f"{grid['fps']:.3g}" if grid["fps"] else "–"


def bench_table(record: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the results table of a :func:`bench_record`: per N, instances drawn,
    the level mix, and per grid vertices + points submitted, median ms and FPS; the speed-up."""
    mix = "/".join(lv["name"] for lv in record["levels"])
    header = [
        "N",
        "drawn",
        f"{mix} instances",
        "LOD submitted",
        "LOD ms",
        "LOD FPS",
        "original submitted",
        "original ms",
        "original FPS",
        "speed-up",
    ]
    rows = []
    for row in record["rows"]:
        lod, original = row["lod"], row["original"]
        rows.append(
            [
                f"{row['instances']:,}",
                f"{lod['drawn']:,}",
                "/".join(f"{n:,}" for n in lod["level_instances"].values()),
                f"{lod['submitted']:,}",
                _ms(lod),
                _fps(lod),
                f"{original['submitted']:,}",
                _ms(original),
                _fps(original),
                _speedup(row),
            ]
        )
    return header, rows


def bench_view_text(record: dict[str, Any]) -> str:
    """What a run drew: renderer, framebuffer, grid spacing, camera and culling."""
    settings = record["settings"]
    width, height = settings["size"]
    culling = "per-instance frustum culling" if settings["frustum_culling"] else "no culling"
    return (
        f"renderer {record['renderer']}; {width}×{height}, {settings['fov_y_deg']:g}° vertical "
        f"FOV; grid spacing {settings['spacing_alpha']:g} α; eye {tuple(settings['eye_alpha'])} α "
        f"looking at {tuple(settings['target_alpha'])} α; {culling}"
    )


def bench_timing_text(record: dict[str, Any]) -> str:
    """How a run timed its frames."""
    settings = record["settings"]
    return (
        f"{settings['warmup']} warm-up + {settings['frames']} timed frame(s), median; budget "
        f"{settings['budget_s']:g} s a frame"
    )


def bench_object_text(record: dict[str, Any]) -> str:
    """One line: the object, its levels, the original mesh, α and the cutoffs."""
    levels = " → ".join(f"{lv['name']} {lv['count']:,}" for lv in record["levels"])
    cutoffs = ", ".join(f"{c / record['alpha']:.1f} α" for c in record["cutoffs"])
    return (
        f"object {record['object']!r} ({record['objects_in_file']} in file): {levels}; original "
        f"{record['reference']['count']:,} vertices; α = {record['alpha']:.6g}, cutoffs {cutoffs}"
    )


def bench_text(record: dict[str, Any]) -> str:
    """The plain-text report: what was drawn and how, then the table."""
    header, rows = bench_table(record)
    table = [header, *rows]
    widths = [max(len(line[i]) for line in table) for i in range(len(header))]
    lines = [
        f"{record['file']}: {bench_object_text(record)}",
        f"{bench_view_text(record)}; {bench_timing_text(record)}",
    ]
    lines += ["  ".join(c.rjust(w) for c, w in zip(line, widths, strict=True)) for line in table]
    return "\n".join(lines)
