"""Subcommands of the command line: ``lodconvert NAME ...``.

Each module listed here defines ``DESCRIPTION``, ``add_arguments(parser)`` and
``run(args, console) -> int`` (an exit code); :mod:`lodconvert.cli` parses, dispatches and turns
exceptions into one-line errors and exit codes.
"""

MAIN_COMMAND = "convert"
"""What ``lodconvert FILE ...`` runs."""

COMMANDS: dict[str, str] = {
    "convert": "lodconvert.commands.convert",
    "ranges": "lodconvert.commands.ranges",
    "evaluate": "lodconvert.commands.evaluate",
    "bench": "lodconvert.commands.bench",
    "validate": "lodconvert.commands.validate",
    "view": "lodconvert.commands.view",
}
