"""A file that a worker opens again, by the input's real path, instead of being sent its bytes:
:func:`opened` checks that it is the file the main process read (docs/cluster.md), and
:class:`NewlinesTask` counts its line breaks in a range (so that workers reading ranges of a
line-based file number their lines as one process does)."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from .. import nofollow
from .spread import Results

COUNT_CHUNK = 1 << 22
"""Bytes a worker reads at a time while it counts."""


class Changed(Exception):
    """The file a worker opened is not the one the main process read."""


def opened(path: str, identity: tuple[int, int], prolog: bytes) -> IO[bytes]:
    """The file ``path`` (the input's real path: a link there is not followed), checked to be
    the one of ``identity`` (its size and modification time) and ``prolog``
    (:class:`Changed`; :class:`OSError` where it cannot be opened)."""
    handle = os.fdopen(os.open(path, nofollow.READ), "rb")
    status = os.fstat(handle.fileno())
    if not stat.S_ISREG(status.st_mode) or (status.st_size, status.st_mtime_ns) != identity:
        handle.close()
        raise Changed("not the file the main process read (its size or time differ)")
    if handle.read(len(prolog)) != prolog:
        handle.close()
        raise Changed("not the file the main process read (its start differs)")
    return handle


def opened_or_why(path: str, identity: tuple[int, int], head: bytes) -> IO[bytes] | str:
    """The file :func:`opened` opens, or why it cannot."""
    try:
        return opened(path, identity, head)
    except (OSError, Changed) as exc:
        return getattr(exc, "strerror", None) or str(exc)


@dataclass(frozen=True)
class FileSpan:
    """``start``–``stop`` of the file at ``path`` (``identity``: its size and modification
    time; ``head``: its first bytes), which a worker opens again."""

    path: str
    identity: tuple[int, int]
    head: bytes
    start: int
    stop: int

    def opened(self) -> IO[bytes] | str:
        """The file, positioned at ``start`` (:func:`opened`), or why it cannot be opened."""
        handle = opened_or_why(self.path, self.identity, self.head)
        if not isinstance(handle, str):
            handle.seek(self.start)
        return handle


@dataclass(frozen=True)
class NewlinesResult:
    """How many line breaks a worker counted in its range, or why it could not open the
    file."""

    count: int = 0
    unreachable: str | None = None


@dataclass(frozen=True)
class NewlinesTask(FileSpan):
    """How many line breaks lie in the span."""

    def run(self, backend: Any = None, progress: Any = None) -> NewlinesResult:
        """Count them (``backend`` and ``progress`` are not used)."""
        handle = self.opened()
        if isinstance(handle, str):
            return NewlinesResult(unreachable=handle)
        with handle:
            return NewlinesResult(newlines(handle, self.start, self.stop))

    def failed(self, reason: str) -> NewlinesResult:
        """The result of a range no worker could count, for ``reason``."""
        return NewlinesResult(unreachable=reason)


def newlines(handle: IO[bytes], start: int, stop: int) -> int:
    """How many line breaks ``handle`` holds in ``start``–``stop``."""
    handle.seek(start)
    count, at = 0, start
    while at < stop and (chunk := handle.read(min(COUNT_CHUNK, stop - at))):
        count += chunk.count(b"\n")
        at += len(chunk)
    return count


def newlines_by_workers(
    path: str, identity: tuple[int, int], head: bytes, results: Results, block: int
) -> list[int] | str:
    """The line breaks before each ``block`` bytes of the file ``path`` (its real path, of
    ``identity`` and ``head``): ``[0, n₁, n₁ + n₂, …]``, one more than the blocks, counted by
    the workers of an executor's ``results``; or why one could not open the file."""
    tasks: Iterator[NewlinesTask] = (
        NewlinesTask(path, identity, head, start, min(identity[0], start + block))
        for start in range(0, identity[0], block)
    )
    before = [0]
    for result in results(tasks):
        if result.unreachable is not None:
            return result.unreachable
        before.append(before[-1] + result.count)
    return before


def identity_of(path: Path) -> tuple[int, int]:
    """The size and modification time of the file ``path``, as :func:`opened` checks them."""
    status = path.stat()
    return status.st_size, status.st_mtime_ns
