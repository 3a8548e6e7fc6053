"""Command line: argument parsing, progress, exit codes. No geometry here.

Exit codes: 0 success, 1 input or processing error, 2 usage error. Errors are one line on
stderr (``lodconvert: error: FILE: what is wrong``); ``--debug`` adds the traceback.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from . import __version__
from .bake import BACKENDS
from .bake.filters import FILTERS
from .chain import MAX_LEVELS, ChainOptions
from .commands import COMMANDS
from .errors import LodConvertError, UsageError
from .ranges import DEFAULT_BETA, DEFAULT_GAMMA

EXIT_OK, EXIT_ERROR, EXIT_USAGE = 0, 1, 2


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


def add_range_options(parser: argparse.ArgumentParser) -> None:
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
        default=DEFAULT_GAMMA,
        metavar="GAMMA",
        help=f"γ, must be > 1 (default {DEFAULT_GAMMA:g}; see README)",
    )
    group.add_argument(
        "--x", metavar="X1,X2,..", help="exponents, one per switch (default 0.33,0.66,1.0)"
    )
    group.add_argument(
        "--cull", type=float, metavar="X", help="add a cutoff Y(X) beyond which the object vanishes"
    )


def build_convert_parser() -> Parser:
    """The parser of the main command: ``lodconvert INPUT -o OUTPUT [options]``."""
    from .commands.view import add_viewer_lib_option

    parser = Parser(
        prog="lodconvert",
        description="Bake a CityGML-style LOD chain (LOD4 mesh, coarser point-cloud levels) "
        "for every object of a mesh and write it as X3D LOD or glTF MSFT_lod.",
        epilog="Other commands: "
        + "; ".join(f"'lodconvert {name} --help'" for name in COMMANDS)
        + ".",
    )
    parser.add_argument("input", help="OBJ, PLY, STL, OFF, GLB or glTF file (optionally .gz)")
    parser.add_argument("-o", "--output", required=True, help="output .x3d, .glb or .gltf")
    parser.add_argument("--version", action="version", version=f"lodconvert {__version__}")
    bake = parser.add_argument_group("baking (one value per point level, finest first)")
    bake.add_argument("--resolution", metavar="T3,..", help="grid cells along the longest side")
    bake.add_argument(
        "--slices", metavar="T1,..", help="slabs along the longest side (default = T3)"
    )
    bake.add_argument("--point-size", metavar="T2,..", help="point size in pixels at switch-in")
    bake.add_argument(
        "--filter", choices=FILTERS, default="median", help="hole filter (default median)"
    )
    bake.add_argument("--backend", choices=BACKENDS, default="auto", help="baker (default auto)")
    bake.add_argument(
        "--level-kind",
        metavar="KIND,..",
        help="pcd (points, default) or qem (source decimated to the same count), per level or all",
    )
    bake.add_argument("--no-mesh", action="store_true", help="bake the finest level too")
    add_range_options(parser)
    out = parser.add_argument_group("output and messages")
    out.add_argument(
        "--report", metavar="FILE", help="write a JSON report (schemas/report.schema.json)"
    )
    out.add_argument(
        "--html",
        action="store_true",
        help="also write a viewer page beside the output (OUTPUT with suffix .html)",
    )
    add_viewer_lib_option(out)
    out.add_argument("-q", "--quiet", action="store_true", help="print errors only")
    out.add_argument("-v", "--verbose", action="store_true", help="print every step")
    out.add_argument("--debug", action="store_true", help="show tracebacks")
    return parser


def chain_options(args: argparse.Namespace) -> ChainOptions:
    """Build :class:`ChainOptions` from parsed arguments (raises UsageError)."""
    keep_mesh = not getattr(args, "no_mesh", False)
    return ChainOptions(
        levels=args.levels,
        keep_mesh=keep_mesh,
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


def _ints(text: str | None, flag: str) -> tuple[int, ...] | None:
    if not text:
        return None
    values = parse_list(text, float, flag)
    if any(v != int(v) for v in values):
        raise UsageError(f"{flag} expects whole numbers, got {text!r}")
    return tuple(int(v) for v in values)


class Console:
    """Progress and messages on stderr; a live single line on a terminal."""

    def __init__(self, quiet: bool, verbose: bool) -> None:
        self.quiet, self.verbose = quiet, verbose
        self.live = sys.stderr.isatty() and not quiet and not verbose
        self.start = time.perf_counter()

    def progress(self, message: str) -> None:
        """Show what is being done now."""
        if self.quiet:
            return
        stamp = f"{time.perf_counter() - self.start:6.1f}s"
        if self.live:
            sys.stderr.write(f"\r\033[K{stamp} {message}")
            sys.stderr.flush()
        elif self.verbose:
            print(f"{stamp} {message}", file=sys.stderr)

    def warn(self, message: str) -> None:
        """A problem that did not stop the run."""
        self.clear()
        print(f"lodconvert: warning: {message}", file=sys.stderr)

    def info(self, message: str) -> None:
        """A result line (suppressed by --quiet)."""
        self.clear()
        if not self.quiet:
            print(message, file=sys.stderr)

    def clear(self) -> None:
        """Remove the live progress line."""
        if self.live:
            sys.stderr.write("\r\033[K")


def run_convert(argv: Sequence[str]) -> int:
    """The main command."""
    args = build_convert_parser().parse_args(argv)
    console = Console(args.quiet, args.verbose)
    return _guarded(args, console, lambda: _convert(args, console))


def _convert(args: argparse.Namespace, console: Console) -> int:
    from .io.atomic import atomic_output
    from .pipeline import convert
    from .viewer import check_library, write_page

    options = chain_options(args)
    if args.viewer_lib and not args.html:
        raise UsageError("--viewer-lib is for the page that --html writes")
    if args.html:
        check_library(args.output, args.viewer_lib)  # before baking, not after
    report = convert(
        args.input,
        args.output,
        options,
        backend=args.backend,
        progress=console.progress,
        warn=console.warn,
    )
    if args.report:
        with atomic_output(args.report) as handle:
            handle.write((json.dumps(report, indent=2) + "\n").encode())
    for obj in report["objects"]:
        counts = " → ".join(f"{lv['name']} {lv['count']:,}" for lv in obj["levels"])
        cuts = ", ".join(f"{c:.4g}" for c in obj["cutoffs"])
        console.info(f"{obj['id']}: {counts}; cutoffs {cuts}")
    console.info(
        f"wrote {args.output} ({report['totals']['objects']} object(s), "
        f"{report['backend']} backend, {sum(report['timings'].values()):.2f} s)"
    )
    if args.html:
        console.info(f"wrote {write_page(args.output, library=args.viewer_lib)}")
    return EXIT_OK


def _guarded(args: argparse.Namespace, console: Console, body: Any) -> int:
    try:
        return body()
    except UsageError as exc:
        console.clear()
        _report_traceback(args)
        print(f"lodconvert: usage error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except LodConvertError as exc:
        console.clear()
        _report_traceback(args)
        print(f"lodconvert: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        console.clear()
        print("lodconvert: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        console.clear()
        print(f"lodconvert: error: {getattr(args, 'input', '')}: out of memory", file=sys.stderr)
        return EXIT_ERROR
    except Exception as exc:  # an unexpected failure still gets one line
        console.clear()
        _report_traceback(args)
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        hint = "" if args.debug else " (run with --debug for the traceback)"
        where = getattr(args, "input", None) or "lodconvert"
        print(f"lodconvert: error: {where}: {type(exc).__name__}: {first}{hint}", file=sys.stderr)
        return EXIT_ERROR


def _report_traceback(args: argparse.Namespace) -> None:
    if getattr(args, "debug", False):
        traceback.print_exc()


def run_command(name: str, argv: Sequence[str]) -> int:
    """Run the subcommand ``name`` (a module of :mod:`lodconvert.commands`)."""
    module = importlib.import_module(COMMANDS[name])
    parser = Parser(prog=f"lodconvert {name}", description=module.DESCRIPTION)
    module.add_arguments(parser)
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    args = parser.parse_args(argv)
    console = Console(quiet=getattr(args, "quiet", False), verbose=getattr(args, "verbose", False))
    return _guarded(args, console, lambda: module.run(args, console))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lodconvert`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in COMMANDS and not Path(argv[0]).exists():
        return run_command(argv[0], argv[1:])
    return run_convert(argv)
