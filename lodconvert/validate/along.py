"""An output checked while it is written: a process of its own reads the staged file as the
writer adds to it (:class:`GrowingFile`) and runs its format's check on that stream
(:func:`~lodconvert.validate.check_stream`), so that the check is done almost as soon as the
file is, instead of starting then, and takes nothing of the main process, which assembles and
writes what the workers bake meanwhile.

Only formats whose check reads the file once from its start can be checked so
(:func:`~lodconvert.validate.streamed_check`: X3D); the others are checked once written.
"""

from __future__ import annotations

import multiprocessing
import pickle
import signal
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Protocol, Self

from ..errors import LodConvertError
from . import check_stream

POLL_SECONDS = 0.02
"""How long a read at the end of the file written so far waits before looking again."""


class Abandoned(Exception):
    """The file will not be finished (its writing failed): the check stops."""


class Flag(Protocol):
    """An event that one side sets and the other waits for (a thread's or a process's)."""

    def is_set(self) -> bool: ...

    def set(self) -> None: ...

    def wait(self, timeout: float | None = None) -> bool: ...


class GrowingFile:
    """The file at ``path`` read from its start while it is written elsewhere: a read at the
    end of what is written so far waits for more, until ``finished`` is set (then it is the
    end) or ``abandoned()`` is true (then it raises :class:`Abandoned`)."""

    def __init__(self, path: Path, finished: Flag, abandoned: Callable[[], bool]) -> None:
        self._handle = path.open("rb")
        self._finished, self._abandoned = finished, abandoned

    def read(self, size: int = -1, /) -> bytes:
        """Up to ``size`` bytes (at least one, unless the file is finished and all read)."""
        while True:
            finished = self._finished.is_set()  # before reading: nothing is written after it
            data = self._handle.read(size)
            if data:
                return data
            if self._abandoned():
                raise Abandoned
            if finished:
                return data
            self._finished.wait(POLL_SECONDS)

    def close(self) -> None:
        self._handle.close()


def _check_process(
    written: Path, target: str | Path, finished: Flag, abandoned: Flag, answer: Connection
) -> None:
    """The checking process: check the file ``written`` as it grows; send ``None`` (passed,
    or abandoned) or the error the check raised."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the main process stops it
    error: BaseException | None = None
    parent = multiprocessing.parent_process()
    assert parent is not None

    def given_up() -> bool:  # by the writer, or with the main process (killed)
        return abandoned.is_set() or not parent.is_alive()

    growing = GrowingFile(written, finished, given_up)
    try:
        check_stream(growing, target)
    except Abandoned:
        pass
    except Exception as exc:  # raised in the main process by CheckAlong.result()
        error = exc
    finally:
        growing.close()
    try:
        answer.send(error)
    except (pickle.PicklingError, TypeError, AttributeError):
        answer.send(LodConvertError(str(error)))


class CheckAlong:
    """The check of the staged file ``written`` of the output ``target``, run by a process of
    its own while the file is written (use as a context manager around the writing):
    :meth:`result` waits for it and raises what :func:`~lodconvert.validate.check_written`
    would."""

    def __init__(self, written: Path, target: str | Path) -> None:
        context = multiprocessing.get_context("spawn")
        self._finished, self._abandoned = context.Event(), context.Event()
        self._answer, answer = context.Pipe(duplex=False)
        self.process = context.Process(
            target=_check_process,
            args=(written, target, self._finished, self._abandoned, answer),
            name="lodconvert-check",
            daemon=True,
        )
        self._sent_end = answer
        self.target = target

    def __enter__(self) -> Self:
        self.process.start()
        self._sent_end.close()
        return self

    def result(self) -> None:
        """Wait for the check of the finished (and flushed) file; raise its error, if any."""
        self._finished.set()
        try:
            error = self._answer.recv()
        except EOFError:  # it died without an answer
            self.process.join()
            stopped = f"its check stopped (exit {self.process.exitcode})"
            raise LodConvertError(stopped, str(self.target)) from None
        if error is not None:
            raise error

    def __exit__(self, *exc: object) -> None:
        """Stop the check (at once where the writing failed), and wait for it."""
        self._abandoned.set()
        self._finished.set()
        if exc[0] is not None:
            self.process.terminate()
        self.process.join()
        self._answer.close()
