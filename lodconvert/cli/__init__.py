"""Command line: ``lodconvert FILE... -o OUT`` and ``lodconvert COMMAND ...``. No geometry here.

The first argument picks a command when it is a command name (see
:data:`~lodconvert.cli.commands.COMMANDS`), else the main command, ``convert``, converts it (a file
named like a command is converted as ``./NAME``). Every command is a module with ``DESCRIPTION``,
``add_arguments(parser)`` and ``run(args, console) -> int``.

Exit codes: 0 success, 1 input or processing error, 2 usage error, 130 interrupted, 143
terminated. Errors are one line on stderr (``lodconvert: error: FILE: what is wrong``);
``--debug`` adds the traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import multiprocessing
import signal
import sys
import traceback
import warnings
from collections.abc import Callable, Sequence
from multiprocessing import resource_tracker
from types import FrameType

from ..errors import LodConvertError, UsageError
from ..heap import tune_collector, tune_heap
from .commands import COMMANDS, MAIN_COMMAND
from .console import Console
from .options import (
    EXIT_ERROR,
    EXIT_OK,
    EXIT_USAGE,
    Parser,
    add_range_options,
    chain_options,
    flag_of,
    parse_list,
)

EXIT_INTERRUPTED, EXIT_TERMINATED = 130, 143


class Terminated(BaseException):
    """SIGTERM arrived: unwind (so staged outputs are removed) and exit 143."""


def _terminate(signum: int, frame: FrameType | None) -> None:
    raise Terminated


def _guarded(args: argparse.Namespace, console: Console, body: Callable[[], int]) -> int:
    """Run a command, turning every failure into one line on stderr and an exit code."""
    try:
        return body()
    except UsageError as exc:
        console.clear()
        _report_traceback(args)
        message = f"{flag_of(exc.field)} {exc.message}" if exc.field else exc.message
        print(f"lodconvert: usage error: {message}", file=sys.stderr)
        return EXIT_USAGE
    except LodConvertError as exc:
        console.clear()
        _report_traceback(args)
        print(f"lodconvert: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        console.clear()
        print("lodconvert: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated:
        console.clear()
        print("lodconvert: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except MemoryError:
        console.clear()
        print(f"lodconvert: error: {_where(args)}: out of memory", file=sys.stderr)
        return EXIT_ERROR
    except Exception as exc:  # an unexpected failure still gets one line
        console.clear()
        _report_traceback(args)
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        hint = "" if args.debug else " (run with --debug for the traceback)"
        print(
            f"lodconvert: error: {_where(args)}: {type(exc).__name__}: {first}{hint}",
            file=sys.stderr,
        )
        return EXIT_ERROR


def _where(args: argparse.Namespace) -> str:
    inputs = getattr(args, "input", None)
    if isinstance(inputs, list):
        inputs = inputs[0] if len(inputs) == 1 else ", ".join(inputs)
    return inputs or "lodconvert"


def _report_traceback(args: argparse.Namespace) -> None:
    if getattr(args, "debug", False):
        traceback.print_exc()


def command_parser(name: str) -> Parser:
    """The argument parser of command ``name``, with every option it takes."""
    module = importlib.import_module(COMMANDS[name])
    prog = "lodconvert" if name == MAIN_COMMAND else f"lodconvert {name}"
    parser = Parser(
        prog=prog, description=module.DESCRIPTION, epilog=getattr(module, "EPILOG", None)
    )
    module.add_arguments(parser)
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    return parser


def run_command(name: str, argv: Sequence[str]) -> int:
    """Parse ``argv`` for command ``name`` and run it."""
    module = importlib.import_module(COMMANDS[name])
    args = command_parser(name).parse_args(argv)
    console = Console(quiet=getattr(args, "quiet", 0) or 0, verbose=getattr(args, "verbose", False))
    return _guarded(args, console, lambda: module.run(args, console))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lodconvert`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    tune_heap()
    tune_collector()
    # multiprocessing starts its resource tracker again where it died, and warns that
    # resources might leak: lodconvert gives it none to look after
    warnings.filterwarnings("ignore", "resource_tracker: process died", UserWarning)
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        if argv and argv[0] in COMMANDS:
            return run_command(argv[0], argv[1:])
        return run_command(MAIN_COMMAND, argv)
    finally:
        signal.signal(signal.SIGTERM, previous)
        _stop_resource_tracker()


def _stop_resource_tracker() -> None:
    """End multiprocessing's resource tracker, which starting the first worker or check
    process started, and wait for it, once no process started here runs (it holds the
    tracker's pipe open): else it ends a moment after this process, reparented. A later
    process start here starts a new one."""
    if multiprocessing.active_children():
        return
    with contextlib.suppress(ChildProcessError):  # already waited for
        resource_tracker._resource_tracker._stop()


__all__ = [
    "EXIT_ERROR",
    "EXIT_OK",
    "EXIT_USAGE",
    "Console",
    "Parser",
    "add_range_options",
    "chain_options",
    "command_parser",
    "main",
    "parse_list",
]
