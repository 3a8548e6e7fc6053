"""Implicit geometry of CityGML city objects (``lod2ImplicitRepresentation``…, a tree's or a
street lamp's): a geometry given in a frame of its own (``relativeGMLGeometry``, 3.0
``relativeGeometry``), placed by its ``ImplicitGeometry``: the ``transformationMatrix`` (4×4,
row by row; the identity where none is given) turns it, and its ``referencePoint`` moves it,
world = reference point + (M · [x, y, z, 1])[:3]. The relative geometry's coordinates are taken
as metres; the reference point is in the document's CRS (projected onto a geographic CRS's
local frame like every other coordinate).

A relative geometry is usually given once and linked (``xlink:href``) by every object that
shares it, objects the document holds after the one that defines it, when that one has been
freed: :class:`Templates` keeps a copy of each relative geometry that has a ``gml:id`` as the
objects are read (at most :data:`MAX_TEMPLATES` of them), where later links find it. Every
object gets triangles of its own, placed (no instancing across objects).
"""

from __future__ import annotations

import copy

import numpy as np
from lxml import etree

from .names import GML_IDS, local

MAX_TEMPLATES = 1024
"""Relative geometries kept for later objects' links (a document's distinct tree and furniture
models; links to geometries past this many are left unresolved)."""
RELATIVE_GEOMETRIES = frozenset({"relativeGMLGeometry", "relativeGeometry"})
"""Properties of an ``ImplicitGeometry`` that hold (or link to) its geometry."""


class Templates:
    """The relative geometries of a document's implicit geometries, by ``gml:id``, copied out
    of the objects that define them."""

    def __init__(self, limit: int = MAX_TEMPLATES) -> None:
        self.limit = limit
        self.geometries: dict[str, etree._Element] = {}

    def register(self, element: etree._Element) -> None:
        """Keep a copy of every relative geometry with a ``gml:id`` below ``element`` (a
        city object about to be read), the first of each id, up to :attr:`limit`."""
        for implicit in element.iter("{*}ImplicitGeometry"):
            for prop in implicit:
                if local(prop) not in RELATIVE_GEOMETRIES:
                    continue
                for geometry in prop:
                    gml_id = next((geometry.get(k) for k in GML_IDS if geometry.get(k)), None)
                    if gml_id is None or gml_id in self.geometries:
                        continue
                    if len(self.geometries) < self.limit:
                        self.geometries[gml_id] = copy.deepcopy(geometry)

    def get(self, href: str) -> etree._Element | None:
        """The copy of the geometry ``href`` (``#id``) links to, or None."""
        return self.geometries.get(href.removeprefix("#"))


def placement(implicit: etree._Element) -> tuple[np.ndarray, np.ndarray]:
    """The ``transformationMatrix`` (4×4) and ``referencePoint`` ((3,), z = 0 for a 2-D point)
    of an ``ImplicitGeometry``; ValueError saying what is wrong with them."""
    matrix = np.eye(4)
    reference = None
    for child in implicit:
        name = local(child)
        if name == "transformationMatrix":
            matrix = _numbers(child.text, "transformationMatrix", (16,)).reshape(4, 4)
        elif name == "referencePoint":
            pos = next((e for e in child.iter("{*}pos") if e.text and e.text.strip()), None)
            if pos is not None:
                point = _numbers(pos.text, "reference point", (2, 3))
                reference = np.append(point, 0.0) if len(point) == 2 else point
    if reference is None:
        raise ValueError("has an ImplicitGeometry without a reference point")
    return matrix, reference


def _numbers(text: str | None, what: str, sizes: tuple[int, ...]) -> np.ndarray:
    """The finite numbers of ``text``, as many as one of ``sizes``; ValueError otherwise."""
    words = (text or "").split()
    try:
        values = np.array(words, dtype=np.float64)
    except ValueError:
        raise ValueError(f"has a {what} that is not numbers") from None
    if len(values) not in sizes:
        raise ValueError(f"has a {what} of {len(words)} values, not {' or '.join(map(str, sizes))}")
    if not np.isfinite(values).all():
        raise ValueError(f"has a {what} that is not finite")
    return values


def placed(local_points: np.ndarray, matrix: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``local_points`` ((n, 3), the relative geometry's) turned by ``matrix`` and moved to
    ``reference`` (in metres); a point past float64 becomes infinite (without a warning: the
    caller checks the points placed)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return local_points @ matrix[:3, :3].T + matrix[:3, 3] + reference
