"""Exception types that the command line maps to exit codes and one-line messages."""

from __future__ import annotations

import signal


class LodConvertError(Exception):
    """Input or processing error: bad file, unreadable geometry, failed write (exit code 1)."""

    def __init__(self, message: str, path: str | None = None) -> None:
        self.path = path
        super().__init__(f"{path}: {message}" if path else message)


class InputError(LodConvertError):
    """The input file is missing, of an unknown kind, empty, truncated or holds bad geometry."""


class UsageError(Exception):
    """An option value is out of range or inconsistent with the others (exit code 2).

    ``field`` names the option of the library API the message is about (``levels``,
    ``gamma``…); the message reads after it (``str(exc)`` is ``"gamma must be > 1"``). The
    command line shows the flag it maps that field to instead.
    """

    def __init__(self, message: str, field: str | None = None) -> None:
        self.message, self.field = message, field
        super().__init__(f"{field} {message}" if field else message)


def ended(code: int | None) -> str:
    """How a process that ended with ``code`` (its ``exitcode``: negative for the signal that
    ended it) ended, in words: ``signal SIGKILL``, ``exit 1``."""
    if code is None:
        return "exit code unknown"
    if code >= 0:
        return f"exit {code}"
    try:
        return f"signal {signal.Signals(-code).name}"
    except ValueError:
        return f"signal {-code}"
