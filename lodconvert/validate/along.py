"""An output checked while it is written: a thread of the main process reads the staged file
as the writer adds to it (:class:`GrowingFile`) and runs its format's check on that stream
(:func:`~lodconvert.validate.check_stream`), so that the check is done almost as soon as the
file is, instead of starting then (the main process mostly waits for workers meanwhile).

Only formats whose check reads the file once from its start can be checked so
(:func:`~lodconvert.validate.streamed_check`: X3D); the others are checked once written.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Self

from . import check_stream

POLL_SECONDS = 0.02
"""How long a read at the end of the file written so far waits before looking again."""


class Abandoned(Exception):
    """The file will not be finished (its writing failed): the check stops."""


class GrowingFile:
    """The file at ``path`` read from its start while another thread writes it: a read at the
    end of what is written so far waits for more, until :meth:`finished` (then it is the end)
    or :meth:`abandon` (then it raises :class:`Abandoned`)."""

    def __init__(self, path: Path) -> None:
        self._handle = path.open("rb")
        self._finished = threading.Event()
        self._abandoned = False

    def read(self, size: int = -1, /) -> bytes:
        """Up to ``size`` bytes (at least one, unless the file is finished and all read)."""
        while True:
            finished = self._finished.is_set()  # before reading: nothing is written after it
            data = self._handle.read(size)
            if data:
                return data
            if self._abandoned:
                raise Abandoned
            if finished:
                return data
            self._finished.wait(POLL_SECONDS)

    def finished(self) -> None:
        """The writer has written (and flushed) the whole file."""
        self._finished.set()

    def abandon(self) -> None:
        """The writer will not finish the file."""
        self._abandoned = True
        self._finished.set()

    def close(self) -> None:
        self._handle.close()


class CheckAlong:
    """The check of the staged file ``written`` of the output ``target``, run by a thread
    while the file is written (use as a context manager around the writing): :meth:`result`
    waits for it and raises what :func:`~lodconvert.validate.check_written` would."""

    def __init__(self, written: Path, target: str | Path) -> None:
        self.file = GrowingFile(written)
        self.target = target
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._check, daemon=True, name="lodconvert-check")

    def __enter__(self) -> Self:
        self.thread.start()
        return self

    def _check(self) -> None:
        try:
            check_stream(self.file, self.target)
        except Abandoned:
            pass
        except BaseException as exc:  # raised in the main thread by result()
            self.error = exc

    def result(self) -> None:
        """Wait for the check of the finished file; raise its error, if any."""
        self.file.finished()
        self.thread.join()
        if self.error is not None:
            raise self.error

    def __exit__(self, *exc: object) -> None:
        """Stop the check where the writing failed, and wait for it."""
        self.file.abandon()
        self.thread.join()
        self.file.close()
