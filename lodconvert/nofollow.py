"""Files inside a folder, reached without following links.

The folder is opened once (a descriptor); every path below it is reached one name at a time
with ``O_NOFOLLOW``, so that a link planted anywhere in it is refused (:class:`Foreign`) instead
of being written, read or removed through. Used for staged output folders and the folders a
run replaces (docs/outputs.md).
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from collections.abc import Iterator
from pathlib import PurePosixPath

DIRECTORY = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC
"""Flags opening a real folder (a link to one fails with ``ELOOP``)."""
CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
READ = os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC
APPEND = os.O_WRONLY | os.O_APPEND | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
"""Flags appending to a file (``O_NONBLOCK``: a FIFO planted there is not waited on)."""


class Foreign(Exception):
    """An entry of a folder that the run did not make: ``relative`` and what it is."""

    def __init__(self, relative: str, what: str) -> None:
        self.relative, self.what = relative, what
        super().__init__(f"{relative}: {what}")


def parts(relative: str | os.PathLike[str]) -> tuple[str, ...]:
    """The names of ``relative``; :class:`ValueError` for a path leaving its folder."""
    path = PurePosixPath(os.fspath(relative))
    if path.is_absolute() or ".." in path.parts or not path.parts:
        raise ValueError(f"{relative} is not a path inside the folder")
    return path.parts


def open_folder(path: str | os.PathLike[str], dir_fd: int | None = None) -> int:
    """A descriptor of the real folder ``path`` (``OSError`` with ``ELOOP`` for a link)."""
    return os.open(path, DIRECTORY, dir_fd=dir_fd)


@contextlib.contextmanager
def parent(root: int, names: tuple[str, ...], make: bool = False) -> Iterator[int]:
    """A descriptor of the folder holding ``names[-1]`` below ``root`` (its folders made when
    ``make``); :class:`Foreign` where one of them is a link or not a folder."""
    fd, opened = root, []
    try:
        for i, name in enumerate(names[:-1]):
            if make:
                with contextlib.suppress(FileExistsError):
                    os.mkdir(name, 0o755, dir_fd=fd)
            try:
                fd = open_folder(name, dir_fd=fd)
            except OSError as exc:
                if exc.errno in (errno.ELOOP, errno.ENOTDIR):
                    raise Foreign("/".join(names[: i + 1]), _kind(fd, name)) from None
                raise
            opened.append(fd)
        yield fd
    finally:
        for each in opened:
            os.close(each)


def create(root: int, relative: str, replace: bool) -> int:
    """A new file at ``relative`` below ``root``, open for writing; an existing regular file
    there is removed first when ``replace``, anything else there is :class:`Foreign`."""
    names = parts(relative)
    with parent(root, names, make=True) as fd:
        try:
            return os.open(names[-1], CREATE, 0o644, dir_fd=fd)
        except FileExistsError:
            kind = _kind(fd, names[-1])
            if not (replace and kind == "a file"):
                raise Foreign(relative, kind) from None
        os.unlink(names[-1], dir_fd=fd)
        return os.open(names[-1], CREATE, 0o644, dir_fd=fd)


def append(root: int, relative: str) -> int:
    """The existing file ``relative`` below ``root``, open for appending; :class:`Foreign`
    where it is anything but a regular file of this user with one name (:func:`what`)."""
    names = parts(relative)
    with parent(root, names) as fd:
        try:
            handle = os.open(names[-1], APPEND, dir_fd=fd)
        except OSError as exc:
            if exc.errno in (errno.ELOOP, errno.ENXIO):
                raise Foreign(relative, _kind(fd, names[-1])) from None
            raise
    found = os.fstat(handle)
    problem = "a folder" if stat.S_ISDIR(found.st_mode) else what(found)
    if problem is not None:
        os.close(handle)
        raise Foreign(relative, problem)
    return handle


def read(root: int, relative: str, limit: int) -> bytes | None:
    """The bytes of the regular file ``relative`` below ``root`` (at most ``limit``); ``None``
    where it is absent, a link, or no regular file."""
    try:
        names = parts(relative)
        with parent(root, names) as fd:
            handle = os.open(names[-1], READ, dir_fd=fd)
    except (OSError, Foreign):
        return None
    with os.fdopen(handle, "rb") as stream:
        found = os.fstat(stream.fileno())
        if not stat.S_ISREG(found.st_mode):
            return None
        return stream.read(min(limit, found.st_size + 1))


def remove(root: int, relative: str) -> None:
    """Remove the file ``relative`` below ``root`` (a link itself, never what it points to)."""
    names = parts(relative)
    with contextlib.suppress(FileNotFoundError), parent(root, names) as fd:
        os.unlink(names[-1], dir_fd=fd)


def walk(root: int, below: str = "") -> Iterator[tuple[str, os.stat_result]]:
    """Every entry below ``root``, sorted, as (relative path, its own ``lstat``): folders
    before what they hold, and never through a link."""
    with os.scandir(root) as listing:
        entries = sorted(listing, key=lambda entry: entry.name)
    for entry in entries:
        relative = f"{below}{entry.name}"
        found = entry.stat(follow_symlinks=False)
        yield relative, found
        if stat.S_ISDIR(found.st_mode):
            fd = open_folder(entry.name, dir_fd=root)
            try:
                yield from walk(fd, f"{relative}/")
            finally:
                os.close(fd)


def what(found: os.stat_result) -> str | None:
    """Why an entry of ``lstat`` ``found`` is not one a run writes: a link, another kind of
    file, a hard link, another user's; ``None`` for a folder or a file of this user."""
    mode = found.st_mode
    if stat.S_ISLNK(mode):
        return "a link"
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        return "neither a file nor a folder"
    if found.st_uid != os.geteuid():
        return "of another user"
    if stat.S_ISREG(mode) and found.st_nlink != 1:
        return "a file with other names (a hard link)"
    return None


def _kind(fd: int, name: str) -> str:
    """What ``name`` in the folder ``fd`` is, in words."""
    try:
        found = os.stat(name, dir_fd=fd, follow_symlinks=False)
    except OSError:
        return "not a file"
    return what(found) or ("a folder" if stat.S_ISDIR(found.st_mode) else "a file")
