"""``lodconvert evaluate REF OUT``: how faithful each level of OUT is to the source mesh REF.

OUT is read back as written (levels, point sizes and switching data from the file), paired with
REF's objects (bounds must agree) and scored with :mod:`lodconvert.analysis.evaluate`:
silhouette precision, recall and F on a fixed protocol and within each level's range, Chamfer
and Hausdorff distance, and counts. Prints a table; ``--json`` and ``--contact-sheet``
(:mod:`lodconvert.analysis.contact_sheet`) write files.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

from ...analysis.contact_sheet import contact_sheet, legend, stack_images
from ...analysis.evaluate import (
    DEFAULT_DISTANCES,
    DEFAULT_SAMPLES,
    DEFAULT_SIZE,
    DEFAULT_VIEWS,
    DistanceScore,
    LevelReport,
    ObjectReport,
    Protocol,
    ReferenceRenders,
    evaluate_object,
    match_references,
)
from ...analysis.silhouette import SilhouetteRenderer
from ...io import read_chains, read_scene
from ...model import LodChain, Surface
from ...ranges import REFERENCE_VIEW
from ...sinks import Outputs
from ..console import Console
from ..options import EXIT_OK, parse_list

DESCRIPTION = (
    "Score every level of a file lodconvert wrote against the source mesh it was converted "
    "from: silhouette precision/recall/F over views on a sphere (the PCD paper's measure), "
    "Chamfer and Hausdorff distance, and counts."
)
POINT_SIZES = (
    "declared sizes: point_size_px at design_distance in the 1080-px reference view, scaled "
    "by 1/distance and by the render's focal length over the reference view's, at least 1 px; "
    "the X3D pointSizeMaxValue is not applied (it never binds within a level's range)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``lodconvert evaluate``."""
    parser.add_argument("reference", metavar="REF", help="the source mesh OUT was converted from")
    parser.add_argument("output", metavar="OUT", help="a .glb, .gltf or .x3d lodconvert wrote")
    protocol = parser.add_argument_group("protocol")
    protocol.add_argument(
        "--views",
        type=int,
        default=DEFAULT_VIEWS,
        help=f"Fibonacci views (default {DEFAULT_VIEWS})",
    )
    protocol.add_argument(
        "--size",
        type=int,
        default=DEFAULT_SIZE,
        help=f"render width and height in pixels, 45° vertical FOV (default {DEFAULT_SIZE})",
    )
    protocol.add_argument(
        "--distances",
        default=",".join(f"{d:g}" for d in DEFAULT_DISTANCES),
        metavar="K1,K2,..",
        help="camera distances in bounding-box diagonals (default 4,8,16)",
    )
    protocol.add_argument(
        "--range-size",
        type=int,
        default=REFERENCE_VIEW.height_px,
        metavar="PX",
        help="render size within each level's range (default "
        f"{REFERENCE_VIEW.height_px}, the reference view's height)",
    )
    protocol.add_argument(
        "--samples",
        type=int,
        default=DEFAULT_SAMPLES,
        help=f"surface samples for Chamfer/Hausdorff (default {DEFAULT_SAMPLES:,})",
    )
    out = parser.add_argument_group("output")
    out.add_argument("--json", metavar="FILE", help="write every number as JSON")
    out.add_argument(
        "--contact-sheet",
        metavar="FILE.png",
        help="write the source and each level side by side, silhouette differences coloured",
    )
    out.add_argument("-q", "--quiet", action="store_true", help="print errors only")
    out.add_argument("-v", "--verbose", action="store_true", help="print every step")


def protocol_of(args: argparse.Namespace) -> Protocol:
    """The :class:`Protocol` asked for (raises :class:`UsageError` for impossible values)."""
    protocol = Protocol(
        views=args.views,
        size=args.size,
        distances=parse_list(args.distances, float, "--distances"),
        samples=args.samples,
        range_size=args.range_size,
    )
    protocol.check()
    return protocol


def run(args: argparse.Namespace, console: Console) -> int:
    """Evaluate, print the table and write the files asked for (paths checked first)."""
    protocol = protocol_of(args)
    with Outputs(inputs=[args.reference, args.output]) as outputs:
        json_sink = outputs.file(args.json) if args.json else None
        sheet_sink = outputs.file(args.contact_sheet) if args.contact_sheet else None
        chains = read_chains(args.output)
        console.progress(f"reading {args.reference}")
        objects = list(read_scene(args.reference).with_geometry())
        sources = match_references(objects, chains, args.reference, args.output)
        renderer = SilhouetteRenderer(protocol.size, protocol.fov_y_deg)
        reports: list[ObjectReport] = []
        sheets = []
        try:
            in_range = SilhouetteRenderer(protocol.range_size, protocol.fov_y_deg)
            try:
                for source, chain in zip(sources, chains, strict=True):
                    console.progress(f"{chain.object_id}: rendering {protocol.views} views")
                    reports.append(_evaluate(renderer, in_range, source, chain, protocol))
                    if sheet_sink is not None:
                        distance = protocol.distances[0]
                        sheets.append(contact_sheet(renderer, source, chain, distance))
            finally:
                in_range.release()
            if sheets:
                sheets.append(legend(sheets[0].width, renderer, protocol.distances[0]))
        finally:
            renderer_name = renderer.renderer_name
            renderer.release()
        console.clear()
        if not args.quiet:
            print(format_report(reports, protocol, renderer_name))
        if json_sink is not None:
            record = report_record(args.reference, args.output, protocol, renderer_name, reports)
            json_sink.write_bytes((json.dumps(record, indent=2) + "\n").encode())
        if sheet_sink is not None:
            with sheet_sink.open() as handle:
                stack_images(sheets).save(handle, format="PNG")
    return EXIT_OK


def _evaluate(
    renderer: SilhouetteRenderer,
    in_range: SilhouetteRenderer,
    source: Surface,
    chain: LodChain,
    protocol: Protocol,
) -> ObjectReport:
    """:func:`evaluate_object` with the source uploaded to both renderers, then freed."""
    references = ReferenceRenders(renderer, source, chain.center, protocol.views)
    range_references = ReferenceRenders(in_range, source, chain.center, protocol.views)
    try:
        return evaluate_object(references, chain, protocol, range_references=range_references)
    finally:
        references.release()
        range_references.release()


def report_record(
    reference: str,
    output: str,
    protocol: Protocol,
    renderer_name: str,
    reports: list[ObjectReport],
) -> dict[str, Any]:
    """What ``--json`` writes: inputs, protocol, GL renderer and every object's report."""
    return {
        "reference": str(Path(reference)),
        "output": str(Path(output)),
        "protocol": asdict(protocol),
        "point_sizes": POINT_SIZES,
        "gl_renderer": renderer_name,
        "objects": [report.to_json() for report in reports],
    }


def _f(score: DistanceScore | None) -> str:
    return f"{score.f:.4f}" if score is not None else "–"


def _percent(value: float | None) -> str:
    return f"{100 * value:.3f}" if value is not None else "–"


def _level_row(level: LevelReport) -> list[str]:
    scores, window = level.scores, level.scores.in_range
    assert window is not None
    return [
        scores.name,
        scores.kind,
        f"{scores.count:,}",
        f"{100 * level.fraction:.1f}",
        *(_f(s) for s in scores.scores),
        f"{_f(window.near)} @{window.near.diagonals:.1f}",
        _f(window.near_1px),
        f"{_f(window.middle)} @{window.middle.diagonals:.1f}",
        _f(window.middle_1px),
        _percent(level.error.chamfer),
        _percent(level.error.hausdorff),
    ]


def format_report(reports: list[ObjectReport], protocol: Protocol, renderer_name: str) -> str:
    """The table printed on stdout: one block per object, one row per level."""
    header = [
        "level",
        "kind",
        "count",
        "% src",
        *(f"F {d:g}α" for d in protocol.distances),
        "F near (@d/α)",
        "1 px",
        "F middle (@d/α)",
        "1 px",
        "chamfer %α",
        "hausdorff %α",
    ]
    lines = [
        f"{protocol.views} Fibonacci views, {protocol.size} x {protocol.size} px "
        f"({protocol.range_size} x {protocol.range_size} within each level's range: near = "
        f"where it first shows, middle = the middle of its range), {protocol.fov_y_deg:g}° "
        f"vertical FOV, GL renderer {renderer_name}; points at their declared size, and "
        f"1 px wide in the 1 px columns; errors from {protocol.samples:,} surface samples"
    ]
    for report in reports:
        rows = [header, *(_level_row(level) for level in report.levels)]
        widths = [max(len(row[i]) for row in rows) for i in range(len(header))]
        lines += [
            "",
            f"{report.object_id}: {report.source_vertices:,} source vertices, "
            f"diagonal α = {report.alpha:.6g}",
        ]
        for row in rows:
            cells = [
                cell.ljust(width) if i < 2 else cell.rjust(width)
                for i, (cell, width) in enumerate(zip(row, widths, strict=True))
            ]
            lines.append("  ".join(cells).rstrip())
        mean = report.mean_point_f
        if mean is not None:
            at = ", ".join(f"{d:g}" for d in protocol.distances)
            lines.append(f"mean F of the point levels at {at} α: {mean:.4f}")
    return "\n".join(lines)
