"""``lodconvert FILE -o OUT``: bake every object's LOD chain and write it (the main command)."""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ...bake import BACKENDS
from ...city.hlod import KINDS, HlodOptions, parse_sizes
from ...errors import UsageError
from ...io import output_format
from ...io.frame import UP_AXES
from ...io.gltf.compression import check_compression
from ...io.gltf.texture_copies import check_texture_format
from ...io.x3d import SWITCHING_MODES
from ...limits import DEFAULT_LIMITS
from ...model.lods import lod_name
from ...sinks import DirectorySink, FileSink, Outputs
from ...textures import check_atlas_size
from ..console import Console
from ..options import (
    EXIT_OK,
    add_bake_options,
    add_range_options,
    add_read_options,
    add_viewer_lib_option,
    chain_options,
    read_options,
)
from . import COMMANDS

DESCRIPTION = (
    "Bake a CityGML-style LOD chain (LOD4 mesh, coarser point-cloud levels where they pay) for "
    "every object of a mesh and write it as X3D LOD or glTF MSFT_lod."
)
EPILOG = (
    "Other commands: "
    + "; ".join(f"'lodconvert {name} --help'" for name in COMMANDS if name != "convert")
    + ". A file named like a command is converted as ./NAME."
)
OBJECT_LINES = 20
"""Up to this many objects, a line each; beyond, the summary only (``-v`` prints them all)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the main command."""
    from ...version import __version__

    parser.add_argument(
        "input",
        nargs="+",
        help="OBJ, PLY, STL, OFF, GLB or glTF file (optionally .gz), or city models; several "
        "inputs are one scene, objects of the same id one object with all their LoDs",
    )
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        help="output .x3d, .glb or .gltf, or DIR/tileset.json (a 3D Tiles 1.1 tileset in DIR)",
    )
    parser.add_argument("--version", action="version", version=f"lodconvert {__version__}")
    read = add_read_options(parser)
    read.add_argument(
        "--up",
        choices=UP_AXES,
        help="mesh files: the model's up axis, turned to +Y (glTF's and X3D's up) as it is "
        "read; a negative one as --up=-z (default y; a usage error for city models, which are "
        "z-up and turned already)",
    )
    read.add_argument(
        "--strict",
        action="store_true",
        help="fail (exit 1, nothing written) when any object is skipped as broken",
    )
    bake = add_bake_options(parser)
    bake.add_argument("--backend", choices=BACKENDS, default="auto", help="baker (default auto)")
    bake.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="processes reading a city and baking objects (default: one for each 6 MiB of "
        "input, up to the cores this process may use; 1 reads and bakes in the main process)",
    )
    bake.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="bake on the workers of a dask.distributed cluster: its scheduler's address "
        "(tcp://host:port) or scheduler file; instead of --workers (see docs/cluster.md)",
    )
    add_range_options(parser)
    group = parser.add_argument_group("LOD parents (cities)")
    group.add_argument(
        "--hlod",
        metavar="SIZES",
        help="group objects into grid cells of SIZES metres (one tier, or coarser tiers after "
        "commas: 250,1000; 'auto' picks one from building density); each cell shows one far "
        "level beyond where all its objects are at their coarsest",
    )
    group.add_argument(
        "--hlod-kind",
        choices=KINDS,
        default="auto",
        help="far level of a cell: points baked from all its objects, their coarsest levels "
        "merged into one mesh, their footprints as block prisms, or auto: the cheapest that "
        "keeps silhouette F ≥ 0.95 (default)",
    )
    out = parser.add_argument_group("output and messages")
    out.add_argument(
        "--switching",
        choices=SWITCHING_MODES,
        default="lod",
        help="X3D only: switch each object's levels by distance from its centre (lod, an X3D LOD "
        "node; default) or on boxes around it (prism: its bounding box grown by each cutoff on "
        "every side, ProximitySensors driving Switch nodes)",
    )
    out.add_argument(
        "--report", metavar="FILE", help="write a JSON report (schemas/report.schema.json)"
    )
    out.add_argument(
        "--html",
        action="store_true",
        help="also write a viewer page beside the output (OUTPUT.html)",
    )
    add_viewer_lib_option(out)
    out.add_argument(
        "--sse",
        type=float,
        metavar="PX",
        help="3D Tiles only: the maximumScreenSpaceError the tiles' geometricError is made for: "
        "a viewer with it refines each tile at our switch distance (default 16, CesiumJS's)",
    )
    out.add_argument(
        "--atlas-size",
        type=int,
        metavar="TEXELS",
        help="3D Tiles only: the largest side of a tile's texture atlas page, a power of two "
        "(default 4096; docs/textures.md)",
    )
    out.add_argument(
        "--compress",
        metavar="HOW",
        help="glTF geometry: none, meshopt (EXT_meshopt_compression, a tile's positions within "
        "0.05 to 1 mm; a tileset's default) or quantize (KHR_mesh_quantization, positions to "
        "1/65535 of a tile's extent); docs/compression.md",
    )
    out.add_argument(
        "--texture-format",
        metavar="FORMAT",
        help="glTF and 3D Tiles textures: default (PNG, or JPEG for photographs), webp "
        "(each also as WebP, EXT_texture_webp, which a viewer that reads it prefers) or ktx2 "
        "(also as KTX2, KHR_texture_basisu: Basis Universal's basisu encoder on PATH); "
        "docs/textures.md",
    )
    out.add_argument(
        "-q",
        "--quiet",
        action="count",
        default=0,
        help="-q: the summary line only; -qq: errors only",
    )
    out.add_argument("--silent", dest="quiet", action="store_const", const=2, help="= -qq")
    out.add_argument("-v", "--verbose", action="store_true", help="print every step")


def _check_switching(args: argparse.Namespace) -> None:
    """:class:`UsageError` when ``--switching`` names a mode other than ``lod`` for an output
    whose format takes no switching option (every format but X3D), before any work."""
    if args.switching != "lod" and "switching" not in output_format(args.output).write_options:
        raise UsageError(
            f"--switching {args.switching} is X3D-only; write an .x3d output, not {args.output}"
        )


def _check_tiles(args: argparse.Namespace) -> None:
    """:class:`UsageError` for ``--sse`` with an output other than a tileset, or an ``--sse``
    that is not a positive number, before any work."""
    if args.sse is not None and "sse" not in output_format(args.output).write_options:
        raise UsageError(f"--sse is for 3D Tiles; write DIR/tileset.json, not {args.output}")
    if args.sse is not None and not (math.isfinite(args.sse) and args.sse > 0):
        raise UsageError(f"--sse must be a positive number of pixels, got {args.sse:g}")
    if args.atlas_size is not None and "atlas_size" not in output_format(args.output).write_options:
        raise UsageError(f"--atlas-size is for 3D Tiles; write DIR/tileset.json, not {args.output}")
    if args.atlas_size is not None:
        check_atlas_size(args.atlas_size)
    if args.compress is not None and "compress" not in output_format(args.output).write_options:
        raise UsageError(f"--compress is for glTF and 3D Tiles, not {args.output}")
    if args.compress is not None:
        check_compression(args.compress)
    if args.texture_format is not None:
        if "texture_format" not in output_format(args.output).write_options:
            raise UsageError(f"--texture-format is for glTF and 3D Tiles, not {args.output}")
        check_texture_format(args.texture_format)


def _hlod_line(hlod: dict[str, Any]) -> str:
    """The summary of the LOD parents: cells by kind, far-view draw calls with and without."""
    kinds = Counter(cell["kind"] for cell in hlod["cells"])
    made = ", ".join(f"{n:,} {kind}" for kind, n in sorted(kinds.items()))
    lowest = min(min(cell["silhouette_f"].values()) for cell in hlod["cells"])
    chosen = min(cell["silhouette_f"][cell["kind"]] for cell in hlod["cells"])
    ours, alone = hlod["draw"]["with"], hlod["draw"]["without"]
    return (
        f"LOD parents: {len(hlod['cells']):,} cell(s) ({made}); {ours['nodes']:,} nodes and "
        f"{ours['shapes']:,} shapes (without: {alone['nodes']:,} and {alone['shapes']:,}); "
        f"seen from afar {ours['far_draw_calls']:,} draw call(s) instead of "
        f"{alone['far_draw_calls']:,}; far levels' silhouette F ≥ {chosen:.3f} (lowest "
        f"candidate {lowest:.3f})"
    )


@contextlib.contextmanager
def _logs_off(off: bool) -> Iterator[None]:
    """Log records (dask.distributed's, of what goes wrong: the error line says it) dropped
    meanwhile, when ``off``."""
    previous = logging.root.manager.disable
    if off:
        logging.disable()
    try:
        yield
    finally:
        logging.disable(previous)


def run(args: argparse.Namespace, console: Console) -> int:
    """Convert, print what was made, return the exit code."""
    from ...pipeline import RunOptions, convert

    _check_switching(args)
    _check_tiles(args)
    options = chain_options(args)
    hlod = HlodOptions(parse_sizes(args.hlod), args.hlod_kind) if args.hlod else None
    limits = DEFAULT_LIMITS.with_text(args.limit)
    if args.viewer_lib and not args.html:
        raise UsageError("--viewer-lib is for the page that --html writes")
    if args.html:
        from ...viewer import check_library

        check_library(args.output, args.viewer_lib)  # before baking, not after

    def stage_page(
        outputs: Outputs, sink: FileSink | DirectorySink, report: dict[str, Any]
    ) -> None:
        from ...viewer import page_path, render_page

        page = page_path(args.output)
        if isinstance(sink, DirectorySink):  # a tileset: the page goes inside its folder
            text = sink.with_staged(
                lambda source: render_page(
                    Path(args.output), page, args.viewer_lib, source=source, limits=limits
                ),
                page.with_suffix("").name,
            )
            with sink.file(page.name) as handle:
                handle.write(text.encode("utf-8"))
        else:
            text = sink.with_staged(
                lambda source: render_page(sink.path, page, args.viewer_lib, source=source)
            )
            outputs.file(page).write_bytes(text.encode("utf-8"))
        report["page"] = str(page)

    run = RunOptions(
        options,
        backend=args.backend,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=console.progress,
        step=console.step,
        warn=console.warn,
        report_path=args.report,
        read_options={**read_options(args), "up": args.up},
        strict=args.strict,
        hlod=hlod,
        hlod_kind=args.hlod_kind,
        write_options={
            "switching": args.switching,
            "sse": args.sse,
            "atlas_size": args.atlas_size,
            "compress": args.compress,
            "texture_format": args.texture_format,
        },
        also=stage_page if args.html else None,
        limits=limits,
    )
    with _logs_off(bool(args.scheduler) and not args.debug):
        report = convert(args.input, args.output, run)
    objects = report["objects"]
    if len(objects) <= OBJECT_LINES or args.verbose:
        for obj in objects:
            counts = " → ".join(f"{lv['name']} {lv['count']:,}" for lv in obj["levels"])
            cuts = ", ".join(f"{c:.4g}" for c in obj["cutoffs"])
            console.info(f"{obj['id']}: {counts}" + (f"; cutoffs {cuts}" if cuts else ""))
    totals = report["totals"]
    if totals["fewer_levels"]:
        kept = ", ".join(f"{n:,} with {k}" for k, n in totals["levels_kept"].items())
        console.info(
            f"{totals['fewer_levels']:,} object(s) keep fewer levels ({kept} level(s)): no coarser "
            "level was both cheaper and faithful there, so the finer one stays on "
            "(see docs/levels.md)"
        )
    if totals["unused_lods"]:
        unused = totals["unused_lods"].items()
        labels = ", ".join(f"{lod_name(label)} ({n:,})" for label, n in unused)
        console.info(
            f"{totals['with_unused_lods']:,} object(s) have source LoDs that no level is made "
            f"from: {labels}; --report says why for each"
        )
    if "hlod" in report:
        console.info(_hlod_line(report["hlod"]))
    moved = report["crs"]["reprojected"]
    plural = "s" if len(moved) > 1 else ""
    for each in moved:
        console.info(f"{each['input']}: reprojected from {each['from']} into {each['to']}")
    skipped = report["totals"]["skipped"]
    dropped = report["totals"]["dropped_faces"]
    console.summary(
        f"wrote {args.output} ({report['totals']['objects']:,} object(s)"
        + (f", {skipped:,} skipped" if skipped else "")
        + (f", {dropped:,} face(s) without area dropped" if dropped else "")
        + (f", {len(moved)} input{plural} reprojected into {moved[0]['to']}" if moved else "")
        + f", {report['backend']} backend, {sum(report['timings'].values()):.2f} s)"
        + (f" and {report['page']}" if "page" in report else "")
    )
    return EXIT_OK
