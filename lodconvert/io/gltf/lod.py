"""Where a chain's nodes go, in ``MSFT_lod`` layout: a root node named after the object (at its
origin), whose one child is the finest level's node, listing the coarser level nodes (in no
scene and no parent) in ``extensions.MSFT_lod.ids``; a LOD parent's root, near node (the
members' roots as children) and far node. Switching data goes to ``extras.MSFT_screencoverage``
and ``extras.lodconvert`` (nodes and asset); a scene with a frame (:mod:`lodconvert.io.frame`)
hangs from one :data:`FRAME_NODE`. The layout and its reasons: ``docs/gltf.md``."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...model import CellChain, LodChain
from .. import OutputInfo, Pieces
from ..frame import ROTATION, SceneFrame, scene_frame
from .chain_part import (
    MEMBER_DEPTH,
    MSFT_LOD,
    ChainParts,
    add_chain,
    chain_text,
    coverages,
    level_params,
    numbers_text,
    plain,
)
from .compression import NONE
from .document import Document
from .json_text import JsonArray, json_object

COVERAGE_MEANING = "projected bounding-box diagonal / viewport height at the reference view"
FRAME_NODE = "scene_frame"
"""Name of the root node that turns a georeferenced scene y-up (:mod:`lodconvert.io.frame`)."""
FRAME_MATRIX = [float(v) for v in np.block([[ROTATION, np.zeros((3, 1))], [0, 0, 0, 1]]).T.ravel()]
"""Its ``matrix`` (column-major): z-up source axes → y-up glTF axes, exact in float32."""


def _cell_extras(cell: CellChain) -> dict[str, Any]:
    """``extras.lodconvert`` of a LOD parent's near node: its switching data and facts."""
    return plain(
        {
            "cell_id": cell.cell_id,
            "tier": cell.tier,
            "size": cell.size,
            "key": list(cell.key),
            "cutoffs": cell.cutoffs,
            "alpha": cell.alpha,
            "beta": cell.beta,
            "gamma": cell.gamma,
            "xs": cell.xs,
            "culled": cell.culled,
            "center": cell.origin + cell.center,
            "members": cell.member_ids(),
            "facts": cell.facts,
        }
    )


def _node_count(item: LodChain | CellChain) -> int:
    """Nodes a chain (root and one per level) or a LOD parent (root, near, far and its
    members') adds."""
    if isinstance(item, CellChain):
        return 3 + sum(_node_count(member) for member in item.members)
    return 1 + len(item.levels)


def _asset_extras(info: OutputInfo, frame: SceneFrame | None) -> dict[str, Any]:
    """``asset.extras.lodconvert``: provenance, the scene frame (a city's or one with a CRS) and the
    meaning of the coverage values."""
    return plain(
        {
            "source": info.source,
            "crs": info.crs,
            **({"vertical_reference": info.vertical} if info.vertical else {}),
            **({"frame": frame.record()} if frame is not None else {}),
            "reference_view": {"height_px": info.view.height_px, "fov_y_deg": info.view.fov_y_deg},
            "screencoverage": COVERAGE_MEANING,
            "options": info.options,
        }
    )


class LodScene:
    """The scene of a :class:`Document`: chains and LOD parents added as nodes in ``MSFT_lod``
    layout (their level meshes from the buffers a worker made, in ``pieces``, where it did)."""

    def __init__(self, doc: Document, info: OutputInfo, pieces: Pieces) -> None:
        self.doc = doc
        self.info = info
        self.reference_view = info.view
        self.pieces = pieces
        self.parts = ChainParts(info.view, doc.layout.indent, doc.compress, doc.copy)
        """Makes the part of a chain no worker made."""
        self.frame: SceneFrame | None = None  # set by the first item, for a framed scene
        self.scene_nodes = doc.array(depth=3)  # at scenes[0].nodes

    def add(self, item: LodChain | CellChain) -> None:
        """Add a chain, or a LOD parent with everything in it, to the scene."""
        if not self.scene_nodes:
            self.frame = scene_frame(self.info.framed, item, self.info.origin)
        self.scene_nodes.append(len(self.doc.nodes))
        self._add(item)

    def _add(self, item: LodChain | CellChain) -> None:
        if isinstance(item, CellChain):
            self._add_cell(item)
        else:
            self._add_chain(item)

    def _add_cell(self, cell: CellChain) -> None:
        """A LOD parent's nodes: its root; its near node (the root's child: the members' roots
        as children, ``MSFT_lod`` naming the far node); the members' nodes; the far node
        (translated to the cell's origin, in no scene and no parent, like coarser levels)."""
        root = len(self.doc.nodes)
        near = root + 1
        members, at = [], near + 1
        for member in cell.members:
            members.append(at)
            at += _node_count(member)
        self.doc.use(MSFT_LOD)
        self.doc.nodes.append(json_object(children=[near], name=cell.cell_id))
        extras = {
            "MSFT_screencoverage": coverages(cell, self.reference_view),
            "lodconvert": _cell_extras(cell),
        }
        extensions = {MSFT_LOD: {"ids": [at]}}
        name = f"{cell.cell_id}_near"
        near_node = json_object(children=members, extensions=extensions, extras=extras, name=name)
        self.doc.nodes.append(near_node)
        for member in cell.members:
            self._add(member)
        far_name = f"{cell.cell_id}_{cell.far.name}"
        mesh = self.doc.level_mesh(self.doc.layout.text(far_name, MEMBER_DEPTH), cell.far)
        facts = {"level": cell.far.name, **level_params(cell.far), "switch_in": cell.cutoffs[0]}
        translation = self._placed(cell.origin, f"cell {cell.cell_id!r}")
        steps = self.doc.mesh_nodes.get(mesh, {}) if mesh is not None else {}
        if steps:  # quantized positions: their corner from the cell's origin, their scale
            translation = translation + np.asarray(steps["translation"])
        far = json_object(
            extras={"lodconvert": plain(facts)},
            mesh=mesh,
            name=far_name,
            translation=[float(v) for v in translation],
            scale=steps.get("scale"),
        )
        assert self.doc.nodes.append(far) == at

    def _add_chain(self, chain: LodChain) -> None:
        """Add a chain's nodes and meshes: its part of the document as a worker made it, where
        one did, or as one would (:mod:`.chain_part`); an instance's here, sharing the meshes
        of its geometry's first chain."""
        doc, what = self.doc, f"object {chain.object_id!r}"
        if chain.transform is None:
            placed = self._placed(chain.origin + 0.0, what)  # + 0.0: no negative zero
            part = self.pieces.take(chain) or self.parts(chain)
            assert part.indent == doc.layout.indent, "a part made for the other layout"
            doc.merge(part.part, numbers_text(doc.layout, placed))
            return
        matrix = chain.transform.copy()
        matrix[:3, 3] += matrix[:3, :3] @ chain.origin
        placed = self._placed(matrix[:3, 3], what)
        text = chain_text(chain, self.reference_view, doc.layout)
        if np.array_equal(matrix[:3, :3], np.eye(3)):
            add_chain(doc, chain, text, numbers_text(doc.layout, placed))
        else:
            matrix[:3, 3] = placed
            add_chain(doc, chain, text, matrix=numbers_text(doc.layout, matrix.T.ravel()))

    def _placed(self, origin: np.ndarray, what: str) -> np.ndarray:
        """Where a node at ``origin`` (source coordinates) is translated: from the scene
        frame's origin where there is one."""
        return origin if self.frame is None else self.frame.offset(origin, what)

    def _scene_roots(self) -> JsonArray | list[int]:
        """``scenes[0].nodes``: the objects' roots, or the frame node holding them (the last
        node, with them as its children)."""
        if self.frame is None:
            return self.scene_nodes
        self.doc.nodes.last = json_object(
            children=self.scene_nodes, matrix=FRAME_MATRIX, name=FRAME_NODE
        )
        return [len(self.doc.nodes)]

    def json_value(self, data_uri: bool) -> dict[str, Any]:
        """The document's glTF JSON object (see :meth:`Document.json_value`) with the asset and
        the scene."""
        extras = _asset_extras(self.info, self.frame)
        if self.doc.compress != NONE:
            extras.update(compress=self.doc.compress, position_error=self.doc.position_error)
        asset = {
            "extras": {"lodconvert": extras},
            "generator": self.info.generator,
            "version": "2.0",
        }
        return self.doc.json_value(asset, self._scene_roots(), data_uri)
