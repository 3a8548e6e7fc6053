"""``lodconvert ranges FILE``: α, γ and the cutoffs of every object, without baking."""

from __future__ import annotations

import argparse
import json

from ..cli import EXIT_OK, Console, add_range_options, chain_options
from ..io import read_scene
from ..pipeline import object_ranges

DESCRIPTION = "Print α (bounding-box diagonal), γ and the cutoffs Y = α·β·γˣ per object."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``lodconvert ranges``."""
    parser.add_argument("input", help="any input lodconvert reads")
    add_range_options(parser)
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")


def run(args: argparse.Namespace, console: Console) -> int:
    """Print the table (or JSON) of ranges."""
    rows = object_ranges(read_scene(args.input), chain_options(args))
    if args.json:
        print(json.dumps(rows, indent=2))
        return EXIT_OK
    print(f"{'object':24} {'alpha':>12} {'gamma':>8}  cutoffs (x: Y)")
    for row in rows:
        cuts = "  ".join(f"{x:g}: {y:.6g}" for x, y in zip(row["xs"], row["cutoffs"], strict=True))
        print(f"{row['id']:24} {row['alpha']:12.6g} {row['gamma']:8g}  {cuts}")
    return EXIT_OK
