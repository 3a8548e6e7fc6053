"""OGC 3D Tiles 1.1: a folder holding ``tileset.json`` and ``tiles/`` (one GLB per tile, and
external tilesets where one JSON would grow too large), written from LOD parents
(:mod:`.writer`) and checked by our own rules (:mod:`.check`).

An output path named ``tileset.json`` selects the format; its folder is the output, staged and
replaced as a whole. A folder that exists must be empty or hold a tileset lodconvert wrote (its
``asset.generator``) and nothing else but its viewer page, so that a run never deletes files it
did not write.
"""

from __future__ import annotations

import json
from pathlib import Path

from ...errors import InputError, UsageError
from .. import Format
from .check import check_tileset
from .writer import DEFAULT_SSE, TILES, write_tileset

NAME = "tileset.json"
GENERATOR = "lodconvert"
"""What ``asset.generator`` of our tilesets starts with."""
PAGE = f"{NAME}.html"
"""The viewer page that ``--html`` and ``lodconvert view`` write inside the folder."""


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
    if folder.is_dir():
        entries = sorted(entry.name for entry in folder.iterdir())
        if entries and (not _ours(folder / NAME) or set(entries) - {NAME, TILES, PAGE}):
            shown = ", ".join(entries[:3]) + (", …" if len(entries) > 3 else "")
            raise InputError(
                f"folder {str(folder)!r} holds files that are not a tileset lodconvert wrote "
                f"({shown}); a tileset replaces its whole folder: name a new or empty one",
                str(path),
            )
    return folder


def _ours(path: Path) -> bool:
    """Whether ``path`` is a tileset JSON lodconvert wrote."""
    try:
        with path.open("rb") as handle:
            asset = json.loads(handle.read(1 << 26)).get("asset", {})
    except (OSError, ValueError, AttributeError):
        return False
    return isinstance(asset, dict) and str(asset.get("generator", "")).startswith(GENERATOR)


FORMAT = Format(
    name="3d-tiles",
    suffixes=(".json",),
    write=write_tileset,
    check=check_tileset,
    write_options=("sse", "executor", "progress"),
    output_folder=output_folder,
    georeferenced=True,
)

__all__ = ["DEFAULT_SSE", "FORMAT", "NAME", "output_folder", "write_tileset"]
