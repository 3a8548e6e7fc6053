"""One tile's content as a picklable task, run by any executor (:mod:`lodconvert.tasks`): its
levels' geometry (:class:`Placed`, opened here where it comes packed) placed in the scene, in
ECEF and in the tile's ENU frame and encoded as a GLB; the result is the GLB, the tile's frame
and content box, which the main process writes into
the staged tileset folder (:meth:`.records.TileRecords.written`), so that a worker needs no
access to it.

Resuming: a task is keyed by a hash of everything that makes its file (:meth:`TileTask.key`:
the placement, the geometry, colours and features, the generator), which the main process
records beside the file (:mod:`.records`).
"""

from __future__ import annotations

import hashlib
import json
import pickle
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import LodConvertError
from ...model import (
    Mesh,
    Numbers,
    Packed,
    PointCloud,
    Surface,
    as_numbers,
    from_numbers,
    in_scene,
)
from ...textures import ATLAS_SIZE
from ..findings import failure_of
from ..gltf.compression import MESHOPT, POSITION_TOLERANCE
from .check import check_content
from .content import TileTextures, mesh_glb, points_glb
from .metadata import Feature
from .placement import Placement, world_to_frame

# glTF content is y-up; 3D Tiles turns it z-up: (x, y, z) -> (x, -z, y). ENU (e, n, u) is
# therefore written as (e, u, -n).
ENU_TO_GLTF = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
TILES = "tiles"
"""The folder of the tiles' files in the tileset folder."""
MARGIN = 0.001
"""Metres a bounding box is grown by on every side (float32 content rounding, flat content)."""


@dataclass(frozen=True)
class Where:
    """What places a scene on the globe (:class:`Placement`'s arguments) and a text naming it
    for tile keys."""

    georef: Any
    crs_name: str | None
    source: str
    key: str

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled once per run (its CRS is long text), and unpickled once per process: a
        tileset has a task per tile, each with its :class:`Where`."""
        if self.key not in _pickled:
            _pickled[self.key] = pickle.dumps(tuple(vars(self).values()), pickle.HIGHEST_PROTOCOL)
        return _where, (self.key, _pickled[self.key])


_pickled: dict[str, bytes] = {}
"""This process's pickled :class:`Where` s, by key."""
_unpickled: dict[str, Where] = {}
"""This process's unpickled :class:`Where` s, by key."""


def _where(key: str, data: bytes) -> Where:
    """The :class:`Where` of ``key``, unpickled from ``data`` the first time."""
    if key not in _unpickled:
        _unpickled[key] = Where(*pickle.loads(data))
    return _unpickled[key]


_placements: dict[str, Placement] = {}
"""This process's placements, by :attr:`Where.key`."""


def placement(where: Where) -> Placement:
    """The placement of ``where``, made once per process."""
    if where.key not in _placements:
        _placements[where.key] = Placement(where.georef, where.crs_name, where.source)
    return _placements[where.key]


@dataclass(frozen=True)
class TileResult:
    """A tile's ENU frame (4×4, ECEF) and content box (min and max corners in it), its GLB
    and key (until written), whether its file was kept from an interrupted run, or why it could
    not be made (``error``)."""

    frame: np.ndarray | None
    box: np.ndarray | None
    reused: bool = False
    error: str | None = None
    data: bytes | None = None
    key: str | None = None


@dataclass(frozen=True)
class Placed:
    """One level drawn in a tile: its geometry (a mesh or points relative to ``origin``, or
    either packed where it was baked) placed by ``transform`` as
    :attr:`~lodconvert.model.LodChain.transform` says."""

    level: Mesh | PointCloud | Packed
    origin: np.ndarray
    transform: np.ndarray | None = None

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled with its origin and transform as numbers (a tile has one per object)."""
        return _restored, (self.level, as_numbers(self.origin), as_numbers(self.transform))

    def geometry(self) -> Mesh | PointCloud:
        """The level's mesh in scene coordinates, or its points (relative to ``origin``)."""
        level = self.level.opened() if isinstance(self.level, Packed) else self.level
        if isinstance(level, Mesh):
            return in_scene(level, self.origin, self.transform)
        return level


def _restored(
    level: Mesh | PointCloud | Packed, origin: Numbers, transform: Numbers | None
) -> Placed:
    """The :class:`Placed` that its ``__reduce__`` pickled."""
    restored = from_numbers(origin)
    assert restored is not None
    return Placed(level, restored, from_numbers(transform))


@dataclass(frozen=True)
class Drawn:
    """What a tile draws: ``vertices`` in scene coordinates, ``colors`` (n, 4) sRGB bytes,
    triangles (``faces``; ``None``: points), each vertex's feature (``feature_ids``; ``None``:
    no features) and the textures of its textured vertices."""

    vertices: np.ndarray
    colors: np.ndarray
    faces: np.ndarray | None = None
    feature_ids: np.ndarray | None = None
    textures: TileTextures | None = None


@dataclass(frozen=True)
class TileTask:
    """The GLB ``name`` in the tileset's ``tiles/``: the levels of ``sources``, one feature per
    level (``features``), or, without features, one far level drawn as it is (its mesh, in
    its colours and textures, or points); textures packed into atlas pages of
    ``atlas_size``; its geometry compressed as ``compress``
    (:data:`~..gltf.compression.COMPRESSIONS`) says (meshopt positions within ``tolerance``
    metres), its atlas pages with a ``copy`` where asked. The sources' geometry is placed
    where the task runs: packed geometry is opened only there."""

    name: str
    where: Where
    sources: tuple[Placed, ...]
    features: tuple[Feature, ...]
    generator: str
    atlas_size: int = ATLAS_SIZE
    compress: str = MESHOPT
    copy: str = ""
    tolerance: float = POSITION_TOLERANCE[0]

    def drawn(self) -> Drawn:
        """What the tile draws, its sources placed in the scene."""
        if not self.features:
            (source,) = self.sources
            far = source.geometry()
            if isinstance(far, PointCloud):
                return Drawn(far.positions + source.origin, far.colors)
            colors = np.concatenate([_colors(part) for part in far.parts])
            return Drawn(far.vertices, colors, far.faces, textures=_textures([far]))
        placed = [source.geometry() for source in self.sources]
        meshes = [mesh for mesh in placed if isinstance(mesh, Mesh)]
        starts = np.cumsum([0] + [mesh.vertex_count for mesh in meshes])
        return Drawn(
            np.concatenate([mesh.vertices for mesh in meshes]),
            np.concatenate([_colors(part) for mesh in meshes for part in mesh.parts]),
            np.concatenate(
                [mesh.faces + start for mesh, start in zip(meshes, starts[:-1], strict=True)]
            ),
            np.repeat(np.arange(len(meshes)), np.diff(starts)),
            _textures(meshes),
        )

    def key(self, drawn: Drawn | None = None) -> str:
        """The hash of everything that makes this tile's file, frame and box (``drawn``: what
        it draws, where already found)."""
        drawn = drawn or self.drawn()
        digest = hashlib.sha256()
        head = [self.name, self.where.key, self.generator, self.features, self.compress]
        head += [self.copy, self.tolerance]
        textures = drawn.textures
        if textures is not None:
            head += [self.atlas_size, textures.photographic]
        digest.update(json.dumps(head, sort_keys=True, default=str).encode())
        arrays = [drawn.vertices, drawn.colors, drawn.faces, drawn.feature_ids]
        if textures is not None:
            arrays += [textures.image_of, textures.uv, *textures.images]
        for array in arrays:
            if array is None:
                digest.update(b"-")
                continue
            digest.update(f"{array.dtype.str}{array.shape}".encode())
            digest.update(np.ascontiguousarray(array).tobytes())
        return digest.hexdigest()

    def run(self, backend: Any = None, progress: Any = None) -> TileResult:
        """Make the tile's GLB, frame and box; a scene that cannot be placed is the result's
        ``error``."""
        drawn = self.drawn()
        try:
            place = placement(self.where)
            ecef = place.ecef(drawn.vertices)
            frame = place.enu_frame((ecef.min(axis=0) + ecef.max(axis=0)) / 2.0)
            local = world_to_frame(frame, ecef)
            data = self._glb(drawn, local @ ENU_TO_GLTF.T)
        except LodConvertError as exc:
            return self.failed(str(exc))
        box = np.stack([local.min(axis=0), local.max(axis=0)])
        grown = box + np.array([[-MARGIN], [MARGIN]])  # as the tileset's box of it grows
        failure = failure_of(check_content(data, grown, self.path))
        if failure is not None:
            return self.failed(failure)
        return TileResult(frame, box, data=data, key=self.key(drawn))

    @property
    def path(self) -> str:
        """The tile's file in the tileset folder."""
        return f"{TILES}/{self.name}"

    def _glb(self, drawn: Drawn, gltf: np.ndarray) -> bytes:
        """The GLB of ``drawn`` at glTF coordinates ``gltf``."""
        if drawn.faces is None:
            return points_glb(gltf, drawn.colors, self.generator, self.compress, self.tolerance)
        return mesh_glb(
            gltf, drawn.faces, drawn.colors, drawn.feature_ids, self.features, self.generator,
            drawn.textures, self.atlas_size, self.compress, self.copy, self.tolerance,
        )  # fmt: skip

    def failed(self, reason: str) -> TileResult:
        """The result of this task when it could not run, for ``reason``."""
        return TileResult(None, None, error=reason)


def _colors(part: Surface) -> np.ndarray:
    """(n, 4) sRGB bytes per vertex of a part of a tile's meshes: white where its texture is
    written (it carries the colour), else its colours."""
    if part.texture is not None and part.uv is not None:
        return np.full((len(part.vertices), 4), 255, dtype=np.uint8)
    return part.baked_colors()


def _textures(meshes: list[Mesh]) -> TileTextures | None:
    """The textures of ``meshes``' vertices (each image once, however many copies of it the
    meshes hold), or None where none is textured."""
    images: dict[int, int] = {}
    by_content: dict[bytes, int] = {}
    found: list[np.ndarray] = []
    image_of, uv = [], []
    photographic = True
    for part in (part for mesh in meshes for part in mesh.parts):
        if part.texture is None or part.uv is None:
            image_of.append(np.full(len(part.vertices), -1, dtype=np.int64))
            uv.append(np.zeros((len(part.vertices), 2)))
            continue
        if id(part.texture) not in images:
            images[id(part.texture)] = by_content.setdefault(_digest(part.texture), len(found))
            if images[id(part.texture)] == len(found):
                found.append(part.texture)
        image_of.append(np.full(len(part.vertices), images[id(part.texture)], dtype=np.int64))
        uv.append(part.uv)
        photographic = photographic and part.photographic
    if not found:
        return None
    return TileTextures(np.concatenate(image_of), np.concatenate(uv), tuple(found), photographic)


def _digest(image: np.ndarray) -> bytes:
    """What tells an image's texels from another's."""
    digest = hashlib.blake2b(f"{image.dtype.str}{image.shape}".encode(), digest_size=16)
    digest.update(np.ascontiguousarray(image).tobytes())
    return digest.digest()
