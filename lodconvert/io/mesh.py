"""Mesh reader: OBJ, PLY, STL, OFF, GLB, glTF (and ``.gz`` of each) through trimesh.

Each object of the file (an OBJ object or group, a glTF node, the whole of a PLY, STL or OFF
file) becomes one :class:`Node`; a geometry the scene graph places several times is read once
and shared, each node with its world ``transform``. Colours and textures are kept as sRGB. A
file whose content is not of its suffix's format, a ``.gz`` inflating past its limit, and a
header declaring more than its data holds or the limits allow are an :class:`InputError`; what
trimesh read then passes :mod:`.geometry_checks`. In full: ``docs/readers.md`` (meshes).
"""

from __future__ import annotations

import gzip
import io
import re
import zlib
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..colors import srgb_bytes
from ..errors import InputError
from ..limits import DEFAULT_LIMITS, Limits
from ..model import Mesh, Node, Scene, Surface
from . import Format, suffix_of
from .frame import y_up
from .geometry_checks import (
    InputTally,
    attach_tally,
    check_extent,
    checked_vertices,
    kept_faces,
)

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
LINEAR_COLOR_SUFFIXES = (".glb", ".gltf")
"""Formats whose colour values (material factors, vertex colours) are linear, not sRGB."""

_EYE = np.eye(4)
_OBJ_DATA = re.compile(rb"^[ \t]*[vf][ \t]", re.MULTILINE)
_OFF_HEADER = re.compile(rb"\A\s*(?:#[^\n]*\n\s*)*[A-Za-z0-9]*OFF\b")
_ASCII_PLY = re.compile(rb"^format[ \t]+ascii", re.MULTILINE)
_OBJ_OBJECT = re.compile(r"^[og](?=[ \t]|$)", re.MULTILINE)
_CHUNK = 1 << 20
"""Bytes inflated at a time from a ``.gz`` input."""
_HEAD = 4096
"""Bytes at the start of a file that :func:`_looks_like` looks at."""
_HEADED = (".ply", ".off", ".glb", ".gltf")
"""Formats known by their first :data:`_HEAD` bytes: a ``.gz`` of another kind is refused
after its first chunk, not inflated whole."""
_PLY_SIZES = {
    **dict.fromkeys(("char", "uchar", "int8", "uint8"), 1),
    **dict.fromkeys(("short", "ushort", "int16", "uint16"), 2),
    **dict.fromkeys(("int", "uint", "int32", "uint32", "float", "float32"), 4),
    **dict.fromkeys(("double", "float64"), 8),
}
"""Bytes of each PLY property type."""


def object_id(name: str, taken: set[str]) -> str:
    """A unique id usable as an X3D DEF / glTF node name: letters, digits, ``_``, ``-``, ``.``;
    not starting with a digit."""
    base = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "object"
    if not (base[0].isalpha() or base[0] == "_"):
        base = f"_{base}"
    candidate = base
    if candidate in taken:
        candidate = f"{base}_{_free_suffix(base, taken)}"
    taken.add(candidate)
    return candidate


def _free_suffix(base: str, taken: set[str]) -> int:
    """A number ``n`` ≥ 2 with ``{base}_{n}`` not in ``taken``: the one after the run of taken
    numbers from 2 (the next free one when they were taken in order), found by doubling and
    then halving, so that naming ``k`` objects alike costs ``k log k``, not ``k²``."""
    low, high = 1, 2  # {base}_{low} counts as taken; {base}_{high} is to be tested
    while f"{base}_{high}" in taken:
        low, high = high, high * 2
    while high - low > 1:
        middle = (low + high) // 2
        if f"{base}_{middle}" in taken:
            low = middle
        else:
            high = middle
    return high


# --- colours --------------------------------------------------------------------------------------


def _image_rgba(image: object | None) -> np.ndarray | None:
    if image is None:
        return None
    return np.asarray(image.convert("RGBA"), dtype=np.uint8)  # type: ignore[attr-defined]


def _set_vertex_colors(surface: Surface, colors: np.ndarray | None) -> None:
    """Give ``surface`` per-vertex ``colors`` (a base colour instead when they are all equal
    and the surface has none)."""
    if colors is None or colors.shape != (len(surface.vertices), 4) or not len(colors):
        return
    if surface.base_color is None and (colors == colors[0]).all():
        surface.base_color = colors[0].copy()
    else:
        surface.vertex_colors = colors


def surface_from_trimesh(
    mesh: object,
    transform: np.ndarray,
    linear_colors: bool = False,
    faces: np.ndarray | None = None,
) -> Surface:
    """Convert a ``trimesh.Trimesh`` placed by ``transform`` into a Surface in that frame.

    ``linear_colors``: the mesh's colour values are linear (as glTF's) and become sRGB bytes.
    ``faces``: the faces to keep (default: all of the mesh's).
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)  # type: ignore[attr-defined]
    if not np.allclose(transform, _EYE):
        vertices = vertices @ transform[:3, :3].T + transform[:3, 3]
    if faces is None:
        faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)  # type: ignore[attr-defined]
    surface = Surface(vertices=vertices, faces=faces)
    visual = mesh.visual  # type: ignore[attr-defined]
    kind = getattr(visual, "kind", None)
    if kind == "texture":
        material = getattr(visual, "material", None)
        factor = getattr(material, "baseColorFactor", None)
        if factor is None:
            factor = getattr(material, "diffuse", None)
        surface.base_color = srgb_bytes(factor, linear_colors)
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
        uv = getattr(visual, "uv", None)
        if image is not None and uv is not None and len(uv) == len(vertices):
            surface.texture = _image_rgba(image)
            surface.uv = np.asarray(uv, dtype=np.float64)
            surface.photographic = getattr(image, "format", None) in ("JPEG", "MPO")
        # glTF COLOR_0 beside a material: trimesh keeps the accessor's values as they are
        attributes = getattr(visual, "vertex_attributes", None) or {}
        _set_vertex_colors(surface, srgb_bytes(attributes.get("color"), linear_colors))
    elif kind in ("vertex", "face"):
        _set_vertex_colors(surface, srgb_bytes(visual.vertex_colors, linear_colors))
    return surface


# --- reading and recognising the file -------------------------------------------------------------


def _file_bytes(path: Path, suffix: str, limit: int) -> bytes:
    """The file's content, decompressed when it ends in ``.gz``: streamed, and stopped with
    :class:`InputError` once it inflates past ``limit`` bytes. In a text format (OBJ, OFF,
    ASCII PLY) a chunk of nothing but white space is kept as one character of it, so that
    blank padding costs no memory."""
    try:
        if not path.name.lower().endswith(".gz"):
            return path.read_bytes()
        out = io.BytesIO()
        inflated, textual = 0, suffix in (".obj", ".off")
        with gzip.open(path, "rb") as stream:
            while chunk := stream.read(_CHUNK):
                if not inflated:
                    if suffix in _HEADED and len(chunk) >= _HEAD:
                        _refuse_other_format(chunk, suffix, path)
                    textual = textual or bool(suffix == ".ply" and _ASCII_PLY.search(chunk[:_HEAD]))
                inflated += len(chunk)
                if inflated > limit:
                    raise InputError(
                        f"inflates past the limit of {limit:,} bytes (decompressed_bytes; "
                        "raise it with --limit decompressed_bytes=N)",
                        str(path),
                    )
                if textual and chunk.isspace():  # white space of text: one character does
                    chunk = b"\n" if b"\n" in chunk else b" "
                out.write(chunk)
    except OSError as exc:
        if isinstance(exc, gzip.BadGzipFile) or not exc.strerror:
            raise InputError(f"is not a valid gzip file ({exc})", str(path)) from None
        raise InputError(f"cannot read: {exc.strerror}", str(path)) from None
    except (EOFError, zlib.error) as exc:
        raise InputError(
            f"is truncated or not a valid {suffix[1:].upper()} file ({exc})", str(path)
        ) from None
    if not out.tell():
        raise InputError("is empty once decompressed", str(path))
    return out.getvalue()


def _refuse_other_format(data: bytes, suffix: str, path: Path) -> None:
    """:class:`InputError` when ``data`` (the file's content, or its first :data:`_HEAD` bytes
    for a format of :data:`_HEADED`) cannot be of ``suffix``'s format."""
    problem = _format_problem(data, suffix)
    if problem:
        raise InputError(f"cannot be read as {suffix[1:].upper()}: {problem}", str(path))


def _is_binary_stl(data: bytes) -> bool:
    """Whether ``data`` is as long as the binary STL its 84-byte header describes."""
    return len(data) >= 84 and len(data) == 84 + 50 * int.from_bytes(data[80:84], "little")


def _looks_like(data: bytes) -> str | None:
    """The format the start of ``data`` suggests (``PLY``, ``GLB``, ...), or None."""
    head = data[:_HEAD]
    stripped = head.removeprefix(b"\xef\xbb\xbf").lstrip()
    if head.startswith(b"glTF"):
        return "GLB"
    if re.match(rb"ply\r?\n", head):
        return "PLY"
    if stripped.startswith(b"{"):
        return "GLTF"
    if _is_binary_stl(data) or stripped[:5].lower() == b"solid":
        return "STL"
    if _OFF_HEADER.match(head):
        return "OFF"
    if b"\0" not in head and _OBJ_DATA.search(head):
        return "OBJ"
    return None


def _format_problem(data: bytes, suffix: str) -> str | None:
    """Why ``data`` cannot be a file of ``suffix``'s format, or None when it may be one."""
    fmt = suffix[1:].upper()
    looks = _looks_like(data)
    if looks == fmt:
        return None
    if fmt == "OBJ":
        if b"\0" in data[:_HEAD]:
            problem = "binary data, not OBJ text"
        elif _OBJ_DATA.search(data):
            return None
        else:
            problem = "no vertex ('v') or face ('f') lines"
    else:
        problem = {
            "GLB": "no binary glTF header",
            "GLTF": "not a JSON glTF document",
            "PLY": "no 'ply' header line",
            "STL": "neither binary STL (its size does not match its triangle count) nor ASCII "
            "STL (no 'solid' line)",
            "OFF": "no 'OFF' header line",
        }[fmt]
    return f"{problem}; it looks like {looks}" if looks else problem


def _truncated(declared: dict[str, int], holds: str, source: str) -> InputError:
    """The error for a file whose header declares more than its data holds."""
    counts = " and ".join(f"{count:,} {name}" for name, count in declared.items())
    return InputError(f"is truncated: its header declares {counts} elements, {holds}", source)


def _check_ply_counts(data: bytes, tally: InputTally) -> int:
    """Compare a PLY header's element counts with what its data can hold (a line per element
    in ASCII, the fixed bytes of each element in binary) and with the limits, before trimesh
    allocates anything for them. A header too damaged to read is left to trimesh. The bytes
    trimesh reads: in ASCII, up to the last element's line (it makes an array of every line,
    junk after the elements included)."""
    end = data.find(b"end_header")
    start = data.find(b"\n", end) + 1
    if end < 0 or not start:
        return len(data)
    binary = re.search(rb"^format[ \t]+binary", data[:end], re.MULTILINE) is not None
    counts: dict[str, int] = {}
    row_bytes: dict[str, int] = {}
    element = ""
    for words in (line.split() for line in data[:end].decode("latin-1").splitlines()):
        if words[:1] == ["element"] and len(words) == 3 and re.fullmatch("[0-9]+", words[2]):
            element = words[1]
            counts[element], row_bytes[element] = int(words[2]), 0
        elif words[:1] == ["property"] and element and len(words) >= 3:
            size_of = words[2] if words[1] == "list" else words[1]
            row_bytes[element] += _PLY_SIZES.get(size_of, 1)
    needed = sum(counts[e] * row_bytes[e] for e in counts)
    if binary and needed > len(data) - start:
        holds = f"at least {needed:,} bytes, but its data has {len(data) - start:,}"
        raise _truncated(counts, holds, tally.source)
    lines = data.count(b"\n", start) + 1
    if not binary and sum(counts.values()) > lines:
        raise _truncated(counts, f"a line each, but its data has {lines:,}", tally.source)
    tally.count(counts.get("vertex", 0), counts.get("face", 0), declared=True)
    return len(data) if binary else _past_lines(data, start, sum(counts.values()))


def _past_lines(data: bytes, start: int, lines: int) -> int:
    """The index past the first ``lines`` lines of ``data[start:]`` (or its end), found by
    counting line breaks a chunk at a time."""
    at = start
    while lines > 0 and at < len(data):
        end = min(at + _CHUNK, len(data))
        found = data.count(b"\n", at, end)
        if found < lines:
            lines, at = lines - found, end
            continue
        for _ in range(lines):
            at = data.index(b"\n", at) + 1
        return at
    return len(data)


def _check_off_counts(data: bytes, tally: InputTally) -> None:
    """Compare an OFF header's vertex and face counts with its data's lines and with the
    limits (see :func:`_check_ply_counts`)."""
    header = _OFF_HEADER.match(data)
    assert header is not None
    rest = (line.split() for line in data[header.end() : header.end() + _HEAD].splitlines())
    words = next((w for w in rest if w and not w[0].startswith(b"#")), [])
    if len(words) < 2 or not (words[0].isdigit() and words[1].isdigit()):
        return
    counts = {"vertex": int(words[0]), "face": int(words[1])}
    lines = data.count(b"\n", header.end()) + 1
    if sum(counts.values()) > lines:
        raise _truncated(counts, f"a line each, but its data has {lines:,}", tally.source)
    tally.count(counts["vertex"], counts["face"], declared=True)


def _text(data: bytes) -> str:
    """Text of a text format: UTF-8, else Latin-1 (which decodes any bytes)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _label_obj_objects(text: str) -> tuple[str, list[str | None]]:
    """``text`` with every OBJ object (``o``, or ``g`` in a file without ``o``) renamed to its
    index, so that trimesh's geometry names say which object they belong to, and the objects'
    names by index (index 0, None: faces before the first object)."""
    text = text.replace("\r\n", "\n")
    letter = "o" if any(m.group() == "o" for m in _OBJ_OBJECT.finditer(text)) else "g"
    labels: list[str | None] = [None]
    index: dict[str, int] = {}

    def renamed(match: re.Match[str]) -> str:
        name = (match.group(1) or "").strip()
        if name not in index:
            index[name] = len(labels)
            labels.append(name)
        return f"o {index[name]}"

    text = re.sub(rf"^{letter}(?:[ \t](.*))?$", renamed, text, flags=re.MULTILINE)
    return f"o 0\n{text}", labels


def _unpacked(data: bytes, path: Path, limit: int) -> bytes:
    """GLB ``data`` with its meshopt-packed views decoded (:func:`~.gltf.binary.unpacked_glb`,
    at most ``limit`` bytes of them), or :class:`InputError` naming ``path``."""
    from .gltf.binary import GlbError, unpacked_glb  # the glTF format: loaded for a GLB only

    try:
        return unpacked_glb(data, limit)
    except (ValueError, TypeError, KeyError, AttributeError, IndexError, RecursionError) as exc:
        reason = str(exc) if isinstance(exc, GlbError) else f"{type(exc).__name__}: {exc}"
        raise InputError(f"cannot be read as GLB: {reason}", str(path)) from None


def _load_trimesh(data: bytes, path: Path, suffix: str, **options: object) -> object:
    """``data`` loaded by trimesh as a scene (resources such as MTL files and textures are
    looked up beside ``path``)."""
    import trimesh

    resolver = trimesh.resolvers.FilePathResolver(str(path.parent))
    return trimesh.load(
        io.BytesIO(data),
        file_type=suffix[1:],
        process=False,
        force="scene",
        resolver=resolver,
        **options,
    )


# --- objects --------------------------------------------------------------------------------------


class _Instance(NamedTuple):
    """One object to be: its name in the file (None: none), the trimesh geometries that are its
    parts and its world placement."""

    name: str | None
    geometries: tuple[str, ...]
    transform: np.ndarray


def _obj_instances(loaded: object, labels: list[str | None] | None) -> list[_Instance]:
    """One instance per labelled OBJ object (see :func:`_label_obj_objects`), in file order;
    one for the whole file when ``labels`` is None."""
    # trimesh adds an OBJ file's geometries last first
    names = list(loaded.geometry)[::-1]  # type: ignore[attr-defined]
    if labels is None:
        return [_Instance(None, tuple(names), _EYE)]
    parts: dict[int, list[str]] = {}
    for name in names:
        # "<index>" or "<index>_<material>"; anything else (a file of points) holds no faces
        labelled = re.match(r"\d+(?=_|$)", name)
        parts.setdefault(int(labelled.group()) if labelled else 0, []).append(name)
    return [_Instance(labels[i], tuple(parts[i]), _EYE) for i in sorted(parts)]


def _graph_instances(loaded: object) -> list[_Instance]:
    """One instance per scene-graph node with geometry, by node name; the primitives of a
    multi-primitive glTF mesh (child nodes trimesh adds) are parts of their node's instance."""
    graph = loaded.graph  # type: ignore[attr-defined]
    geometry = loaded.geometry  # type: ignore[attr-defined]
    order = {name: i for i, name in enumerate(geometry)}
    parents = graph.transforms.parents
    owned: dict[str, list[str]] = {}
    for node in graph.nodes_geometry:
        name = graph[node][1]
        metadata = getattr(geometry.get(name), "metadata", {})
        owner = parents[node] if metadata.get("from_gltf_primitive") else node
        owned.setdefault(owner, []).append(name)
    return [
        _Instance(owner, tuple(sorted(owned[owner], key=order.__getitem__)), graph[owner][0])
        for owner in sorted(owned)
    ]


class _Checked(NamedTuple):
    """The geometries of a file after :mod:`.geometry_checks`: the faces kept of each (by
    trimesh geometry name) and how many were dropped."""

    faces: dict[str, np.ndarray]
    dropped: dict[str, int]


def _checked_geometry(loaded: object, tally: InputTally) -> _Checked:
    """Check every triangle geometry of ``loaded`` (counts against the limits, vertices, face
    indices) and keep its faces with area; the dropped ones are counted in ``tally``."""
    import trimesh

    checked = _Checked({}, {})
    for name, mesh in loaded.geometry.items():  # type: ignore[attr-defined]
        if not isinstance(mesh, trimesh.Trimesh):
            continue
        tally.count(len(mesh.vertices), len(mesh.faces))
        vertices = checked_vertices(mesh.vertices, tally.source)
        checked.faces[name], checked.dropped[name] = kept_faces(vertices, mesh.faces, tally.source)
        tally.dropped_faces += checked.dropped[name]
    return checked


def _world_bounds(loaded: object, inst: _Instance) -> np.ndarray:
    """(2, 3) bounds of an instance's parts as placed in the world."""
    geometry = loaded.geometry  # type: ignore[attr-defined]
    boxes = np.stack([geometry[g].bounds for g in inst.geometries])
    low, high = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
    corners = np.array(np.meshgrid(*zip(low, high, strict=True))).reshape(3, -1).T
    transform = np.asarray(inst.transform, dtype=np.float64)
    placed = corners @ transform[:3, :3].T + transform[:3, 3]
    return np.stack([placed.min(axis=0), placed.max(axis=0)])


def _kept(
    loaded: object, instances: list[_Instance], checked: _Checked, tally: InputTally
) -> list[_Instance]:
    """``instances`` with only their parts that hold faces, and only those left with any; an
    instance whose faces were all dropped is recorded as skipped in ``tally``, and one too
    large or too small for the outputs is an :class:`InputError`."""
    kept = []
    for inst in instances:
        parts = tuple(name for name in inst.geometries if len(checked.faces.get(name, ())))
        dropped = sum(checked.dropped.get(name, 0) for name in inst.geometries)
        if parts:
            inst = inst._replace(geometries=parts)
            where = tally.source if len(instances) == 1 else f"{tally.source}: {inst.name}"
            check_extent(_world_bounds(loaded, inst), where)
            kept.append(inst)
        elif dropped:
            tally.skip(inst.name or Path(tally.source).name, dropped)
    return kept


def _nodes(
    loaded: object,
    kept: list[_Instance],
    file_name: str,
    linear: bool,
    checked: _Checked,
    tally: InputTally,
) -> Iterator[Node]:
    """The nodes of ``kept``, one at a time: geometry placed once is moved into world
    coordinates, a geometry placed several times is shared and placed by each node's
    ``transform``. Each trimesh geometry is let go after its last use, so the input shrinks as
    the nodes are consumed. Faces dropped from each are counted in ``tally`` by node id."""
    geometry = loaded.geometry  # type: ignore[attr-defined]
    uses = Counter(inst.geometries for inst in kept)
    left = Counter(g for inst in kept for g in inst.geometries)
    shared: dict[tuple[str, ...], Mesh] = {}
    taken: set[str] = set()
    for inst in kept:
        transform = np.array(inst.transform, dtype=np.float64)
        instanced = uses[inst.geometries] > 1
        mesh = shared.get(inst.geometries) if instanced else None
        if mesh is None:
            placement = _EYE if instanced else transform
            mesh = Mesh(
                [
                    surface_from_trimesh(geometry[g], placement, linear, checked.faces[g])
                    for g in inst.geometries
                ]
            )
            if instanced:
                shared[inst.geometries] = mesh
        for name in inst.geometries:
            left[name] -= 1
            if not left[name]:
                del geometry[name]
                del checked.faces[name]
        name = inst.name if inst.name is not None and len(kept) > 1 else file_name
        node_id = object_id(name, taken)
        dropped = sum(checked.dropped.get(g, 0) for g in inst.geometries)
        if dropped:
            tally.dropped_by_object[node_id] = dropped
        yield Node(
            id=node_id,
            geometry=mesh,
            transform=transform if instanced else None,
            attributes={"source_node": inst.name} if inst.name is not None else {},
        )


def read_mesh(
    path: Path, merge_groups: bool = False, limits: Limits = DEFAULT_LIMITS, up: str = "y"
) -> Scene:
    """Read a mesh file into a Scene; raise :class:`InputError` with a one-line reason.

    ``merge_groups``: read an OBJ file's objects / groups as one node (other formats keep their
    scene-graph nodes). ``limits``: the decompressed size, vertices and faces the file may
    hold. ``up``: the model's up axis (:data:`~.frame.UP_AXES`), turned to +y as it is read:
    each object's placement is turned (:func:`~.frame.y_up`). The scene carries an
    :class:`~.geometry_checks.InputTally` of the faces dropped (no area) and the objects
    skipped (none left).
    """
    turn = np.eye(4)
    turn[:3, :3] = y_up(up)  # before any work: a bad axis is a usage error
    path = Path(path)
    suffix = suffix_of(path)
    if not path.exists():
        raise InputError("no such file", str(path))
    if path.is_dir():
        raise InputError("is a directory, not a mesh file", str(path))
    if path.stat().st_size == 0:
        raise InputError("is empty", str(path))
    data = _file_bytes(path, suffix, limits.decompressed_bytes)
    fmt = suffix[1:].upper()
    _refuse_other_format(data, suffix, path)
    tally = InputTally(str(path), limits)
    if suffix == ".ply":
        needed = _check_ply_counts(data, tally)
        data = data[:needed] if needed < len(data) else data
    elif suffix == ".off":
        _check_off_counts(data, tally)
    if suffix == ".glb":
        data = _unpacked(data, path, limits.decompressed_bytes)
    labels = None
    options: dict[str, object] = {}
    if suffix in (".obj", ".off") or (suffix == ".stl" and not _is_binary_stl(data)):
        text = _text(data)
        if suffix == ".obj" and not merge_groups and _OBJ_OBJECT.search(text):
            text, labels = _label_obj_objects(text)
            options = {"split_objects": True, "group_material": True}
        data = text.encode("utf-8")
    try:
        loaded = _load_trimesh(data, path, suffix, **options)
    except FileNotFoundError as exc:  # a glTF buffer or image beside the file
        raise InputError(f"refers to a missing file: {exc}", str(path)) from None
    except Exception as exc:  # trimesh raises many types for malformed files
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"cannot be read as {fmt}: {reason}", str(path)) from None

    instances = _obj_instances(loaded, labels) if suffix == ".obj" else _graph_instances(loaded)
    if up != "y":
        instances = [inst._replace(transform=turn @ inst.transform) for inst in instances]
    file_name = path.name.split(".")[0]
    checked = _checked_geometry(loaded, tally)
    kept = _kept(loaded, instances, checked, tally)
    if not kept and tally.dropped_faces:
        raise tally.nothing_left()
    if not kept:
        raise InputError("has no faces (empty, or points only: nothing to bake)", str(path))
    nodes = _nodes(loaded, kept, file_name, suffix in LINEAR_COLOR_SUFFIXES, checked, tally)
    return attach_tally(Scene(source=str(path), nodes=nodes, size=len(kept)), tally)


FORMAT = Format(
    name="mesh",
    suffixes=MESH_SUFFIXES,
    read=read_mesh,
    read_options=("merge_groups", "limits", "up"),
)
