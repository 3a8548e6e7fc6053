"""OGC 3D Tiles 1.1: a folder holding ``tileset.json`` and ``tiles/`` (one GLB per tile, and
external tilesets where one JSON would grow too large), written from LOD parents
(:mod:`.writer`) and checked by our own rules (:mod:`.check`).

An output path named ``tileset.json`` selects the format; its folder is the output, staged and
replaced as a whole. A folder that exists must be empty or hold a tileset lodconvert wrote, every
file as its manifest lists (:mod:`lodconvert.manifest`), so that a run never deletes files it did
not write.
"""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path

from ... import manifest, nofollow
from ...errors import InputError, UsageError
from .. import Format
from .check import check_tileset
from .writer import DEFAULT_SSE, cell_tiles, write_tileset

NAME = "tileset.json"
GENERATOR = "lodconvert"
"""What ``asset.generator`` of our tilesets starts with (then a space and the version)."""


def output_folder(path: Path) -> Path:
    """The folder the tileset ``path`` is written as: :class:`UsageError` for a ``.json`` name
    other than :data:`NAME`, :class:`InputError` for a folder that is not ours to replace."""
    if path.name != NAME:
        raise UsageError(
            f"{path}: a .json output is a 3D Tiles tileset and must be named {NAME} "
            f"(e.g. {path.parent / path.stem / NAME})"
        )
    folder = path.parent
    if folder.resolve() == Path.cwd().resolve():
        raise UsageError(
            f"{path}: a tileset replaces its whole folder, and this one is the current folder; "
            f"name a folder of its own (e.g. -o tiles/{NAME})"
        )
    if folder.is_dir() and any(folder.iterdir()):
        refusal = _not_ours(folder)
        if refusal is not None:
            raise InputError(f"folder {str(folder)!r} {refusal}", str(path))
    return folder


def written_by_lodconvert(generator: object) -> bool:
    """Whether ``generator`` (a tileset's ``asset.generator``) names lodconvert."""
    return isinstance(generator, str) and re.fullmatch(rf"{GENERATOR}( .*)?", generator) is not None


def _not_ours(folder: Path) -> str | None:
    """Why the folder ``folder`` is not a tileset lodconvert wrote, intact, to be replaced
    (``None``: it is): every file in it must be as its manifest lists."""
    try:
        fd = nofollow.open_folder(folder)
    except OSError as exc:
        return f"cannot be read ({os.strerror(exc.errno or errno.EIO)})"
    try:
        listed = manifest.read(fd)
        head = nofollow.read(fd, NAME, 1 << 16) or b""
    finally:
        os.close(fd)
    ours = re.search(rb'"generator":\s*"lodconvert[ "]', head) is not None
    if listed is None:
        entries = sorted(entry.name for entry in folder.iterdir())
        shown = ", ".join(entries[:3]) + (", …" if len(entries) > 3 else "")
        if ours:
            return (
                f"holds a tileset lodconvert wrote, but not the list of its files "
                f"({manifest.NAME}) that shows nothing else was added; a tileset replaces its "
                "whole folder: remove that folder yourself or name a new one"
            )
        return (
            f"holds files that are not a tileset lodconvert wrote ({shown}); a tileset "
            "replaces its whole folder: name a new or empty one"
        )
    strays = manifest.strays(folder, listed)
    if not strays:
        return None
    relative, why = strays[0]
    more = f" (and {len(strays) - 1} more)" if len(strays) > 1 else ""
    if why.startswith("changed"):
        return (
            f"holds a tileset lodconvert wrote whose {relative} has changed since (damaged or "
            f"edited){more}; remove that folder yourself (or move it) to write a new tileset "
            "there, or name a new one"
        )
    return (
        f"holds a tileset lodconvert wrote and {relative!r}, {why}{more}; a tileset replaces "
        "its whole folder: move that file away or name a new folder"
    )


FORMAT = Format(
    name="3d-tiles",
    suffixes=(".json",),
    write=write_tileset,
    cell_formatter=cell_tiles,
    check=check_tileset,
    write_options=("sse", "atlas_size", "compress", "texture_format"),
    output_folder=output_folder,
    viewer="tiles",
    georeferenced=True,
    takes_packed=True,
)

__all__ = [
    "DEFAULT_SSE",
    "FORMAT",
    "NAME",
    "output_folder",
    "write_tileset",
    "written_by_lodconvert",
]
