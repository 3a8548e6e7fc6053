"""Parking a city's nodes on disk while its plot radii are found gives back the same nodes."""

from __future__ import annotations

import numpy as np

from lodconvert.model import Node
from lodconvert.spool import NodeSpool
from tests.test_lods import block


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


def test_nodes_past_the_memory_given_are_parked_on_disk_and_come_back_alike() -> None:
    houses = [block(8, 8, 6 + i, 20.0 * i) for i in range(4)]
    nodes = [Node(f"b{i}", m, "Building", lods={"lod2": m}) for i, m in enumerate(houses)]
    one = sum(a.nbytes for a in (houses[0].vertices, houses[0].faces))
    with NodeSpool(memory=2 * one) as spool:
        for node in nodes:
            spool.add(node)
        assert spool._file.tell() > 0  # the last two went to disk
        back = list(spool)
    assert [n.id for n in back] == [n.id for n in nodes]
    assert back[0].geometry is houses[0]  # kept in memory, not copied
    assert back[3].geometry is not houses[3]
    for before, after in zip(houses, back, strict=True):
        assert np.array_equal(after.geometry.vertices, before.vertices)
        assert np.array_equal(after.lods["lod2"].faces, before.faces)
