"""CityGML reader: CityGML 1.0, 2.0 and 3.0 (``.gml``, ``.xml``, and a ``.gz`` or ``.zip``
holding one such file), streamed one city object at a time.

Every top-level city object becomes one :class:`Node` with each LoD it carries in
``node.lods`` (``"lod0"`` … ``"lod4"``, one :class:`Surface` per semantic type); its parts and
interior join its geometry, implicit geometry is placed (:mod:`.implicit`), and a geographic
CRS is projected onto a local transverse Mercator (:class:`LocalFrame`). The parse is
hardened (no DTD, entity or network; every text held to the limits as it streams,
:mod:`.text_limit`); members are read :data:`~.document.BATCH` at a time, or in worker
processes (:mod:`.parallel`), and pass :mod:`..geometry_checks`. In full:
``docs/readers.md`` (CityGML).
"""

from __future__ import annotations

from itertools import chain
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import InputError
from ...limits import DEFAULT_LIMITS, Limits
from ...model import Scene
from ...semantics import DEFAULT_PALETTE, Palette
from .. import Format
from ..crs import Crs, LocalFrame, crs_attributes
from ..geometry_checks import InputTally, attach_tally
from ..images import Images
from .appearance import MARKS, Appearances, document_appearances
from .document import Document
from .names import CITYGML_NAMESPACE
from .parallel import SpreadReading
from .ranges import RangeReading, by_ranges, marks_by_workers

if TYPE_CHECKING:
    from ...context import RunContext

__all__ = ["CITYGML_NAMESPACE", "FORMAT", "LocalFrame", "read_citygml"]


def read_citygml(
    path: Path,
    limits: Limits = DEFAULT_LIMITS,
    types: frozenset[str] | None = None,
    colors: Palette = DEFAULT_PALETTE,
    crs: str | None = None,
    context: RunContext | None = None,
    appearance_theme: str | None = None,
) -> Scene:
    """Read a CityGML file (``.gml``/``.xml``, or a ``.gz``/``.zip`` of one) into a Scene whose
    nodes are streamed; raise :class:`InputError` with a one-line reason. ``crs`` (an EPSG
    name or URN) replaces whatever CRS the document declares.

    ``types``: read only top-level city objects of these types (local names: ``Building``,
    ``Road``…); None reads every type. The document is parsed up to its first city object
    before this returns (so that the scene's CRS is known); the rest as the nodes are taken.
    The scene's attributes hold the CityGML version, the vertical CRS, the local frame of a
    geographic CRS, and counts (links not resolved, degenerate polygons, features not read).
    With ``context``, the rest of the document is read by the workers of its executor
    (:mod:`.parallel`). Appearances are read in the theme ``appearance_theme`` (else the
    first met; :mod:`.appearance`), their images through the scene's ``appearance``
    attribute (:class:`~..images.Images`).
    """
    path = Path(path)
    source = str(path)
    if not path.exists():
        raise InputError("no such file", source)
    if path.is_dir():
        raise InputError("is a directory, not a CityGML file", source)
    if path.stat().st_size == 0:
        raise InputError("is empty", source)

    marks = None  # with workers, they look for appearances in a plain file
    if context is not None and by_ranges(path):
        marks = marks_by_workers(path, context.executor.results, MARKS)
    appearances = document_appearances(path, limits, appearance_theme, marks)
    images: Images | None = None

    def make() -> Document:
        nonlocal images
        document = Document(path, limits, types, InputTally(source, limits), colors)
        document.crs = Crs.of(crs, source) if crs is not None else None
        if appearances is not None:
            images = Images(path, limits, document.tally.warn)
            document.appearances, document.images = appearances, images
        return document

    reading = None
    if context is not None:
        reading = (RangeReading if by_ranges(path) else SpreadReading)(make)
        reading.use(context.executor.results, context.progress, context.executor.task_seconds)
    document = reading.document if reading is not None else make()
    tally = document.tally
    nodes = reading.nodes() if reading is not None else document.nodes()
    first = next(nodes, None)
    if first is None and tally.skipped_count == 1:
        raise InputError(tally.skipped[0]["reason"], source)
    if first is None and tally.skipped:
        reason = tally.skipped[0]["reason"]
        raise InputError(f"none of its {tally.skipped_count:,} objects is left ({reason}…)", source)
    if first is None:
        wanted = f" of type {', '.join(sorted(types))}" if types else ""
        raise InputError(f"has no city objects{wanted} with surface geometry", source)
    declared = document.crs or Crs()
    attributes: dict[str, Any] = {"citygml_version": document.version, "citygml": document.stats}
    if appearances is not None and images is not None:
        attributes["appearance"] = _told(appearances, images, tally)
    attributes.update(crs_attributes(declared))
    scene = Scene(
        source=source,
        nodes=chain([first], nodes),
        crs=declared.scene_crs,
        attributes=attributes,
        city=True,
    )
    return attach_tally(scene, tally)


def _told(appearances: Appearances, images: Images, tally: InputTally) -> Images:
    """``images``, knowing the themes of ``appearances``; what was wrong with the
    appearances, and a theme asked for that the document lacks, warned of."""
    images.theme = appearances.theme
    images.themes = appearances.themes  # the same list: the themes met later join it
    for problem in dict.fromkeys(appearances.problems):
        tally.warn(f"{tally.source}: {problem} (not read)")
    wanted = appearances.wanted
    if wanted is not None and appearances.themes and wanted not in appearances.themes:
        known = ", ".join(repr(theme) for theme in appearances.themes)
        tally.warn(f"{tally.source}: has no appearance theme {wanted!r} (it has {known})")
    return images


FORMAT = Format(
    name="citygml",
    suffixes=(".gml", ".xml", ".zip"),
    read=read_citygml,
    read_options=("limits", "types", "colors", "crs", "appearance_theme"),
    reads_on_workers=True,
)
