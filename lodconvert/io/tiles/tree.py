"""A tileset's tree as ``lodconvert validate`` and ``lodconvert view`` read it, whoever wrote it:
each tileset JSON read within the run's limits (size, then nesting depth counted on its bytes,
:data:`MAX_DEPTH`), its tiles walked without recursion, its content URIs held to its folder
(relative, never followed out through ``..`` or a link), its external tilesets read each once,
one at a time (a cycle, or a second reference, reported and not read again).

:func:`walk` yields every tile, parents before children, and hands each problem to its caller
as a :class:`Problem`: ``validate`` records them as findings, ``view`` refuses the tileset at
the first. Every case: *Hostile tilesets* in ``docs/3d-tiles.md``.
"""

from __future__ import annotations

import json
import os
import stat
import urllib.parse
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ...errors import InputError
from ...limits import DEFAULT_LIMITS, Limits
from ..gltf.stream import Source, too_deep

MAX_DEPTH = 256
"""Deepest nesting of arrays and objects in one tileset JSON (lodconvert's nest about 10 deep:
two levels a tile)."""


@dataclass(frozen=True)
class Problem:
    """What is wrong with a tileset: ``code`` (``JSON``: a tileset JSON that cannot be read;
    ``URI``: a content URI that names no file inside the folder; ``CYCLE``: external tilesets
    that refer to each other), the JSON file it is in (``file``: the top file as given, an
    external one below the top file's folder; ``name``: relative to the folder), the tile
    (``where``, e.g. ``root/0/2``; ``None``: the file as a whole) and the ``reason``."""

    code: str
    file: Path
    name: str
    where: str | None
    reason: str
    top: bool

    def __str__(self) -> str:
        """One line after the top file's name: the external file's name, the tile, the
        reason."""
        if self.where is None:
            return f"{self.name}: {self.reason}"
        return f"{self.where if self.top else f'{self.name} {self.where}'}: {self.reason}"

    def error(self) -> InputError:
        """The one-line error that refuses the tileset, naming the file and the tile."""
        message = f"{self.where}: {self.reason}" if self.where else self.reason
        return InputError(message, str(self.file))


@dataclass(frozen=True)
class Content:
    """A tile's content: its ``uri`` as written and the file it names (resolved, inside the
    folder; ``None`` when it names none, which was reported)."""

    uri: Any
    target: Path | None

    @property
    def external(self) -> bool:
        """Whether it is an external tileset (a ``.json`` file)."""
        return self.target is not None and self.target.suffix.lower() == ".json"


@dataclass(frozen=True)
class Referrer:
    """The tile whose content is an external tileset: where it is and what its walker's
    caller kept of it (:attr:`Tile.state`), without its JSON."""

    where: str
    state: Any


@dataclass(eq=False)
class Tile:
    """One tile: its JSON (``node``), where it is (``root/0/2``, after the file's name in an
    external tileset), its JSON file's name (relative to the folder), the tile above it in
    the same file (``parent``; ``None`` for a file's root), for a file's root the tile that
    refers to the file (``referrer``; ``None`` for the top file) and the file's document
    (``tileset``), its index among its parent's children and its contents. ``state`` is the
    caller's, for the tiles below it (and the external tilesets it refers to)."""

    node: dict
    where: str
    file: str
    parent: Tile | None
    referrer: Referrer | None
    tileset: dict | None
    index: int
    contents: list[Content]
    state: Any = None


@dataclass(frozen=True)
class _File:
    """A tileset JSON: as named (``path``), resolved, relative to the folder, and the file
    that refers to it (``None``: the top file)."""

    path: Path
    resolved: Path
    name: str
    above: _File | None


class _Refused(Exception):
    """A tileset JSON that is not read (the reason)."""


def read_json(path: Path, limits: Limits = DEFAULT_LIMITS) -> Any:
    """The JSON value of the tileset JSON ``path``, read within ``limits``; raises
    :class:`InputError` naming it when it cannot be read or is over a limit."""
    try:
        return _read(path, limits)
    except _Refused as exc:
        raise InputError(str(exc), str(path)) from None


def _read(path: Path, limits: Limits) -> Any:
    """:func:`read_json`, raising :class:`_Refused`."""
    limit = limits.tileset_json_bytes
    over = (
        f"over the limit of {limit:,} for a tileset JSON "
        "(raise it with --limit tileset_json_bytes=N)"
    )
    try:  # not blocking on a FIFO, which is refused once open
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise _Refused("no such file") from None
    except (OSError, ValueError) as exc:
        raise _Refused(f"cannot be read ({getattr(exc, 'strerror', None) or exc})") from None
    with open(fd, "rb") as handle:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise _Refused("is not a regular file")
        if info.st_size > limit:
            raise _Refused(f"holds {info.st_size:,} bytes, {over}")
        data = handle.read(info.st_size + 1)
    if len(data) > info.st_size:
        raise _Refused("grew while it was read")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _Refused(
            f"is not UTF-8 text: byte 0x{data[exc.start]:02x} at offset {exc.start}"
        ) from None
    if too_deep(Source(data, 0, len(data), None), MAX_DEPTH):
        raise _Refused(f"nests arrays and objects over {MAX_DEPTH} deep")
    del data
    try:
        return json.loads(text)
    except RecursionError:  # not reached after too_deep; a last guard
        raise _Refused(f"nests arrays and objects over {MAX_DEPTH} deep") from None
    except ValueError as exc:
        raise _Refused(f"is not JSON ({exc})") from None


def walk(
    path: Path, report: Callable[[Problem], None], limits: Limits = DEFAULT_LIMITS
) -> Iterator[Tile]:
    """Every tile of the tileset ``path`` and of its external tilesets: a file's tiles depth
    first, each before its children, and each external tileset after the whole of the file
    that refers to it (by then the referring tile's :attr:`Tile.state` is set). Each problem
    is handed to ``report``, which may raise to stop the walk."""
    path = Path(path)
    folder = path.parent.resolve()
    top = _File(path, path.resolve(), path.name, None)
    seen: dict[Path, str] = {top.resolved: "the top tileset"}  # file → the tile naming it
    queue: deque[tuple[_File, Referrer | None]] = deque([(top, None)])
    while queue:
        file, referrer = queue.popleft()

        def problem(code: str, where: str | None, reason: str, file: _File = file) -> None:
            report(Problem(code, file.path, file.name, where, reason, file is top))

        try:
            document = _read(file.path, limits)
        except _Refused as exc:
            problem("JSON", None, str(exc))
            continue
        root = document.get("root") if isinstance(document, dict) else None
        if not isinstance(root, dict):
            what = "no root tile" if isinstance(document, dict) else _kind(document)
            problem("JSON", None, f"is not a tileset ({what})")
            continue
        stack: list[tuple[Any, str, Tile | None, int]] = [(root, "root", None, -1)]
        while stack:
            node, where, parent, index = stack.pop()
            label = where if file is top else f"{file.name} {where}"
            if not isinstance(node, dict):
                problem("JSON", where, f"is {_kind(node)}, not a tile")
                continue
            contents = [
                Content(uri, _target(folder, file.resolved.parent, uri, where, problem))
                for uri in _uris(node, where, problem)
            ]
            tile = Tile(
                node,
                label,
                file.name,
                parent,
                referrer if parent is None else None,
                document if parent is None else None,
                index,
                contents,
            )
            yield tile
            children = node.get("children", [])
            if not isinstance(children, list):
                problem("JSON", where, f"has children that are {_kind(children)}, not a list")
                children = []
            stack.extend(
                (child, f"{where}/{i}", tile, i) for i, child in reversed(list(enumerate(children)))
            )
            for content in contents:
                if not content.external:
                    continue
                assert content.target is not None
                name = content.target.relative_to(folder).as_posix()
                if content.target in seen:
                    problem("CYCLE" if _above(file, content.target) else "URI", where,
                            _again(content.uri, name, file, content.target, seen))  # fmt: skip
                    continue
                seen[content.target] = label
                below = _File(path.parent / name, content.target, name, file)
                queue.append((below, Referrer(label, tile.state)))


def _uris(node: dict, where: str, problem: Callable[[str, str | None, str], None]) -> list[Any]:
    """The URIs of a tile's ``content`` and ``contents`` (3D Tiles 1.1)."""
    found = []
    if "content" in node:
        content = node["content"]
        if isinstance(content, dict):
            found.append(content.get("uri"))
        else:
            problem("JSON", where, f"has a content that is {_kind(content)}, not an object")
    contents = node.get("contents", [])
    if not isinstance(contents, list):
        problem("JSON", where, f"has contents that are {_kind(contents)}, not a list")
        contents = []
    for content in contents:
        if isinstance(content, dict):
            found.append(content.get("uri"))
        else:
            problem("JSON", where, f"has a content that is {_kind(content)}, not an object")
    return found


def _target(
    folder: Path,
    base: Path,
    uri: Any,
    where: str,
    problem: Callable[[str, str | None, str], None],
) -> Path | None:
    """The regular file inside ``folder`` that the content ``uri`` of a JSON file in ``base``
    names (resolved: no link left to follow), else a problem and ``None``."""
    if not isinstance(uri, str) or not uri:
        problem("URI", where, f"content uri {uri!r} is not a relative path")
        return None
    parts = urllib.parse.urlsplit(uri)
    if parts.scheme or parts.netloc or uri.startswith("/") or "\\" in uri:
        problem("URI", where, f"content uri {uri!r} is not a relative path")
        return None
    if parts.query or parts.fragment or "#" in uri:
        problem("URI", where, f"content uri {uri!r} is not a plain path (query or fragment)")
        return None
    relative = urllib.parse.unquote(parts.path)
    if not relative or "\0" in relative or relative.startswith("/") or "\\" in relative:
        problem("URI", where, f"content uri {uri!r} is not a relative path")
        return None
    try:
        target = (base / relative).resolve()
    except (OSError, RuntimeError) as exc:  # a link loop, a name too long
        problem("URI", where, f"content uri {uri!r} cannot be resolved ({exc})")
        return None
    if not target.is_relative_to(folder):
        problem("URI", where, f"content uri {uri!r} leads outside the tileset's folder")
        return None
    try:
        regular = stat.S_ISREG(target.stat().st_mode)
    except OSError:
        regular = False
    if not regular:
        problem("URI", where, f"content uri {uri!r} names no file in the tileset's folder")
        return None
    return target


def _above(file: _File, target: Path) -> bool:
    """Whether ``target`` is ``file`` or a file that refers to it, in turn."""
    current: _File | None = file
    while current is not None:
        if current.resolved == target:
            return True
        current = current.above
    return False


def _again(uri: Any, name: str, file: _File, target: Path, seen: dict[Path, str]) -> str:
    """Why the external tileset ``target`` (``name``), already read, is not read again."""
    if _above(file, target):
        return (
            f"content uri {uri!r} leads back to {name}, which holds this tile or a tile above it: "
            "external tilesets in a cycle"
        )
    first = seen[target]
    return f"content uri {uri!r} names {name}, an external tileset that {first} refers to already"


def _kind(value: Any) -> str:
    """``value``'s JSON type, as a phrase (``a JSON array``)."""
    if value is None:
        return "JSON null"
    names = {dict: "object", list: "array", str: "string", bool: "boolean", int: "number",
             float: "number"}  # fmt: skip
    return f"a JSON {names.get(type(value), type(value).__name__)}"
