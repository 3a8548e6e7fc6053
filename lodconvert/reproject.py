"""Several inputs in one CRS: each input whose CRS differs from the output's (the first input's,
or the one ``--crs`` names for all) is reprojected with pyproj, node by node as it is read, so a
streamed input stays streamed.

A scene's coordinates are metres in its CRS; a geographic CRS's are metres of the local frame
the reader projected them onto (:class:`~.io.crs.LocalFrame`), so a transformation goes back
through that frame's inverse to the CRS's own latitude and longitude, into the output's CRS,
and, where the output's CRS is geographic, onto its frame. Geometry stays relative to each
node's float64 origin; a shared mesh placed by a transform keeps its vertices, its placement
takes the transformation's local linear part (accurate to well under 1 mm over 100 m).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .io.crs import CrsError, frame_pipeline, pyproj_crs, vertical_reference
from .model import Mesh, Node, Scene, Surface, unpacked

Message = Callable[[str], None]
SOURCE_CRS_KEYS = ("local_frame", "vertical_crs")
"""Scene attributes that describe the CRS a reader found (:func:`~.io.crs.crs_attributes`)."""
_STEP = 1.0
"""Metres either side of a placement's point where its local linear part is measured."""


@dataclass(frozen=True)
class Georef:
    """Where a scene's coordinates lie: its CRS as outputs record it (``name``), the pyproj CRS
    it was declared in, and the PROJ definition of the local frame a geographic CRS's
    coordinates were projected onto (None for others)."""

    name: str
    crs: Any
    frame: str | None = None
    label: str = ""
    """The CRS as messages name it: the declared one (a local frame's source), with its
    vertical CRS where the file names one apart."""

    @classmethod
    def of(cls, scene: Scene) -> Georef | None:
        """The georeference of ``scene`` (None when it declares no CRS); raises pyproj's
        ``CRSError`` for a CRS that pyproj does not know."""
        if scene.crs is None:
            return None
        frame = scene.attributes.get("local_frame")
        declared = frame["source_crs"] if frame else scene.crs
        vertical = scene.attributes.get("vertical_crs")
        crs = pyproj_crs(declared, vertical)
        label = f"{declared} + {vertical}" if vertical else declared
        return cls(scene.crs, crs, frame["proj"] if frame else None, label)


class Reprojection:
    """The transformation of one scene's coordinates into another's (both float64 metres)."""

    def __init__(self, source: Georef, target: Georef) -> None:
        import pyproj

        self.source, self.target = source, target
        self.back = frame_pipeline(source.frame) if source.frame else None
        self.onto = frame_pipeline(target.frame) if target.frame else None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pyproj's own warning of missing grids
            group = pyproj.transformer.TransformerGroup(source.crs, target.crs, always_xy=True)
            self.transformer = pyproj.Transformer.from_crs(source.crs, target.crs, always_xy=True)
        self.best_available: bool = group.best_available
        # every transformation PROJ has takes the heights over as they are
        self.ballpark_heights = bool(group.transformers) and all(
            "ballpark vertical" in t.description.lower() for t in group.transformers
        )
        self.missing = sorted(
            {
                grid.short_name
                for operation in group.unavailable_operations[:1]
                for grid in operation.grids
                if not grid.available
            }
        )

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """``points`` (n, 3) of the source scene in the target scene's coordinates."""
        x, y, z = (np.array(points[:, k], dtype=np.float64) for k in range(3))
        if self.back is not None:
            x, y = self.back.transform(x, y, direction="INVERSE")
        x, y, z = self.transformer.transform(x, y, z)
        if self.onto is not None:
            x, y = self.onto.transform(x, y)
        return np.stack([x, y, z], axis=1)

    def placed(
        self, transform: np.ndarray, origin: np.ndarray, moved_origin: np.ndarray
    ) -> np.ndarray:
        """A node's 4×4 placement after ``origin``, in the target's coordinates after
        ``moved_origin``: its point moved, its axes turned and scaled by the transformation's
        local linear part there."""
        point = origin + transform[:3, 3]
        probes = point + np.vstack([np.zeros(3), _STEP * np.eye(3), -_STEP * np.eye(3)])
        moved = self(probes)
        jacobian = (moved[1:4] - moved[4:7]).T / (2 * _STEP)
        placed = np.eye(4)
        placed[:3, :3] = jacobian @ transform[:3, :3]
        placed[:3, 3] = moved[0] - moved_origin
        return placed

    def record(self, source: str) -> dict[str, Any]:
        """What the report says of this input's reprojection."""
        return {
            "input": source,
            "from": self.source.label,
            "to": self.target.label,
            "best_available": self.best_available,
            "missing_grids": self.missing,
            "ballpark_heights": self.ballpark_heights,
        }


def _reprojected_node(node: Node, reprojection: Reprojection) -> Node:
    """``node`` and its descendants moved into the target's coordinates, in place: meshes
    placed by a transform keep their vertices (the placement moves), other surfaces are
    transformed once each however many meshes share them."""
    surfaces: dict[int, tuple[Surface, Surface]] = {}
    meshes: dict[int, tuple[Mesh, Mesh]] = {}  # the old objects kept, so no id is reused

    def rebuilt(mesh: Mesh) -> Mesh:
        if id(mesh) not in meshes:
            meshes[id(mesh)] = (mesh, Mesh([surfaces[id(part)][1] for part in mesh.parts]))
        return meshes[id(mesh)][1]

    for each in node.walk():
        each.crs = reprojection.target.name
        origin = None if each.origin is None else reprojection(each.offset[None])[0]
        if each.transform is not None:
            each.transform = reprojection.placed(
                np.asarray(each.transform), each.offset, np.zeros(3) if origin is None else origin
            )
            each.origin = origin
            continue
        fresh = {
            id(part): part
            for mesh in (each.geometry, *each.lods.values())
            if mesh is not None
            for part in mesh.parts
            if id(part) not in surfaces
        }
        if fresh:
            parts = list(fresh.values())
            moved = reprojection(np.concatenate([p.vertices for p in parts]) + each.offset)
            if origin is not None:
                moved -= origin
            pieces = np.split(moved, np.cumsum([len(p.vertices) for p in parts])[:-1])
            for part, vertices in zip(parts, pieces, strict=True):
                surfaces[id(part)] = (part, replace(part, vertices=vertices))
        each.origin = origin
        each.lods = {label: rebuilt(mesh) for label, mesh in each.lods.items()}
        each.geometry = rebuilt(each.geometry) if each.geometry is not None else None
    return node


def _reprojected(scene: Scene, reprojection: Reprojection) -> Scene:
    """``scene`` in the target's CRS, its nodes transformed as they are taken."""
    nodes: Iterator[Node] | list[Node] = (
        _reprojected_node(unpacked(node), reprojection) for node in scene.nodes
    )
    if isinstance(scene.nodes, list):
        nodes = list(nodes)
    attributes = {k: v for k, v in scene.attributes.items() if k not in SOURCE_CRS_KEYS}
    return replace(scene, nodes=nodes, crs=reprojection.target.name, attributes=attributes)


@dataclass
class OneCrs:
    """The inputs of a run in the output's CRS, and what the report says of it."""

    scenes: list[Scene]
    record: dict[str, Any]


def in_one_crs(scenes: Sequence[Scene], warn: Message, georeferenced: bool = False) -> OneCrs:
    """``scenes`` in the CRS of the first that declares one (inputs that declare none are
    kept as they are: city inputs warned of, and where another declares one, meshes too); the
    report's ``crs``: the output's CRS, the vertical reference of its heights and the inputs
    reprojected. Raises :class:`CrsError` naming both files and CRSs where no transformation
    exists, and, for an output placed on the globe by its CRS (``georeferenced``), naming an
    input that declares none beside one that does; warns once per input where the best
    transformation is unavailable (PROJ without its datum grids)."""
    import pyproj

    first = next((scene for scene in scenes if scene.crs is not None), None)
    target = _georef(first, first) if first is not None else None
    done: list[Scene] = []
    reprojected: list[dict[str, Any]] = []
    for scene in scenes:
        if scene.crs is None:
            if first is not None:
                _without_crs(scene, first, target, warn, georeferenced)
            elif scene.city:
                warn(
                    f"{scene.source}: declares no CRS; its coordinates are written as they are "
                    "(--crs EPSG:… names it)"
                )
            done.append(scene)
            continue
        assert first is not None
        if _same_crs(scene, first):
            done.append(scene)
            continue
        if target is None:
            raise _no_way(scene, first, f"{first.crs} is no CRS pyproj knows")
        source = _georef(scene, first)
        assert source is not None
        try:
            reprojection = Reprojection(source, target)
        except pyproj.exceptions.ProjError as exc:
            raise _no_way(scene, first, str(exc)) from None
        if not reprojection.best_available:
            grids = ", ".join(reprojection.missing) or "a grid"
            heights = (
                ": heights are taken over as they are, and may be tens of metres off"
                if reprojection.ballpark_heights
                else ""
            )
            warn(
                f"{scene.source}: the best transformation from {source.label} into "
                f"{target.label} is unavailable ({grids} missing); a less accurate one is "
                f"used{heights}"
            )
        reprojected.append(reprojection.record(scene.source))
        done.append(_reprojected(scene, reprojection))
    record = {
        "name": first.crs if first is not None else None,
        "vertical": vertical_reference(target.crs if target is not None else None),
        "reprojected": reprojected,
    }
    return OneCrs(done, record)


def _without_crs(
    scene: Scene, first: Scene, target: Georef | None, warn: Message, georeferenced: bool
) -> None:
    """Warn that ``scene``, which declares no CRS, is taken to be in ``first``'s; raise
    :class:`CrsError` naming it instead for an output placed on the globe
    (``georeferenced``)."""
    what = "declares no CRS" if scene.city else "is a mesh, which declares no CRS"
    hint = " (--crs EPSG:… names it)" if scene.city else ""
    crs = target.label if target is not None else first.crs
    if georeferenced:
        raise CrsError(
            f"{what}, beside {Path(first.source).name} in {crs}; a 3D Tiles output places "
            f"every input on the globe by its CRS{hint or ': convert it on its own'}",
            scene.source,
        )
    warn(f"{scene.source}: {what}; its coordinates are taken to be in {crs}{hint}")


def _same_crs(scene: Scene, first: Scene) -> bool:
    """Whether ``scene`` is in ``first``'s CRS: the same name, and the same vertical CRS
    where both name one apart."""
    vertical = scene.attributes.get("vertical_crs"), first.attributes.get("vertical_crs")
    return scene.crs == first.crs and (None in vertical or vertical[0] == vertical[1])


def _georef(scene: Scene, first: Scene) -> Georef | None:
    """:meth:`Georef.of` ``scene``; a CRS that pyproj does not know is an error where it has
    to be transformed (into ``first``'s), else (``first`` itself) None."""
    import pyproj

    try:
        return Georef.of(scene)
    except pyproj.exceptions.CRSError as exc:
        if scene is first:
            return None
        raise _no_way(scene, first, str(exc).split("proj_create: ")[-1].rstrip(")")) from None


def _no_way(scene: Scene, first: Scene, reason: str) -> CrsError:
    """The error of an input whose CRS cannot be transformed into the first input's."""
    return CrsError(
        f"its CRS {scene.crs} cannot be transformed into {first.crs}, the CRS of "
        f"{Path(first.source).name} ({reason.splitlines()[0] if reason else 'no operation'})",
        scene.source,
    )
