"""Mesh reader: OBJ, PLY, STL, OFF, GLB, glTF (and ``.gz`` of each) through trimesh.

Every geometry instance of the file's scene graph becomes one :class:`Node` with its
transform applied (world coordinates, float64). Vertex colours, material base colours and
textures (with UVs, via Pillow) are kept so baked points can take the surface's colour.
"""

from __future__ import annotations

import gzip
import io
import re
import zlib
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..model import Node, Scene, Surface
from . import READERS, suffix_of

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


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


def _rgba(color: object | None) -> np.ndarray | None:
    """A trimesh colour (uint8 0..255, or float 0..1; RGB or RGBA) as uint8 RGBA, or None."""
    if color is None:
        return None
    c = np.asarray(color).ravel()
    if c.size not in (3, 4):
        return None
    c = c.astype(np.float64) * (255.0 if c.dtype.kind == "f" else 1.0)
    if c.size == 3:
        c = np.append(c, 255.0)
    return np.clip(np.rint(c), 0, 255).astype(np.uint8)


def _image_rgba(image: object | None) -> np.ndarray | None:
    if image is None:
        return None
    return np.asarray(image.convert("RGBA"), dtype=np.uint8)  # type: ignore[attr-defined]


def surface_from_trimesh(mesh: object, transform: np.ndarray) -> Surface:
    """Convert a ``trimesh.Trimesh`` placed by ``transform`` into a world-space Surface."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)  # type: ignore[attr-defined]
    if not np.allclose(transform, np.eye(4)):
        vertices = vertices @ transform[:3, :3].T + transform[:3, 3]
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)  # type: ignore[attr-defined]
    surface = Surface(vertices=vertices, faces=faces)
    visual = mesh.visual  # type: ignore[attr-defined]
    kind = getattr(visual, "kind", None)
    if kind == "texture":
        material = getattr(visual, "material", None)
        base = _rgba(getattr(material, "baseColorFactor", None))
        if base is None:
            base = _rgba(getattr(material, "diffuse", None))
        if base is not None:
            surface.base_color = base
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
        uv = getattr(visual, "uv", None)
        if image is not None and uv is not None and len(uv) == len(vertices):
            surface.texture = _image_rgba(image)
            surface.uv = np.asarray(uv, dtype=np.float64)
    elif kind in ("vertex", "face"):
        colors = np.asarray(visual.vertex_colors, dtype=np.uint8)
        if colors.shape == (len(vertices), 4):
            if (colors == colors[0]).all():
                surface.base_color = colors[0].copy()
            else:
                surface.vertex_colors = colors
    return surface


def _load_trimesh_scene(path: Path, suffix: str) -> object:
    import trimesh

    if path.name.lower().endswith(".gz"):
        with gzip.open(path, "rb") as handle:
            data = handle.read()
        resolver = trimesh.resolvers.FilePathResolver(str(path.parent))
        return trimesh.load(
            io.BytesIO(data), file_type=suffix[1:], process=False, force="scene", resolver=resolver
        )
    return trimesh.load(str(path), file_type=suffix[1:], process=False, force="scene")


def read_mesh(path: Path) -> Scene:
    """Read a mesh file into a Scene; raise :class:`InputError` with a one-line reason."""
    path = Path(path)
    suffix = suffix_of(path)
    if not path.exists():
        raise InputError("no such file", str(path))
    if path.is_dir():
        raise InputError("is a directory, not a mesh file", str(path))
    if path.stat().st_size == 0:
        raise InputError("is empty", str(path))
    try:
        loaded = _load_trimesh_scene(path, suffix)
    except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
        raise InputError(
            f"is truncated or not a valid {suffix[1:].upper()} file ({exc})", str(path)
        ) from None
    except Exception as exc:  # trimesh raises many types for malformed files
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"cannot be read as {suffix[1:].upper()}: {reason}", str(path)) from None

    import trimesh

    nodes: list[Node] = []
    scene = Scene(source=str(path), nodes=nodes)
    taken: set[str] = set()
    graph = loaded.graph  # type: ignore[attr-defined]
    for node in sorted(graph.nodes_geometry):
        transform, geometry_name = graph[node]
        mesh = loaded.geometry.get(geometry_name)  # type: ignore[attr-defined]
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            continue
        name = node if len(graph.nodes_geometry) > 1 else path.name.split(".")[0]
        nodes.append(
            Node(
                id=object_id(str(name), taken),
                geometry=surface_from_trimesh(mesh, np.asarray(transform, dtype=np.float64)),
                attributes={"source_node": str(node), "geometry": str(geometry_name)},
            )
        )
    if not nodes:
        raise InputError("has no faces (empty, or points only: nothing to bake)", str(path))
    return scene


for _suffix in MESH_SUFFIXES:
    READERS[_suffix] = read_mesh
