"""glTF 2.0 output (``.glb`` and self-contained ``.gltf``) with levels chained by ``MSFT_lod``.

Each chain becomes a root node named after the object, translated to ``chain.origin`` (float64
JSON numbers, while level geometry stays small in float32 buffers). Its only child is the
finest level's node, which carries ``extensions.MSFT_lod.ids`` (the coarser level nodes, finest
to coarsest) and ``extras.MSFT_screencoverage``. Coarser nodes belong to no scene and no
parent: a client without ``MSFT_lod`` loads the finest level only, one with it substitutes them
for the finest node.

A city model's scene or one with a CRS is written in its scene frame (:mod:`lodconvert.io.frame`):
the object roots are the children of one root node whose ``matrix`` turns z-up into glTF's
y-up, and their translations are offsets from one scene origin (within 100 km, so float32
node matrices keep them), recorded in ``asset.extras.lodconvert.frame`` with the CRS. A plain
mesh without a CRS keeps its axes and absolute translations.

No viewer switches levels by distance from ``MSFT_lod``, so the switching data (cutoffs, bake
parameters, point sizes) is also written to ``extras.lodconvert`` on the nodes and the asset.
Colours in buffers are linear, as glTF requires; :func:`read_lod_gltf` converts them back to the
sRGB bytes that were written.

The document is written as it is made: the binary buffer and each JSON array (accessors,
nodes, …) go to a temporary file of their own (in memory up to ``_SPOOL_BYTES`` each), so memory
holds the chain being added, not the chains before it. The file is then put together from them
in blocks, its JSON laid out exactly as ``json.dumps`` lays out the whole document; a ``.gltf``
buffer is base64-encoded block by block into its data URI.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import math
import shutil
import struct
import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import IO, Any, BinaryIO

import numpy as np

from ...errors import LodConvertError
from ...model import CellChain, Level, LodChain, PointCloud, Surface
from ...ranges import ReferenceView, screen_coverage
from ...sinks import writing_temporary
from .. import OutputInfo, Pieces
from ..frame import ROTATION, SceneFrame, scene_frame

MSFT_LOD = "MSFT_lod"
UNLIT = "KHR_materials_unlit"
COVERAGE_MEANING = "projected bounding-box diagonal / viewport height at the reference view"
GLB_MAGIC = b"glTF"
GLB_JSON = b"JSON"
GLB_BIN = b"BIN\x00"
DATA_URI = "data:application/octet-stream;base64,"
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_POINTS, _TRIANGLES = 0, 4
_LINEAR, _LINEAR_MIPMAP_LINEAR, _REPEAT = 9729, 9987, 10497
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}
_WIDTHS = {name: width for width, name in _TYPES.items()}
_COMPONENTS = {
    np.dtype(np.float32): 5126,
    np.dtype(np.uint8): 5121,
    np.dtype(np.uint16): 5123,
    np.dtype(np.uint32): 5125,
}
_DTYPES = {code: dtype for dtype, code in _COMPONENTS.items()}
_SPOOL_BYTES = 1 << 20
"""How much of each temporary file (the buffer, each JSON array) stays in memory."""
_SHARED_MATERIALS = 4096
"""Distinct untextured mesh materials remembered for sharing (later ones are not shared)."""
_PENDING = 256
"""Elements of a JSON array kept as text before they are written to its file."""
_BLOCK = 3 << 18
"""Bytes copied at a time (768 KiB, a multiple of 3: base64 blocks join without padding)."""
FRAME_NODE = "scene_frame"
"""Name of the root node that turns a georeferenced scene y-up (:mod:`lodconvert.io.frame`)."""
FRAME_MATRIX = [float(v) for v in np.block([[ROTATION, np.zeros((3, 1))], [0, 0, 0, 1]]).T.ravel()]
"""Its ``matrix`` (column-major): z-up source axes → y-up glTF axes, exact in float32."""


def float32_positions(positions: np.ndarray) -> np.ndarray:
    """``positions`` as float32, or :class:`LodConvertError` where a coordinate is beyond the
    float32 range (it would be written as infinity)."""
    largest = float(np.abs(positions).max(initial=0.0))
    if not largest <= np.finfo(np.float32).max:
        raise LodConvertError(
            f"a level coordinate of magnitude {largest:.3g} is beyond the float32 range of glTF"
        )
    return positions.astype(np.float32)


def _srgb_table() -> np.ndarray:
    c = np.arange(256) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


SRGB_TO_LINEAR = _srgb_table()
"""Linear value in [0, 1] of each sRGB byte."""
_SRGB_MIDPOINTS = (SRGB_TO_LINEAR[1:] + SRGB_TO_LINEAR[:-1]) / 2.0


# --- colour and geometry conversions ------------------------------------------------------------


def linear_rgba(rgba: np.ndarray) -> np.ndarray:
    """sRGB RGBA bytes (..., 4) → linear float64 in [0, 1] (alpha is linear already: /255)."""
    out = SRGB_TO_LINEAR[rgba]
    out[..., 3] = rgba[..., 3] / 255.0
    return out


def srgb_rgba(linear: np.ndarray) -> np.ndarray:
    """Linear RGBA floats (..., 4) → sRGB bytes: the nearest byte, so that :func:`linear_rgba`
    followed by any encoding finer than the byte spacing round-trips exactly."""
    out = np.searchsorted(_SRGB_MIDPOINTS, np.clip(linear, 0.0, 1.0)).astype(np.uint8)
    out[..., 3] = np.clip(np.rint(linear[..., 3] * 255.0), 0, 255).astype(np.uint8)
    return out


def _unit16(values: np.ndarray) -> np.ndarray:
    """Floats in [0, 1] as normalised unsigned shorts."""
    return np.rint(np.clip(values, 0.0, 1.0) * 65535.0).astype(np.uint16)


NORMALS_AT_ONCE = 1 << 16
"""Faces (or rows) whose normals :func:`vertex_normals` (:func:`unit_normals`) finds at a
time."""


def unit_normals(normals: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length as float32; zero or non-finite rows become (0, 0, 1).
    :data:`NORMALS_AT_ONCE` rows at a time."""
    n = np.asarray(normals, dtype=np.float64)
    out = np.empty((len(n), 3), dtype=np.float32)
    for start in range(0, len(n), NORMALS_AT_ONCE):
        rows = n[start : start + NORMALS_AT_ONCE]
        length = np.sqrt(np.add.reduce(rows * rows, axis=1))  # as np.linalg.norm(rows, axis=1)
        ok = np.isfinite(length) & (length > 0)
        unit = np.zeros((len(rows), 3))
        unit[:, 2] = 1.0
        unit[ok] = rows[ok] / length[ok, None]
        out[start : start + len(rows)] = unit
    return out


def vertex_normals(surface: Surface) -> np.ndarray:
    """Area-weighted unit vertex normals (n, 3) float32; unused vertices get (0, 0, 1). The
    faces' normals are found :data:`NORMALS_AT_ONCE` faces at a time (their corners' (m, 3, 3)
    coordinates took five times the output's memory)."""
    faces, vertices = surface.faces, surface.vertices
    crossed = np.empty((len(faces), 3))  # each face's cross product: 2 · area long
    for start in range(0, len(faces), NORMALS_AT_ONCE):
        tri = vertices[faces[start : start + NORMALS_AT_ONCE]]
        a, b = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
            crossed[start : start + len(tri), k] = a[:, i] * b[:, j] - a[:, j] * b[:, i]
    corners = faces.ravel()
    n = len(vertices)
    summed = np.empty((n, 3))
    for k in range(3):
        summed[:, k] = np.bincount(corners, np.repeat(crossed[:, k], 3), minlength=n)
    return unit_normals(summed)


def _alpha_mode(*alphas: np.ndarray | None) -> str:
    """``BLEND`` when any given alpha byte is below 255, else ``OPAQUE``."""
    blend = any(a is not None and a.size and int(a.min()) < 255 for a in alphas)
    return "BLEND" if blend else "OPAQUE"


def _png(rgba: np.ndarray) -> bytes:
    """Deterministic PNG bytes of an RGBA uint8 image (no timestamps or text chunks)."""
    from PIL import Image as PILImage  # only for textures: a worker baking none never loads it

    out = io.BytesIO()
    PILImage.fromarray(np.ascontiguousarray(rgba, dtype=np.uint8), "RGBA").save(out, format="PNG")
    return out.getvalue()


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


# --- extras -------------------------------------------------------------------------------------


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


# --- JSON laid out as it is written ---------------------------------------------------------------


class _Layout:
    """How JSON text is laid out: exactly as ``json.dumps`` with ``indent`` (``None``: compact,
    for GLB; 1: one space per depth, for ``.gltf``) and no NaN or infinity."""

    def __init__(self, indent: int | None) -> None:
        self.indent = indent
        separators = (",", ":") if indent is None else (",", ": ")
        self.colon = separators[1]
        self.encode = json.JSONEncoder(indent=indent, separators=separators, allow_nan=False).encode

    def newline(self, depth: int) -> str:
        """What comes before a member at ``depth``: a line break and its indentation (nothing
        when compact)."""
        return "" if self.indent is None else "\n" + " " * (self.indent * depth)

    def text(self, value: Any, depth: int) -> str:
        """``value`` as JSON text that starts at ``depth`` (compact text has no line breaks)."""
        if type(value) is dict:
            flat = self._flat(value, depth)
            if flat is not None:
                return flat
        text = self.encode(value)
        return text if self.indent is None else text.replace("\n", self.newline(depth))

    def _flat(self, value: dict[str, Any], depth: int) -> str | None:
        """An object of integers, strings, booleans and lists of numbers (an accessor, a
        buffer view) laid out without the encoder; ``None`` for any other object."""
        inner, items = self.newline(depth + 2), self.newline(depth + 1)
        parts = []
        for key, item in value.items():
            kind = type(item)
            if kind is int:
                text = int.__repr__(item)
            elif kind is str and item.isalnum() and item.isascii():
                text = f'"{item}"'
            elif kind is bool:
                text = "true" if item else "false"
            elif kind is list and item and all(type(v) is float and math.isfinite(v) for v in item):
                text = "[" + ",".join(inner + float.__repr__(v) for v in item) + items + "]"
            else:
                return None
            if not (type(key) is str and key.isalnum() and key.isascii()):
                return None
            parts.append(f'{items}"{key}"{self.colon}{text}')
        if not parts:
            return None
        return "{" + ",".join(parts) + self.newline(depth) + "}"


_COMPACT = _Layout(None)
_INDENTED = _Layout(1)


class _Array:
    """A JSON array at a fixed depth of the document, written item by item to a temporary file
    (one item in memory at a time)."""

    def __init__(self, layout: _Layout, depth: int, spool: IO[bytes]) -> None:
        self.layout = layout
        self.depth = depth
        self.spool = spool
        self.count = 0
        self.last: dict[str, Any] | None = None
        """An element written after the others, which may hold :class:`_Array` s itself."""
        self._head = "," + layout.newline(depth + 1)
        self._pending: list[str] = []

    def __len__(self) -> int:
        return self.count

    def append(self, item: Any) -> int:
        """Write ``item`` as the next element; its index."""
        return self.append_text(self.layout.text(item, self.depth + 1))

    def append_text(self, text: str) -> int:
        """Write the JSON text of an element laid out at the array's depth; its index."""
        self._pending.append(self._head + text if self.count else self._head[1:] + text)
        if len(self._pending) >= _PENDING:
            self._flush()
        self.count += 1
        return self.count - 1

    def _flush(self) -> None:
        self.spool.write("".join(self._pending).encode())
        self._pending.clear()

    def write_json(self, out: BinaryIO) -> None:
        """Write the array's JSON text to ``out``."""
        self._flush()
        out.write(b"[")
        _copy(self.spool, out)
        if self.last is not None:
            out.write((("," if self.count else "") + self.layout.newline(self.depth + 1)).encode())
            _write_json(self.last, out, self.layout, self.depth + 1)
        empty = not self.count and self.last is None
        out.write((("" if empty else self.layout.newline(self.depth)) + "]").encode())


class _DataUri:
    """The binary buffer as a JSON string: a base64 ``data:`` URI, encoded block by block."""

    def __init__(self, blob: IO[bytes]) -> None:
        self.blob = blob

    def write_json(self, out: BinaryIO) -> None:
        """Write the quoted URI to ``out``."""
        out.write(b'"' + DATA_URI.encode())
        self.blob.seek(0)
        rest = b""
        while block := self.blob.read(_BLOCK):
            block = rest + block
            whole = len(block) - len(block) % 3
            out.write(base64.b64encode(block[:whole]))
            rest = block[whole:]
        out.write(base64.b64encode(rest) + b'"')


def _copy(source: IO[bytes], out: BinaryIO) -> None:
    """Copy ``source`` from its start to ``out``, :data:`_BLOCK` bytes at a time."""
    source.seek(0)
    shutil.copyfileobj(source, out, _BLOCK)


def _write_json(value: Any, out: BinaryIO, layout: _Layout, depth: int = 0) -> None:
    """Write ``value`` (starting at ``depth``) to ``out`` as ``json.dumps`` lays it out, with
    the :class:`_Array` and :class:`_DataUri` values it holds streamed from their files."""
    if isinstance(value, _Array | _DataUri):
        value.write_json(out)
        return
    if not (isinstance(value, dict | list) and value):
        out.write(layout.text(value, depth).encode())
        return
    members = value.items() if isinstance(value, dict) else ((None, item) for item in value)
    brackets = "{}" if isinstance(value, dict) else "[]"
    out.write(brackets[0].encode())
    for i, (key, item) in enumerate(members):
        name = "" if key is None else layout.encode(key) + layout.colon
        out.write((("," if i else "") + layout.newline(depth + 1) + name).encode())
        _write_json(item, out, layout, depth + 1)
    out.write((layout.newline(depth) + brackets[1]).encode())


def _object(**members: Any) -> dict[str, Any]:
    """A JSON object of the ``members`` that are set: no ``None`` and no empty list, object or
    :class:`_Array`."""
    return {
        key: value
        for key, value in members.items()
        if value is not None and not (isinstance(value, list | dict | _Array) and not value)
    }


def _material(
    base_color: list[float],
    alpha_mode: str,
    double_sided: bool,
    texture: int | None = None,
    extensions: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A non-metallic, fully rough material (``emissiveFactor`` written out, black)."""
    pbr = _object(
        baseColorFactor=base_color,
        metallicFactor=0.0,
        roughnessFactor=1.0,
        baseColorTexture=None if texture is None else {"index": texture, "texCoord": 0},
    )
    return _object(
        extensions=extensions,
        pbrMetallicRoughness=pbr,
        emissiveFactor=[0.0, 0.0, 0.0],
        alphaMode=alpha_mode,
        doubleSided=double_sided,
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
    return _object(
        extras={"attributes": _plain(chain.metadata)} if chain.metadata else None,
        translation=[float(v) for v in placed[:3, 3]] if moved_only else None,
        children=[finest],
        matrix=None if moved_only else [float(v) for v in placed.T.ravel()],
        name=chain.object_id,
    )


# --- buffers of a chain (made where it is baked) ------------------------------------------------


@dataclass(frozen=True)
class _AccessorData:
    """An accessor's bytes (little-endian), its buffer view's target and its other fields, with
    their compact JSON text (what follows its ``bufferView`` number in a GLB)."""

    data: bytes
    target: int
    fields: dict[str, Any]
    compact_tail: str


_VIEW_HEAD = '{"bufferView":'


def _accessor_data(
    array: np.ndarray, target: int = _ARRAY_BUFFER, normalized: bool = False, bounds: bool = False
) -> _AccessorData:
    """An accessor over ``array`` ((k,) scalars or (k, w) vectors, dtype of the buffer)."""
    data = np.ascontiguousarray(array)
    stored = np.ascontiguousarray(data, dtype=data.dtype.newbyteorder("<"))
    fields = _object(
        byteOffset=0,
        componentType=_COMPONENTS[data.dtype],
        normalized=True if normalized else None,
        count=len(data),
        type=_TYPES[1 if data.ndim == 1 else data.shape[1]],
        max=[float(v) for v in data.max(axis=0)] if bounds else None,
        min=[float(v) for v in data.min(axis=0)] if bounds else None,
    )
    compact = _COMPACT.text({"bufferView": 0, **fields}, 2)
    return _AccessorData(stored.tobytes(), target, fields, compact[len(_VIEW_HEAD) + 1 :])


def _colors(rgba: np.ndarray) -> _AccessorData:
    """COLOR_0 accessor: VEC4 normalised unsigned shorts in linear space."""
    return _accessor_data(_unit16(linear_rgba(rgba)), normalized=True)


@dataclass(frozen=True)
class _PrimitiveData:
    """What a primitive's JSON needs of its geometry: its accessors' data in the order they
    are added to the buffer (``POSITION``, ``NORMAL``, ``COLOR_0``, ``TEXCOORD_0``), its
    texture (PNG bytes, added next) and indices (last); for a mesh, the linear base colour of
    its material (``None``: a point level's shared unlit one) and the alpha mode."""

    attributes: dict[str, _AccessorData]
    mode: int
    alpha_mode: str
    base: list[float] | None = None
    png: bytes | None = None
    indices: _AccessorData | None = None


def _mesh_data(surface: Surface, normals: bool = True) -> _PrimitiveData:
    attributes = {"POSITION": _accessor_data(float32_positions(surface.vertices), bounds=True)}
    if normals:
        attributes["NORMAL"] = _accessor_data(vertex_normals(surface))
    if surface.vertex_colors is not None:
        attributes["COLOR_0"] = _colors(surface.vertex_colors)
    textured = surface.texture is not None and surface.uv is not None
    png = None
    if textured:
        # Surface.uv has its origin at the image's bottom-left, glTF at the top-left.
        flipped = np.column_stack([surface.uv[:, 0], 1.0 - surface.uv[:, 1]])
        attributes["TEXCOORD_0"] = _accessor_data(flipped.astype(np.float32))
        png = _png(surface.texture)
    index_type = np.uint16 if len(surface.vertices) < 65536 else np.uint32
    indices = _accessor_data(surface.faces.ravel().astype(index_type), _ELEMENT_ARRAY_BUFFER)
    alpha_mode = _alpha_mode(
        surface.material_color[3:],
        None if surface.vertex_colors is None else surface.vertex_colors[:, 3],
        surface.texture[..., 3] if textured else None,
    )
    base = [float(v) for v in linear_rgba(surface.material_color)]
    return _PrimitiveData(attributes, _TRIANGLES, alpha_mode, base, png, indices)


def _points_data(points: PointCloud) -> _PrimitiveData:
    attributes = {
        "POSITION": _accessor_data(float32_positions(points.positions), bounds=True),
        "NORMAL": _accessor_data(unit_normals(points.normals)),
        "COLOR_0": _colors(points.colors),
    }
    return _PrimitiveData(attributes, _POINTS, _alpha_mode(points.colors[:, 3]))


def _level_data(level: Level) -> list[_PrimitiveData]:
    """The primitives of one (non-empty) level. A LOD parent's merged far mesh has no normals:
    its corners are welded (:func:`~lodconvert.bake.qem.simplify_within`), where normals per
    vertex would round every building's edges, and glTF clients shade a primitive without
    normals flat (three.js from screen-space derivatives, with no vertex split)."""
    if level.mesh is None:
        return [_points_data(level.points)]
    flat = level.kind == "merged"
    return [_mesh_data(part, not flat) for part in level.mesh.parts]


ChainBuffers = tuple["list[_PrimitiveData] | None", ...]
"""A chain's buffers made by a worker: each level's primitives (``None`` for an empty one)."""


def chain_buffers(chain: LodChain) -> ChainBuffers | None:
    """The glTF formats' chain formatter (:mod:`lodconvert.io`): the buffers of a chain that
    is not an instance of shared geometry (whose levels are written once, by the first)."""
    if chain.transform is not None:
        return None
    return tuple(_level_data(level) if level.count else None for level in chain.levels)


def buffers_formatter(info: OutputInfo) -> Callable[[LodChain], ChainBuffers | None]:
    """The glTF formats' ``formatter`` (:mod:`lodconvert.io`)."""
    return chain_buffers


# --- document assembly --------------------------------------------------------------------------


class _Document:
    """A glTF document being written: its JSON arrays and binary buffer go to temporary files
    as they are made, so memory holds the chain being added, not what was added before."""

    def __init__(self, info: OutputInfo, layout: _Layout, pieces: Pieces) -> None:
        self.reference_view = info.view
        self.info = info
        self.pieces = pieces
        self.frame: SceneFrame | None = None  # set by the first item, for a framed scene
        self._layout = layout
        self._files = contextlib.ExitStack()
        self.blob = self._spool()
        self.blob_length = 0
        self._blob_pending = bytearray()
        self.accessors = self._array()
        self.buffer_views = self._array()
        self.images = self._array()
        self.materials = self._array()
        self.meshes = self._array()
        self.nodes = self._array()
        self.samplers = self._array()
        self.textures = self._array()
        self.scene_nodes = self._array(depth=3)  # at scenes[0].nodes
        self.extensions_used: list[str] = []
        self._point_materials: dict[str, int] = {}
        self._mesh_materials: dict[tuple[float | str, ...], int] = {}
        self._shared: dict[int, tuple[Level, int]] = {}  # level of an instance → its mesh

    def _spool(self) -> IO[bytes]:
        return self._files.enter_context(tempfile.SpooledTemporaryFile(_SPOOL_BYTES))

    def _array(self, depth: int = 1) -> _Array:
        """A JSON array in a temporary file of its own (``depth`` 1: a top-level member)."""
        return _Array(self._layout, depth, self._spool())

    def flush_blob(self) -> None:
        """Write what was added to the buffer to its file."""
        self.blob.write(self._blob_pending)
        self._blob_pending.clear()

    def close(self) -> None:
        """Delete the temporary files."""
        self._files.close()

    def _use(self, extension: str) -> None:
        if extension not in self.extensions_used:
            self.extensions_used.append(extension)

    def _buffer_view(self, data: bytes | memoryview, target: int | None = None) -> int:
        """Append ``data`` at the next 4-byte boundary of the buffer as a new buffer view."""
        pad = -self.blob_length % 4
        self._blob_pending += b"\x00" * pad
        self._blob_pending += data
        if len(self._blob_pending) >= _SPOOL_BYTES:
            self.flush_blob()
        start = self.blob_length + pad
        self.blob_length = start + len(data)
        if self._layout is _COMPACT:  # as _Layout.text lays it out, without the walk
            tail = "}" if target is None else f',"target":{target}}}'
            text = f'{{"buffer":0,"byteOffset":{start},"byteLength":{len(data)}{tail}'
            return self.buffer_views.append_text(text)
        view = _object(buffer=0, byteOffset=start, byteLength=len(data), target=target)
        return self.buffer_views.append(view)

    def _accessor(self, accessor: _AccessorData) -> int:
        """Add an accessor (and its buffer view); its index."""
        view = self._buffer_view(accessor.data, accessor.target)
        if self._layout is _COMPACT:
            return self.accessors.append_text(_VIEW_HEAD + str(view) + accessor.compact_tail)
        return self.accessors.append({"bufferView": view, **accessor.fields})

    def _texture(self, png: bytes) -> int:
        image = {"mimeType": "image/png", "bufferView": self._buffer_view(png)}
        sampler = {
            "magFilter": _LINEAR,
            "minFilter": _LINEAR_MIPMAP_LINEAR,
            "wrapS": _REPEAT,
            "wrapT": _REPEAT,
        }
        return self.textures.append(
            {"sampler": self.samplers.append(sampler), "source": self.images.append(image)}
        )

    def _primitive(self, data: _PrimitiveData) -> dict[str, Any]:
        """A primitive's JSON, its accessors (and texture) added."""
        added = {name: self._accessor(accessor) for name, accessor in data.attributes.items()}
        texture = self._texture(data.png) if data.png is not None else None
        primitive: dict[str, Any] = {
            "attributes": _object(
                POSITION=added["POSITION"],
                NORMAL=added.get("NORMAL"),
                TEXCOORD_0=added.get("TEXCOORD_0"),
                COLOR_0=added.get("COLOR_0"),
            )
        }
        if data.indices is not None:
            primitive["indices"] = self._accessor(data.indices)
        primitive["mode"] = data.mode
        if data.base is None:
            primitive["material"] = self._point_material(data.alpha_mode)
        else:
            primitive["material"] = self._mesh_material(data.base, data.alpha_mode, texture)
        return primitive

    def _mesh_material(self, base: list[float], alpha_mode: str, texture: int | None) -> int:
        """The material of a mesh primitive: one for all primitives of the same colour and
        alpha mode (a city's few surface colours), its own for a textured one."""
        key = (*base, alpha_mode)
        if texture is None and key in self._mesh_materials:
            return self._mesh_materials[key]
        index = self.materials.append(_material(base, alpha_mode, True, texture=texture))
        if texture is None and len(self._mesh_materials) < _SHARED_MATERIALS:
            self._mesh_materials[key] = index
        return index

    def _point_material(self, alpha_mode: str) -> int:
        """The shared unlit white material of point levels (one per alpha mode)."""
        if alpha_mode not in self._point_materials:
            self._use(UNLIT)
            material = _material(
                [1.0, 1.0, 1.0, 1.0], alpha_mode, double_sided=False, extensions={UNLIT: {}}
            )
            self._point_materials[alpha_mode] = self.materials.append(material)
        return self._point_materials[alpha_mode]

    def _level_mesh(
        self,
        name: str,
        level: Level,
        shared: bool = False,
        made: list[_PrimitiveData] | None = None,
    ) -> int | None:
        """The mesh of one level's geometry (``None`` when the level is empty), of its
        primitives as a worker ``made`` them or made here. The levels of instances of one
        geometry (``shared``) share their meshes."""
        if not level.count:
            return None
        if id(level) in self._shared:
            return self._shared[id(level)][1]
        primitives = [self._primitive(data) for data in made or _level_data(level)]
        mesh = self.meshes.append({"primitives": primitives, "name": name})
        if shared:  # kept alive with the level, so its id stays unique
            self._shared[id(level)] = (level, mesh)
        return mesh

    def add(self, item: LodChain | CellChain) -> None:
        """Add a chain, or a LOD parent with everything in it, to the scene."""
        if not self.scene_nodes:
            self.frame = scene_frame(self.info.framed, item)
        self.scene_nodes.append(len(self.nodes))
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
        root = len(self.nodes)
        near = root + 1
        members, at = [], near + 1
        for member in cell.members:
            members.append(at)
            at += _node_count(member)
        self._use(MSFT_LOD)
        self.nodes.append(_object(children=[near], name=cell.cell_id))
        extras = {
            "MSFT_screencoverage": _coverages(cell, self.reference_view),
            "lodconvert": _cell_extras(cell),
        }
        extensions = {MSFT_LOD: {"ids": [at]}}
        name = f"{cell.cell_id}_near"
        near_node = _object(children=members, extensions=extensions, extras=extras, name=name)
        self.nodes.append(near_node)
        for member in cell.members:
            self._add(member)
        far_name = f"{cell.cell_id}_{cell.far.name}"
        mesh = self._level_mesh(far_name, cell.far)
        facts = {"level": cell.far.name, **_level_params(cell.far), "switch_in": cell.cutoffs[0]}
        far = _object(
            extras={"lodconvert": _plain(facts)},
            mesh=mesh,
            name=far_name,
            translation=[float(v) for v in self._placed(cell.origin, f"cell {cell.cell_id!r}")],
        )
        assert self.nodes.append(far) == at

    def _add_chain(self, chain: LodChain) -> None:
        """Add a chain's root node, finest node (its child) and coarser nodes (their buffers
        as a worker made them, where one did)."""
        shared = chain.transform is not None
        made: ChainBuffers = self.pieces.take(chain) or (None,) * len(chain.levels)
        meshes = [
            self._level_mesh(_level_name(chain, level), level, shared, buffers)
            for level, buffers in zip(chain.levels, made, strict=True)
        ]
        finest_mesh = meshes[0]
        coarser = list(zip(chain.levels[1:], chain.cutoffs, meshes[1:], strict=False))
        root = self.nodes.append(_root_node(chain, len(self.nodes) + 1, self.frame))
        ids = list(range(root + 2, root + 2 + len(coarser)))
        extras: dict[str, Any] = {}
        if ids:
            self._use(MSFT_LOD)
            extras["MSFT_screencoverage"] = _coverages(chain, self.reference_view)
        extras["lodconvert"] = _chain_extras(chain)
        extensions = {MSFT_LOD: {"ids": ids}} if ids else None
        self.nodes.append(_level_node(chain, chain.levels[0], finest_mesh, extras, extensions))
        for level, switch_in, mesh in coarser:
            facts = {"level": level.name, **_level_params(level), "switch_in": float(switch_in)}
            self.nodes.append(_level_node(chain, level, mesh, {"lodconvert": facts}))

    def _placed(self, origin: np.ndarray, what: str) -> np.ndarray:
        """Where a node at ``origin`` (source coordinates) is translated: from the scene
        frame's origin where there is one."""
        return origin if self.frame is None else self.frame.offset(origin, what)

    def _scene_roots(self) -> _Array | list[int]:
        """``scenes[0].nodes``: the objects' roots, or the frame node holding them (the last
        node, with them as its children)."""
        if self.frame is None:
            return self.scene_nodes
        self.nodes.last = _object(children=self.scene_nodes, matrix=FRAME_MATRIX, name=FRAME_NODE)
        return [len(self.nodes)]

    def json_value(self, data_uri: bool) -> dict[str, Any]:
        """The glTF JSON object; the buffer is embedded as a base64 data URI when ``data_uri``,
        else left for a GLB BIN chunk."""
        asset = {
            "extras": {"lodconvert": _asset_extras(self.info, self.frame)},
            "generator": self.info.generator,
            "version": "2.0",
        }
        buffers = []
        if self.blob_length:
            uri = _DataUri(self.blob) if data_uri else None
            buffers.append(_object(uri=uri, byteLength=self.blob_length))
        return _object(
            accessors=self.accessors,
            asset=asset,
            bufferViews=self.buffer_views,
            buffers=buffers,
            extensionsUsed=self.extensions_used,
            images=self.images,
            materials=self.materials,
            meshes=self.meshes,
            nodes=self.nodes,
            samplers=self.samplers,
            scene=0,
            scenes=[_object(nodes=self._scene_roots())],
            textures=self.textures,
        )


def _level_name(chain: LodChain, level: Level) -> str:
    return f"{chain.object_id}_{level.name}"


def _level_node(
    chain: LodChain,
    level: Level,
    mesh: int | None,
    extras: dict[str, Any],
    extensions: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A node holding one level's mesh (none when the level is empty)."""
    return _object(extensions=extensions, extras=extras, mesh=mesh, name=_level_name(chain, level))


@contextlib.contextmanager
def _document(
    chains: Iterable[LodChain], info: OutputInfo, layout: _Layout, pieces: Pieces | None
) -> Iterator[_Document]:
    """A document holding ``chains`` (with the buffers workers made of them in ``pieces``); its
    temporary files are deleted when the block ends."""
    doc = _Document(info, layout, pieces or Pieces())
    try:
        with writing_temporary():
            for item in chains:
                doc.add(item)
            doc.flush_blob()
        yield doc
    finally:
        doc.close()


def _padded_length(length: int) -> int:
    return length + -length % 4


def _write_chunk(out: BinaryIO, kind: bytes, source: IO[bytes], length: int, fill: bytes) -> None:
    """A GLB chunk of ``source``'s ``length`` bytes, padded with ``fill`` to a multiple of 4."""
    out.write(struct.pack("<I4s", _padded_length(length), kind))
    _copy(source, out)
    out.write(fill * (_padded_length(length) - length))


def write_glb(
    chains: Iterable[LodChain], handle: BinaryIO, info: OutputInfo, pieces: Pieces | None = None
) -> None:
    """Write ``chains`` as binary glTF (one JSON chunk, one BIN chunk) to ``handle``; the
    buffers of a chain in ``pieces`` (made by a worker, :func:`chain_buffers`) are taken as
    they are."""
    with (
        _document(chains, info, _COMPACT, pieces) as doc,
        tempfile.SpooledTemporaryFile(_SPOOL_BYTES) as text,
    ):
        with writing_temporary():
            _write_json(doc.json_value(data_uri=False), text, _COMPACT)
        chunks = [(GLB_JSON, text, text.tell(), b" ")]
        if doc.blob_length:
            chunks.append((GLB_BIN, doc.blob, doc.blob_length, b"\x00"))
        total = 12 + sum(8 + _padded_length(length) for _, _, length, _ in chunks)
        handle.write(struct.pack("<4sII", GLB_MAGIC, 2, total))
        for chunk in chunks:
            _write_chunk(handle, *chunk)


def write_gltf(
    chains: Iterable[LodChain], handle: BinaryIO, info: OutputInfo, pieces: Pieces | None = None
) -> None:
    """Write ``chains`` as one self-contained glTF JSON file (buffer as a base64 data URI), as
    :func:`write_glb` takes ``pieces``."""
    with _document(chains, info, _INDENTED, pieces) as doc:
        _write_json(doc.json_value(data_uri=True), handle, _INDENTED)
    handle.write(b"\n")
