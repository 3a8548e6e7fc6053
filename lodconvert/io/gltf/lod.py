"""Where a chain's nodes go, in ``MSFT_lod`` layout: a root node named after the object (at its
origin), whose one child is the finest level's node, listing the coarser level nodes (in no
scene and no parent) in ``extensions.MSFT_lod.ids``; a LOD parent's root, near node (the
members' roots as children) and far node. Switching data goes to ``extras.MSFT_screencoverage``
and ``extras.lodconvert`` (nodes and asset); a scene with a frame (:mod:`lodconvert.io.frame`)
hangs from one :data:`FRAME_NODE`. The layout and its reasons: ``docs/gltf.md``."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...model import CellChain, Level, LodChain
from ...ranges import ReferenceView, screen_coverage
from .. import OutputInfo, Pieces
from ..frame import ROTATION, SceneFrame, scene_frame
from .buffers import ChainBuffers
from .compression import NONE
from .document import Document
from .json_text import JsonArray, json_object

MSFT_LOD = "MSFT_lod"
COVERAGE_MEANING = "projected bounding-box diagonal / viewport height at the reference view"
FRAME_NODE = "scene_frame"
"""Name of the root node that turns a georeferenced scene y-up (:mod:`lodconvert.io.frame`)."""
FRAME_MATRIX = [float(v) for v in np.block([[ROTATION, np.zeros((3, 1))], [0, 0, 0, 1]]).T.ravel()]
"""Its ``matrix`` (column-major): z-up source axes → y-up glTF axes, exact in float32."""


def _plain(value: Any) -> Any:
    """``value`` as JSON-able Python data: numpy scalars and arrays unpacked, tuples as lists,
    non-finite floats as ``None``, unknown objects as their ``str``."""
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, str | int):
        return value
    return str(value)


def _level_params(level: Level) -> dict[str, Any]:
    """Bake parameters of a point level (empty for a mesh level)."""
    if not level.is_points:
        return {}
    params = level.params
    out: dict[str, Any] = {}
    if params is not None:
        out.update(
            resolution=params.resolution,
            slices=params.slices,
            point_size_px=params.point_size,
            filter=params.filter,
        )
    out.update(spacing=level.spacing, design_distance=level.design_distance)
    return _plain(out)


def _chain_extras(chain: LodChain) -> dict[str, Any]:
    """``extras.lodconvert`` of a chain's finest node: switching data and every level's facts."""
    return _plain(
        {
            "cutoffs": chain.cutoffs,
            "alpha": chain.alpha,
            "beta": chain.beta,
            "gamma": chain.gamma,
            "xs": chain.xs,
            "culled": chain.culled,
            "center": chain.center,
            **(
                {"transform": chain.transform.ravel(), "origin": chain.origin}
                if chain.transform is not None
                else {}
            ),
            "levels": [
                {"name": lv.name, "kind": lv.kind, "count": lv.count, **_level_params(lv)}
                for lv in chain.levels
            ],
        }
    )


def _cell_extras(cell: CellChain) -> dict[str, Any]:
    """``extras.lodconvert`` of a LOD parent's near node: its switching data and facts."""
    return _plain(
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


def _coverages(chain: LodChain | CellChain, view: ReferenceView) -> list[float]:
    """``MSFT_screencoverage``: one threshold per cutoff, then 0 unless the chain is culled."""
    values = [screen_coverage(chain.alpha, d, view) for d in chain.cutoffs]
    return [float(v) for v in values] + ([] if chain.culled else [0.0])


def _asset_extras(info: OutputInfo, frame: SceneFrame | None) -> dict[str, Any]:
    """``asset.extras.lodconvert``: provenance, the scene frame (a city's or one with a CRS) and the
    meaning of the coverage values."""
    return _plain(
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


def _root_node(chain: LodChain, finest: int, frame: SceneFrame | None) -> dict[str, Any]:
    """A chain's root node: translated to the chain's origin, or placed by the instance's
    matrix (from the ``frame``'s origin, where there is one), with the object's attributes
    (where a GIS user looks for them)."""
    placed = np.eye(4) if chain.transform is None else chain.transform.copy()
    placed[:3, 3] += placed[:3, :3] @ chain.origin
    if frame is not None:
        placed[:3, 3] = frame.offset(placed[:3, 3], f"object {chain.object_id!r}")
    moved_only = chain.transform is None or np.array_equal(placed[:3, :3], np.eye(3))
    return json_object(
        extras={"attributes": _plain(chain.metadata)} if chain.metadata else None,
        translation=[float(v) for v in placed[:3, 3]] if moved_only else None,
        children=[finest],
        matrix=None if moved_only else [float(v) for v in placed.T.ravel()],
        name=chain.object_id,
    )


def _level_name(chain: LodChain, level: Level) -> str:
    return f"{chain.object_id}_{level.name}"


def _level_node(
    chain: LodChain,
    level: Level,
    mesh: int | None,
    extras: dict[str, Any],
    extensions: dict[str, Any] | None = None,
    placed: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A node holding one level's mesh (none when the level is empty), ``placed`` by the
    translation and scale of its quantized positions where they are."""
    return json_object(
        extensions=extensions,
        extras=extras,
        mesh=mesh,
        name=_level_name(chain, level),
        **(placed or {}),
    )


class LodScene:
    """The scene of a :class:`Document`: chains and LOD parents added as nodes in ``MSFT_lod``
    layout (their level meshes from the buffers a worker made, in ``pieces``, where it did)."""

    def __init__(self, doc: Document, info: OutputInfo, pieces: Pieces) -> None:
        self.doc = doc
        self.info = info
        self.reference_view = info.view
        self.pieces = pieces
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
            "MSFT_screencoverage": _coverages(cell, self.reference_view),
            "lodconvert": _cell_extras(cell),
        }
        extensions = {MSFT_LOD: {"ids": [at]}}
        name = f"{cell.cell_id}_near"
        near_node = json_object(children=members, extensions=extensions, extras=extras, name=name)
        self.doc.nodes.append(near_node)
        for member in cell.members:
            self._add(member)
        far_name = f"{cell.cell_id}_{cell.far.name}"
        mesh = self.doc.level_mesh(far_name, cell.far)
        facts = {"level": cell.far.name, **_level_params(cell.far), "switch_in": cell.cutoffs[0]}
        translation = self._placed(cell.origin, f"cell {cell.cell_id!r}")
        steps = self.doc.mesh_nodes.get(mesh, {}) if mesh is not None else {}
        if steps:  # quantized positions: their corner from the cell's origin, their scale
            translation = translation + np.asarray(steps["translation"])
        far = json_object(
            extras={"lodconvert": _plain(facts)},
            mesh=mesh,
            name=far_name,
            translation=[float(v) for v in translation],
            scale=steps.get("scale"),
        )
        assert self.doc.nodes.append(far) == at

    def _add_chain(self, chain: LodChain) -> None:
        """Add a chain's root node, finest node (its child) and coarser nodes (their buffers
        as a worker made them, where one did)."""
        shared = chain.transform is not None
        made: ChainBuffers = self.pieces.take(chain) or (None,) * len(chain.levels)
        meshes = [
            self.doc.level_mesh(_level_name(chain, level), level, shared, buffers)
            for level, buffers in zip(chain.levels, made, strict=True)
        ]
        finest_mesh = meshes[0]
        coarser = list(zip(chain.levels[1:], chain.cutoffs, meshes[1:], strict=False))
        root = self.doc.nodes.append(_root_node(chain, len(self.doc.nodes) + 1, self.frame))
        ids = list(range(root + 2, root + 2 + len(coarser)))
        extras: dict[str, Any] = {}
        if ids:
            self.doc.use(MSFT_LOD)
            extras["MSFT_screencoverage"] = _coverages(chain, self.reference_view)
        extras["lodconvert"] = _chain_extras(chain)
        extensions = {MSFT_LOD: {"ids": ids}} if ids else None
        placed = self.doc.mesh_nodes.get
        finest = _level_node(
            chain, chain.levels[0], finest_mesh, extras, extensions, placed(finest_mesh)
        )
        self.doc.nodes.append(finest)
        for level, switch_in, mesh in coarser:
            facts = {"level": level.name, **_level_params(level), "switch_in": float(switch_in)}
            node = _level_node(chain, level, mesh, {"lodconvert": facts}, placed=placed(mesh))
            self.doc.nodes.append(node)

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
