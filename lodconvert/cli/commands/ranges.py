"""``lodconvert ranges FILE...``: the levels, α, γ and cutoffs of every object as ``convert``
plans them, without baking."""

from __future__ import annotations

import argparse
import json

from ...bakery import object_ranges
from ...inputs import read_inputs
from ...limits import DEFAULT_LIMITS
from ..console import Console
from ..options import (
    EXIT_OK,
    add_bake_options,
    add_range_options,
    add_read_options,
    chain_options,
    read_options,
)

DESCRIPTION = (
    "Print the levels, α (bounding-box diagonal), γ and the cutoffs Y = α·β·γˣ of every object "
    "as convert plans them, without baking."
)
TO_BAKE = "*"
"""Marks a level of points still to bake in the table."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``lodconvert ranges``: convert's reading, baking and range options."""
    parser.add_argument(
        "input", nargs="+", help="any input lodconvert reads; several are one scene, as in convert"
    )
    add_read_options(parser)
    add_bake_options(parser)
    add_range_options(parser)
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")


def run(args: argparse.Namespace, console: Console) -> int:
    """Print the table (or JSON) of ranges."""
    limits = DEFAULT_LIMITS.with_text(args.limit)
    scene, _ = read_inputs(args.input, read_options(args), limits, warn=console.warn)
    rows = object_ranges(scene, chain_options(args), console.warn)
    if args.json:
        print(json.dumps(rows, indent=2))
        return EXIT_OK
    width = max([24, *(len(row["id"]) for row in rows)])
    print(f"{'object':{width}} {'alpha':>12} {'gamma':>8}  {'levels':24} cutoffs (x: Y)")
    for row in rows:
        cuts = "  ".join(f"{x:g}: {y:.6g}" for x, y in zip(row["xs"], row["cutoffs"], strict=True))
        levels = " ".join(
            lv["name"] + (TO_BAKE if lv.get("to_bake") else "") for lv in row["levels"]
        )
        print(f"{row['id']:{width}} {row['alpha']:12.6g} {row['gamma']:8g}  {levels:24} {cuts}")
    if any(lv.get("to_bake") for row in rows for lv in row["levels"]):
        print(
            f"{TO_BAKE} points convert bakes: kept, with the cutoff where they switch in, where "
            "they are cheaper than the level before and look like the object"
        )
    return EXIT_OK
