"""Argument parsing shared by the commands: the parser class, list values, the reading, baking
and range options, and the mapping from the library's option fields to the flags that set them."""

from __future__ import annotations

import argparse
import math
from typing import Any, NoReturn

from ..bake.filters import FILTERS
from ..chain import MAX_LEVELS, ChainOptions
from ..errors import UsageError
from ..ranges import DEFAULT_BETA, DEFAULT_GAMMA
from ..semantics import DEFAULT_PALETTE

EXIT_OK, EXIT_ERROR, EXIT_USAGE = 0, 1, 2

FLAGS = {
    "resolutions": "--resolution",
    "point_sizes": "--point-size",
    "gamma": "--plot-radius",
    "xs": "--x",
    "level_kinds": "--level-kind",
    "keep_mesh": "--no-mesh",
}
"""Library option field → command-line flag, where the flag is not ``--`` + the field."""


def flag_of(field: str) -> str:
    """The flag that sets the library option ``field`` (``gamma`` → ``--plot-radius``)."""
    return FLAGS.get(field, "--" + field.replace("_", "-"))


class Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors and exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: usage error: {message} (see --help)\n")


def parse_list(text: str, kind: type, flag: str) -> tuple:
    """Parse a comma-separated option value (``"128,64,32"``) or raise :class:`UsageError`."""
    try:
        values = tuple(kind(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise UsageError(f"{flag} expects comma-separated numbers, got {text!r}") from None
    if not values:
        raise UsageError(f"{flag} expects at least one value")
    return values


def add_limit_option(
    parser: argparse.ArgumentParser, example: str = "decompressed_bytes=8G"
) -> None:
    """``--limit NAME=VALUE`` (repeatable): the run's :class:`~lodconvert.limits.Limits` are
    ``DEFAULT_LIMITS.with_text(args.limit)``."""
    parser.add_argument(
        "--limit",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help=f"raise (or lower) a limit, e.g. {example} (see docs/bad-input.md)",
    )


def add_read_options(parser: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """``--limit`` and the reading options ``--merge-groups``, ``--types``, ``--colors``,
    ``--crs`` and ``--appearance-theme``; returns their group."""
    add_limit_option(parser)
    read = parser.add_argument_group("reading")
    read.add_argument(
        "--merge-groups",
        action="store_true",
        help="read an OBJ file's objects and groups as one object",
    )
    read.add_argument(
        "--types",
        metavar="TYPE,..",
        help="city models: only these object types (e.g. Building,Bridge)",
    )
    read.add_argument(
        "--colors",
        metavar="CLASS=#RRGGBB,..",
        help="city models: colours of the surface classes roof, wall, ground, other "
        "(source materials win; defaults in docs/cities.md)",
    )
    read.add_argument(
        "--crs",
        metavar="EPSG:CODE",
        help="city models: the CRS of every input's coordinates, replacing what the files "
        "declare (an EPSG code pyproj knows; default: each file's own, the first one's for the "
        "output, into which the others are reprojected)",
    )
    read.add_argument(
        "--appearance-theme",
        metavar="NAME",
        help="city models: the appearance theme whose textures and materials are read "
        "(default: the file's only or first; docs/textures.md)",
    )
    return read


def read_options(args: argparse.Namespace) -> dict[str, Any]:
    """The readers' options of :func:`add_read_options`' arguments (raises UsageError)."""
    return {
        "merge_groups": args.merge_groups or None,
        "types": frozenset(parse_list(args.types, str, "--types")) if args.types else None,
        "colors": DEFAULT_PALETTE.with_text(args.colors) if args.colors else None,
        "crs": args.crs,
        "appearance_theme": args.appearance_theme,
    }


def add_bake_options(parser: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """The per-level baking options and ``--no-mesh``; returns their group."""
    bake = parser.add_argument_group("baking (one value per point level, finest first)")
    bake.add_argument("--resolution", metavar="T3,..", help="grid cells along the longest side")
    bake.add_argument(
        "--slices", metavar="T1,..", help="slabs along the longest side (default = T3)"
    )
    bake.add_argument("--point-size", metavar="T2,..", help="point size in pixels at switch-in")
    bake.add_argument(
        "--filter", choices=FILTERS, default="median", help="hole filter (default median)"
    )
    bake.add_argument(
        "--level-kind",
        metavar="KIND,..",
        help="pcd (points, default) or qem (source decimated to the same count), per level or all",
    )
    bake.add_argument("--no-mesh", action="store_true", help="bake the finest level too")
    return bake


def add_range_options(parser: argparse.ArgumentParser) -> None:
    """``--levels``, ``--beta``, ``--plot-radius``, ``--x`` and ``--cull``."""
    group = parser.add_argument_group("switching ranges (Y = α·β·γˣ)")
    group.add_argument(
        "--levels", type=int, default=4, help=f"levels in the chain, 2..{MAX_LEVELS} (default 4)"
    )
    group.add_argument(
        "--beta", type=float, default=DEFAULT_BETA, help="β (default 3, the user-study optimum)"
    )
    group.add_argument(
        "--plot-radius",
        type=float,
        metavar="GAMMA",
        help=f"γ, must be > 1 (default: {DEFAULT_GAMMA:g} for a mesh's objects; for city objects "
        "half the distance to the nearest neighbour, 2–100 m; see docs/cities.md)",
    )
    group.add_argument(
        "--x", metavar="X1,X2,..", help="exponents, one per switch (default 0.33,0.66,1.0)"
    )
    group.add_argument(
        "--cull", type=float, metavar="X", help="add a cutoff Y(X) beyond which the object vanishes"
    )


def _ints(text: str | None, flag: str) -> tuple[int, ...] | None:
    if not text:
        return None
    values = parse_list(text, float, flag)
    if any(not math.isfinite(v) or v != int(v) for v in values):
        raise UsageError(f"{flag} expects whole numbers, got {text!r}")
    return tuple(int(v) for v in values)


def chain_options(args: argparse.Namespace) -> ChainOptions:
    """Build :class:`ChainOptions` from parsed arguments (raises UsageError)."""
    return ChainOptions(
        levels=args.levels,
        keep_mesh=not getattr(args, "no_mesh", False),
        resolutions=_ints(getattr(args, "resolution", None), "--resolution"),
        slices=_ints(getattr(args, "slices", None), "--slices"),
        point_sizes=parse_list(args.point_size, float, "--point-size")
        if getattr(args, "point_size", None)
        else None,
        filter=getattr(args, "filter", "median"),
        beta=args.beta,
        gamma=args.plot_radius,
        xs=parse_list(args.x, float, "--x") if args.x else None,
        cull=args.cull,
        level_kinds=parse_list(args.level_kind, str, "--level-kind")
        if getattr(args, "level_kind", None)
        else None,
    )


def add_viewer_lib_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--viewer-lib``, for the page of ``--html`` and of ``lodconvert view``."""
    parser.add_argument(
        "--viewer-lib",
        metavar="URL|DIR",
        help="base URL or local folder of the viewer library's npm package "
        "(x_ite for X3D, three for glTF; default: jsDelivr CDN); a folder must lie inside the "
        "page's folder, unless 'lodconvert view --serve' serves it",
    )
