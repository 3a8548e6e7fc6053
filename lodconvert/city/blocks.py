"""Block proxies: a LOD parent's far level as a few prisms standing for whole blocks.

Each object's **footprint** (outline, base and top, roof and wall colours, as :mod:`.prisms`
derives them) is found once and kept with its finest level. A cell unions its objects'
footprints into connected **blocks**, cuts each into **height bands** so that a tower does not
vanish into the block around it, simplifies the outlines within a tolerance and extrudes them
without floors: one part with vertex colours, one draw call. Objects that do not stand on the
ground (:data:`~lodconvert.model.lods.GROUND_COVERS`) have no block. Coordinates are z-up.
The rules in full: *Block proxies* in ``docs/cities.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model import LodChain, Mesh, Surface
from ..model.lods import GROUND_COVERS
from .prisms import (
    FootprintPart,
    coloured,
    extruded,
    footprint,
    polygons,
    prism_colors,
    simplified_polygons,
    standing_height,
)

ROOF_PERCENTILE = 80.0
"""An object's top in a block: this percentile of its roof's heights. Of 70, 80 and 90 it let
the most TUM Munich cells' blocks reach silhouette F 0.95 (``benchmarks/results/hlod.md``)."""
BAND_PERCENTILE = 90.0
"""A band's top: this percentile of its objects' tops, over their footprint areas."""


@dataclass(frozen=True)
class Footprint:
    """An object's ``outline`` seen from above (a shapely multipolygon, scene metres), the
    heights (``base``, ``top``) its block stands between, its ``roof`` and ``wall`` colours
    (RGBA) and its ``area``."""

    outline: Any
    base: float
    top: float
    roof: np.ndarray
    wall: np.ndarray
    area: float


def object_footprint(chain: LodChain, finest: Mesh) -> Footprint | None:
    """The footprint of ``chain``'s object, whose finest level is ``finest`` in scene
    coordinates (kept with its finest level for the next call); ``None`` for a ground cover or
    an object with no footprint with area and height."""
    if chain.transform is not None:  # an instance: its own placement
        return _footprint(chain, finest)
    level = next(lv.mesh for lv in chain.levels if lv.mesh is not None)
    key = f"block-footprint-{np.asarray(chain.origin, dtype=np.float64).tobytes().hex()}"
    return level.derived(key, lambda: _footprint(chain, finest))


def _footprint(chain: LodChain, finest: Mesh) -> Footprint | None:
    """:func:`object_footprint`, found anew."""
    if chain.metadata.get("type") in GROUND_COVERS:
        return None
    import shapely

    base, top = standing_height(finest, chain.metadata, percentile=ROOF_PERCENTILE)
    found = footprint({}, finest).polygons if top > base else []
    if not found:
        return None
    outline = shapely.MultiPolygon(found)
    roof, wall = prism_colors(finest)
    return Footprint(outline, base, top, roof, wall, float(outline.area))


@dataclass(frozen=True)
class Blocks:
    """A cell's objects' footprints (``prints``) unioned into connected ``polygons``, each
    with the indices of the footprints it holds (``members``)."""

    prints: list[Footprint]
    polygons: list[Any]
    members: list[np.ndarray]
    closing: float
    _unions: dict[tuple[int, ...], Any] = field(default_factory=dict, repr=False, compare=False)
    _parts: dict[tuple[Any, ...], Any] = field(default_factory=dict, repr=False, compare=False)
    """Band outlines and their polygons, found once: every outline tolerance and band depth
    tries the same bands."""

    def parts(
        self, block: int, taller: tuple[int, ...] | None, tolerance: float
    ) -> list[FootprintPart]:
        """The polygons to extrude of block ``block`` (``taller``: of the union of those
        footprints instead, gaps narrower than ``closing`` closed), simplified within
        ``tolerance``."""
        import shapely

        key = (block, taller, tolerance)
        if key not in self._parts:
            outline = self.polygons[block] if taller is None else self._union(taller)
            kept = simplified_polygons(outline, tolerance)
            self._parts[key] = polygons(shapely.MultiPolygon(kept)) if kept else []
        return self._parts[key]

    def _union(self, indices: tuple[int, ...]) -> Any:
        """The outlines of the footprints ``indices`` unioned, gaps narrower than ``closing``
        closed."""
        import shapely

        if indices not in self._unions:
            outlines = [self.prints[i].outline for i in indices]
            self._unions[indices] = _closed(shapely.union_all(outlines), self.closing)
        return self._unions[indices]


def blocks_of(prints: list[Footprint], closing: float) -> Blocks:
    """``prints`` unioned into connected blocks, gaps narrower than ``closing`` closed."""
    import shapely

    union = _closed(shapely.union_all([p.outline for p in prints]), closing)
    found = [g for g in getattr(union, "geoms", [union]) if isinstance(g, shapely.Polygon)]
    inside = np.full(len(prints), -1)
    points = shapely.point_on_surface([p.outline for p in prints])
    pairs = shapely.STRtree(found).query(points, predicate="intersects")
    inside[pairs[0]] = pairs[1]
    members = [np.flatnonzero(inside == b) for b in range(len(found))]
    kept = [b for b, m in enumerate(members) if len(m)]
    return Blocks(prints, [found[b] for b in kept], [members[b] for b in kept], closing)


def _closed(outline: Any, closing: float) -> Any:
    """``outline`` with its gaps narrower than ``closing`` filled (square corners kept)."""
    if closing <= 0:
        return outline
    return outline.buffer(closing / 2, join_style="mitre").buffer(-closing / 2, join_style="mitre")


def block_proxy(blocks: Blocks, tolerance: float, band: float) -> Mesh | None:
    """The blocks as prisms in height bands ``band`` metres deep, outlines simplified within
    ``tolerance``: one part with vertex colours, in scene coordinates (``None`` when nothing
    with area is left)."""
    prints = blocks.prints
    tops = np.array([p.top for p in prints])
    areas = np.array([p.area for p in prints])
    surfaces: list[Surface] = []
    colors: list[np.ndarray] = []
    for b, members in enumerate(blocks.members):
        base = min(prints[i].base for i in members)
        taller: list[int] = []
        bands = _bands(members[np.argsort(-tops[members], kind="stable")], tops, band)
        for last, group in ((g == len(bands) - 1, group) for g, group in enumerate(bands)):
            taller += group
            parts = blocks.parts(b, None if last else tuple(taller), tolerance)
            if not parts:
                continue
            top = _weighted_percentile(tops[group], areas[group], BAND_PERCENTILE / 100)
            roof, wall = (_mean_color([getattr(prints[i], k) for i in taller], areas[taller])
                          for k in ("roof", "wall"))  # fmt: skip
            for part in parts:
                surfaces += extruded(part, base, top)
                colors += [roof, wall]
    return coloured(surfaces, colors) if surfaces else None


def shared_corners(proxy: Mesh) -> Mesh:
    """``proxy`` (one part with vertex colours) with one vertex per corner position and colour:
    faces of one colour (a block's walls, its roof) share their corners, and a roof's corner is
    a vertex apart from its walls', so that each keeps its own colour."""
    (part,) = proxy.parts
    assert part.vertex_colors is not None
    keys = np.column_stack([part.vertices, part.vertex_colors.view(np.uint32).astype(np.float64)])
    _, first, corners = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    faces = corners.reshape(-1)[part.faces]
    return Mesh([Surface(part.vertices[first], faces, vertex_colors=part.vertex_colors[first])])


def _bands(order: np.ndarray, tops: np.ndarray, depth: float) -> list[list[int]]:
    """Footprints ``order`` (tallest first) in bands: each joins the band before while its top
    lies within ``depth`` of that band's tallest."""
    bands: list[list[int]] = []
    for i in order.tolist():
        if bands and tops[bands[-1][0]] - tops[i] <= depth:
            bands[-1].append(i)
        else:
            bands.append([i])
    return bands


def _weighted_percentile(values: np.ndarray, weights: np.ndarray, share: float) -> float:
    """The least of ``values`` below or at which ``share`` of the ``weights`` lies."""
    order = np.argsort(values, kind="stable")
    total = np.cumsum(weights[order])
    return float(values[order][min(int(np.searchsorted(total, share * total[-1])), len(order) - 1)])


def _mean_color(colors: list[np.ndarray], weights: np.ndarray) -> np.ndarray:
    """The ``weights``-weighted mean of RGBA ``colors``."""
    mean = weights @ np.stack(colors).astype(np.float64) / weights.sum()
    return np.rint(mean).astype(np.uint8)
