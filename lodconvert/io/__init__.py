"""File formats: one module (or package) per format, each declaring one :class:`Format` entry.

An entry says everything the rest of lodconvert may know of a format: its suffixes, and
whichever of ``read`` (an input), ``write`` (an output, streamed into a sink), ``read_back``,
``read_cells`` and ``read_frame`` (our own files), ``check`` (what ``validate`` and every
conversion run), ``output_folder`` (a format written as a folder), ``georeferenced`` and
``formatter`` (a chain's piece of the output, made in the workers) it offers, with the
``read_options`` and ``write_options`` it takes. No other module parses our files or looks at
suffixes. Each field in full: ``docs/format-registry.md``.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import InputError, UsageError
from ..limits import DEFAULT_LIMITS, Limits
from ..model import CellChain, LodChain, Scene
from ..ranges import REFERENCE_VIEW, ReferenceView
from .archive import member_name

if TYPE_CHECKING:
    from ..context import RunContext

FORMAT_MODULES = (
    "lodconvert.io.cityjson",
    "lodconvert.io.mesh",
    "lodconvert.io.x3d",
    "lodconvert.io.gltf",
    "lodconvert.io.citygml",
    "lodconvert.io.tiles",
)
"""Modules that declare a ``FORMAT`` (or ``FORMATS``), in lookup order."""


@dataclass(frozen=True)
class CheckOptions:
    """What a format's ``check`` may use: an X3D schema to validate against too (a file, or a
    folder holding ``x3d-4.0.xsd``), the limits of what it reads, and whether it reads a
    tileset's contents (a conversion's tiles are checked by the tasks that make them)."""

    x3d_schema: str | Path | None = None
    limits: Limits = DEFAULT_LIMITS
    contents: bool = True


@dataclass
class OutputInfo:
    """Scene-wide facts a writer records: who wrote it, from what, in which CRS and vertical
    reference (a city's; None for a mesh's), for which reference view, with which options."""

    generator: str
    source: str
    crs: str | None = None
    vertical: str | None = None
    view: ReferenceView = REFERENCE_VIEW
    options: dict[str, Any] = field(default_factory=dict)
    city: bool = False
    """Whether the scene is a city model's (z-up, with or without a CRS)."""
    georef: Any = None
    """Where the scene's coordinates lie (:class:`~lodconvert.reproject.Georef`; ``None``
    without a CRS, or with one pyproj does not know), for outputs placed on the globe."""
    origin: Any = None
    """Where the input's first object lies (its bounding-box centre, a (3,) array, scene
    coordinates): the scene frame's origin before rounding (:func:`~.frame.scene_frame`). The
    pipeline sets it as that object is read, before any chain reaches the writer; ``None``: the
    first chain's origin."""

    @property
    def framed(self) -> bool:
        """Whether the scene is written in its scene frame (:mod:`lodconvert.io.frame`): a city
        model's or one with a CRS; a plain mesh keeps its axes."""
        return self.crs is not None or self.city


@dataclass(frozen=True)
class Format:
    """One format's registry entry (``docs/format-registry.md``)."""

    name: str
    suffixes: tuple[str, ...]
    read: Callable[..., Scene] | None = None
    write: Callable[..., None] | None = None
    read_back: Callable[..., list[LodChain]] | None = None
    read_cells: Callable[..., list[dict[str, Any]]] | None = None
    read_frame: Callable[..., Any] | None = None
    check: Callable[..., None] | None = None
    output_folder: Callable[[Path], Path] | None = None
    georeferenced: bool = False
    reads_on_workers: bool = False
    checked_as_streamed: bool = False
    takes_packed: bool = False
    viewer: str | None = None
    formatter: Callable[..., Callable[[LodChain], Any]] | None = None
    cell_formatter: Callable[..., Callable[[CellChain], Any]] | None = None
    read_options: tuple[str, ...] = ()
    write_options: tuple[str, ...] = ()

    @property
    def lod_parents(self) -> bool:
        """Whether its outputs always have LOD parents: a format written as a folder (3D
        Tiles, whose tile tree is the LoD hierarchy)."""
        return self.output_folder is not None

    def read_file(
        self, path: str | Path, context: RunContext | None = None, **options: Any
    ) -> Scene:
        """``read`` with the options this format takes; a format that reads on workers
        (``reads_on_workers``) reads on the executor of ``context``, where one is given."""
        assert self.read is not None
        taken = _taken(options, self.read_options)
        if self.reads_on_workers and context is not None:
            return self.read(Path(path), context=context, **taken)
        return self.read(Path(path), **taken)

    def write_chains(
        self,
        chains: Iterable[LodChain],
        sink: Any,
        info: OutputInfo,
        context: RunContext | None = None,
        pieces: Pieces | None = None,
        **options: Any,
    ) -> None:
        """``write`` with the run's ``context`` (its executor, where the format has tasks of
        its own: ``None`` runs them here), the ``pieces`` workers made and the options this
        format takes."""
        assert self.write is not None
        self.write(chains, sink, info, context, pieces, **_taken(options, self.write_options))

    def pieces(
        self, info: OutputInfo, options: dict[str, Any], suffix: str | None = None
    ) -> Pieces | None:
        """Where the pieces its ``formatter`` (for an output with ``suffix``, by default its
        first, and the write options this format takes) and its ``cell_formatter`` make are
        kept for ``write``; ``None`` for a format without either."""
        if self.formatter is None and self.cell_formatter is None:
            return None
        taken = _taken(options, self.write_options)
        chains = cells = None
        if self.formatter is not None:
            chains = self.formatter(info, suffix or self.suffixes[0], **taken)
        if self.cell_formatter is not None:
            cells = self.cell_formatter(info, **taken)
        return Pieces(chains, cells)


class Pieces:
    """Chains' pieces of the output made by workers with ``formatter`` (a format's), and
    coarsest cells' made with ``cells`` where they are baked, each kept with its chain until
    the writer takes it: a piece is only ever given for the very chain it was made of."""

    def __init__(
        self,
        formatter: Callable[[LodChain], Any] | None = None,
        cells: Callable[[CellChain], Any] | None = None,
    ) -> None:
        self.formatter, self.cells = formatter, cells
        self._held: dict[int, tuple[LodChain | CellChain, Any]] = {}

    def add(self, chain: LodChain | CellChain, piece: Any) -> None:
        """Keep ``piece`` (made of ``chain``) until :meth:`take`."""
        self._held[id(chain)] = (chain, piece)

    def take(self, chain: LodChain | CellChain) -> Any:
        """The piece made of ``chain`` (forgotten here), or ``None``."""
        held = self._held.get(id(chain))
        if held is None or held[0] is not chain:
            return None
        del self._held[id(chain)]
        return held[1]


StreamWriter = Callable[..., None]
"""``writer(chains, handle, info, **options)``: chains into a binary stream."""


def streamed(writers: dict[str, StreamWriter]) -> Callable[..., None]:
    """A ``write`` for formats written as one stream: the writer for the sink's suffix, into
    the sink's file, with the format's write options."""

    def write(
        chains: Iterable[LodChain],
        sink: Any,
        info: OutputInfo,
        context: RunContext | None,
        pieces: Pieces | None,
        **options: Any,
    ) -> None:
        with sink.open() as handle:
            writers[sink.path.suffix.lower()](chains, handle, info, pieces=pieces, **options)

    return write


def _taken(options: dict[str, Any], names: tuple[str, ...]) -> dict[str, Any]:
    return {k: v for k, v in options.items() if k in names and v is not None}


def formats() -> list[Format]:
    """Every registered format, in lookup order."""
    found: list[Format] = []
    for name in FORMAT_MODULES:
        module = importlib.import_module(name)
        found.extend(getattr(module, "FORMATS", None) or [module.FORMAT])
    return found


def suffix_of(path: str | Path) -> str:
    """Lower-case format suffix, looking through a trailing ``.gz`` (``a.PLY.gz`` → ``.ply``)."""
    suffixes = [s.lower() for s in Path(path).suffixes]
    if suffixes and suffixes[-1] == ".gz":
        suffixes = suffixes[:-1]
    return suffixes[-1] if suffixes else ""


def _find(role: str, suffix: str) -> Format | None:
    """The first format that offers ``role`` (read, write, read_back, check) for ``suffix``."""
    for entry in formats():
        if suffix in entry.suffixes and getattr(entry, role) is not None:
            return entry
    return None


def _known(role: str) -> str:
    return ", ".join(sorted({s for f in formats() if getattr(f, role) for s in f.suffixes}))


def input_format(path: str | Path) -> Format:
    """The format that reads ``path`` — for a ``.zip``, the format of the one city model file
    it holds (:mod:`.archive`) — or :class:`InputError` naming the known suffixes."""
    suffix = suffix_of(path)
    if suffix == ".zip" and Path(path).is_file():
        suffix = suffix_of(member_name(Path(path)))
    entry = _find("read", suffix)
    if entry is None:
        raise InputError(
            f"unknown input format {suffix or '(no suffix)'!r}; known: {_known('read')}",
            str(path),
        )
    return entry


def output_format(path: str | Path) -> Format:
    """The format that writes ``path``, or :class:`UsageError` naming the known suffixes."""
    suffix = Path(path).suffix.lower()
    entry = _find("write", suffix)
    if entry is None:
        raise UsageError(
            f"{path}: unknown output format {suffix or '(no suffix)'!r}; known: {_known('write')}"
        )
    return entry


def own_format(path: str | Path, role: str = "read_back") -> Format:
    """The format that reads back (``role='read_back'``) or checks (``'check'``) files
    lodconvert wrote, like ``path``; :class:`InputError` for other suffixes."""
    suffix = Path(path).suffix.lower()
    entry = _find(role, suffix)
    if entry is None:
        raise InputError(
            f"is not a file lodconvert writes ({_known(role)})",
            str(path),
        )
    return entry


def read_scene(path: str | Path, **options: Any) -> Scene:
    """Read any supported input (the registry picks the reader by suffix, a ``.zip``'s by
    the file it holds)."""
    return input_format(path).read_file(path, **options)


def read_chains(path: str | Path, geometry: bool = True) -> list[LodChain]:
    """The chains of a file lodconvert wrote, read back by its format (without level geometry
    when ``geometry`` is false)."""
    entry = own_format(path)
    assert entry.read_back is not None
    return entry.read_back(Path(path), geometry=geometry)
