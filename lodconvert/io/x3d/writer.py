"""The X3D 4.0 writer: a document streamed chain by chain (:func:`write_x3d`), each object a
``Transform`` holding its metadata and an ``LOD`` of its level ``Group`` s (or, with prism
switching, that LOD hidden in a ``Switch`` and :mod:`.prism`'s nodes drawing its levels), each
LOD parent a ``Group`` around an ``LOD`` of its members and its far level. A city's scene, or
one with a CRS, sits in one ``Transform`` turning it y-up (:mod:`lodconvert.io.frame`); the
``Viewpoint`` comes last (:mod:`.viewpoint`). Instances of shared geometry ``USE`` the first
one's LOD. Workers can make a chain's text (:class:`ChainTexts`), which the writer names.

The layout of a file, node by node, and the rules behind it: ``docs/x3d.md``.
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import BinaryIO

import numpy as np

from ...errors import UsageError
from ...model import CellChain, Level, LodChain
from .. import OutputInfo, Pieces
from ..frame import scene_frame
from ..numbers import format_exact
from .head import SWITCHING_MODES, root_fields, write_head
from .metadata import cell_metadata, chain_metadata, frame_metadata, level_metadata, metadata_set
from .names import appearance_name, derived_names, unique_names
from .prism import hidden_name, regions, write_prism
from .shapes import mesh_shapes, point_shapes
from .viewpoint import NAVIGATION, SceneBox
from .xmltext import XmlOut, piece_text

FRAME_DEF = "scene_frame"
"""DEF of the ``Transform`` that turns a georeferenced scene y-up (:mod:`lodconvert.io.frame`)."""
FRAME_ROTATION = "1 0 0 -1.5707963267948966"
"""The frame's ``rotation``: −90° about x, source (x, y, z) → scene (x, z, −y)."""


def _check_chain(chain: LodChain) -> None:
    """Raise ``ValueError`` unless ``chain``'s level names are unique and its cutoffs increase,
    one per level after the first (and one more for culling)."""
    names = [level.name for level in chain.levels]
    if len(set(names)) != len(names):
        raise ValueError(f"{chain.object_id}: level names must be unique: {names}")
    expected = len(chain.levels) - 1 + int(chain.culled)
    if len(chain.cutoffs) != expected:
        raise ValueError(
            f"{chain.object_id}: {len(chain.levels)} levels (culled={chain.culled}) need "
            f"{expected} cutoffs, got {len(chain.cutoffs)}"
        )
    if any(b <= a for a, b in zip(chain.cutoffs, chain.cutoffs[1:], strict=False)):
        raise ValueError(f"{chain.object_id}: cutoffs must increase strictly: {chain.cutoffs}")


def instance_fields(matrix: np.ndarray) -> dict[str, str]:
    """``Transform`` fields equal to the 4×4 ``matrix`` (no projective part): the linear part
    split by SVD into rotation · (scale along the axes of ``scaleOrientation``), as X3D
    composes them; reflections become a negative scale."""
    from scipy.spatial.transform import Rotation

    u, sigma, vt = np.linalg.svd(np.asarray(matrix, dtype=np.float64)[:3, :3])
    if np.linalg.det(u @ vt) < 0:
        u[:, -1], sigma[-1] = -u[:, -1], -sigma[-1]
    v = vt.T
    if np.linalg.det(v) < 0:
        v[:, -1] = -v[:, -1]
        u[:, -1] = -u[:, -1] if np.linalg.det(u @ v.T) < 0 else u[:, -1]

    def axis_angle(rotation: np.ndarray) -> list[float]:
        vector = Rotation.from_matrix(rotation).as_rotvec()
        angle = float(np.linalg.norm(vector))
        return [*(vector / angle if angle > 0 else (0.0, 0.0, 1.0)), angle]

    fields = {
        "translation": format_exact(np.asarray(matrix)[:3, 3]),
        "rotation": format_exact(axis_angle(u @ v.T)),
        "scale": format_exact(sigma),
    }
    if not np.allclose(sigma, sigma[0]):  # uniform scale needs no orientation
        fields["scaleOrientation"] = format_exact(axis_angle(v))
    return fields


@dataclass(frozen=True)
class _Written:
    """Levels shared by instances, as first written: the list (kept alive, so that ids stay
    unique), the DEF of their ``LOD`` and those of their level Groups."""

    levels: list[Level]
    lod: str
    level_defs: list[str]


@dataclass
class _Document:
    """What writing one document keeps from item to item: how levels switch, the scene origin
    positions are less (zero without a frame), the chains' text made by workers, the DEFs used
    so far and the levels shared by instances (by the id of their list)."""

    switching: str
    shift: np.ndarray
    pieces: Pieces
    used: set[str] = field(default_factory=set)
    written: dict[int, _Written] = field(default_factory=dict)

    def prism_regions(self, chain: LodChain) -> int | None:
        """How many regions ``chain`` switches on (``None``: it switches by an ``LOD``)."""
        return _prism_regions(chain, self.switching)


def _prism_regions(chain: LodChain, switching: str) -> int | None:
    """How many regions ``chain`` switches on with ``switching`` (``None``: by an ``LOD``)."""
    return len(chain.cutoffs) if switching == "prism" else None


_BASE = "\x00"
"""The DEF base in a worker's text of a chain, replaced by the one the writer gives it: no
text written holds this character (:func:`~.xmltext.escape`,
:mod:`~lodconvert.model.safe_text`)."""


@dataclass(frozen=True)
class ChainText:
    """What a chain's ``Transform`` holds, made by a worker (:class:`ChainTexts`) with
    :data:`_BASE` for its DEF base (:func:`piece_text`)."""

    inner: str


@dataclass(frozen=True)
class ChainTexts:
    """Makes the text of a chain that is not an instance of shared geometry, as the writer
    would with ``switching``, whatever DEF base the writer gives it."""

    switching: str = "lod"

    def __call__(self, chain: LodChain) -> ChainText | None:
        if chain.transform is not None:
            return None
        _check_chain(chain)
        region_count = _prism_regions(chain, self.switching)
        level_defs, _ = derived_names(_BASE, chain.levels, region_count)
        return ChainText(
            piece_text(lambda out: _write_contents(out, chain, _BASE, level_defs, region_count))
        )


def chain_texts(info: OutputInfo, suffix: str, switching: str = "lod") -> ChainTexts:
    """The X3D format's ``formatter`` (:mod:`lodconvert.io`; ``.x3d`` is its one ``suffix``)."""
    return ChainTexts(switching)


def _write_chain(out: XmlOut, chain: LodChain, doc: _Document) -> None:
    """One chain: its ``Transform`` (inside one more for an instance of shared geometry) with
    the chain's metadata and its ``LOD`` — defined the first time its levels are written,
    ``USE`` d by later instances. With prism switching the LOD goes into a ``Switch`` that
    draws nothing, followed by the nodes that draw its levels (:func:`write_prism`). Positions
    are less ``doc.shift``: an object's translation, or an instance's placement (its chain
    keeps its origin, as its facts declare). A worker's text of the chain is used where there
    is one, with the DEF base given here."""
    piece: ChainText | None = doc.pieces.take(chain)
    shared = doc.written.get(id(chain.levels))
    prism_regions = doc.prism_regions(chain)
    levels = [] if shared else chain.levels
    base, level_defs = unique_names(chain.object_id, doc.used, levels, prism_regions)
    if piece is not None:
        placed = {"DEF": base, "translation": format_exact(chain.origin - doc.shift)}
        with out.node("Transform", placed):
            out.inserted(piece.inner.replace(_BASE, base))
        return
    _check_chain(chain)
    origin = chain.origin if chain.transform is not None else chain.origin - doc.shift
    transform = {"DEF": base, "translation": format_exact(origin)}
    with contextlib.ExitStack() as stack:
        if chain.transform is not None:
            placed = chain.transform.copy()
            placed[:3, 3] -= doc.shift
            fields = {"DEF": f"{base}_instance", **instance_fields(placed)}
            stack.enter_context(out.node("Transform", fields))
        with out.node("Transform", transform):
            _write_contents(out, chain, base, level_defs, prism_regions, shared, doc.written)


def _write_contents(
    out: XmlOut,
    chain: LodChain,
    base: str,
    level_defs: list[str],
    prism_regions: int | None,
    shared: _Written | None = None,
    written: dict[int, _Written] | None = None,
) -> None:
    """What a chain's ``Transform`` holds: the chain's metadata (on the Transform: X3DOM counts
    a MetadataSet inside LOD as its first level), its ``LOD`` and, with prism switching, the
    nodes that draw its levels."""
    metadata_set(out, chain_metadata(chain))
    if prism_regions is None:
        _write_lod(out, chain, base, level_defs, shared, written)
        return
    hidden = {"DEF": hidden_name(base), "whichChoice": "-1"}
    with out.node("Switch", hidden):
        _write_lod(out, chain, base, level_defs, shared, written)
    defs = shared.level_defs if shared else level_defs
    write_prism(out, chain, regions(base, prism_regions), defs)


def _write_lod(
    out: XmlOut,
    chain: LodChain,
    base: str,
    level_defs: list[str],
    shared: _Written | None,
    written: dict[int, _Written] | None,
) -> None:
    """The chain's ``LOD``: a ``USE`` of the ``shared`` one, or defined with its levels (and,
    for an instance, remembered in ``written``)."""
    if shared:
        out.leaf("LOD", {"USE": shared.lod})
        return
    lod = {
        "DEF": f"{base}_LOD",
        "center": format_exact(chain.center),
        "range": format_exact(chain.cutoffs),
        "forceTransitions": "true",
    }
    if chain.transform is not None and written is not None:
        written[id(chain.levels)] = _Written(chain.levels, lod["DEF"], level_defs)
    with out.node("LOD", lod):
        _write_levels(out, chain, level_defs)


def _write_item(out: XmlOut, item: LodChain | CellChain, doc: _Document) -> None:
    """An object's chain, or a LOD parent with everything in it."""
    if isinstance(item, CellChain):
        _write_cell(out, item, doc)
    else:
        _write_chain(out, item, doc)


def _write_cell(out: XmlOut, cell: CellChain, doc: _Document) -> None:
    """A LOD parent: a ``Group`` with the cell's metadata around an ``LOD`` (centred on the
    members' bounding box, in scene coordinates) whose near child holds the members as they
    are written alone and whose far child is the cell's one level, in a ``Transform`` to the
    cell's origin (then an empty ``Group`` for a culled cell); positions less ``doc.shift``."""
    base, (far_def,) = unique_names(cell.cell_id, doc.used, [cell.far])
    near, far = f"{base}_near", f"{base}_far"
    doc.used.update((near, far))
    with out.node("Group", {"DEF": base}):
        metadata_set(out, cell_metadata(cell))
        lod = {
            "DEF": f"{base}_LOD",
            "center": format_exact(cell.origin - doc.shift + cell.center),
            "range": format_exact(cell.cutoffs),
            "forceTransitions": "true",
        }
        with out.node("LOD", lod):
            with out.node("Group", {"DEF": near}):
                for member in cell.members:
                    _write_item(out, member, doc)
            placed = format_exact(cell.origin - doc.shift)
            with out.node("Transform", {"DEF": far, "translation": placed}):
                # the far level shows from the cell's first cutoff on, like a chain's second
                _write_level(out, cell.far, far_def, cell.cutoffs, 1, cell.alpha)
            if cell.culled:
                out.leaf("Group")


def _write_level(
    out: XmlOut, level: Level, name: str, cutoffs: Sequence[float], index: int, alpha: float
) -> None:
    """Level ``index`` of a chain with ``cutoffs`` as a ``Group`` named ``name``."""
    bounds = [0.0, *cutoffs]
    switch_out = bounds[index + 1] if index + 1 < len(bounds) else None
    with out.node("Group", {"DEF": name}):
        metadata_set(out, level_metadata(level, bounds[index], switch_out))
        if not level.is_points:
            assert level.mesh is not None
            mesh_shapes(out, level.mesh, appearance_name(name))
        else:
            point_shapes(out, level, bounds[index], alpha, appearance_name(name))


def _write_levels(out: XmlOut, chain: LodChain, level_defs: list[str]) -> None:
    """The LOD's children: one Group per level, finest first, then the empty cull child."""
    for i, (level, name) in enumerate(zip(chain.levels, level_defs, strict=True)):
        _write_level(out, level, name, chain.cutoffs, i, chain.alpha)
    if chain.culled:
        out.leaf("Group")


def write_x3d(
    chains: Iterable[LodChain],
    handle: BinaryIO,
    info: OutputInfo,
    switching: str = "lod",
    pieces: Pieces | None = None,
) -> None:
    """Write ``chains`` as an X3D 4.0 XML document to the binary ``handle``, each object's
    levels switching as ``switching`` says (one of :data:`SWITCHING_MODES`; else
    :class:`~lodconvert.errors.UsageError`); a chain's text in ``pieces`` (made by a worker,
    :class:`ChainTexts`) is written with the DEF names given here.

    The document is streamed: each chain is written (and flushed) as the iterable yields it, so
    only one chain's text is held in memory. Same input, same bytes.
    """
    if switching not in SWITCHING_MODES:
        modes = " or ".join(SWITCHING_MODES)
        raise UsageError(f"must be {modes}, not {switching!r}", field="switching")
    out = XmlOut(handle)
    with out.node("X3D", root_fields(switching)):
        write_head(out, info, switching)
        with out.node("Scene"):
            items = iter(chains)
            first = next(items, None)
            frame = scene_frame(info.framed, first, info.origin) if first is not None else None
            box = SceneBox(frame)
            shift = frame.origin if frame is not None else np.zeros(3)
            doc = _Document(switching, shift, pieces or Pieces())
            with contextlib.ExitStack() as framed:
                if frame is not None:
                    doc.used.add(FRAME_DEF)
                    attrib = {"DEF": FRAME_DEF, "rotation": FRAME_ROTATION}
                    framed.enter_context(out.node("Transform", attrib))
                    frame_metadata(out, frame)
                for item in itertools.chain([first] if first is not None else [], items):
                    _write_item(out, item, doc)
                    box.add(item)
                    out.flush()
            view = box.viewpoint()
            if view is not None:
                out.leaf("NavigationInfo", NAVIGATION)
                out.leaf("Viewpoint", view)
    out.flush()
    handle.write(b"\n")
