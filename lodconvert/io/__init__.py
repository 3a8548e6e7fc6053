"""File formats: one module per format, and a registry mapping suffixes to readers/writers.

A reader takes a path and returns a :class:`~lodconvert.scene.Scene`. A writer takes an
iterable of :class:`~lodconvert.scene.LodChain` (consumed once, so chains can be baked and
written one at a time), an open binary file and an :class:`OutputInfo`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from ..errors import InputError
from ..model import LodChain, Scene
from ..ranges import REFERENCE_VIEW, ReferenceView


@dataclass
class OutputInfo:
    """Scene-wide facts a writer records: who wrote it, from what, in which CRS, for which
    reference view, with which options."""

    generator: str
    source: str
    crs: str | None = None
    view: ReferenceView = REFERENCE_VIEW
    options: dict[str, Any] = field(default_factory=dict)


Reader = Callable[[Path], Scene]
Writer = Callable[[Iterable[LodChain], BinaryIO, OutputInfo], None]

READERS: dict[str, Reader] = {}
WRITERS: dict[str, Writer] = {}


def suffix_of(path: str | Path) -> str:
    """Lower-case format suffix, looking through a trailing ``.gz`` (``a.PLY.gz`` → ``.ply``)."""
    suffixes = [s.lower() for s in Path(path).suffixes]
    if suffixes and suffixes[-1] == ".gz":
        suffixes = suffixes[:-1]
    return suffixes[-1] if suffixes else ""


def reader_for(path: str | Path) -> Reader:
    """The reader registered for ``path``'s suffix, or :class:`InputError`."""
    _load_formats()
    suffix = suffix_of(path)
    if suffix not in READERS:
        known = ", ".join(sorted(READERS))
        raise InputError(
            f"unknown input format {suffix or '(no suffix)'!r}; known: {known}", str(path)
        )
    return READERS[suffix]


def writer_for(path: str | Path) -> Writer:
    """The writer registered for ``path``'s suffix, or :class:`InputError`."""
    _load_formats()
    suffix = Path(path).suffix.lower()
    if suffix not in WRITERS:
        known = ", ".join(sorted(WRITERS))
        raise InputError(
            f"unknown output format {suffix or '(no suffix)'!r}; known: {known}", str(path)
        )
    return WRITERS[suffix]


def _load_formats() -> None:
    """Import the format modules, which register themselves."""
    from . import gltf, mesh, x3d  # noqa: F401
