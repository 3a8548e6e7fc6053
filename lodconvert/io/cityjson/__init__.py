"""CityJSON reader: CityJSON 1.1 and 2.0 (``.json``, ``.city.json``) and CityJSONSeq
(``.city.jsonl``), each also gzip-compressed (``.gz``) or the one city model file of a ``.zip``
(:mod:`..archive`; what it inflates to is capped at ``decompressed_bytes``, as CityGML's).
CityJSON 1.0 is read the same way (its numeric ``lod`` values become labels: ``2`` → ``"2"``);
other versions are refused.

Every CityObject with geometry or with children becomes a :class:`Node`: ``id`` is its key (the
writers make it a valid X3D DEF; the raw key is kept in ``attributes["id"]``), ``type`` its
CityObject type, ``attributes`` its own ``attributes`` plus ``id`` and ``type`` (which win over
source attributes of those names). Children (``children``/``parents``: BuildingParts,
Installations…) are the ``children`` of their parent's node. The LoDs of a 1st-level object's
parts (children of the 2nd-level types, :data:`~.objects.PART_TYPES`, not placed as geometry
instances) are merged into its own, as a CityGML building's are: the object is one node with
geometry, its parts children without geometry that keep their attributes and LoDs (a 3D BAG
``Building`` with its LoD0 and its ``BuildingPart``'s LoD 1.2–2.2 is one object). Other children
with geometry stay nodes with geometry of their own. ``types`` keeps only objects of those
types and the descendants of kept ones (a kept descendant of a dropped object becomes a root).

Geometry: Solid, MultiSolid, CompositeSolid, MultiSurface and CompositeSurface (points and
lines are ignored). Polygons with holes are triangulated :data:`~.document.BATCH` objects at a
time, in one :func:`lodconvert.polygons.triangulate_many` call that ear-clips each as
:func:`~lodconvert.polygons.triangulate` would (a lone ring of three indices is kept as it is).
Every LoD of an object is one :class:`Mesh` in ``node.lods`` under the ``lod`` string
(``"1.2"``); ``node.geometry`` is the highest of them (in numeric order of the label). A mesh
has one part per semantic class — roof, wall, ground, other (:mod:`lodconvert.semantics`) — and
material: the ``diffuseColor`` (and ``transparency``) of ``appearance.materials`` in the first
theme each geometry lists wins over the class colour. CityJSON materials follow X3D's, whose
colours are taken as sRGB as X3D browsers draw them, so they become the part's sRGB base colour
unchanged. Surfaces of no semantic class take their object type's colour where
:data:`lodconvert.semantics.TYPE_COLORS` has one. Textures are not read.

Vertices: the integer ``vertices`` are scaled and translated by ``transform`` into float64
coordinates of the file's CRS, kept as they are (no origin is taken off: the pipeline stores
each chain relative to its own float64 centre). A file without ``transform`` (which CityJSON
1.1 and 2.0 require) has its vertices taken as given, integers or not. Geometry templates are
read once per template into one :class:`Mesh` that every ``GeometryInstance`` node shares, in
the template's frame, with the instance's ``transform``: its ``transformationMatrix`` (4×4, row
by row) moved to its reference point. An object with several instances, or instances beside
geometry of its own, gets one child node per instance (``<id>-instance<k>``).

Checks (:mod:`..geometry_checks`): degenerate polygons (those
:func:`~lodconvert.polygons.triangulate` refuses) and triangles without area are dropped and
counted; an object with a boundary index out of range or not a whole number, a malformed
boundary, a vertex that is unreadable or not finite (:mod:`.vertices`) or an extent the outputs
cannot hold is reported (one line naming file and object) in the tally's ``skipped`` and left
out, the rest of its batch converts; so is an object whose JSON is not of the shape CityJSON
gives it, and one nested more than :data:`~.objects.MAX_DEPTH` levels deep in
``children``/``parents`` (with the objects below it). Objects in a cycle of ``children`` and
``parents`` hang below the first of them in file order.

CRS: ``metadata.referenceSystem`` in its URL or URN form becomes ``EPSG:<code>`` on the scene
and every node; none declared leaves it ``None``. A projected CRS stays as it is. A geographic
one (EPSG:4326, 4979, 6697…: vertices in the CRS's axis order, latitude and longitude in
degrees) is projected with ``pyproj``, as CityGML's is (:mod:`lodconvert.io.crs`), onto a
transverse Mercator centred on the document's vertices (a CityJSONSeq file's: on its first
feature's), whose PROJ definition becomes the scene's and every node's CRS and whose definition
the scene's ``local_frame`` attribute keeps; template vertices are taken as metres from their
reference points. CityJSONSeq is read line by line (:mod:`.sequence`: in chunks, blank lines
skipped, a ``.gz`` stopped at ``decompressed_bytes``, a line longer than
``sequence_line_bytes`` passed over as it streams):
the header line (``transform``, ``metadata``, ``geometry-templates``) first, then one
``CityJSONFeature`` per line; features are read until they hold :data:`~.document.BATCH`
objects (or that many lines, or ``sequence_line_bytes`` of text), then triangulated together
and their nodes yielded, so memory holds one batch of features at a time; a line that is not a
feature, or is too long, is reported and skipped.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from ...errors import InputError
from ...limits import DEFAULT_LIMITS, Limits
from ...model import Scene
from ...semantics import DEFAULT_PALETTE, Palette
from .. import Format
from ..archive import member_name
from .document import read_document, read_sequence

__all__ = ["FORMAT", "read_cityjson"]


def _types(types: Iterable[str] | None) -> frozenset[str] | None:
    return frozenset(types) if types is not None else None


def read_cityjson(
    path: Path,
    limits: Limits = DEFAULT_LIMITS,
    types: Iterable[str] | None = None,
    colors: Palette = DEFAULT_PALETTE,
    crs: str | None = None,
    spread: bool = False,
) -> Scene:
    """Read a CityJSON (``.json``) or CityJSONSeq (``.jsonl``) file, plain, ``.gz`` or in a
    ``.zip``, into a Scene (see the module docstring); :class:`InputError` with a one-line
    reason when it cannot be. ``types``: keep only CityObjects of these types (and their
    descendants); ``colors``: the semantic classes' colours (:mod:`lodconvert.semantics`);
    ``crs`` replaces the CRS the file declares; with ``spread``, the objects can be read by
    workers (:attr:`~.model.Scene.spread`).
    The scene carries an :class:`~..geometry_checks.InputTally` of dropped faces and skipped
    objects."""
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file" if not path.exists() else "is not a file", str(path))
    if path.stat().st_size == 0:
        raise InputError("is empty", str(path))
    name = (member_name(path) if path.name.lower().endswith(".zip") else path.name).lower()
    name = name.removesuffix(".gz")
    if name.endswith(".jsonl"):
        return read_sequence(path, limits, _types(types), colors, crs, spread)
    return read_document(path, limits, _types(types), colors, crs, spread)


FORMAT = Format(
    name="cityjson",
    suffixes=(".json", ".jsonl", ".zip"),
    read=read_cityjson,
    read_options=("limits", "types", "colors", "crs", "spread"),
)
