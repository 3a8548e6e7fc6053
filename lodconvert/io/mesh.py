"""Mesh reader: OBJ, PLY, STL, OFF, GLB, glTF (and ``.gz`` of each) through trimesh.

Each object of the file becomes one :class:`Node`: an OBJ object (``o``), or group (``g``) in a
file without objects; a glTF node (its primitives are the parts of one mesh); the whole file for
PLY, STL and OFF. A geometry placed once has its placement applied (world coordinates, float64,
``transform`` None); one that the scene graph places several times is read once, and its nodes
share that :class:`Mesh` (in the geometry's own frame), each with its world ``transform``.

Vertex colours, material base colours and textures (with UVs, via Pillow) are kept, as the sRGB
bytes a :class:`Surface` holds: glTF's linear ``baseColorFactor`` and ``COLOR_0`` are converted;
OBJ, PLY and OFF colours and all textures are sRGB already.

A file whose content is not of its suffix's format is an :class:`InputError` saying so
(``cannot be read as STL: ...``), before trimesh gets to guess at it.
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

from ..errors import InputError
from ..limits import DEFAULT_LIMITS, Limits
from ..model import Mesh, Node, Scene, Surface
from . import Format, suffix_of
from .gltf import srgb_rgba

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
LINEAR_COLOR_SUFFIXES = (".glb", ".gltf")
"""Formats whose colour values (material factors, vertex colours) are linear, not sRGB."""

_EYE = np.eye(4)
_OBJ_DATA = re.compile(rb"^[ \t]*[vf][ \t]", re.MULTILINE)
_OFF_HEADER = re.compile(rb"\A\s*(?:#[^\n]*\n\s*)*[A-Za-z0-9]*OFF\b")
_OBJ_OBJECT = re.compile(r"^[og](?=[ \t]|$)", re.MULTILINE)


def object_id(name: str, taken: set[str]) -> str:
    """A unique id usable as an X3D DEF / glTF node name: letters, digits, ``_``, ``-``, ``.``;
    not starting with a digit."""
    base = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "object"
    if not (base[0].isalpha() or base[0] == "_"):
        base = f"_{base}"
    candidate, n = base, 2
    while candidate in taken:
        candidate, n = f"{base}_{n}", n + 1
    taken.add(candidate)
    return candidate


# --- colours --------------------------------------------------------------------------------------


def _unit_rgba(values: object | None) -> np.ndarray | None:
    """Colour values (one or many; RGB or RGBA; uint8, uint16 or float 0..1) as float64 RGBA
    in [0, 1], or None when there are none."""
    if values is None:
        return None
    c = np.asarray(values)
    if c.ndim == 0 or c.shape[-1] not in (3, 4):
        return None
    if c.dtype.kind in "ui":
        c = c / float(np.iinfo(c.dtype).max)
    c = np.clip(np.nan_to_num(c.astype(np.float64)), 0.0, 1.0)
    if c.shape[-1] == 3:
        c = np.concatenate([c, np.ones((*c.shape[:-1], 1))], axis=-1)
    return c


def _color_bytes(values: object | None, linear: bool) -> np.ndarray | None:
    """Colour values as sRGB RGBA uint8 (converted from linear when ``linear``), or None."""
    unit = _unit_rgba(values)
    if unit is None:
        return None
    return srgb_rgba(unit) if linear else np.rint(unit * 255.0).astype(np.uint8)


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
    mesh: object, transform: np.ndarray, linear_colors: bool = False
) -> Surface:
    """Convert a ``trimesh.Trimesh`` placed by ``transform`` into a Surface in that frame.

    ``linear_colors``: the mesh's colour values are linear (as glTF's) and become sRGB bytes.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)  # type: ignore[attr-defined]
    if not np.allclose(transform, _EYE):
        vertices = vertices @ transform[:3, :3].T + transform[:3, 3]
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)  # type: ignore[attr-defined]
    surface = Surface(vertices=vertices, faces=faces)
    visual = mesh.visual  # type: ignore[attr-defined]
    kind = getattr(visual, "kind", None)
    if kind == "texture":
        material = getattr(visual, "material", None)
        factor = getattr(material, "baseColorFactor", None)
        if factor is None:
            factor = getattr(material, "diffuse", None)
        surface.base_color = _color_bytes(factor, linear_colors)
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
        uv = getattr(visual, "uv", None)
        if image is not None and uv is not None and len(uv) == len(vertices):
            surface.texture = _image_rgba(image)
            surface.uv = np.asarray(uv, dtype=np.float64)
        # glTF COLOR_0 beside a material: trimesh keeps the accessor's values as they are
        attributes = getattr(visual, "vertex_attributes", None) or {}
        _set_vertex_colors(surface, _color_bytes(attributes.get("color"), linear_colors))
    elif kind in ("vertex", "face"):
        _set_vertex_colors(surface, _color_bytes(visual.vertex_colors, linear_colors))
    return surface


# --- reading and recognising the file -------------------------------------------------------------


def _file_bytes(path: Path, suffix: str) -> bytes:
    """The file's content, decompressed when it ends in ``.gz``."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", str(path)) from None
    if not path.name.lower().endswith(".gz"):
        return data
    try:
        data = gzip.decompress(data)
    except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
        raise InputError(
            f"is truncated or not a valid {suffix[1:].upper()} file ({exc})", str(path)
        ) from None
    if not data:
        raise InputError("is empty once decompressed", str(path))
    return data


def _is_binary_stl(data: bytes) -> bool:
    """Whether ``data`` is as long as the binary STL its 84-byte header describes."""
    return len(data) >= 84 and len(data) == 84 + 50 * int.from_bytes(data[80:84], "little")


def _looks_like(data: bytes) -> str | None:
    """The format the start of ``data`` suggests (``PLY``, ``GLB``, ...), or None."""
    head = data[:4096]
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
        if b"\0" in data[:4096]:
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


def _kept(loaded: object, instances: list[_Instance]) -> list[_Instance]:
    """``instances`` with only their parts that hold faces, and only those left with any."""
    import trimesh

    geometry = loaded.geometry  # type: ignore[attr-defined]

    def has_faces(name: str) -> bool:
        mesh = geometry.get(name)
        return isinstance(mesh, trimesh.Trimesh) and len(mesh.faces) > 0

    return [
        inst._replace(geometries=parts)
        for inst in instances
        if (parts := tuple(name for name in inst.geometries if has_faces(name)))
    ]


def _nodes(loaded: object, kept: list[_Instance], file_name: str, linear: bool) -> Iterator[Node]:
    """The nodes of ``kept``, one at a time: geometry placed once is moved into world
    coordinates, a geometry placed several times is shared and placed by each node's
    ``transform``. Each trimesh geometry is let go after its last use, so the input shrinks as
    the nodes are consumed."""
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
                [surface_from_trimesh(geometry[g], placement, linear) for g in inst.geometries]
            )
            if instanced:
                shared[inst.geometries] = mesh
        for name in inst.geometries:
            left[name] -= 1
            if not left[name]:
                del geometry[name]
        name = inst.name if inst.name is not None and len(kept) > 1 else file_name
        yield Node(
            id=object_id(name, taken),
            geometry=mesh,
            transform=transform if instanced else None,
            attributes={"source_node": inst.name} if inst.name is not None else {},
        )


def read_mesh(path: Path, merge_groups: bool = False, limits: Limits = DEFAULT_LIMITS) -> Scene:
    """Read a mesh file into a Scene; raise :class:`InputError` with a one-line reason.

    ``merge_groups``: read an OBJ file's objects / groups as one node (other formats keep their
    scene-graph nodes).
    """
    path = Path(path)
    suffix = suffix_of(path)
    if not path.exists():
        raise InputError("no such file", str(path))
    if path.is_dir():
        raise InputError("is a directory, not a mesh file", str(path))
    if path.stat().st_size == 0:
        raise InputError("is empty", str(path))
    data = _file_bytes(path, suffix)
    fmt = suffix[1:].upper()
    problem = _format_problem(data, suffix)
    if problem:
        raise InputError(f"cannot be read as {fmt}: {problem}", str(path))
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
    file_name = path.name.split(".")[0]
    kept = _kept(loaded, instances)
    if not kept:
        raise InputError("has no faces (empty, or points only: nothing to bake)", str(path))
    nodes = _nodes(loaded, kept, file_name, suffix in LINEAR_COLOR_SUFFIXES)
    return Scene(source=str(path), nodes=nodes, size=len(kept))


FORMAT = Format(
    name="mesh", suffixes=MESH_SUFFIXES, read=read_mesh, read_options=("merge_groups", "limits")
)
