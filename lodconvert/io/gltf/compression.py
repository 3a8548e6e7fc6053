"""Compressed glTF geometry (``--compress``, docs/compression.md): vertex attributes stored as
small integers (``KHR_mesh_quantization``: positions as 16-bit steps of the content's extent
under the node's scale, normals as signed bytes, texture coordinates as 16-bit fractions)
and buffer views packed with meshoptimizer's codecs (``EXT_meshopt_compression``, the
views' uncompressed layout in a fallback buffer that holds no bytes)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import UsageError
from .binary import ARRAY_BUFFER
from .binary import MESHOPT as MESHOPT_EXTENSION

NONE, MESHOPT, QUANTIZE = "none", "meshopt", "quantize"
COMPRESSIONS = (NONE, MESHOPT, QUANTIZE)
"""The ``--compress`` choices: ``meshopt`` keeps positions exact (float32) and stores normals
and texture coordinates as ``quantize`` does, under meshopt's codecs; ``quantize`` stores
positions as 16-bit steps too, without the codecs."""
QUANTIZATION = "KHR_mesh_quantization"
PACKING_COST = 160
"""Bytes a packed view's JSON adds (its extension object, the fallback view's stride): a
view is packed only where that saves more."""
POSITION_TOLERANCE = (5e-5, 1e-3)
"""The least and most metres a ``meshopt`` position of a tile may move: a thousandth of the
tile's geometric error between them (:func:`position_tolerance`), from a twentieth of the
1 mm placement claim (a leaf's, below a source's millimetres) to that claim. A ``.glb``, whose
units may not be metres, keeps float32's own step."""


def position_tolerance(geometric_error: float) -> float:
    """How far (metres) a ``meshopt`` position of a tile of ``geometric_error`` may move:
    a thousandth of it (a 16 px screen-space error there is 0.016 px), within
    :data:`POSITION_TOLERANCE`."""
    least, most = POSITION_TOLERANCE
    return min(most, max(least, geometric_error / 1000.0))


POSITION_STEPS = 65535
"""Steps of a quantized position across the content's largest extent."""


def check_compression(name: str) -> str:
    """``name`` when it is one of :data:`COMPRESSIONS`, else :class:`UsageError`."""
    if name not in COMPRESSIONS:
        raise UsageError(f"--compress must be one of {', '.join(COMPRESSIONS)}, got {name!r}")
    return name


@dataclass(frozen=True)
class Quantizer:
    """Positions as 16-bit steps: a position is ``translation`` + ``scale`` × its steps (the
    transform of the node holding them)."""

    translation: tuple[float, float, float]
    scale: float

    def steps(self, positions: np.ndarray) -> np.ndarray:
        """``positions`` (n, 3) as the nearest steps (uint16)."""
        steps = np.rint((positions - np.asarray(self.translation)) / self.scale)
        return steps.clip(0, POSITION_STEPS).astype(np.uint16)

    def positions(self, steps: np.ndarray) -> np.ndarray:
        """The positions ``steps`` stand for (float64)."""
        return np.asarray(self.translation) + self.scale * steps.astype(np.float64)

    def node(self) -> dict[str, Any]:
        """The node fields that turn the steps back into positions."""
        return {"translation": list(self.translation), "scale": [self.scale] * 3}


def quantizer(positions: np.ndarray) -> Quantizer:
    """Steps of ``positions``' largest extent / :data:`POSITION_STEPS` from their least
    corner (one scale for all axes, so normals need no correction)."""
    low = positions.min(axis=0) if len(positions) else np.zeros(3)
    extent = float((positions.max(axis=0) - low).max()) if len(positions) else 0.0
    scale = extent / POSITION_STEPS if extent > 0 else 1.0
    return Quantizer((float(low[0]), float(low[1]), float(low[2])), scale)


Filtered = tuple[np.ndarray, str]
"""A vertex attribute's data under a meshopt filter, and the filter's name."""


@dataclass(frozen=True)
class StoredAttribute:
    """A ``NORMAL`` or ``TEXCOORD_0`` accessor's ``values`` as stored (those a reader
    decodes), whether they are normalized integers (quantized), and the filtered data packed
    in their place (``filtered``)."""

    values: np.ndarray
    normalized: bool = False
    filtered: Filtered | None = None


def stored_attribute(name: str, values: np.ndarray, compress: str) -> StoredAttribute:
    """A ``NORMAL`` or ``TEXCOORD_0`` accessor's float32 ``values`` as ``compress`` stores
    them: unit normals as signed bytes (``meshopt``: under the octahedral filter, 8 bits),
    texture coordinates in [0, 1] as 16-bit fractions (others keep float32, as a repeating
    texture needs)."""
    if compress == NONE:
        return StoredAttribute(values)
    if name == "NORMAL":
        if compress != MESHOPT:
            return StoredAttribute(
                np.rint(np.clip(values, -1.0, 1.0) * 127.0).astype(np.int8), True
            )
        from .meshopt import from_octahedral, octahedral  # numba loaded here (compiled codecs)

        words = octahedral(values)
        return StoredAttribute(from_octahedral(words)[:, :3], True, (words, "OCTAHEDRAL"))
    if len(values) and not (
        np.isfinite(values).all() and values.min() >= 0.0 and values.max() <= 1.0
    ):
        return StoredAttribute(values)
    return StoredAttribute(np.rint(values * 65535.0).astype(np.uint16), True)


@dataclass(frozen=True)
class StoredView:
    """What a buffer view holds: ``data`` (its bytes in the buffer: packed with meshopt where
    ``packed`` gives the extension's fields other than where the data lies), its uncompressed
    ``length`` and ``stride`` (``None``: elements tightly packed)."""

    data: bytes
    length: int
    stride: int | None = None
    packed: dict[str, Any] | None = None

    def json(
        self, target: int | None, offset: int | str, fallback_offset: int | str
    ) -> dict[str, Any]:
        """The buffer view, its data at ``offset`` of buffer 0; a packed one's uncompressed
        layout at ``fallback_offset`` of the fallback buffer (1); offsets are numbers, or the
        marks of a chain's part (:class:`~.document.PartDocument`)."""
        if self.packed is None:
            view = {"buffer": 0, "byteOffset": offset, "byteLength": self.length}
        else:
            view = {"buffer": 1, "byteOffset": fallback_offset, "byteLength": self.length}
        if self.stride is not None:
            view["byteStride"] = self.stride
        if target is not None:
            view["target"] = target
        if self.packed is not None:
            packed = {"buffer": 0, "byteOffset": offset, **self.packed}
            view["extensions"] = {MESHOPT_EXTENSION: packed}
        return view


def _rows(array: np.ndarray, target: int) -> tuple[np.ndarray, int, int]:
    """``array``'s elements as rows of bytes (vertex attributes padded to a multiple of 4:
    glTF aligns each element so), the stride and the unpadded size of an element."""
    rows = np.ascontiguousarray(array).view(np.uint8).reshape(len(array), -1)
    size = rows.shape[1]
    stride = -(-size // 4) * 4 if target == ARRAY_BUFFER else size
    if stride != size:
        rows = np.pad(rows, ((0, 0), (0, stride - size)))
    return rows, stride, size


def stored_view(
    array: np.ndarray, target: int, compress: str, filtered: Filtered | None = None
) -> StoredView:
    """The buffer view of accessor data ``array`` (little-endian, (n,) or (n, k)) for
    ``target``, packed with meshopt's codec where ``compress`` is ``meshopt`` and that makes
    it smaller by more than :data:`PACKING_COST` (a vertex attribute's ``filtered`` data
    packed in its place, where given)."""
    rows, stride, size = _rows(array, target)
    plain = StoredView(rows.tobytes(), len(rows) * stride, stride if stride != size else None)
    if compress != MESHOPT:
        return plain
    from .meshopt import encode_triangles, encode_vertices  # compiled: numba loaded here

    if target == ARRAY_BUFFER:
        source = rows if filtered is None else _rows(filtered[0], target)[0]
        data, mode = encode_vertices(source), "ATTRIBUTES"
    else:
        data, mode = encode_triangles(rows.view(f"<u{stride}").ravel()), "TRIANGLES"
    if len(data) + PACKING_COST >= plain.length:
        return plain
    packed: dict[str, Any] = {"byteLength": len(data), "byteStride": stride,
                              "count": len(rows), "mode": mode}  # fmt: skip
    if filtered is not None:
        packed["filter"] = filtered[1]
    vertex_stride = stride if target == ARRAY_BUFFER else None
    return StoredView(data, plain.length, vertex_stride, packed)


@dataclass(frozen=True)
class StoredPositions:
    """Float32 positions as ``compress`` stores them: the accessor's ``values`` (16-bit steps
    where quantized, else float32: those a reader decodes), the data under the exponential
    filter (``filtered``, meshopt), the steps' node transform (``quantizer``) and the largest
    difference of a coordinate from its float32 position (``error``, metres)."""

    values: np.ndarray
    filtered: Filtered | None = None
    quantizer: Quantizer | None = None
    error: float = 0.0


def stored_positions(
    positions: np.ndarray,
    compress: str,
    steps_of: Quantizer | None = None,
    tolerance: float | None = None,
) -> StoredPositions:
    """float32 ``positions`` (n, 3) as ``compress`` stores them (quantized: as ``steps_of``,
    default their own :func:`quantizer`, makes them; under the exponential filter: within
    ``tolerance``, default float32's own step)."""
    if compress == QUANTIZE:
        q = steps_of or quantizer(positions.astype(np.float64))
        steps = q.steps(positions.astype(np.float64))
        return StoredPositions(steps, None, q, _largest_gap(q.positions(steps), positions))
    if compress == MESHOPT:
        from .meshopt import exponential, from_exponential  # compiled: numba loaded here

        words = exponential(positions, tolerance)
        values = from_exponential(words)
        error = _largest_gap(values, positions)
        return StoredPositions(values, (words, "EXPONENTIAL"), None, error)
    return StoredPositions(positions)


def _largest_gap(stored: np.ndarray, positions: np.ndarray) -> float:
    """The largest coordinate difference between ``stored`` and ``positions``."""
    gap = np.abs(stored.astype(np.float64) - positions.astype(np.float64))
    return float(gap.max(initial=0.0))


def fallback_buffer(length: int) -> dict[str, Any]:
    """The meshopt fallback buffer of ``length`` bytes (it holds none)."""
    return {"byteLength": length, "extensions": {MESHOPT_EXTENSION: {"fallback": True}}}


def required(quantized: bool, packed: bool) -> list[str]:
    """The extensions a reader needs: ``KHR_mesh_quantization`` where an attribute is
    quantized, ``EXT_meshopt_compression`` where a view is packed."""
    return [QUANTIZATION] * quantized + [MESHOPT_EXTENSION] * packed
