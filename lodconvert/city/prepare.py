"""City preparation before baking: a city read through and its objects parked
(:class:`~lodconvert.spool.NodeSpool`), each with the plot radius its neighbours' spacing gives
as its γ (:mod:`.plots`); docs/cities.md."""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator

import numpy as np

from ..chain import ChainOptions
from ..model import Node, PackedNode
from ..model.lods import GROUND_COVERS
from ..spool import NodeSpool
from .plots import plot_radii


def with_plot_radii(
    nodes: Iterator[Node | PackedNode], options: ChainOptions
) -> Iterator[tuple[Node | PackedNode, float | None]]:
    """``nodes`` (a scene's with geometry), each with the plot radius to use as its γ: unless
    ``options`` set γ, a city object's (a node with its own LoDs) comes from its neighbours'
    spacing (:mod:`.city.plots`), so a city is read through first, its nodes parked on disk
    (:class:`~.spool.NodeSpool`); a mesh file's nodes stay streamed (radius ``None``)."""
    first = next(nodes, None) if options.gamma is None else None
    if first is None or not first.is_city_object():
        for node in itertools.chain([first] if first is not None else [], nodes):
            yield node, None
        return
    with NodeSpool() as spool:
        _, radii = spooled(itertools.chain([first], nodes), options, spool)
        yield from zip(spool, radii, strict=True)


def spooled(
    nodes: Iterable[Node | PackedNode], options: ChainOptions, spool: NodeSpool
) -> tuple[np.ndarray, list[float | None]]:
    """Park ``nodes`` in ``spool``; their ground centres ((n, 2), scene coordinates) and the
    plot radius of each city object standing on the ground, from its neighbours among them
    (``None`` for others, terrain and ground covers among them, and for all where ``options``
    set γ)."""
    centres: list[tuple[float, float]] = []
    city: list[bool] = []
    for node in nodes:
        spool.add(node)
        centres.append(node.ground_centre())
        city.append(node.is_city_object() and node.type not in GROUND_COVERS)
    placed = np.array(centres, dtype=np.float64).reshape(-1, 2)
    radii: list[float | None] = [None] * len(placed)
    chosen = np.flatnonzero(city)
    if options.gamma is None and len(chosen):
        for i, radius in zip(chosen, plot_radii(placed[chosen]).tolist(), strict=True):
            radii[i] = radius
    return placed, radii
