"""``lodconvert validate FILE...``: the structural checks the converter runs, as a command."""

from __future__ import annotations

import argparse

from ...limits import DEFAULT_LIMITS
from ...validate import errors_of, validate_file
from ..console import Console
from ..options import EXIT_ERROR, EXIT_OK, add_limit_option

DESCRIPTION = (
    "Check .x3d, .glb and .gltf files and tileset.json: X3D structure (LOD ranges and children, "
    "PointSet counts; the official XSD with --x3d-schema), glTF MSFT_lod rules, accessor bounds "
    "and counts, 3D Tiles geometricError, bounding volumes, feature ids and property tables. "
    "Prints one line per finding; exit status 1 when any file has an error."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``lodconvert validate``."""
    parser.add_argument(
        "files", nargs="+", metavar="FILE", help=".x3d, .glb, .gltf or tileset.json"
    )
    parser.add_argument(
        "--x3d-schema",
        metavar="PATH",
        help="also validate X3D against this XSD (or folder holding x3d-4.0.xsd and catalog.xml)",
    )
    add_limit_option(parser, "tileset_json_bytes=64M")
    parser.add_argument("-q", "--quiet", action="store_true", help="print errors only")


def run(args: argparse.Namespace, console: Console) -> int:
    """Print the findings of every file and a summary line per file (errors only with
    --quiet) on stdout."""
    failed = False
    limits = DEFAULT_LIMITS.with_text(args.limit)
    for path in args.files:
        findings = validate_file(path, x3d_schema=args.x3d_schema, limits=limits)
        errors = errors_of(findings)
        failed = failed or bool(errors)
        for finding in errors if args.quiet else findings:
            print(finding)
        if not args.quiet:
            warnings = len(findings) - len(errors)
            verdict = f"{len(errors)} error(s)" if errors else "valid"
            print(f"{path}: {verdict}" + (f", {warnings} warning(s)" if warnings else ""))
    return EXIT_ERROR if failed else EXIT_OK
