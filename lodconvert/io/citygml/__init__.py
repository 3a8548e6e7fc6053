"""CityGML reader: CityGML 1.0, 2.0 and 3.0 (``.gml``, ``.xml``, and a ``.gz`` or ``.zip``
holding one such file), streamed one city object at a time.

Every top-level city object (a ``Building``, ``Bridge``, ``Road``, ``LandUse``, ``WaterBody``,
``PlantCover``, ``GenericCityObject``, ``ReliefFeature``… typed by its element's local name)
becomes one :class:`Node`. Each LoD the object carries (``lodNSolid``, ``lodNMultiSurface``,
``lodNGeometry``, ``lod0FootPrint``/``lod0RoofEdge``, and the same properties of its thematic
surfaces, openings and installations) is read into ``node.lods`` as ``"lod0"`` … ``"lod4"``, one
:class:`Surface` per semantic type (``RoofSurface``, ``WallSurface``, ``Window``…) coloured by
:mod:`lodconvert.semantics`; ``node.geometry`` is the highest LoD above 0 with faces (LoD 0 when
there is no other). A polygon that a solid refers to (``xlink:href``) and a thematic surface
holds is read once, with its semantics. Building (bridge, tunnel) parts are children of their
object: each keeps its own attributes and LoDs, and their geometry is part of the object's (one
surface per LoD and colour), so that a building is one object of the output however many parts
it has. Its interior (rooms,
furniture, interior installations: ``interiorRoom``, 3.0 ``buildingRoom``…) is read the same
way, as parts, in the LoD it is given at (LoD4 in 1.0 and 2.0). Terrain is read from its
``TINRelief`` components (their ``tin`` triangles, at the component's ``lod``; a ``Tin`` of
control points alone is triangulated in plan); mass points, break lines and raster reliefs
hold no surfaces. Implicit geometry (``lodNImplicitRepresentation``: a tree's or a lamp's
relative geometry, given inline or linked from an object read before) is placed by its
``ImplicitGeometry``'s matrix and reference point (:mod:`.implicit`).

Geometry stays in the file's coordinates (float64) when its CRS is projected; a geographic CRS
(latitude, longitude, height: EPSG:6697, 4326, 4979) is projected onto a transverse Mercator
centred on the data (:class:`LocalFrame`), whose PROJ definition becomes the scene's CRS.

The parse is hardened: no DTD is loaded, no entity resolved, no network used, and a document
with a DOCTYPE is refused before its content is read; every text of the document is held to
the run's :class:`~lodconvert.limits.Limits` as its bytes stream in (:mod:`.text_limit`), each
city object's nesting depth before it is walked, and what a ``.gz`` or ``.zip`` inflates to.
Nothing is walked by recursion deeper than :data:`~.geometry.MAX_PART_DEPTH` parts. Only the
root's children reach Python as the document streams; city objects are read
:data:`~.document.BATCH` at a time and their elements freed once converted, so memory follows
the batch, not the file. With workers, runs of members are read in worker processes, as one
process reads them (:mod:`.parallel`).

What a reader must check passes :mod:`..geometry_checks`: a polygon whose ring is degenerate
(fewer than three distinct points, no area) is dropped and counted with the object's dropped
faces; an object with no element in it is only counted by type (``"empty"`` of the
scene's ``citygml`` attribute); an object left with nothing, or whose coordinates cannot be
read (a word that is not a number, a ring of partial points, a coordinate that is not finite
or beyond 1e15), or whose parts nest too deep, is recorded as skipped.
"""

from __future__ import annotations

from itertools import chain
from pathlib import Path
from typing import Any

from ...errors import InputError
from ...limits import DEFAULT_LIMITS, Limits
from ...model import Scene
from ...semantics import DEFAULT_PALETTE, Palette
from .. import Format
from ..crs import Crs, LocalFrame, crs_attributes
from ..geometry_checks import InputTally, attach_tally
from .document import Document
from .names import CITYGML_NAMESPACE
from .parallel import SpreadReading

__all__ = ["CITYGML_NAMESPACE", "FORMAT", "LocalFrame", "read_citygml"]


def read_citygml(
    path: Path,
    limits: Limits = DEFAULT_LIMITS,
    types: frozenset[str] | None = None,
    colors: Palette = DEFAULT_PALETTE,
    crs: str | None = None,
    spread: bool = False,
) -> Scene:
    """Read a CityGML file (``.gml``/``.xml``, or a ``.gz``/``.zip`` of one) into a Scene whose
    nodes are streamed; raise :class:`InputError` with a one-line reason. ``crs`` (an EPSG
    name or URN) replaces whatever CRS the document declares.

    ``types``: read only top-level city objects of these types (local names: ``Building``,
    ``Road``…); None reads every type. The document is parsed up to its first city object
    before this returns (so that the scene's CRS is known); the rest as the nodes are taken.
    The scene's attributes hold the CityGML version, the vertical CRS, the local frame of a
    geographic CRS, and counts (links not resolved, degenerate polygons, features not read).
    With ``spread``, the scene's :attr:`~.model.Scene.spread` lets an executor read the rest
    of the document in workers (:mod:`.parallel`).
    """
    path = Path(path)
    source = str(path)
    if not path.exists():
        raise InputError("no such file", source)
    if path.is_dir():
        raise InputError("is a directory, not a CityGML file", source)
    if path.stat().st_size == 0:
        raise InputError("is empty", source)

    def make() -> Document:
        document = Document(path, limits, types, InputTally(source, limits), colors)
        document.crs = Crs.of(crs, source) if crs is not None else None
        return document

    reading = SpreadReading(make) if spread else None
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
    attributes.update(crs_attributes(declared))
    scene = Scene(
        source=source,
        nodes=chain([first], nodes),
        crs=declared.scene_crs,
        attributes=attributes,
        city=True,
        spread=reading.use if reading is not None else None,
    )
    return attach_tally(scene, tally)


FORMAT = Format(
    name="citygml",
    suffixes=(".gml", ".xml", ".zip"),
    read=read_citygml,
    read_options=("limits", "types", "colors", "crs", "spread"),
)
