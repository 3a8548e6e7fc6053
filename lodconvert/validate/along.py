"""An output checked while it is written: a process of its own reads the staged file as the
writer adds to it (:class:`GrowingFile`) and runs its format's check on that stream
(:func:`~lodconvert.validate.check_stream`), so that the check is done almost as soon as the
file is, instead of starting then, and takes nothing of the main process, which assembles and
writes what the workers bake meanwhile.

Only formats whose check reads the file once from its start can be checked so
(:func:`~lodconvert.validate.streamed_check`: X3D); the others are checked once written.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import pickle
import signal
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Protocol, Self

from ..errors import LodConvertError, ended
from . import check_stream

POLL_SECONDS = 0.02
"""How long a read at the end of the file written so far waits before looking again."""


class Abandoned(Exception):
    """The file will not be finished (its writing failed): the check stops."""


class Flag(Protocol):
    """What a :class:`GrowingFile` asks of its ``finished``: whether it is set, and a wait for
    it (a thread's event, or what the main process tells a check)."""

    def is_set(self) -> bool: ...

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


FINISHED, ABANDONED = "finished", "abandoned"
"""What the main process tells its check: the file is written whole, or will not be."""


class _Told:
    """The check's end of the pipe through which the main process tells it :data:`FINISHED`
    or :data:`ABANDONED` (the pipe's end, the main process gone, abandons the file too): the
    ``finished`` :class:`Flag` of its :class:`GrowingFile`, and ``abandoned``. A pipe, not
    :mod:`multiprocessing` events: a check killed while it waits on one leaves the main
    process's next ``set()`` of it waiting forever."""

    def __init__(self, conn: Connection) -> None:
        self._conn = conn
        self._heard: set[str] = set()

    def _hear(self, timeout: float | None) -> None:
        """Take in what was told, waiting up to ``timeout`` (``None``: until told) for
        something."""
        while ABANDONED not in self._heard and self._conn.poll(timeout):
            try:
                self._heard.add(self._conn.recv())
            except (EOFError, OSError):
                self._heard.add(ABANDONED)
            timeout = 0

    def is_set(self) -> bool:
        self._hear(0)
        return FINISHED in self._heard

    def wait(self, timeout: float | None = None) -> bool:
        self._hear(timeout)
        return FINISHED in self._heard

    def abandoned(self) -> bool:
        self._hear(0)
        return ABANDONED in self._heard


def _check_process(written: Path, target: str | Path, told: Connection, answer: Connection) -> None:
    """The checking process: check the file ``written`` as it grows, as ``told`` says; send
    ``None`` (passed, or abandoned) or the error the check raised."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the main process stops it
    error: BaseException | None = None
    orders = _Told(told)
    growing = GrowingFile(written, orders, orders.abandoned)
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
    except OSError:  # the main process is gone
        pass


class CheckAlong:
    """The check of the staged file ``written`` of the output ``target``, run by a process of
    its own while the file is written (use as a context manager around the writing):
    :meth:`result` waits for it and raises what :func:`~lodconvert.validate.check_written`
    would, or :class:`LodConvertError` when that process died."""

    def __init__(self, written: Path, target: str | Path) -> None:
        context = multiprocessing.get_context("spawn")
        told, self._orders = context.Pipe(duplex=False)
        self._answer, answer = context.Pipe(duplex=False)
        self.process = context.Process(
            target=_check_process,
            args=(written, target, told, answer),
            name="lodconvert-check",
            daemon=True,
        )
        self._their_ends = (told, answer)
        self.target = target

    def __enter__(self) -> Self:
        self.process.start()
        for conn in self._their_ends:
            conn.close()
        return self

    def _tell(self, word: str) -> None:
        """Tell the check ``word`` (nothing, once it has ended)."""
        with contextlib.suppress(OSError):
            self._orders.send(word)

    def result(self) -> None:
        """Wait for the check of the finished (and flushed) file; raise its error, if any."""
        self._tell(FINISHED)
        try:
            error = self._answer.recv()
        except EOFError:  # it died without an answer
            self.process.join()
            died = f"the process checking it died ({ended(self.process.exitcode)})"
            raise LodConvertError(died, str(self.target)) from None
        if error is not None:
            raise error

    def __exit__(self, *exc: object) -> None:
        """Stop the check (at once where the writing failed), and wait for it."""
        self._tell(ABANDONED)
        if exc[0] is not None:
            self.process.terminate()
        self.process.join()
        self._orders.close()
        self._answer.close()
