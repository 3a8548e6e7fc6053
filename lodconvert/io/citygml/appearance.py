"""CityGML appearances (1.0, 2.0 and 3.0): what each polygon wears in the theme read
(:class:`Appearances`): a ``ParameterizedTexture``'s image and texture coordinates per ring
(``TexCoordList``) or world-to-texture matrix (``TexCoordGen``), a ``GeoreferencedTexture``'s
image placed in plan by its reference point and orientation, and an ``X3DMaterial``'s diffuse
colour and transparency, targeted by polygon or by a surface above it. The theme is
the one asked for (``--appearance-theme``), else the first met. Appearances inside a city
object and those at the root (``appearanceMember``, read before the objects:
:func:`read_global`) count alike. In full: ``docs/textures.md``."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from lxml import etree

from ...limits import Limits
from ..archive import open_compressed
from ..numbers import parse_floats
from .member_bytes import appearance_members
from .names import GML_IDS, MEMBERS, local
from .source import Stream, first_look, open_document, parser_options

GLOBAL_MARK = b"appearanceMember"
"""Bytes that only a document with appearances at its root holds."""
ANY_MARK = b"Appearance"
"""Bytes that every document with an appearance holds (the ``Appearance`` element; namespace
names spell it in lower case)."""
_ROOT_CHILDREN = tuple(f"{{*}}{name}" for name in sorted(MEMBERS | {"appearanceMember"}))
"""Tags of the root's children that the scan for appearances frees or reads."""
_SCAN_BYTES = 1 << 22
"""Bytes read at a time when a document is scanned for the marks."""


class Look(NamedTuple):
    """What one polygon wears: an image (its URI, as the file gives it) with texture
    coordinates per ring (``uv``: (n, 2) each, a ring's points in order, the closing one
    included; with ``texels``, in texels of the image from its top-left texel's centre), a
    3×4 world-to-texture matrix (``matrix``) or a plan-to-texel one (``plan``: 2×3), and a
    material colour (RGBA bytes), any of them ``None``."""

    image: str | None = None
    uv: tuple[np.ndarray | None, ...] | None = None
    matrix: np.ndarray | None = None
    color: np.ndarray | None = None
    plan: np.ndarray | None = None
    texels: bool = False


@dataclass
class Appearances:
    """The appearances of one document in the theme read: texture coordinates by ring id,
    world-to-texture matrices and materials by the id of the surface they target (a polygon
    or a surface holding polygons), the themes met and the number of appearances read."""

    wanted: str | None = None
    theme: str | None = None
    """The theme read: ``wanted``, else the first one met."""
    themes: list[str] = field(default_factory=list)
    rings: dict[str, tuple[str, np.ndarray]] = field(default_factory=dict)
    generated: dict[str, tuple[str, np.ndarray]] = field(default_factory=dict)
    georeferenced: dict[str, tuple[str, np.ndarray]] = field(default_factory=dict)
    """By target, a ``GeoreferencedTexture``'s image and plan-to-texel matrix (2×3)."""
    materials: dict[str, np.ndarray] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    """What could not be read (a count of numbers that is no pair, a matrix not of 12)."""

    @property
    def empty(self) -> bool:
        return not (self.rings or self.generated or self.georeferenced or self.materials)

    def add(self, appearance: etree._Element) -> None:
        """Read one ``Appearance`` element, if it is of the theme read."""
        theme = next((c.text or "" for c in appearance if local(c) == "theme"), "").strip()
        if theme not in self.themes:
            self.themes.append(theme)
        if self.theme is None:
            self.theme = self.wanted if self.wanted is not None else theme
        if theme != self.theme:
            return
        for data in appearance.iter(
            "{*}ParameterizedTexture", "{*}GeoreferencedTexture", "{*}X3DMaterial"
        ):
            name = local(data)
            if name == "X3DMaterial":
                self._material(data)
            elif name == "GeoreferencedTexture":
                self._georeferenced(data)
            else:
                self._texture(data)

    def _georeferenced(self, data: etree._Element) -> None:
        """A ``GeoreferencedTexture``: the texel (i, j) of its image (columns from the left,
        rows from the top) lies at its reference point plus its orientation matrix times
        (i, j), in plan, from the centre of the top-left texel; read for its targets."""
        uri = next((c.text or "" for c in data if local(c) == "imageURI"), "").strip()
        reference = next((e.text or "" for e in data.iter("{*}pos", "{*}coordinates")), "")
        orientation = next((c.text or "" for c in data if local(c) == "orientation"), "")
        try:
            point = parse_floats(reference.replace(",", " "))
            matrix = parse_floats(orientation).reshape(2, 2)
            inverse = np.linalg.inv(matrix)
        except (ValueError, np.linalg.LinAlgError):
            point, inverse = np.zeros(0), np.zeros((2, 2))
        if not uri or len(point) < 2 or not np.isfinite(inverse).all() or not inverse.any():
            self.problems.append(
                "a GeoreferencedTexture without an image, a reference point and an invertible "
                "orientation (a world file is not read)"
            )
            return
        plan = np.column_stack([inverse, -inverse @ point[:2]])
        for target in _targets(data):
            self.georeferenced.setdefault(target, (uri, plan))

    def _material(self, data: etree._Element) -> None:
        values = {local(c): c.text or "" for c in data}
        try:
            diffuse = parse_floats(values.get("diffuseColor", "0.8 0.8 0.8"))
            transparency = float(values.get("transparency", "0") or 0)
        except ValueError:
            self.problems.append("an X3DMaterial's colour is not numbers")
            return
        if len(diffuse) != 3 or not np.isfinite(diffuse).all() or not math.isfinite(transparency):
            self.problems.append("an X3DMaterial's diffuseColor is not three numbers")
            return
        rgb = np.clip(diffuse, 0.0, 1.0)
        alpha = 1.0 - min(max(transparency, 0.0), 1.0)
        color = np.rint(np.append(rgb, alpha) * 255).astype(np.uint8)
        for target in _targets(data):
            self.materials.setdefault(target, color)

    def _texture(self, data: etree._Element) -> None:
        uri = next((c.text or "" for c in data if local(c) == "imageURI"), "").strip()
        if not uri:
            self.problems.append("a ParameterizedTexture has no imageURI")
            return
        for element in data.iter("{*}TexCoordList", "{*}TexCoordGen"):
            if element.tag.endswith("TexCoordList"):
                self._coordinates(uri, element)
                continue
            target = _association_target(element)
            text = next((e.text or "" for e in element.iter("{*}worldToTexture")), "")
            try:
                matrix = parse_floats(text)
            except ValueError:
                matrix = np.zeros(0)
            if len(matrix) != 12 or not np.isfinite(matrix).all() or target is None:
                self.problems.append("a TexCoordGen's worldToTexture is not 12 numbers")
                continue
            self.generated.setdefault(target, (uri, matrix.reshape(3, 4)))

    def _coordinates(self, uri: str, element: etree._Element) -> None:
        """The texture coordinates of a ``TexCoordList``: each ``textureCoordinates`` for
        the ring its ``ring`` attribute (2.0) or the ``ring`` element in its place (3.0)
        names."""
        named: list[str] | None = None  # 3.0's ring elements, read where first needed
        for i, coordinates in enumerate(element.iterchildren("{*}textureCoordinates")):
            ring = coordinates.get("ring")
            if not ring:
                if named is None:
                    named = [(c.text or "").strip() for c in element.iterchildren("{*}ring")]
                ring = named[i] if i < len(named) else ""
            ring = ring.strip().removeprefix("#")
            if ring in self.rings:
                continue  # the first coordinates of a ring count (PLATEAU gives each twice)
            try:
                values = parse_floats(coordinates.text or "")
            except ValueError:
                values = np.zeros(1)
            if not ring or len(values) % 2:
                self.problems.append("a ring's texture coordinates are not pairs of numbers")
                continue
            self.rings.setdefault(ring, (uri, values.reshape(-1, 2)))

    def look(self, polygon: etree._Element, rings: list[etree._Element]) -> Look | None:
        """What ``polygon`` (its element, and its rings' elements in the order they are
        read) wears, or None when nothing targets it."""
        uv: tuple[np.ndarray | None, ...] | None = None
        image = matrix = color = plan = None
        if self.rings and len(rings) == 1:  # most polygons: one ring, no lists made
            if (one := self.rings.get(_gml_id(rings[0]) or "")) is not None:
                image, uv = one[0], (one[1],)
        elif self.rings:
            found = [self.rings.get(_gml_id(ring) or "") for ring in rings]
            first = next((f for f in found if f is not None), None)
            if first is not None:
                image = first[0]
                uv = tuple(f[1] if f is not None and f[0] == image else None for f in found)
        if self.generated or self.georeferenced or self.materials:
            for target in _ids_up(polygon):
                if image is None and target in self.generated:
                    image, matrix = self.generated[target]
                if image is None and target in self.georeferenced:
                    image, plan = self.georeferenced[target]
                if color is None and target in self.materials:
                    color = self.materials[target]
        if image is None and color is None:
            return None
        return Look(image, uv, matrix, color, plan)


_GML_ID, _GML_32_ID = GML_IDS


def _gml_id(element: etree._Element) -> str | None:
    found = element.get(_GML_ID)
    return found if found is not None else element.get(_GML_32_ID)


def _ids_up(element: etree._Element) -> Iterator[str]:
    """The gml:ids of ``element`` and of the elements above it, nearest first."""
    for each in (element, *element.iterancestors()):
        if (found := _gml_id(each)) is not None:
            yield found


def _targets(data: etree._Element) -> list[str]:
    """The surfaces an ``X3DMaterial`` targets (``target`` elements' texts, ``#`` dropped)."""
    return [
        (c.text or "").strip().removeprefix("#")
        for c in data
        if local(c) == "target" and (c.text or "").strip()
    ]


def _association_target(element: etree._Element) -> str | None:
    """The surface a ``TexCoordGen`` or ``TexCoordList`` is for: its ``target``'s ``uri``
    (2.0) or its ``TextureAssociation``'s ``target`` text (3.0)."""
    for above in element.iterancestors():
        name = local(above)
        if name == "target" and above.get("uri"):
            return above.get("uri", "").strip().removeprefix("#")
        if name == "TextureAssociation":
            text = next((c.text or "" for c in above if local(c) == "target"), "")
            return text.strip().removeprefix("#") or None
    return None


MARKS = (ANY_MARK, GLOBAL_MARK)
"""What tells whether a document holds appearances, and whether at its root."""


def document_appearances(
    path: Path, limits: Limits, theme: str | None, marks: set[bytes] | None = None
) -> Appearances | None:
    """The appearances at the root of the document ``path`` (in the theme ``theme``, else the
    first met), read before its objects; ``None`` when it holds no appearance at all.
    ``marks``: which of :data:`MARKS` it holds, where workers looked (else looked for here)."""
    marks = _marks(path, limits) if marks is None else marks
    if ANY_MARK not in marks:
        return None
    appearances = Appearances(wanted=theme)
    if GLOBAL_MARK in marks:
        stream = open_document(path, limits)
        try:
            read_global(stream, appearances, limits, str(path))
        finally:
            stream.close()
    return appearances


def _marks(path: Path, limits: Limits) -> set[bytes]:
    """Which of :data:`ANY_MARK` and :data:`GLOBAL_MARK` the document ``path`` holds, read a
    chunk at a time (what it inflates to, for a ``.gz`` or ``.zip``): a memory map would put
    every page of a large file in the process's resident memory."""
    found: set[bytes] = set()
    stream = open_compressed(path, limits)
    try:
        last = b""
        while len(found) < 2 and (chunk := stream.read(_SCAN_BYTES)):
            # every appearanceMember holds an Appearance: look for it once that is found (in
            # this chunk and the one before, which its start tag may end)
            mark = GLOBAL_MARK if found else ANY_MARK
            edge = last[-len(GLOBAL_MARK) :] + chunk[: len(GLOBAL_MARK)]  # across the chunks
            if mark in chunk or mark in edge:
                found.add(mark)
                if mark is ANY_MARK and (GLOBAL_MARK in last or GLOBAL_MARK in edge
                                         or GLOBAL_MARK in chunk):  # fmt: skip
                    found.add(GLOBAL_MARK)
            last = chunk
    finally:
        stream.close()
    return found


def read_global(stream: Stream, appearances: Appearances, limits: Limits, source: str) -> None:
    """Add the appearances at the root of the document ``stream`` to ``appearances``: its
    ``appearanceMember`` elements picked from its bytes (:mod:`.member_bytes`), else (a
    document in UTF-16) the whole document parsed, every other child of the root freed as it
    ends."""
    replay, root = first_look(stream, limits, source)
    members = appearance_members(replay, replay.head, root) or replay
    events = etree.iterparse(members, events=("end",), tag=_ROOT_CHILDREN, **parser_options(limits))
    for _, element in events:
        parent = element.getparent()
        if parent is None or parent.getparent() is not None:
            continue  # not a child of the root
        if local(element) == "appearanceMember":
            for appearance in element.iter("{*}Appearance"):
                appearances.add(appearance)
        element.clear(keep_tail=False)
        while element.getprevious() is not None:
            del parent[0]
