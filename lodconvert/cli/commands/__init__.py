"""Subcommands of the command line: ``lodconvert NAME ...``.

Each module listed here defines ``DESCRIPTION``, ``add_arguments(parser)`` and
``run(args, console) -> int`` (an exit code); :mod:`lodconvert.cli` parses, dispatches and turns
exceptions into one-line errors and exit codes.
"""

MAIN_COMMAND = "convert"
"""What ``lodconvert FILE ...`` runs."""

COMMANDS: dict[str, str] = {
    "convert": "lodconvert.cli.commands.convert",
    "ranges": "lodconvert.cli.commands.ranges",
    "evaluate": "lodconvert.cli.commands.evaluate",
    "bench": "lodconvert.cli.commands.bench",
    "validate": "lodconvert.cli.commands.validate",
    "view": "lodconvert.cli.commands.view",
}
