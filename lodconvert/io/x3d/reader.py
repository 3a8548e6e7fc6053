"""Reading back the X3D files lodconvert wrote: level geometry (:func:`read_x3d_points`),
chains with the facts declared in the lodconvert ``MetadataSet`` s (:func:`read_back`) and
LOD parents (:func:`read_cells`). Origins and centres come back in the source's coordinates:
the scene frame of a georeferenced file (the ``scene_frame`` Transform, see
:mod:`lodconvert.io.frame`) is undone."""

from __future__ import annotations

import contextlib
import json
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from ...errors import InputError
from ...model import LodChain
from ..declared import chain_from_facts, level_from_facts
from ..frame import SceneFrame, frame_from_record
from .metadata import FRAME_METADATA, METADATA_SET


@dataclass
class X3DLevel:
    """The geometry of one DEF'd level ``Group`` read back from an X3D file: its ``Shape`` s
    joined in document order.

    ``coordinates`` (k, 3) float64 are as written, relative to ``translation`` (the sum of the
    ``Transform`` translations enclosing the Group); ``colors`` (k, 4) uint8 or ``None``;
    ``index`` (m, 3) int64 triangles of ``IndexedTriangleSet`` s into ``coordinates``,
    ``None`` for ``PointSet`` s. A mesh split over several Shapes comes back with the vertices
    the Shapes share repeated in each, and without vertices that no face used.
    """

    geometry: str
    coordinates: np.ndarray
    translation: np.ndarray
    colors: np.ndarray | None = None
    index: np.ndarray | None = None

    @property
    def world(self) -> np.ndarray:
        """Coordinates in world units (float64)."""
        return self.coordinates + self.translation


def _numbers(text: str | None, width: int, dtype: type, what: str) -> np.ndarray:
    values = np.array((text or "").replace(",", " ").split(), dtype=dtype)
    if len(values) % width:
        raise ValueError(f"{what} has {len(values)} values, not a multiple of {width}")
    return values.reshape(-1, width)


def _sum(offsets: list[np.ndarray]) -> np.ndarray:
    """The sum of the enclosing translations ``offsets`` (zero without any)."""
    return np.sum(offsets, axis=0) if offsets else np.zeros(3)


def _read_shape(shape: etree._Element, translation: np.ndarray) -> X3DLevel | None:
    """The ``PointSet`` or ``IndexedTriangleSet`` of one ``Shape``; ``None`` without one."""
    for geometry in ("PointSet", "IndexedTriangleSet"):
        node = shape.find(geometry)
        if node is not None:
            break
    else:
        return None
    coordinate = node.find("Coordinate")
    points = coordinate.get("point") if coordinate is not None else None
    coords = _numbers(points, 3, np.float64, "point")
    if not np.isfinite(coords).all():
        raise ValueError("point has NaN or infinite coordinates")
    colors = None
    for tag, width in (("Color", 3), ("ColorRGBA", 4)):
        color = node.find(tag)
        if color is not None:
            values = _numbers(color.get("color"), width, np.float64, "color")
            if len(values) != len(coords) or not np.isfinite(values).all():
                raise ValueError(f"{tag} has {len(values)} finite colours for {len(coords)} points")
            rgba = np.full((len(values), 4), 255, dtype=np.uint8)
            rgba[:, :width] = np.clip(np.rint(values * 255.0), 0, 255).astype(np.uint8)
            colors = rgba
    index = _numbers(node.get("index"), 3, np.int64, "index") if geometry != "PointSet" else None
    if index is not None and len(index) and not (index.min() >= 0 and index.max() < len(coords)):
        raise ValueError(f"index refers to vertices beyond the {len(coords)} points")
    return X3DLevel(geometry, coords, translation, colors, index)


def _join_shapes(parts: list[X3DLevel]) -> X3DLevel:
    """One level from the Shapes of its Group: coordinates and colours concatenated, triangle
    indices shifted by the vertices of the Shapes before."""
    first = parts[0]
    if any(part.geometry != first.geometry for part in parts):
        raise ValueError(f"a level mixes {sorted({part.geometry for part in parts})}")
    coloured = [part.colors is not None for part in parts]
    if any(coloured) and not all(coloured):
        raise ValueError("a level has colours on some Shapes only")
    colors = np.concatenate([p.colors for p in parts]) if all(coloured) else None
    index = None
    if first.index is not None:
        starts = np.cumsum([0, *(len(part.coordinates) for part in parts[:-1])])
        index = np.concatenate([p.index + start for p, start in zip(parts, starts, strict=True)])
    coordinates = np.concatenate([part.coordinates for part in parts])
    return X3DLevel(first.geometry, coordinates, first.translation, colors, index)


def read_x3d_points(path: str | Path) -> dict[str, X3DLevel]:
    """Read the levels of an X3D file written by :func:`write_x3d`: for each DEF'd ``Group``
    the ``PointSet`` s or ``IndexedTriangleSet`` s of the ``Shape`` s directly inside it,
    joined (see :class:`X3DLevel`), keyed by the Group's DEF, in document order.

    The file is parsed with libxml2's default limits (no ``huge_tree``), which files written
    by :func:`write_x3d` stay within. Raises :class:`~lodconvert.errors.InputError` naming the
    file when it is missing, not well-formed (truncated, say), not X3D, or holds malformed
    numbers or geometry.
    """
    levels: dict[str, X3DLevel] = {}
    offsets: list[np.ndarray] = []
    groups: list[tuple[str | None, list[X3DLevel]]] = []
    with x3d_read_errors(path, "numbers or geometry"):
        events = etree.iterparse(str(path), events=("start", "end"))
        for event, element in events:
            if event == "start":
                if element.tag == "Transform":
                    shift = _numbers(element.get("translation"), 3, np.float64, "translation")
                    offsets.append(shift[0] if len(shift) else np.zeros(3))
                elif element.tag == "Group":
                    groups.append((element.get("DEF"), []))
                continue
            if element.tag == "Transform":
                offsets.pop()
            elif element.tag == "Shape" and groups and groups[-1][0]:
                shape = _read_shape(element, _sum(offsets))
                if shape is not None:
                    groups[-1][1].append(shape)
                element.clear()
            elif element.tag == "Group":
                name, parts = groups.pop()
                if name and parts:
                    levels[name] = _join_shapes(parts)
        if events.root is None or events.root.tag != "X3D":
            raise InputError("is not an X3D document", str(path))
    return levels


@contextlib.contextmanager
def x3d_read_errors(path: str | Path, malformed: str) -> Iterator[None]:
    """Turn what reading an X3D file can raise into a one-line :class:`InputError` naming
    ``path``; ``malformed`` says what a ``ValueError`` means (e.g. "numbers or geometry")."""
    try:
        yield
    except etree.XMLSyntaxError as err:
        raise InputError(f"is not well-formed X3D: {err}", str(path)) from None
    except OSError as err:
        raise InputError(f"cannot be read: {err.strerror or err}", str(path)) from None
    except ValueError as err:
        raise InputError(f"holds malformed {malformed}: {err}", str(path)) from None


_MFSTRING = re.compile(r'"((?:[^"\\]|\\.)*)"')
_LISTS = ("xs", "cutoffs", "members")
"""Metadata entries read as lists even when they hold one value."""


def _metadata_values(element: etree._Element) -> dict[str, Any]:
    """The entries of a ``MetadataSet``: single values as scalars, several as lists."""
    facts: dict[str, Any] = {}
    for child in element:
        name, text = child.get("name"), child.get("value") or ""
        if child.tag == "MetadataString":
            values: list[Any] = [
                re.sub(r"\\(.)", r"\1", m.group(1)) for m in _MFSTRING.finditer(text)
            ]
        elif child.tag == "MetadataBoolean":
            values = [v == "true" for v in text.replace(",", " ").split()]
        elif child.tag == "MetadataInteger":
            values = [int(v) for v in text.replace(",", " ").split()]
        elif child.tag == "MetadataDouble":
            values = [float(v) for v in text.replace(",", " ").split()]
        else:
            continue
        facts[name] = values if len(values) != 1 or name in _LISTS else values[0]
    return facts


def _vector(text: str | None) -> np.ndarray:
    values = np.array((text or "").replace(",", " ").split(), dtype=np.float64)
    return values[:3] if len(values) >= 3 else np.zeros(3)


def _frame_origin(element: etree._Element) -> np.ndarray:
    """The scene origin that the frame's ``MetadataSet`` ``element`` records; ``ValueError``
    for one that is not a frame lodconvert writes."""
    facts = _metadata_values(element)
    rotation = np.asarray(facts.get("rotation"), dtype=np.float64).reshape(-1, 3).tolist()
    frame = frame_from_record({"origin": facts.get("origin"), "rotation": rotation})
    assert frame is not None
    return frame.origin


def _is_frame(element: etree._Element) -> bool:
    return element.tag == "MetadataSet" and element.get("name") == FRAME_METADATA


def read_frame(path: str | Path) -> SceneFrame | None:
    """The scene frame of an ``.x3d`` lodconvert wrote (``None``: none, the file is in source
    coordinates); read up to the first ``LOD``. Raises
    :class:`~lodconvert.errors.InputError` as :func:`read_back` does."""
    with x3d_read_errors(path, "scene frame"):
        for event, element in etree.iterparse(str(path), events=("start", "end")):
            if event == "start" and element.tag == "LOD":
                return None
            if event == "end" and _is_frame(element):
                return SceneFrame(_frame_origin(element))
    return None


def _x3d_facts(path: str | Path) -> list[dict[str, Any]]:
    """Per ``LOD`` node carrying lodconvert metadata: its origin (the enclosing translations),
    centre, chain facts (from the ``MetadataSet`` of its ``Transform``, or of the LOD itself),
    the DEF of the chain's ``Transform`` and, per level ``Group``, its DEF and facts. Shapes are
    skipped."""
    objects: list[dict[str, Any]] = []
    lods: dict[str, dict[str, Any]] = {}  # DEF → entry, for LODs that instances USE
    transforms: list[dict[str, Any]] = []  # open Transforms: translation and metadata
    shift = np.zeros(3)  # the scene origin, once the frame declares it
    for event, element in etree.iterparse(str(path), events=("start", "end")):
        tag = element.tag
        if event == "start":
            if tag == "Transform":
                offset = _vector(element.get("translation"))
                transforms.append({"offset": offset, "facts": {}, "def": element.get("DEF")})
            elif tag == "LOD":
                facts = dict(transforms[-1]["facts"]) if transforms else {}
                # an instance's own Transform is declared in its facts; the origin is the
                # translation of the chain's Transform alone
                offsets = [t["offset"] for t in transforms[-1:] if "transform" in facts] or [
                    t["offset"] for t in transforms
                ]
                used = lods.get(element.get("USE", ""))
                entry = {
                    "origin": _sum(offsets) + (0.0 if "transform" in facts else shift),
                    "center": _vector(element.get("center")) if used is None else used["center"],
                    "facts": facts,
                    "levels": [] if used is None else [dict(lv) for lv in used["levels"]],
                    "element": element,
                    "lod": element.get("DEF") or element.get("USE"),
                    "transform": transforms[-1]["def"] if transforms else None,
                }
                objects.append(entry)
                if element.get("DEF"):
                    lods[element.get("DEF")] = entry
            elif (
                tag == "Group"
                and objects
                and element.getparent() is objects[-1]["element"]
                and element.get("DEF")  # the empty child of a culled chain has none
            ):
                objects[-1]["levels"].append({"def": element.get("DEF"), "facts": {}})
            continue
        if tag == "Transform":
            transforms.pop()
        elif tag == "Shape":
            element.clear()
        elif _is_frame(element):
            shift = _frame_origin(element)
        elif (
            tag == "MetadataSet"
            and element.get("name") == METADATA_SET
            and element.getparent() is not None  # not the document itself
        ):
            parent = element.getparent()
            lod = objects[-1]["element"] if objects else None
            if parent.tag == "Transform" and transforms:
                transforms[-1]["facts"] = _metadata_values(element)
            elif parent is lod:
                objects[-1]["facts"] = _metadata_values(element)
            elif objects[-1:] and objects[-1]["levels"] and parent.getparent() is lod:
                objects[-1]["levels"][-1]["facts"] = _metadata_values(element)
    return [obj for obj in objects if obj["facts"]]


def read_back(path: Path, geometry: bool = True) -> list[LodChain]:
    """The chains of an ``.x3d`` lodconvert wrote, with the facts of its lodconvert
    ``MetadataSet`` s and (unless ``geometry`` is false) the level geometry, relative to each
    chain's origin. ``chain.metadata`` holds the object's attributes (the JSON of its
    ``MetadataString name='attributes'``) and, under ``"x3d"`` (in place of an attribute of
    that name), the DEFs of the ``LOD`` node and of the chain's ``Transform`` (after which
    prism switching names the nodes that draw the levels)."""
    with x3d_read_errors(path, "metadata"):
        objects = _x3d_facts(path)
    if not objects:
        raise InputError("is not an X3D file written by lodconvert (no lodconvert LOD)", str(path))
    shapes_of = read_x3d_points(path) if geometry else {}
    chains = []
    for obj in objects:
        object_id = obj["facts"].get("object_id", "")
        where = f"{path}: object {object_id!r}"
        levels = []
        for entry in obj["levels"]:
            facts = {"name": entry["facts"].get("level"), **entry["facts"]}
            shapes = shapes_of.get(entry["def"])
            positions = shapes.coordinates if shapes is not None else np.zeros((0, 3))
            faces = shapes.index if shapes is not None else None
            colors = shapes.colors if shapes is not None else None
            levels.append(level_from_facts(facts, positions, faces, colors, where))
        chain_facts = {**obj["facts"], "center": obj["center"]}
        chain = chain_from_facts(object_id, chain_facts, levels, obj["origin"], where)
        chain.metadata["x3d"] = {"lod": obj["lod"], "transform": obj["transform"]}
        chains.append(chain)
    return chains


def read_cells(path: str | Path) -> list[dict[str, Any]]:
    """The LOD parents of an ``.x3d`` lodconvert wrote, coarsest first in document order (see
    :mod:`lodconvert.io`): the facts of each cell ``Group``'s lodconvert ``MetadataSet``
    (``facts`` parsed from its JSON), ``center`` (its ``LOD``'s, plus the enclosing
    translations), ``far`` (the facts of its far level ``Group``) and, under ``"x3d"``, its
    ``LOD``'s DEF. Raises :class:`~lodconvert.errors.InputError` for a file that cannot be
    read, or a cell without its ``LOD`` or far level."""
    cells: list[dict[str, Any]] = []
    with x3d_read_errors(path, "cell metadata"):
        opened: list[dict[str, Any]] = []  # cells whose Group is open: group, LOD, entry
        offsets: list[np.ndarray] = []
        shift = np.zeros(3)  # the scene origin, once the frame declares it
        for event, element in etree.iterparse(str(path), events=("start", "end")):
            tag, cell = element.tag, opened[-1] if opened else None
            if event == "start":
                if tag == "Transform":
                    offsets.append(_vector(element.get("translation")))
                elif tag == "LOD" and cell is not None and element.getparent() is cell["group"]:
                    cell["lod"] = element
                    centre = shift + _sum(offsets) + _vector(element.get("center"))
                    cell["entry"]["center"] = centre.tolist()
                    cell["entry"]["x3d"] = {"lod": element.get("DEF")}
            elif tag == "Transform":
                offsets.pop()
            elif tag == "Shape":
                element.clear()
            elif _is_frame(element):
                shift = _frame_origin(element)
            elif tag == "MetadataSet" and element.get("name") == METADATA_SET:
                _cell_metadata(element, cell, cells, opened)
            elif tag == "Group" and cell is not None and element is cell["group"]:
                _check_cell(opened.pop()["entry"])
    return cells


def _cell_metadata(
    element: etree._Element,
    cell: dict[str, Any] | None,
    cells: list[dict[str, Any]],
    opened: list[dict[str, Any]],
) -> None:
    """Read a lodconvert ``MetadataSet`` ``element`` that :func:`read_cells` met inside the open
    ``cell`` (or none): a new cell's facts (added to ``cells`` and ``opened``), or its far
    level's facts (its parent Group lies in a ``Transform`` that is a child of the cell's
    ``LOD``); other MetadataSets are the objects'."""
    group = element.getparent()
    if group is None or group.tag != "Group":
        return
    placed = group.getparent()
    lod = cell["lod"] if cell is not None else None
    if lod is not None and placed.tag == "Transform" and placed.getparent() is lod:
        cell["entry"]["far"] = _metadata_values(element)
        return
    facts = _metadata_values(element)
    if "cell_id" in facts:
        facts["facts"] = json.loads(facts.get("facts") or "{}")
        cells.append(facts)
        opened.append({"group": group, "lod": None, "entry": facts})


_CELL_PARTS = {"x3d": "LOD", "far": "far level"}
"""What :func:`read_cells` finds of a cell besides its metadata: entry key → node."""


def _check_cell(cell: dict[str, Any]) -> None:
    """Raise :class:`ValueError` for a cell read without its ``LOD`` or far level."""
    missing = [node for key, node in _CELL_PARTS.items() if key not in cell]
    if missing:
        raise ValueError(f"cell {cell['cell_id']!r} has no {' and no '.join(missing)}")
