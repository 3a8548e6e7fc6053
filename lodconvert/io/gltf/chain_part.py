"""A chain's part of a glTF document: its meshes and nodes (:func:`add_chain`), from the JSON
text of its nodes that holds no index (:class:`ChainText`: the object's name and attributes,
its levels' names, the switching data and facts of its finest node and those of each coarser
one). The worker that bakes a chain makes its part apart (:class:`ChainParts`, the glTF formats'
``formatter``: a :class:`~.document.PartDocument`), so that the writer only fills in where it
lands (:meth:`~.document.Document.merge`). What the nodes hold: ``docs/gltf.md``."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...model import CellChain, Level, LodChain
from ...ranges import ReferenceView, screen_coverage
from .. import OutputInfo
from .compression import NONE, check_compression
from .document import TRANSLATION, Document, DocumentPart, PartDocument
from .json_text import COMPACT, INDENTED, Layout
from .texture_copies import check_texture_format

MSFT_LOD = "MSFT_lod"
MEMBER_DEPTH = 3
"""Where a node's (or a mesh's) members start in the document: ``nodes`` (1), a node (2)."""


def plain(value: Any) -> Any:
    """``value`` as JSON-able Python data: numpy scalars and arrays unpacked, tuples as lists,
    non-finite floats as ``None``, unknown objects as their ``str``."""
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return plain(value.item())
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, str | int):
        return value
    return str(value)


def level_params(level: Level) -> dict[str, Any]:
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
    return plain(out)


def coverages(chain: LodChain | CellChain, view: ReferenceView) -> list[float]:
    """``MSFT_screencoverage``: one threshold per cutoff, then 0 unless the chain is culled."""
    values = [screen_coverage(chain.alpha, d, view) for d in chain.cutoffs]
    return [float(v) for v in values] + ([] if chain.culled else [0.0])


def _chain_extras(chain: LodChain) -> dict[str, Any]:
    """``extras.lodconvert`` of a chain's finest node: switching data and every level's facts."""
    return plain(
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
                {"name": lv.name, "kind": lv.kind, "count": lv.count, **level_params(lv)}
                for lv in chain.levels
            ],
        }
    )


def coarser_count(chain: LodChain) -> int:
    """How many levels after the finest have a node listed in ``MSFT_lod`` (one per cutoff)."""
    return min(len(chain.levels) - 1, len(chain.cutoffs))


@dataclass(frozen=True)
class ChainText:
    """A chain's node texts that hold no index, each laid out as a node's member: the
    object's ``name`` and ``attributes`` (its root's ``extras``, ``None`` without
    attributes), each level node's (and mesh's) name, the finest node's ``extras`` and each
    coarser node's ``facts`` (its ``extras``)."""

    name: str
    attributes: str | None
    levels: tuple[str, ...]
    extras: str
    facts: tuple[str, ...]


def chain_text(chain: LodChain, view: ReferenceView, layout: Layout) -> ChainText:
    """The :class:`ChainText` of ``chain`` for the reference ``view``, laid out by ``layout``."""

    def text(value: Any) -> str:
        return layout.text(value, MEMBER_DEPTH)

    coarser = coarser_count(chain)
    extras: dict[str, Any] = {}
    if coarser:
        extras["MSFT_screencoverage"] = coverages(chain, view)
    extras["lodconvert"] = _chain_extras(chain)
    facts = tuple(
        text({"lodconvert": {"level": lv.name, **level_params(lv), "switch_in": float(d)}})
        for lv, d in zip(chain.levels[1 : 1 + coarser], chain.cutoffs[:coarser], strict=True)
    )
    return ChainText(
        name=text(chain.object_id),
        attributes=text({"attributes": plain(chain.metadata)}) if chain.metadata else None,
        levels=tuple(text(f"{chain.object_id}_{lv.name}") for lv in chain.levels),
        extras=text(extras),
        facts=facts,
    )


def numbers_text(layout: Layout, values: Iterable[float]) -> str:
    """A node member's list of numbers as JSON text (:class:`ValueError` for one that is not
    finite, as the JSON encoder)."""
    texts = []
    for value in values:
        number = float(value)
        if not math.isfinite(number):
            raise ValueError(f"Out of range float values are not JSON compliant: {number!r}")
        texts.append(float.__repr__(number))
    return layout.array_text(texts, MEMBER_DEPTH)


def _root_node(
    doc: Document, text: ChainText, finest: int, translation: str | None, matrix: str | None
) -> str:
    """A chain's root node: ``translation`` to the chain's origin, or placed by the
    instance's ``matrix`` (JSON texts), with the object's attributes (where a GIS user looks
    for them)."""
    layout = doc.layout
    members = [("extras", text.attributes)] if text.attributes is not None else []
    if translation is not None:
        members.append(("translation", translation))
    members.append(("children", layout.array_text([doc.ref("n", finest)], MEMBER_DEPTH)))
    if matrix is not None:
        members.append(("matrix", matrix))
    members.append(("name", text.name))
    return layout.object_text(members, MEMBER_DEPTH - 1)


def _level_node(
    doc: Document, name: str, mesh: int | None, extras: str, extensions: str | None = None
) -> str:
    """A node holding one level's mesh (none when the level is empty), placed by the
    translation and scale of its quantized positions where they are; ``name``, ``extras`` and
    ``extensions`` as JSON text."""
    members = [("extensions", extensions)] if extensions is not None else []
    members.append(("extras", extras))
    if mesh is not None:
        members.append(("mesh", doc.ref("M", mesh)))
    members.append(("name", name))
    for key, values in doc.mesh_nodes.get(mesh, {}).items() if mesh is not None else ():
        members.append((key, numbers_text(doc.layout, values)))
    return doc.layout.object_text(members, MEMBER_DEPTH - 1)


def _lod_ids(doc: Document, ids: list[int]) -> str:
    """A finest node's ``extensions`` text: ``MSFT_lod`` listing its coarser nodes."""
    layout = doc.layout
    listed = layout.array_text([doc.ref("n", i) for i in ids], MEMBER_DEPTH + 2)
    lod = layout.object_text([("ids", listed)], MEMBER_DEPTH + 1)
    return layout.object_text([(MSFT_LOD, lod)], MEMBER_DEPTH)


def add_chain(
    doc: Document,
    chain: LodChain,
    text: ChainText,
    translation: str | None = None,
    matrix: str | None = None,
) -> None:
    """Add a chain's meshes, root node (placed by the JSON text of its ``translation`` or
    ``matrix``), finest node (its child) and coarser nodes (listed in its ``MSFT_lod``)."""
    shared = chain.transform is not None
    meshes = [
        doc.level_mesh(name, level, shared)
        for name, level in zip(text.levels, chain.levels, strict=True)
    ]
    root = doc.nodes.append_text(_root_node(doc, text, len(doc.nodes) + 1, translation, matrix))
    ids = list(range(root + 2, root + 2 + coarser_count(chain)))
    if ids:
        doc.use(MSFT_LOD)
    extensions = _lod_ids(doc, ids) if ids else None
    doc.nodes.append_text(_level_node(doc, text.levels[0], meshes[0], text.extras, extensions))
    for name, mesh, facts in zip(text.levels[1:], meshes[1:], text.facts, strict=False):
        doc.nodes.append_text(_level_node(doc, name, mesh, facts))


@dataclass(frozen=True)
class ChainPart:
    """A chain's part of a glTF document laid out with ``indent``, made apart."""

    indent: int | None
    part: DocumentPart


@dataclass(frozen=True)
class ChainParts:
    """Makes the :class:`ChainPart` of a chain that is not an instance of shared geometry
    (whose levels are written once, by the first), as the writer of a document laid out with
    ``indent`` adds it, for the reference ``view``, compressed as ``compress`` says, textures
    with a ``copy`` where asked (:func:`~.texture_copies.check_texture_format`); its root's
    translation is left to the writer, which knows the scene frame."""

    view: ReferenceView
    indent: int | None
    compress: str
    copy: str

    def __call__(self, chain: LodChain) -> ChainPart | None:
        if chain.transform is not None:
            return None
        layout = COMPACT if self.indent is None else INDENTED
        doc = PartDocument(layout, self.compress, self.copy)
        add_chain(doc, chain, chain_text(chain, self.view, layout), TRANSLATION)
        return ChainPart(self.indent, doc.part())


def chain_parts(
    info: OutputInfo, suffix: str, compress: str = NONE, texture_format: str = "default"
) -> ChainParts:
    """The glTF formats' ``formatter`` (:mod:`lodconvert.io`) for a ``.glb`` (compact JSON)
    or ``.gltf`` (indented) ``suffix``."""
    indent = COMPACT.indent if suffix == ".glb" else INDENTED.indent
    copy = check_texture_format(texture_format)
    return ChainParts(info.view, indent, check_compression(compress), copy)
