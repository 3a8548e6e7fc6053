"""Where outputs go: a file or a directory, staged beside its target and committed together.

One run's outputs (the model file, ``--report``, ``--html``, files written beside them, or a
directory of tiles) form one :class:`Outputs`. Each target is checked before any work is done;
everything is written to temporary names in the target folders, and :meth:`Outputs.commit`
renames them all into place, putting back what it replaced if a rename fails: a run that fails
or is interrupted leaves no new file. A run holds an exclusive ``flock`` on what it stages; the
next run to a target removes what a killed run left, and takes over a staged directory of its
own ``resume`` key (:attr:`DirectorySink.resumed`). In full: ``docs/outputs.md``.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, TypeVar

from . import manifest, nofollow
from .errors import InputError, LodConvertError
from .version import __version__

T = TypeVar("T")
Check = Callable[[Path], None]
"""Called with a complete staged file (or directory) before the commit; raises to refuse it."""
RESUME = ".resume"
"""The folder inside a staged directory holding the journal of the files its runs wrote
(``written``), its run's key (``run``, when resumable) and what its writer records to resume;
removed before the directory is checked and committed."""
JOURNAL = f"{RESUME}/written"
RUN = f"{RESUME}/run"
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})
"""Errors of a write that no input or option causes: a full disk, a full quota, a file too
large for its file system, a file system turned read-only. (Not EIO: input read lazily while
an output is written could raise it too.)"""


class _Writing:
    """The ``with`` block of :func:`writing`: no state of its own, so one serves any number of
    blocks, and where it writes is named only when a write fails (a city writes a file or a
    record per tile and parks many of its objects in a temporary file: their names are not
    made for each)."""

    __slots__ = ("_where",)

    def __init__(self, where: str | Path | Callable[[], str | Path]) -> None:
        self._where = where

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: object, exc: BaseException | None, traceback: object) -> None:
        if isinstance(exc, OSError) and exc.errno in WRITE_ERRNOS:
            where = self._where() if callable(self._where) else self._where
            raise LodConvertError(f"cannot write: {os.strerror(exc.errno)}", str(where)) from exc


def writing(where: str | Path | Callable[[], str | Path]) -> _Writing:
    """A failed write in the ``with`` block (:data:`WRITE_ERRNOS`) as one line naming ``where``
    (or what it gives, called then) (:class:`LodConvertError`: ``out.glb: cannot write: No space
    left on device``); any other error as it is."""
    return _Writing(where)


_TEMPORARY = _Writing(lambda: f"temporary folder {tempfile.gettempdir()}")


def writing_temporary() -> _Writing:
    """:func:`writing` for work files in the temporary folder (``TMPDIR``), naming it."""
    return _TEMPORARY


def _same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name one file (same resolved path, or same device and inode)."""
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


@dataclass
class _Staged:
    target: Path
    temp: Path
    check: Check | None = None
    lock: int | None = None
    """A descriptor of ``temp`` holding its ``flock`` while this run lives (for a directory,
    the descriptor every file inside it is reached from)."""
    resumed: bool = False
    """Whether ``temp`` is a killed run's staged directory of the same key, taken over."""
    directory: bool = False
    written: set[str] = field(default_factory=set)
    """A staged directory's files that its runs wrote (the journal :data:`JOURNAL` keeps)."""

    def note(self, relative: str) -> bool:
        """Journal ``relative`` as written in this staged directory before it is; returns
        whether it already was (it may then be replaced)."""
        if relative in self.written:
            return True
        assert self.lock is not None
        names = nofollow.parts(JOURNAL)
        with nofollow.parent(self.lock, names) as folder:
            fd = os.open(names[-1], os.O_WRONLY | os.O_APPEND | os.O_NOFOLLOW, dir_fd=folder)
        with os.fdopen(fd, "ab") as journal:
            journal.write(f"{relative}\n".encode())
        self.written.add(relative)
        return False


def _staged_pattern(target: Path) -> re.Pattern[str]:
    """Names that :meth:`Outputs.file` and :meth:`Outputs.directory` stage ``target`` under:
    ``.name.`` + the 8 characters of :mod:`tempfile` + ``.tmp`` (+ the suffix, for a file)."""
    suffix = re.escape(target.suffix)
    return re.compile(rf"\.{re.escape(target.name)}\.[a-z0-9_]{{8}}\.tmp(?:{suffix})?")


_NO_LOCKS = frozenset({errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL})
"""``flock`` errors of file systems without locks: staged names there are left unlocked, and
another run, failing to lock them too, leaves them alone."""


def _held(path: Path) -> int | None:
    """A descriptor of ``path`` (never through a link) holding its exclusive ``flock``
    (waiting for it), or ``None`` when ``path`` no longer names the locked file (another run
    removed it meanwhile)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except FileNotFoundError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
    except OSError as exc:
        if exc.errno not in _NO_LOCKS:
            os.close(fd)
            raise
    with contextlib.suppress(OSError):
        if os.path.samestat(os.fstat(fd), os.stat(path, follow_symlinks=False)):
            return fd
    os.close(fd)
    return None


def _journal(fd: int) -> set[str]:
    """The files the journal of the staged directory ``fd`` lists."""
    data = nofollow.read(fd, JOURNAL, manifest.LIMIT) or b""
    return {line for line in data.decode("utf-8", "replace").splitlines() if line}


def _foreign(fd: int, written: set[str]) -> tuple[str, str] | None:
    """The first entry of the staged directory ``fd`` that its runs did not write (a link,
    another user's file, a file its journal does not list): its relative path and what it is;
    ``None`` where there is none."""
    own = (JOURNAL, RUN)
    for relative, found in nofollow.walk(fd):
        why = nofollow.what(found)
        if (
            why is None
            and stat.S_ISREG(found.st_mode)
            and relative not in written
            and relative not in own
        ):
            why = "a file no run wrote there"
        if why is not None:
            return relative, why
    return None


def _clear_dead_runs(target: Path, resume: str | None = None) -> tuple[int, set[str]] | None:
    """Remove what runs that are no longer alive staged for ``target``: its staged names in its
    folder that no process holds locked and that hold only what those runs wrote (anything
    else, a link above all, is left alone). A staged directory of the ``resume`` key is kept
    instead, and a descriptor holding its lock returned with its journal (``None``: there is
    none); one holding anything its runs did not write is refused (:class:`InputError`)."""
    pattern = _staged_pattern(target)
    try:
        names = [name for name in os.listdir(target.parent) if pattern.fullmatch(name)]
    except OSError:
        return None
    ours = None if resume is None else _resume_name(target, resume).name
    kept = None
    for name in sorted(names):
        path = target.parent / name
        try:  # a link fails here (ELOOP): never ours to follow or remove
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # locked by a live run (or locks unsupported here): leave it
            os.close(fd)
            continue
        found = os.fstat(fd)
        if stat.S_ISDIR(found.st_mode):
            written = _journal(fd)
            stray = _foreign(fd, written) or (
                None if (why := nofollow.what(found)) is None else (".", why)
            )
            if stray is not None:
                os.close(fd)
                if name == ours:
                    raise InputError(
                        f"the staged folder {name!r} that an interrupted run left holds "
                        f"{stray[0]!r}, {stray[1]}; remove that folder and run again",
                        str(target),
                    )
                continue
            if kept is None and name == ours and _resumable(fd, resume):
                kept = fd, written
                continue
        elif nofollow.what(found) is not None:
            os.close(fd)
            continue
        _remove(path)
        os.close(fd)
    return kept


def _resume_name(target: Path, resume: str) -> Path:
    """The staged name of the directory ``target`` for the run of key ``resume``."""
    return target.parent / f".{target.name}.{resume[:8]}.tmp"


def _resumable(fd: int, resume: str | None) -> bool:
    """Whether the staged directory ``fd`` is one of the run of key ``resume``."""
    return resume is not None and nofollow.read(fd, RUN, 1 << 12) == resume.encode()


@dataclass
class FileSink:
    """One output file: :meth:`open` writes its staged copy; :meth:`beside` stages another file
    in the same folder (a texture, a buffer) that is committed with it."""

    outputs: Outputs
    path: Path
    staged: _Staged

    @contextlib.contextmanager
    def open(self) -> Iterator[BinaryIO]:
        """The staged file, opened for binary writing (flushed to disk when the block ends);
        a failed write is one line naming the output (:func:`writing`)."""
        flags = os.O_WRONLY | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC
        with writing(self.path), os.fdopen(os.open(self.staged.temp, flags), "wb") as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())

    def write_bytes(self, data: bytes) -> None:
        """Write the whole file."""
        with self.open() as handle:
            handle.write(data)

    def beside(self, name: str) -> FileSink:
        """A sink for ``name`` in this output's folder."""
        return self.outputs.file(self.path.parent / name)

    def with_staged(self, use: Callable[[Path], T]) -> T:
        """``use`` called with the path of the staged copy, to check or read it before the
        commit (the one way to that path outside this module)."""
        return use(self.staged.temp)


@dataclass
class DirectorySink:
    """One output directory, staged as a whole: :meth:`file` writes a file inside it."""

    outputs: Outputs
    path: Path
    staged: _Staged

    @property
    def resumed(self) -> bool:
        """Whether the staged directory is an interrupted run's of the same key, taken over
        with what it holds (see :meth:`Outputs.directory`)."""
        return self.staged.resumed

    @contextlib.contextmanager
    def file(self, relative: str | Path) -> Iterator[BinaryIO]:
        """A file at ``relative`` inside the staged directory (folders made as needed), never
        written through a link: one found on the way is :class:`LodConvertError`, and so is
        any entry there that no run of this output wrote."""
        name = "/".join(nofollow.parts(relative))
        with writing(lambda: self.path / name), self._inside(name):
            replace = self.staged.note(name)
            with os.fdopen(nofollow.create(_root(self.staged), name, replace), "wb") as handle:
                yield handle

    @contextlib.contextmanager
    def appended(self, relative: str | Path) -> Iterator[BinaryIO]:
        """The file at ``relative`` inside the staged directory, open for appending where a run
        of this output wrote it, made as :meth:`file` makes it otherwise."""
        name = "/".join(nofollow.parts(relative))
        if name not in self.staged.written:
            with self.file(name) as handle:
                yield handle
            return
        with (
            writing(lambda: self.path / name),
            self._inside(name),
            os.fdopen(nofollow.append(_root(self.staged), name), "ab") as handle,
        ):
            yield handle

    def with_staged(self, use: Callable[[Path], T], relative: str = "") -> T:
        """``use`` called with the path of the staged folder (or of ``relative`` inside it), to
        check or read it before the commit."""
        return use(
            self.staged.temp / "/".join(nofollow.parts(relative)) if relative else self.staged.temp
        )

    def read(self, relative: str | Path, limit: int) -> bytes | None:
        """The file at ``relative`` inside the staged directory (at most ``limit`` bytes) when
        a run of this output wrote it; ``None`` otherwise (absent, a link, not written)."""
        name = "/".join(nofollow.parts(relative))
        if name not in self.staged.written:
            return None
        return nofollow.read(_root(self.staged), name, limit)

    def prune(self, folder: str, keep: set[str]) -> None:
        """Remove the files of ``folder`` (inside the staged directory) that runs of this
        output wrote, but for those named in ``keep``."""
        prefix = "/".join(nofollow.parts(folder)) + "/"
        for name in sorted(self.staged.written):
            rest = name.removeprefix(prefix)
            if rest != name and "/" not in rest and rest not in keep:
                nofollow.remove(_root(self.staged), name)

    @contextlib.contextmanager
    def _inside(self, name: str) -> Iterator[None]:
        """:class:`nofollow.Foreign` in the block as one line naming the output."""
        try:
            yield
        except nofollow.Foreign as exc:
            raise LodConvertError(
                f"cannot write {name}: the staged folder holds {exc.relative!r}, {exc.what} "
                "that this run did not make",
                str(self.path),
            ) from None


@dataclass
class Outputs:
    """The outputs of one run. Use as a context manager: commit when the block succeeds,
    discard everything staged when it raises (an interrupt included)."""

    inputs: Sequence[str | Path] = ()
    _staged: list[_Staged] = field(default_factory=list)

    def __enter__(self) -> Outputs:
        return self

    def __exit__(self, kind: type[BaseException] | None, *_: object) -> None:
        if kind is None:
            self.commit()
        else:
            self.discard()

    def target(self, path: str | Path, directory: bool = False) -> Path:
        """``path`` checked as an output: raise :class:`InputError` naming it when its folder is
        missing or not writable, when it is a directory (a file, for a directory output), when
        it is one of the run's inputs (holds one, for a directory output), or when this run
        already writes it."""
        path = Path(path)
        where = str(path)
        folder = path.parent if str(path.parent) else Path(".")
        if not folder.is_dir():
            raise InputError(f"cannot write here: no folder {str(folder)!r}", where)
        if not os.access(folder, os.W_OK | os.X_OK):
            raise InputError(f"cannot write here: folder {str(folder)!r} is not writable", where)
        if path.exists() and path.is_dir() != directory:
            kind = "a directory" if path.is_dir() else "a file"
            raise InputError(f"is {kind}; the output must not be", where)
        for source in self.inputs:
            if Path(source).exists() and path.exists() and _same_file(Path(source), path):
                raise InputError("is an input of this run; it would be overwritten", where)
            if directory and Path(source).resolve().is_relative_to(path.resolve()):
                raise InputError(
                    f"holds {source}, an input of this run; it would be replaced", where
                )
        for staged in self._staged:
            if staged.target.resolve() == path.resolve():
                raise InputError("is written twice by this run", where)
        return path

    def file(self, path: str | Path, check: Check | None = None) -> FileSink:
        """Stage the output file ``path`` (checked first, see :meth:`target`; what dead runs
        staged for it is removed)."""
        target = self.target(path)
        staged = self._stage(target, check, directory=False)
        return FileSink(self, target, staged)

    def directory(
        self, path: str | Path, check: Check | None = None, resume: str | None = None
    ) -> DirectorySink:
        """Stage the output directory ``path`` (replacing an existing one on commit). With a
        ``resume`` key, a staged directory a killed run of the same key left is taken over
        (:attr:`DirectorySink.resumed`), and the new one is staged where the next run of that
        key finds it."""
        target = self.target(path, directory=True)
        staged = None
        if resume is not None:
            staged = self._resumed(target, check, resume)
        if staged is None:
            staged = self._stage(target, check, directory=True)
        return DirectorySink(self, target, staged)

    def _resumed(self, target: Path, check: Check | None, resume: str) -> _Staged | None:
        """The staged directory of ``target`` for the run of key ``resume``: a dead run's,
        taken over, or a new one with the key recorded (``None``: a live run holds the name)."""
        kept = _clear_dead_runs(target, resume)
        temp = _resume_name(target, resume)
        if kept is not None:
            lock, written = kept
            staged = _Staged(target, temp, check, lock, True, True, written)
        else:
            try:
                temp.mkdir(mode=0o700)
            except OSError:  # a live run of the same key stages it (or :meth:`_stage` says why)
                return None
            lock = _held(temp)
            if lock is None:
                return None
            staged = _Staged(target, temp, check, lock, directory=True)
            _begin(staged, resume)
        self._staged.append(staged)
        return staged

    def _stage(self, target: Path, check: Check | None, directory: bool) -> _Staged:
        """A locked staged name beside ``target``: ``.name.XXXX.tmp.suffix`` for a file
        (hidden, marked as temporary, and still of its format), ``.name.XXXX.tmp`` for a
        directory."""
        _clear_dead_runs(target)
        lock = None
        while lock is None:
            try:
                if directory:
                    temp = tempfile.mkdtemp(
                        prefix=f".{target.name}.", suffix=".tmp", dir=target.parent
                    )
                else:
                    fd, temp = tempfile.mkstemp(
                        prefix=f".{target.name}.", suffix=f".tmp{target.suffix}", dir=target.parent
                    )
                    os.close(fd)
                lock = _held(Path(temp))
            except OSError as exc:  # /proc, /sys: folders that take no new files
                folder = str(target.parent)
                raise InputError(
                    f"cannot write here: folder {folder!r} takes no new file "
                    f"({os.strerror(exc.errno or errno.EIO)})",
                    str(target),
                ) from exc
        staged = _Staged(target, Path(temp), check, lock, directory=directory)
        if directory:
            _begin(staged)
        self._staged.append(staged)
        return staged

    def commit(self) -> list[Path]:
        """Check every staged output, then rename all into place; on any failure nothing is
        left changed. Returns the targets written."""
        try:
            for staged in self._staged:
                if staged.directory:
                    _sealed(staged)
                if staged.check is not None:
                    staged.check(staged.temp)
                if staged.directory:
                    manifest.write(_root(staged), f"lodconvert {__version__}")
        except BaseException:
            self.discard()
            raise
        done: list[tuple[_Staged, Path | None]] = []
        try:
            for staged in self._staged:
                backup = None
                if os.path.lexists(staged.target):
                    backup = Path(f"{staged.temp}.old")
                    os.replace(staged.target, backup)
                done.append((staged, backup))
                staged.temp.chmod(0o755 if staged.directory else 0o644)  # made private by mkdtemp
                os.replace(staged.temp, staged.target)
        except BaseException:
            for staged, backup in reversed(done):
                if staged.target.exists() and not staged.temp.exists():
                    os.replace(staged.target, staged.temp)
                if backup is not None:
                    os.replace(backup, staged.target)
            self.discard()
            raise
        for _, backup in done:
            if backup is not None and not backup.is_dir():
                _remove(backup)
            elif backup is not None:
                manifest.remove_listed(backup)
        written = [staged.target for staged in self._staged]
        self._release()
        return written

    def discard(self) -> None:
        """Remove everything staged; targets stay as they were."""
        for staged in self._staged:
            _remove(staged.temp)
        self._release()

    def _release(self) -> None:
        """Drop the locks of what was staged (committed or removed by now)."""
        for staged in self._staged:
            if staged.lock is not None:
                os.close(staged.lock)
        self._staged.clear()


def _root(staged: _Staged) -> int:
    """The descriptor a staged directory's files are reached from."""
    assert staged.lock is not None
    return staged.lock


def _begin(staged: _Staged, resume: str | None = None) -> None:
    """Start the journal of a new staged directory (and record its run's key ``resume``)."""
    with writing(staged.target):
        os.mkdir(RESUME, 0o700, dir_fd=_root(staged))
        os.close(nofollow.create(_root(staged), JOURNAL, replace=False))
        if resume is not None:
            with os.fdopen(nofollow.create(_root(staged), RUN, replace=False), "wb") as stream:
                stream.write(resume.encode())


def _sealed(staged: _Staged) -> None:
    """Check that a staged directory holds only what its runs wrote (:class:`LodConvertError`
    naming the output otherwise), then remove its :data:`RESUME` folder."""
    stray = _foreign(_root(staged), staged.written)
    if stray is not None:
        raise LodConvertError(
            f"the staged folder holds {stray[0]!r}, {stray[1]} that this run did not make; "
            "nothing was written",
            str(staged.target),
        )
    shutil.rmtree(RESUME, dir_fd=_root(staged))


def _remove(path: Path) -> None:
    """Remove a file or a directory tree, if it exists."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
