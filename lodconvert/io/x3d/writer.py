"""X3D 4.0 XML output: one ``Transform`` + ``LOD`` per chain (or, with prism switching, the
``LOD`` as the list of levels and nested ``Switch`` es on ProximitySensor boxes showing them).

Layout of a written file (validates against the official x3d-4.0.xsd)::

    <X3D profile='Interchange' version='4.0' ...>
      <head> components Navigation 2, Rendering 4, Shape 5; meta generator, source, crs,
              vertical-reference, ...
      <Scene>
        <Transform DEF='scene_frame' rotation='1 0 0 -1.5707963267948966'>   (a city or a CRS)
          <MetadataSet name='lodconvert_frame' containerField='metadata'> origin, rotation, ...
        <Transform DEF='id' translation='origin (full float64 precision)'>
          <LOD DEF='id_LOD' center=... range='cutoffs' forceTransitions='true'>
            <MetadataSet name='lodconvert' containerField='metadata'> alpha, β, γ, xs, ...
            <Group DEF='id_LOD4'>   (the source mesh)
              <MetadataSet name='lodconvert' containerField='metadata'> level parameters
              <Shape> <Appearance DEF='id_LOD4_Appearance'> Material (+ ImageTexture)
                      + IndexedTriangleSet: Coordinate (+ Color) (+ TextureCoordinate)
              <Shape> <Appearance USE='id_LOD4_Appearance'/> + IndexedTriangleSet ...
            <Group DEF='id_LOD3'>   (baked points)
              <MetadataSet ...> + Shapes with PointProperties + PointSet ...
            <Group/>   (only for a culled chain: nothing is drawn beyond the last range)
        </Transform>   (scene_frame: it holds every object)
        <NavigationInfo type='"EXAMINE" "ANY"'/>
        <Viewpoint DEF='lodconvert_view' ...>   (the whole scene, seen obliquely)

A city model's scene or one with a CRS is written in its scene frame (:mod:`lodconvert.io.frame`):
one ``Transform`` turns its z-up coordinates into X3D's y-up, and the objects' translations
are offsets from the scene origin its ``MetadataSet`` records (float64, with the rotation).
The ``Viewpoint`` comes last, once every object is written (:mod:`.viewpoint`).

Each level is a ``Group`` of one or more ``Shape`` s so that no attribute value comes near
libxml2's 10 MB limit on a text node (``XML_MAX_TEXT_LENGTH``), which default XML parsers and
schema validators enforce: a ``Shape`` holds at most :data:`MAX_SHAPE_VERTICES` vertices or
points and :data:`MAX_SHAPE_TRIANGLES` triangles. A mesh is split into runs of consecutive
faces, each with only the vertices it uses (re-indexed, in their original order); a point
level into consecutive slices. The level's ``Appearance`` is defined once and re-used.

A textured mesh part keeps its texture, as in glTF: an ``ImageTexture`` whose ``url`` is the image
as a PNG ``data:`` URI (see :func:`texture_url`) and a ``TextureCoordinate`` per vertex. X3D 4.0
multiplies the texture by the Material's ``diffuseColor`` (or by the ``Color`` node where the part
also has vertex colours), so the base colour modulates it as glTF's ``baseColorFactor`` does.

Geometry inside the ``Transform`` is relative to the chain origin and printed with float32-level
precision (:data:`~lodconvert.io.numbers.GEOMETRY_DIGITS` significant digits on the level's
largest coordinate, the same decimals in all its Shapes, so a vertex shared by two Shapes is
written identically in both); the origin itself keeps every digit, so georeferenced data in the
millions keeps its position. X3D LOD needs ``n + 1`` children for ``n`` ranges: without culling
the chain has one cutoff fewer than levels; with culling the last cutoff is where the empty
``Group`` takes over.

Point sizes follow the X3D 4.0 ``PointProperties`` node, whose attenuation factor is
``1 / (a + b·r + c·r²)`` with ``r`` the distance from the viewer to each point; the nominal size
(``pointSizeScaleFactor`` × the browser's minimum point size, 1 px) is multiplied by it and
clipped to ``[pointSizeMinValue, pointSizeMaxValue]`` × the minimum point size. With
``a = c = 0`` and ``b = s / (p·d)`` a point is ``p·d / r`` pixels wide: ``p`` (the level's
``params.point_size``) at its design distance ``d``, shrinking with 1/r like a surface splat.
The scale factor ``s = max(1, p)`` keeps the XSD's ``pointSizeScaleFactor >= 1``.

Prism switching (``switching='prism'``, the box regions of the ProxyPrismLOD paper) switches an
object's levels on boxes instead of spheres around its centre, without a ``Script``. The ``LOD``
stays, unchanged, as the list of the object's levels that readers find, but inside a ``Switch``
that draws nothing; nested ``Switch`` es draw the levels by ``USE``::

    <Transform DEF='id' translation=...>
      <MetadataSet name='lodconvert' containerField='metadata'> (as above)
      <Switch DEF='id_levels' whichChoice='-1'>           never drawn
        <LOD DEF='id_LOD' ...> the level Groups, as above
      <Switch DEF='id_Switch0' whichChoice='1'>
        <Group USE='id_LOD4'/>                            inside box 0
        <Switch DEF='id_Switch1' whichChoice='1'>
          <Group USE='id_LOD3'/>                          inside box 1, outside box 0
          <Switch DEF='id_Switch2' whichChoice='1'>
            <Group USE='id_LOD2'/>                        inside box 2, outside box 1
            <Group USE='id_LOD1'/>                        outside box 2 (culled: an empty Group)
      <ProximitySensor DEF='id_Prism0' center='box centre' size='box size + 2 cutoffs[0]'/>
      <BooleanFilter DEF='id_Filter0'/>
      <IntegerTrigger DEF='id_Inside0' integerKey='0'/>
      <IntegerTrigger DEF='id_Outside0' integerKey='1'/>
      <ROUTE> id_Prism0.isActive → id_Filter0.set_boolean; id_Filter0.inputTrue →
              id_Inside0.set_boolean; id_Filter0.inputFalse → id_Outside0.set_boolean;
              id_Inside0.triggerValue and id_Outside0.triggerValue → id_Switch0.set_whichChoice
      … the same for boxes 1 and 2

Box ``k`` is the finest level's axis-aligned bounding box in the object's frame, grown by
``cutoffs[k]`` on every side, so each box holds the one before. Each ``Switch`` has a sensor of
its own: one flat Switch fed by overlapping sensors would get conflicting events. The
``BooleanFilter`` splits ``isActive`` in two, as an ``IntegerTrigger`` fires on any
``set_boolean``, false included. Every ``Switch`` starts at its far choice, so a viewer that
starts outside every box sees the coarsest level (nothing, culled) before any event; a viewer
inside boxes at load gets their ``isActive TRUE`` with the first frame (a browser without
ProximitySensor keeps the coarsest level). An instance of shared
geometry has sensors and Switches of its own (a ``USE`` d sensor would sense the union of its
boxes) and ``USE`` s the first instance's ``LOD`` and level Groups. The head records the mode
(``meta name='switching'``); the profile is Interactive (:data:`PROFILES`).
"""

from __future__ import annotations

import base64
import contextlib
import io
import itertools
import json
import math
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import astuple, dataclass, field, replace
from typing import BinaryIO

import numpy as np

from ...errors import UsageError
from ...model import CellChain, Level, LodChain, Mesh, Surface
from ...model.safe_text import NOT_XML_CHARS, xml_text
from .. import OutputInfo, Pieces
from ..frame import ROTATION, SceneFrame, scene_frame
from ..numbers import format_exact, format_fixed, format_ints, format_unit_bytes, geometry_decimals
from .viewpoint import NAVIGATION, SceneBox

XSI = "http://www.w3.org/2001/XMLSchema-instance"
SCHEMA_URL = "https://www.web3d.org/specifications/x3d-4.0.xsd"
COMPONENTS = (("Navigation", 2), ("Rendering", 4), ("Shape", 5))
"""Beyond the Interchange profile: LOD needs Navigation 2, ColorRGBA alpha is guaranteed from
Rendering 4, PointProperties needs Shape 5."""

MAX_POINT_GROWTH = 4.0
"""Cap on how much larger than ``params.point_size`` a point may grow when the viewer comes
closer than the design distance (a baked finest level shows from distance 0)."""

MAX_SHAPE_VERTICES = 100_000
"""Most vertices (mesh) or points (point level) in one ``Shape``. With 7 significant digits a
coordinate takes at most 12 characters and a space while the level's largest coordinate is at
least 0.001 (10 from 0.1 on), so the ``point`` attribute stays under 3.9 MB, and an RGBA
``color`` (at most 7 characters a channel) under 2.8 MB."""

MAX_SHAPE_TRIANGLES = 200_000
"""Most triangles in one ``Shape``: its ``index`` attribute (indices below
:data:`MAX_SHAPE_VERTICES`, at most 6 characters each) stays under 3.6 MB."""

MAX_TEXTURE_URL = 8_000_000
"""Most characters of a texture's PNG ``data:`` URI, so that the ``url`` attribute stays under
libxml2's 10 MB limit like every other: a larger image is halved until it fits."""

PNG_DATA_URI = "data:image/png;base64,"

SWITCHING_MODES = ("lod", "prism")
"""How levels switch: ``lod``, by distance from the object's centre (an X3D ``LOD``); ``prism``,
on boxes around the object (see the module docstring)."""
PROFILES = {"lod": "Interchange", "prism": "Interactive"}
"""The X3D profile per switching mode. Prism switching's ProximitySensor, BooleanFilter and
IntegerTrigger are in Interactive (EnvironmentalSensor 1, EventUtilities 1), which holds all of
Interchange. A profile, not component statements: a script adding a component the scene
already declares fails in X_ITE (lodconvert's viewer page adds EnvironmentalSensor)."""

METADATA_SET = "lodconvert"
FRAME_DEF = "scene_frame"
"""DEF of the ``Transform`` that turns a georeferenced scene y-up (:mod:`lodconvert.io.frame`)."""
FRAME_METADATA = "lodconvert_frame"
"""Name of that Transform's ``MetadataSet``: the scene origin and rotation."""
FRAME_ROTATION = "1 0 0 -1.5707963267948966"
"""The frame's ``rotation``: −90° about x, source (x, y, z) → scene (x, z, −y)."""
_NOT_NCNAME = re.compile(r"[^A-Za-z0-9_.\-]")

Metadata = tuple[str, str, str]
"""One metadata entry: node type (``MetadataDouble`` …), name, value as X3D field text."""


_DECLARATION = "<?xml version='1.0' encoding='UTF-8'?>"
_ENTITIES = (
    ("&", "&amp;"),
    ("<", "&lt;"),
    (">", "&gt;"),
    ('"', "&quot;"),
    ("\t", "&#9;"),
    ("\n", "&#10;"),
    ("\r", "&#13;"),
)
"""What libxml2 escapes in a double-quoted attribute value, ``&`` first."""
_TO_ESCAPE = re.compile(f'[&<>"\\t\\n\\r{NOT_XML_CHARS}]')


def _escape(value: str) -> str:
    """``value`` as double-quoted XML attribute text, escaped as libxml2 (lxml) writes it; a
    character XML cannot hold (which lxml refuses) or a lone surrogate is written as
    ``\\uXXXX`` first (:func:`~lodconvert.model.safe_text.xml_text`)."""
    if _TO_ESCAPE.search(value) is None:
        return value
    value = xml_text(value)
    for char, entity in _ENTITIES:
        if char in value:
            value = value.replace(char, entity)
    return value


_VERBATIM_FIELDS = frozenset(
    {
        *("DEF", "USE", "name", "containerField", "solid"),
        *("fromNode", "toNode", "fromField", "toField"),
        *("index", "point", "color", "diffuseColor", "transparency", "level"),
        *("translation", "rotation", "scale", "scaleOrientation", "center", "size", "range"),
        *("whichChoice", "integerKey", "attenuation"),
        *("pointSizeScaleFactor", "pointSizeMinValue", "pointSizeMaxValue"),
    }
)
"""Fields that this writer fills only with number text (:mod:`..numbers`, ``repr``, ``str``),
its own constant names, ``true``/``false`` or the NCName DEFs of :func:`_unique_names`: nothing
in them needs escaping, so they are written as they are (coordinates are most of the text)."""


class _Out:
    """The XML text of a document, as lxml's ``xmlfile`` writes it with two-space indentation:
    each element on a line of its own, indented by its depth, empty ones self-closed, attribute
    values escaped (:func:`_escape`; not those of :data:`_VERBATIM_FIELDS`). :meth:`flush`
    writes the text added so far to the binary ``handle`` in UTF-8."""

    def __init__(self, handle: BinaryIO) -> None:
        self.handle = handle
        self.parts: list[str] = [_DECLARATION]
        self.indent = "\n"
        self.open_tags: list[str] = []

    def _start_tag(self, tag: str, attrib: dict[str, str] | None) -> str:
        text = f"{self.indent}<{tag}"
        if attrib:
            for name, value in attrib.items():
                text += f' {name}="{value if name in _VERBATIM_FIELDS else _escape(value)}"'
        return text

    def node(self, tag: str, attrib: dict[str, str] | None = None) -> _Out:
        """Open an element whose children are written inside the ``with`` block that this
        call starts (``with out.node(tag):``)."""
        self.parts.append(f"{self._start_tag(tag, attrib)}>")
        self.open_tags.append(tag)
        self.indent += "  "
        return self

    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc_info: object) -> None:
        """Close the element :meth:`node` opened last."""
        self.indent = indent = self.indent[:-2]
        self.parts.append(f"{indent}</{self.open_tags.pop()}>")

    def leaf(self, tag: str, attrib: dict[str, str] | None = None) -> None:
        """Write an element without children."""
        self.parts.append(f"{self._start_tag(tag, attrib)}/>")

    def flush(self) -> None:
        """Write the text added since the last flush to the handle."""
        self.handle.write("".join(self.parts).encode("utf-8"))
        self.parts.clear()

    def inserted(self, text: str) -> None:
        """Add ``text`` made by :func:`_piece_text` as the children of the element open now."""
        self.parts.append(text.replace("\n", self.indent))


def _piece_text(write: Callable[[_Out], None]) -> str:
    """The text ``write`` adds to a document as the children of an element at depth 0, each
    line starting with its line break and its depth's indentation, to be moved to any depth by
    :meth:`_Out.inserted` (no line break stands elsewhere: attribute values have theirs
    escaped, and the fields written verbatim hold none)."""
    out = _Out(io.BytesIO())
    out.parts.clear()
    write(out)
    return "".join(out.parts)


def _mfstring(values: Iterable[str]) -> str:
    """X3D MFString text: each value double-quoted, with ``\\`` and ``"`` escaped."""
    return " ".join('"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"' for v in values)


_PRISM_TEXT = (
    "each object's levels switch on nested ProximitySensor boxes, the finest level's bounding "
    "box grown by each LOD range on every side, driving Switch nodes through BooleanFilter and "
    "IntegerTrigger; the LOD inside a Switch with whichChoice -1 lists the levels and is not drawn"
)


def _head(out: _Out, info: OutputInfo, switching: str) -> None:
    view = info.view
    meta = [
        ("generator", info.generator),
        ("source", info.source),
        *([("crs", info.crs)] if info.crs else []),
        *([("vertical-reference", info.vertical)] if info.vertical else []),
        (
            "reference-view",
            f"{view.height_px} px high viewport, {view.fov_y_deg:g} degree vertical field of "
            f"view (focal length {view.focal_px:.2f} px)",
        ),
        ("switching", switching),
        *([("prism-switching", _PRISM_TEXT)] if switching == "prism" else []),
        (
            "lod-ranges",
            "LOD range values are distances in scene units from the LOD center at which the next "
            "coarser child takes over: Y = alpha * beta * gamma^x (alpha = bounding-box "
            "diagonal); after the last range of a culled object an empty Group shows nothing",
        ),
        (
            "point-size",
            "PointSet points are point_size_px pixels wide at design_distance in the reference "
            "view and scale with 1/distance (PointProperties attenuation 0 b 0)",
        ),
        *(
            [("options", json.dumps(info.options, sort_keys=True, default=str))]
            if info.options
            else []
        ),
    ]
    with out.node("head"):
        for name, level in COMPONENTS:
            out.leaf("component", {"name": name, "level": str(level)})
        for name, content in meta:
            out.leaf("meta", {"name": name, "content": content})


def _frame_metadata(out: _Out, frame: SceneFrame) -> None:
    """The scene frame's ``MetadataSet``: its origin (float64), rotation (row-major), axes and
    how to get source coordinates back."""
    record = frame.record()
    with out.node("MetadataSet", {"name": FRAME_METADATA, "containerField": "metadata"}):
        out.leaf("MetadataDouble", {"name": "origin", "value": format_exact(frame.origin)})
        out.leaf("MetadataDouble", {"name": "rotation", "value": format_exact(ROTATION.ravel())})
        for name in ("axes", "meaning"):
            out.leaf("MetadataString", {"name": name, "value": _mfstring([record[name]])})


def _metadata_set(out: _Out, entries: list[Metadata]) -> None:
    with out.node("MetadataSet", {"name": METADATA_SET, "containerField": "metadata"}):
        for tag, name, value in entries:
            out.leaf(tag, {"name": name, "value": value})


def _appearance_name(level_def: str) -> str:
    """DEF of the ``Appearance`` shared by the Shapes of the level ``Group`` ``level_def``."""
    return f"{level_def}_Appearance"


@dataclass(frozen=True)
class _Region:
    """DEFs of the nodes that switch an object's levels at one of its cutoffs (prism switching):
    the box's ``ProximitySensor``, the ``BooleanFilter`` splitting its ``isActive``, the
    ``IntegerTrigger`` s sending the near and the far choice, and the ``Switch`` they set."""

    sensor: str
    filter: str
    inside: str
    outside: str
    switch: str


NEAR_CHOICE, FAR_CHOICE = 0, 1
"""A prism Switch's choices: the level inside its box, and what shows outside it."""


def _regions(base: str, count: int) -> list[_Region]:
    """The DEFs of the first ``count`` regions of the object whose DEF base is ``base``."""
    roles = ("Prism", "Filter", "Inside", "Outside", "Switch")
    return [_Region(*(f"{base}_{role}{k}" for role in roles)) for k in range(count)]


def _hidden_name(base: str) -> str:
    """DEF of the ``Switch`` that holds the ``LOD`` of a prism-switched object, undrawn."""
    return f"{base}_levels"


def _ncname(object_id: str) -> str:
    """``object_id`` made an XML NCName: the DEF base it gets when no other object has it."""
    base = _NOT_NCNAME.sub("_", object_id) or "_"
    return base if base[0].isalpha() or base[0] == "_" else "_" + base


def _derived_names(
    candidate: str, levels: list[Level], regions: int | None
) -> tuple[list[str], list[str]]:
    """The level DEFs of an object whose DEF base is ``candidate``, and every name that base
    takes (itself, LOD, level Groups and their Appearances; with prism switching, the Switch
    hiding the LOD and the nodes of ``regions`` regions)."""
    level_defs = [f"{candidate}_{lv.name}" for lv in levels]
    names = [
        candidate,
        f"{candidate}_LOD",
        f"{candidate}_instance",
        *level_defs,
        *map(_appearance_name, level_defs),
    ]
    if regions is not None:
        names.append(_hidden_name(candidate))
        names += [name for region in _regions(candidate, regions) for name in astuple(region)]
    return level_defs, names


def _unique_names(
    object_id: str, used: set[str], levels: list[Level], regions: int | None = None
) -> tuple[str, list[str]]:
    """A DEF base (an XML NCName) for ``object_id`` whose derived names
    (:func:`_derived_names`) are not yet in ``used``, and the level DEFs; all are added to
    ``used``."""
    base = _ncname(object_id)
    candidate, n = base, 1
    while True:
        level_defs, names = _derived_names(candidate, levels, regions)
        if not used.intersection(names):
            used.update(names)
            return candidate, level_defs
        n += 1
        candidate = f"{base}_{n}"


def _check_chain(chain: LodChain) -> None:
    names = [level.name for level in chain.levels]
    if len(set(names)) != len(names):
        raise ValueError(f"{chain.object_id}: level names must be unique: {names}")
    expected = len(chain.levels) - 1 + int(chain.culled)
    if len(chain.cutoffs) != expected:
        raise ValueError(
            f"{chain.object_id}: {len(chain.levels)} levels (culled={chain.culled}) need "
            f"{expected} cutoffs, got {len(chain.cutoffs)}"
        )
    if any(b <= a for a, b in zip(chain.cutoffs, chain.cutoffs[1:], strict=False)):
        raise ValueError(f"{chain.object_id}: cutoffs must increase strictly: {chain.cutoffs}")


def _switching_metadata(item: LodChain | CellChain) -> list[Metadata]:
    """α, β, γ, exponents, cutoffs and culling of a chain or a LOD parent."""
    return [
        ("MetadataDouble", "alpha", format_exact([item.alpha])),
        ("MetadataDouble", "beta", format_exact([item.beta])),
        ("MetadataDouble", "gamma", format_exact([item.gamma])),
        ("MetadataDouble", "xs", format_exact(item.xs)),
        ("MetadataDouble", "cutoffs", format_exact(item.cutoffs)),
        ("MetadataBoolean", "culled", "true" if item.culled else "false"),
    ]


def _chain_metadata(chain: LodChain) -> list[Metadata]:
    entries = [
        ("MetadataString", "object_id", _mfstring([chain.object_id])),
        *_switching_metadata(chain),
    ]
    if chain.transform is not None:
        entries.append(("MetadataDouble", "transform", format_exact(chain.transform.ravel())))
    if chain.metadata:
        attributes = json.dumps(chain.metadata, sort_keys=True, default=str, ensure_ascii=False)
        entries.append(("MetadataString", "attributes", _mfstring([attributes])))
    return entries


def _level_metadata(level: Level, switch_in: float, switch_out: float | None) -> list[Metadata]:
    entries = [
        ("MetadataString", "level", _mfstring([level.name])),
        ("MetadataString", "kind", _mfstring([level.kind])),
        ("MetadataInteger", "count", str(level.count)),
        ("MetadataDouble", "switch_in", format_exact([switch_in])),
    ]
    if switch_out is not None:
        entries.append(("MetadataDouble", "switch_out", format_exact([switch_out])))
    if level.mesh is not None:
        entries.append(("MetadataInteger", "triangles", str(len(level.mesh.faces))))
    if level.params is not None:
        entries += [
            ("MetadataInteger", "resolution", str(level.params.resolution)),
            ("MetadataInteger", "slices", str(level.params.slices)),
            ("MetadataDouble", "point_size_px", format_exact([level.params.point_size])),
            ("MetadataString", "filter", _mfstring([level.params.filter])),
        ]
    if level.spacing is not None:
        entries.append(("MetadataDouble", "spacing", format_exact([level.spacing])))
    if level.design_distance is not None:
        entries.append(("MetadataDouble", "design_distance", format_exact([level.design_distance])))
    return entries


def point_properties(level: Level, switch_in: float, alpha: float) -> dict[str, str]:
    """``PointProperties`` fields that draw ``level``'s points ``point_size · d / r`` pixels
    wide (``d`` its design distance, ``r`` the viewer distance; see the module docstring).

    The maximum is the size at the nearest distance the level can be seen from: its switch-in
    distance less half the object diagonal ``alpha`` (points lie up to that far from the
    centre), but never closer than ``d / MAX_POINT_GROWTH``. Without a design distance the
    points keep a constant ``point_size``.
    """
    size = level.params.point_size if level.params is not None else 1.0
    scale = max(1.0, size)
    design = level.design_distance
    if design is None or design <= 0:
        fixed = format_exact([scale])
        return {"pointSizeScaleFactor": fixed, "pointSizeMinValue": "1", "pointSizeMaxValue": fixed}
    nearest = max(switch_in - alpha / 2.0, design / MAX_POINT_GROWTH)
    return {
        "pointSizeScaleFactor": format_exact([scale]),
        "pointSizeMinValue": "1",
        # rounded up, so the clamp never cuts the size the attenuation asks for
        "pointSizeMaxValue": format_fixed(
            [max(1.0, math.ceil(100 * size * design / nearest - 1e-6) / 100)], 2
        ),
        "attenuation": "0 " + format_exact([scale / (size * design)]) + " 0",
    }


def _color_node(out: _Out, rgba: np.ndarray) -> None:
    """``Color`` (RGB) when every alpha is 255, else ``ColorRGBA``."""
    if (rgba[:, 3] == 255).all():
        out.leaf("Color", {"color": format_unit_bytes(rgba[:, :3])})
    else:
        out.leaf("ColorRGBA", {"color": format_unit_bytes(rgba)})


def _appearance(
    out: _Out, name: str, first: bool, children: Sequence[tuple[str, dict[str, str]]]
) -> None:
    """A level's or part's ``Appearance``: defined (``DEF``, with the ``(tag, fields)``
    ``children``) in its first ``Shape`` and re-used (``USE``) in the others."""
    if first:
        with out.node("Appearance", {"DEF": name}):
            for tag, fields in children:
                out.leaf(tag, fields)
    else:
        out.leaf("Appearance", {"USE": name})


def _face_runs(faces: np.ndarray) -> Iterator[np.ndarray]:
    """Split ``faces`` (m, 3) into consecutive runs of at most :data:`MAX_SHAPE_TRIANGLES`
    faces using at most :data:`MAX_SHAPE_VERTICES` distinct vertices (each run as long as
    both allow; at least one face, and one empty run for a mesh without faces)."""
    if len(faces) <= MAX_SHAPE_TRIANGLES and faces.size <= MAX_SHAPE_VERTICES:
        yield faces  # too few corners to use too many vertices
        return
    start = 0
    while True:
        window = faces[start : start + MAX_SHAPE_TRIANGLES]
        # distinct vertices of each prefix of the window: the corners where a vertex first occurs
        _, first = np.unique(window, return_index=True)
        new_per_face = np.bincount(first // 3, minlength=len(window))
        fitting = int(np.count_nonzero(np.cumsum(new_per_face) <= MAX_SHAPE_VERTICES))
        stop = start + max(1, fitting)
        yield faces[start:stop]
        if stop >= len(faces):
            return
        start = stop


def _run_vertices(run: np.ndarray, vertex_count: int) -> tuple[np.ndarray | slice, np.ndarray]:
    """The vertices (of ``vertex_count``) that the faces ``run`` use, ascending, and ``run``
    re-indexed into them, as ``np.unique(run, return_inverse=True)`` gives them; all vertices
    as a slice when every one is used."""
    used = np.zeros(vertex_count, dtype=bool)
    used[run.ravel()] = True
    if used.all():
        return slice(None), run
    return np.flatnonzero(used), (np.cumsum(used) - 1)[run]


def _point_slices(count: int) -> Iterator[slice]:
    """Consecutive slices of at most :data:`MAX_SHAPE_VERTICES` points (one, empty, for none)."""
    for start in range(0, max(count, 1), MAX_SHAPE_VERTICES):
        yield slice(start, start + MAX_SHAPE_VERTICES)


def _textured(surface: Surface) -> bool:
    return surface.texture is not None and surface.uv is not None


def texture_url(rgba: np.ndarray) -> str:
    """The image ``rgba`` (h, w, 4) uint8, top row first, as a PNG ``data:`` URI for an
    ``ImageTexture`` ``url``: same pixels, same text.

    Pillow writes the PNG with fixed options and no timestamp or text chunk. An image whose URI
    would be longer than :data:`MAX_TEXTURE_URL` is halved (2×2 box average, odd edges
    rounded up) until it fits; texture coordinates stay valid as they are relative.
    """
    from PIL import Image as PILImage  # only for textures: a worker baking none never loads it

    image = PILImage.fromarray(np.ascontiguousarray(rgba, dtype=np.uint8))
    while True:
        png = io.BytesIO()
        image.save(png, format="PNG", optimize=False, compress_level=6)
        url = PNG_DATA_URI + base64.b64encode(png.getvalue()).decode("ascii")
        if len(url) <= MAX_TEXTURE_URL or max(image.size) == 1:
            return url
        image = image.reduce(2)


def vertex_colors(surface: Surface) -> np.ndarray | None:
    """Per-vertex RGBA (n, 4) uint8 of the ``Color`` node of ``surface``'s Shapes, or ``None``
    when the surface has no vertex colours (its :attr:`~Surface.material_color` then goes to
    the Material, and a texture to an ``ImageTexture``).

    Each vertex takes :meth:`Surface.colors_at` of the surface without its texture at its own
    position on the first face that uses it: the vertex colour modulated by the base colour
    (the texture is written as a texture, which X3D multiplies by these colours). Vertices used
    by no face get the material colour.
    """
    if surface.vertex_colors is None:
        return None
    if _textured(surface):
        surface = replace(surface, uv=None, texture=None)
    colors = np.repeat(surface.material_color[None, :], len(surface.vertices), axis=0)
    corners = surface.faces.ravel()
    order = np.argsort(corners, kind="stable")
    ordered = corners[order]
    first = np.ones(len(ordered), dtype=bool)
    first[1:] = ordered[1:] != ordered[:-1]
    used = ordered[first]
    colors[used] = surface.colors_at(order[first] // 3, surface.vertices[used])
    return colors


def _mesh_shapes(out: _Out, mesh: Mesh, appearance: str) -> None:
    """Every part of ``mesh`` as Shapes (:func:`_part_shapes`); parts after the first name their
    Appearance ``<appearance>_<part>``."""
    for i, part in enumerate(mesh.parts):
        _part_shapes(out, part, appearance if i == 0 else f"{appearance}_{i}")


def _part_shapes(out: _Out, surface: Surface, appearance: str) -> None:
    """One part as ``Shape`` s with an ``IndexedTriangleSet`` each, one per run of faces
    (:func:`_face_runs`), holding the vertices (colours, texture coordinates) that run uses,
    re-indexed. A textured part's ``Appearance`` holds its ``ImageTexture``."""
    base = surface.material_color
    material = {"diffuseColor": format_unit_bytes(base[:3])}
    if base[3] < 255:
        material["transparency"] = format_fixed([1.0 - base[3] / 255.0], 4)
    children = [("Material", material)]
    uv = surface.uv if _textured(surface) else None
    if uv is not None:
        assert surface.texture is not None
        children.append(("ImageTexture", {"url": _mfstring([texture_url(surface.texture)])}))
    colors = vertex_colors(surface)
    decimals = geometry_decimals(surface.vertices)
    uv_decimals = geometry_decimals(uv) if uv is not None else 0
    for k, run in enumerate(_face_runs(surface.faces)):
        used, index = _run_vertices(run, len(surface.vertices))
        with out.node("Shape"):
            _appearance(out, appearance, k == 0, children)
            attrib = {"solid": "false", "index": format_ints(index)}
            with out.node("IndexedTriangleSet", attrib):
                out.leaf("Coordinate", {"point": format_fixed(surface.vertices[used], decimals)})
                if colors is not None:
                    _color_node(out, colors[used])
                if uv is not None:
                    out.leaf("TextureCoordinate", {"point": format_fixed(uv[used], uv_decimals)})


def _point_shapes(out: _Out, level: Level, switch_in: float, alpha: float, appearance: str) -> None:
    """The level's points as ``Shape`` s with a ``PointSet`` each, one per slice of
    :data:`MAX_SHAPE_VERTICES` consecutive points."""
    assert level.points is not None
    positions, colors = level.points.positions, level.points.colors
    fields = point_properties(level, switch_in, alpha)
    decimals = geometry_decimals(positions)
    for k, part in enumerate(_point_slices(len(positions))):
        with out.node("Shape"):
            _appearance(out, appearance, k == 0, [("PointProperties", fields)])
            with out.node("PointSet"):
                _color_node(out, colors[part])
                out.leaf("Coordinate", {"point": format_fixed(positions[part], decimals)})


def instance_fields(matrix: np.ndarray) -> dict[str, str]:
    """``Transform`` fields equal to the 4×4 ``matrix`` (no projective part): the linear part
    split by SVD into rotation · (scale along the axes of ``scaleOrientation``), as X3D
    composes them; reflections become a negative scale."""
    from scipy.spatial.transform import Rotation

    u, sigma, vt = np.linalg.svd(np.asarray(matrix, dtype=np.float64)[:3, :3])
    if np.linalg.det(u @ vt) < 0:
        u[:, -1], sigma[-1] = -u[:, -1], -sigma[-1]
    v = vt.T
    if np.linalg.det(v) < 0:
        v[:, -1] = -v[:, -1]
        u[:, -1] = -u[:, -1] if np.linalg.det(u @ v.T) < 0 else u[:, -1]

    def axis_angle(rotation: np.ndarray) -> list[float]:
        vector = Rotation.from_matrix(rotation).as_rotvec()
        angle = float(np.linalg.norm(vector))
        return [*(vector / angle if angle > 0 else (0.0, 0.0, 1.0)), angle]

    fields = {
        "translation": format_exact(np.asarray(matrix)[:3, 3]),
        "rotation": format_exact(axis_angle(u @ v.T)),
        "scale": format_exact(sigma),
    }
    if not np.allclose(sigma, sigma[0]):  # uniform scale needs no orientation
        fields["scaleOrientation"] = format_exact(axis_angle(v))
    return fields


@dataclass(frozen=True)
class _Written:
    """Levels shared by instances, as first written: the list (kept alive, so that ids stay
    unique), the DEF of their ``LOD`` and those of their level Groups."""

    levels: list[Level]
    lod: str
    level_defs: list[str]


@dataclass
class _Document:
    """What writing one document keeps from item to item: how levels switch, the scene origin
    positions are less (zero without a frame), the chains' text made by workers, the DEFs used
    so far and the levels shared by instances (by the id of their list)."""

    switching: str
    shift: np.ndarray
    pieces: Pieces
    used: set[str] = field(default_factory=set)
    written: dict[int, _Written] = field(default_factory=dict)

    def prism_regions(self, chain: LodChain) -> int | None:
        """How many regions ``chain`` switches on (``None``: it switches by an ``LOD``)."""
        return _prism_regions(chain, self.switching)


def _prism_regions(chain: LodChain, switching: str) -> int | None:
    return len(chain.cutoffs) if switching == "prism" else None


_BASE = "\x00"
"""The DEF base in a worker's text of a chain, replaced by the one the writer gives it: no
text written holds this character (:func:`_escape`, :mod:`~lodconvert.model.safe_text`)."""


@dataclass(frozen=True)
class ChainText:
    """What a chain's ``Transform`` holds, made by a worker (:class:`ChainTexts`) with
    :data:`_BASE` for its DEF base (:func:`_piece_text`)."""

    inner: str


@dataclass(frozen=True)
class ChainTexts:
    """Makes the text of a chain that is not an instance of shared geometry, as the writer
    would with ``switching``, whatever DEF base the writer gives it."""

    switching: str = "lod"

    def __call__(self, chain: LodChain) -> ChainText | None:
        if chain.transform is not None:
            return None
        _check_chain(chain)
        regions = _prism_regions(chain, self.switching)
        level_defs, _ = _derived_names(_BASE, chain.levels, regions)
        return ChainText(
            _piece_text(lambda out: _write_contents(out, chain, _BASE, level_defs, regions))
        )


def chain_texts(info: OutputInfo, switching: str = "lod") -> ChainTexts:
    """The X3D format's ``formatter`` (:mod:`lodconvert.io`)."""
    return ChainTexts(switching)


def _write_chain(out: _Out, chain: LodChain, doc: _Document) -> None:
    """One chain: its ``Transform`` (inside one more for an instance of shared geometry) with
    the chain's metadata and its ``LOD`` — defined the first time its levels are written,
    ``USE`` d by later instances. With prism switching the LOD goes into a ``Switch`` that
    draws nothing, followed by the nodes that draw its levels (:func:`_write_prism`). Positions
    are less ``doc.shift``: an object's translation, or an instance's placement (its chain
    keeps its origin, as its facts declare). A worker's text of the chain is used where there
    is one, with the DEF base given here."""
    piece: ChainText | None = doc.pieces.take(chain)
    shared = doc.written.get(id(chain.levels))
    prism_regions = doc.prism_regions(chain)
    levels = [] if shared else chain.levels
    base, level_defs = _unique_names(chain.object_id, doc.used, levels, prism_regions)
    if piece is not None:
        placed = {"DEF": base, "translation": format_exact(chain.origin - doc.shift)}
        with out.node("Transform", placed):
            out.inserted(piece.inner.replace(_BASE, base))
        return
    _check_chain(chain)
    origin = chain.origin if chain.transform is not None else chain.origin - doc.shift
    transform = {"DEF": base, "translation": format_exact(origin)}
    with contextlib.ExitStack() as stack:
        if chain.transform is not None:
            placed = chain.transform.copy()
            placed[:3, 3] -= doc.shift
            fields = {"DEF": f"{base}_instance", **instance_fields(placed)}
            stack.enter_context(out.node("Transform", fields))
        with out.node("Transform", transform):
            _write_contents(out, chain, base, level_defs, prism_regions, shared, doc.written)


def _write_contents(
    out: _Out,
    chain: LodChain,
    base: str,
    level_defs: list[str],
    prism_regions: int | None,
    shared: _Written | None = None,
    written: dict[int, _Written] | None = None,
) -> None:
    """What a chain's ``Transform`` holds: the chain's metadata (on the Transform: X3DOM counts
    a MetadataSet inside LOD as its first level), its ``LOD`` and, with prism switching, the
    nodes that draw its levels."""
    _metadata_set(out, _chain_metadata(chain))
    if prism_regions is None:
        _write_lod(out, chain, base, level_defs, shared, written)
        return
    hidden = {"DEF": _hidden_name(base), "whichChoice": "-1"}
    with out.node("Switch", hidden):
        _write_lod(out, chain, base, level_defs, shared, written)
    defs = shared.level_defs if shared else level_defs
    _write_prism(out, chain, _regions(base, prism_regions), defs)


def _write_lod(
    out: _Out,
    chain: LodChain,
    base: str,
    level_defs: list[str],
    shared: _Written | None,
    written: dict[int, _Written] | None,
) -> None:
    """The chain's ``LOD``: a ``USE`` of the ``shared`` one, or defined with its levels (and,
    for an instance, remembered in ``written``)."""
    if shared:
        out.leaf("LOD", {"USE": shared.lod})
        return
    lod = {
        "DEF": f"{base}_LOD",
        "center": format_exact(chain.center),
        "range": format_exact(chain.cutoffs),
        "forceTransitions": "true",
    }
    if chain.transform is not None and written is not None:
        written[id(chain.levels)] = _Written(chain.levels, lod["DEF"], level_defs)
    with out.node("LOD", lod):
        _write_levels(out, chain, level_defs)


def _finest_box(chain: LodChain) -> np.ndarray:
    """(2, 3) min and max corner of ``chain``'s finest level in its frame: the vertices its
    faces use, or its points; the chain centre (a box of no size) when it has neither."""
    finest = chain.levels[0]
    if finest.mesh is not None and finest.mesh.vertex_count:
        return finest.mesh.bounds
    if finest.points is not None and len(finest.points):
        positions = finest.points.positions
        return np.stack([positions.min(axis=0), positions.max(axis=0)])
    return np.stack([chain.center, chain.center]).astype(np.float64)


def prism_boxes(chain: LodChain) -> list[tuple[np.ndarray, np.ndarray]]:
    """Centre and size of each of ``chain``'s switching boxes, nearest first: its finest level's
    bounding box (:func:`_finest_box`) grown by each cutoff on every side."""
    low, high = _finest_box(chain)
    return [((low + high) / 2, high - low + 2 * cutoff) for cutoff in chain.cutoffs]


def _write_prism(out: _Out, chain: LodChain, regions: list[_Region], level_defs: list[str]) -> None:
    """The nodes that draw a chain's levels on boxes: the nested Switches, then each box's
    sensor, filter, triggers and the ROUTEs between them (see the module docstring)."""
    _write_switches(out, regions, level_defs)
    for region, (centre, size) in zip(regions, prism_boxes(chain), strict=True):
        box = {"center": format_exact(centre), "size": format_exact(size)}
        out.leaf("ProximitySensor", {"DEF": region.sensor, **box})
        out.leaf("BooleanFilter", {"DEF": region.filter})
        out.leaf("IntegerTrigger", {"DEF": region.inside, "integerKey": str(NEAR_CHOICE)})
        out.leaf("IntegerTrigger", {"DEF": region.outside, "integerKey": str(FAR_CHOICE)})
        for route in _routes(region):
            out.leaf("ROUTE", route)


def _write_switches(out: _Out, regions: list[_Region], level_defs: list[str]) -> None:
    """One ``Switch`` per region, each holding the next: its near choice ``USE`` s the level
    inside its box, its far choice is the next Switch; past the last region, the remaining
    level (an empty ``Group`` when none remains: a culled chain). Each starts at its far choice."""
    if not regions:
        out.leaf("Group", {"USE": level_defs[0]} if level_defs else {})
        return
    with out.node("Switch", {"DEF": regions[0].switch, "whichChoice": str(FAR_CHOICE)}):
        out.leaf("Group", {"USE": level_defs[0]})
        _write_switches(out, regions[1:], level_defs[1:])


def _routes(region: _Region) -> list[dict[str, str]]:
    """The ROUTEs of one region: ``isActive`` into the filter, its true and false outputs into
    the near and far triggers, and both triggers into the Switch's ``whichChoice``."""
    connections = (
        (region.sensor, "isActive", region.filter, "set_boolean"),
        (region.filter, "inputTrue", region.inside, "set_boolean"),
        (region.filter, "inputFalse", region.outside, "set_boolean"),
        (region.inside, "triggerValue", region.switch, "set_whichChoice"),
        (region.outside, "triggerValue", region.switch, "set_whichChoice"),
    )
    keys = ("fromNode", "fromField", "toNode", "toField")
    return [dict(zip(keys, connection, strict=True)) for connection in connections]


def _write_item(out: _Out, item: LodChain | CellChain, doc: _Document) -> None:
    """An object's chain, or a LOD parent with everything in it."""
    if isinstance(item, CellChain):
        _write_cell(out, item, doc)
    else:
        _write_chain(out, item, doc)


def _cell_metadata(cell: CellChain) -> list[Metadata]:
    facts = json.dumps(cell.facts, sort_keys=True, default=str, ensure_ascii=False)
    return [
        ("MetadataString", "cell_id", _mfstring([cell.cell_id])),
        ("MetadataInteger", "tier", str(cell.tier)),
        ("MetadataDouble", "size", format_exact([cell.size])),
        ("MetadataInteger", "key", " ".join(map(str, cell.key))),
        *_switching_metadata(cell),
        ("MetadataString", "members", _mfstring(cell.member_ids())),
        ("MetadataString", "facts", _mfstring([facts])),
    ]


def _write_cell(out: _Out, cell: CellChain, doc: _Document) -> None:
    """A LOD parent: a ``Group`` with the cell's metadata around an ``LOD`` (centred on the
    members' bounding box, in scene coordinates) whose near child holds the members as they
    are written alone and whose far child is the cell's one level, in a ``Transform`` to the
    cell's origin (then an empty ``Group`` for a culled cell); positions less ``doc.shift``."""
    base, (far_def,) = _unique_names(cell.cell_id, doc.used, [cell.far])
    near, far = f"{base}_near", f"{base}_far"
    doc.used.update((near, far))
    with out.node("Group", {"DEF": base}):
        _metadata_set(out, _cell_metadata(cell))
        lod = {
            "DEF": f"{base}_LOD",
            "center": format_exact(cell.origin - doc.shift + cell.center),
            "range": format_exact(cell.cutoffs),
            "forceTransitions": "true",
        }
        with out.node("LOD", lod):
            with out.node("Group", {"DEF": near}):
                for member in cell.members:
                    _write_item(out, member, doc)
            placed = format_exact(cell.origin - doc.shift)
            with out.node("Transform", {"DEF": far, "translation": placed}):
                # the far level shows from the cell's first cutoff on, like a chain's second
                _write_level(out, cell.far, far_def, cell.cutoffs, 1, cell.alpha)
            if cell.culled:
                out.leaf("Group")


def _write_level(
    out: _Out, level: Level, name: str, cutoffs: Sequence[float], index: int, alpha: float
) -> None:
    """Level ``index`` of a chain with ``cutoffs`` as a ``Group`` named ``name``."""
    bounds = [0.0, *cutoffs]
    switch_out = bounds[index + 1] if index + 1 < len(bounds) else None
    with out.node("Group", {"DEF": name}):
        _metadata_set(out, _level_metadata(level, bounds[index], switch_out))
        if not level.is_points:
            assert level.mesh is not None
            _mesh_shapes(out, level.mesh, _appearance_name(name))
        else:
            _point_shapes(out, level, bounds[index], alpha, _appearance_name(name))


def _write_levels(out: _Out, chain: LodChain, level_defs: list[str]) -> None:
    """The LOD's children: one Group per level, finest first, then the empty cull child."""
    for i, (level, name) in enumerate(zip(chain.levels, level_defs, strict=True)):
        _write_level(out, level, name, chain.cutoffs, i, chain.alpha)
    if chain.culled:
        out.leaf("Group")


def write_x3d(
    chains: Iterable[LodChain],
    handle: BinaryIO,
    info: OutputInfo,
    switching: str = "lod",
    pieces: Pieces | None = None,
) -> None:
    """Write ``chains`` as an X3D 4.0 XML document to the binary ``handle``, each object's
    levels switching as ``switching`` says (one of :data:`SWITCHING_MODES`; else
    :class:`~lodconvert.errors.UsageError`); a chain's text in ``pieces`` (made by a worker,
    :class:`ChainTexts`) is written with the DEF names given here.

    The document is streamed: each chain is written (and flushed) as the iterable yields it, so
    only one chain's text is held in memory. Same input, same bytes.
    """
    if switching not in SWITCHING_MODES:
        modes = " or ".join(SWITCHING_MODES)
        raise UsageError(f"must be {modes}, not {switching!r}", field="switching")
    out = _Out(handle)
    root = {
        "xmlns:xsd": XSI,
        "profile": PROFILES[switching],
        "version": "4.0",
        "xsd:noNamespaceSchemaLocation": SCHEMA_URL,
    }
    with out.node("X3D", root):
        _head(out, info, switching)
        with out.node("Scene"):
            items = iter(chains)
            first = next(items, None)
            frame = scene_frame(info.framed, first, info.origin) if first is not None else None
            box = SceneBox(frame)
            shift = frame.origin if frame is not None else np.zeros(3)
            doc = _Document(switching, shift, pieces or Pieces())
            with contextlib.ExitStack() as framed:
                if frame is not None:
                    doc.used.add(FRAME_DEF)
                    attrib = {"DEF": FRAME_DEF, "rotation": FRAME_ROTATION}
                    framed.enter_context(out.node("Transform", attrib))
                    _frame_metadata(out, frame)
                for item in itertools.chain([first] if first is not None else [], items):
                    _write_item(out, item, doc)
                    box.add(item)
                    out.flush()
            view = box.viewpoint()
            if view is not None:
                out.leaf("NavigationInfo", NAVIGATION)
                out.leaf("Viewpoint", view)
    out.flush()
    handle.write(b"\n")
