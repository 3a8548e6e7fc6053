"""Parking a city's nodes on disk while its plot radii are found gives back the same nodes."""

from __future__ import annotations

import numpy as np

from lodconvert.model import Node
from lodconvert.spool import NodeSpool
from tests.test_sourcelods import block


def test_nodes_come_back_in_order_with_their_geometry_and_lods() -> None:
    houses = [block(8, 8, 6 + i, 20.0 * i) for i in range(5)]
    shared = block(2, 2, 2)
    nodes = [
        Node(f"b{i}", m, "Building", {"measuredHeight": 6 + i}, lods={"lod2": m})
        for i, m in enumerate(houses)
    ]
    nodes[1].children.append(Node("part", houses[0], "BuildingPart"))
    instances = [Node(f"tree{i}", shared, transform=np.eye(4)) for i in range(2)]
    with NodeSpool() as spool:
        for node in [*nodes, *instances]:
            spool.add(node)
        back = list(spool)
    assert [n.id for n in back] == [n.id for n in [*nodes, *instances]]
    for before, after in zip(nodes, back[: len(nodes)], strict=True):
        assert after.attributes == before.attributes and after.children == []
        assert np.array_equal(after.geometry.vertices, before.geometry.vertices)
        assert np.array_equal(after.lods["lod2"].faces, before.lods["lod2"].faces)
    # instances still share one geometry, so it is baked once
    assert back[-1].geometry is back[-2].geometry is shared
