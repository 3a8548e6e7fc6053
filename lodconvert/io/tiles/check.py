"""Our own checks of a tileset (``lodconvert validate DIR/tileset.json``, and every conversion
on its staged folder): what the official validator does not check, and what lodconvert
promises.

- every content URI names a file inside the tileset's folder, external tilesets read each once
  and within the run's limits (:mod:`.tree`, which reads and walks the tileset for this
  module and for ``lodconvert view``);
- geometricError: the tileset's ≥ its root's, strictly decreasing from parent to child (equal
  only from a tile to the root of the external tileset it refers to), 0 at leaves;
  ``refine`` ``REPLACE`` everywhere;
- each tile's bounding ``box`` encloses its content's positions (in the tile's frame: the
  transforms multiplied down the tree, content turned y-up → z-up) and its children's boxes;
- GLB content: ``_FEATURE_ID_0`` values below their ``featureCount``; every property table
  with as many rows as its ``count``, its columns of the class's properties, long enough.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ...limits import DEFAULT_LIMITS, Limits
from ..findings import Finding, Findings, errors_of
from ..gltf.binary import accessor_values, split_glb
from ..gltf.stream import Source, too_deep
from .tree import MAX_DEPTH, Problem, Tile, walk

if TYPE_CHECKING:
    from .. import CheckOptions

TOLERANCE = 1e-3
"""Metres a position or a child's corner may lie outside a box (float rounding)."""
_GLTF_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_BYTES = {"INT8": 1, "UINT8": 1, "INT16": 2, "UINT16": 2, "INT32": 4, "UINT32": 4, "INT64": 8,
          "UINT64": 8, "FLOAT32": 4, "FLOAT64": 8}  # fmt: skip


def check_tileset(path: Path, findings: Findings, options: CheckOptions | None = None) -> None:
    """Check the tileset ``path`` (its external tilesets and contents too) into ``findings``,
    reading within the limits of ``options`` (default: the defaults)."""
    limits = options.limits if options is not None else DEFAULT_LIMITS
    contents = options.contents if options is not None else True
    try:
        _Checker(findings, contents).run(path, limits)
    except (ValueError, KeyError, IndexError, TypeError, AttributeError) as exc:
        findings.error("JSON", f"not a tileset as lodconvert writes them ({type(exc).__name__})")


@dataclass(frozen=True)
class _State:
    """What a tile's checks leave for the tiles below it: its frame (ECEF), its geometric
    error and whether points lie in its box (``None``: it has none)."""

    frame: np.ndarray
    error: float
    inside: _BoxTest | None


class _Checker:
    """The checks of one tileset, reported into ``findings``; the tileset is read and walked by
    :func:`.tree.walk`, which reports what it finds unreadable too."""

    def __init__(self, findings: Findings, contents: bool = True) -> None:
        self.findings = findings
        self.contents = contents
        """Whether contents are read (else their makers checked them: :func:`check_content`)."""

    def _problem(self, problem: Problem) -> None:
        self.findings.error(problem.code, str(problem))

    def run(self, path: Path, limits: Limits) -> None:
        """Check every tile of the tileset ``path``."""
        for tile in walk(path, self._problem, limits):
            tile.state = self.tile(tile)

    def tile(self, tile: Tile) -> _State | None:
        """Check ``tile`` (and, for a file's root, its tileset's geometric error) against the
        tile above it; what the tiles below it need (``None``: they are not checked, as
        ``tile`` was not)."""
        node, where = tile.node, tile.where
        if tile.parent is None:  # a file's root: above it, the tile that refers to the file
            referrer = tile.referrer
            above = referrer.state if referrer is not None else None
            if referrer is not None and above is None:
                return None
            frame = np.eye(4) if above is None else above.frame
            if not self._tileset(tile, None if above is None else above.error):
                return None
            parent = None
        else:
            above, parent = tile.parent.state, tile.parent.node
            if above is None:
                return None
            frame = above.frame
        transform = node.get("transform")
        if transform is not None:
            frame = frame @ np.asarray(transform, dtype=np.float64).reshape(4, 4).T
        if parent is not None and above.inside is not None:
            box = node.get("boundingVolume", {}).get("box")
            if box is not None and not above.inside(_corners(frame, box)):
                self.findings.error(
                    "VOLUME",
                    f"{tile.parent.where}: child {tile.index}'s box lies outside its own",
                )
        error = float(node.get("geometricError", -1.0))
        if node.get("refine", "REPLACE" if parent is not None else None) != "REPLACE":
            self.findings.error("REFINE", f"{where}: refine is not REPLACE")
        if parent is not None and not error < float(parent["geometricError"]):
            self.findings.error(
                "GEOMETRIC_ERROR",
                f"{where}: geometricError {error} is not below its parent's "
                f"{parent['geometricError']}",
            )
        children = node.get("children", [])
        if not children and error != 0.0 and tile.contents and not _external(tile):
            self.findings.error("GEOMETRIC_ERROR", f"{where}: a leaf's geometricError is {error}")
        box = node.get("boundingVolume", {}).get("box")
        if box is None:
            self.findings.error("VOLUME", f"{where}: no bounding box")
            return _State(frame, error, None)
        centre, axes = np.asarray(box[:3], float), np.asarray(box[3:], float).reshape(3, 3)
        inside = _BoxTest(frame, centre, axes)
        for content in tile.contents if self.contents else ():
            if content.target is not None and not content.external:
                positions = self.glb(content.target, where)
                if positions is not None and not inside(frame_points(frame, positions)):
                    self.findings.error("VOLUME", f"{where}: content lies outside its box")
        return _State(frame, error, inside)

    def _tileset(self, root: Tile, parent_error: float | None) -> bool:
        """Check the geometric error of the tileset whose root is ``root``, under a tile of
        geometric error ``parent_error`` (``None``: the top tileset); whether it has one."""
        data, node, name = root.tileset, root.node, root.file
        assert data is not None
        value = data.get("geometricError")
        try:
            error = float(value)
        except (TypeError, ValueError):
            self.findings.error("JSON", f"{name}: not a tileset (geometricError {value!r})")
            return False
        if error < float(node.get("geometricError", 0.0)):
            self.findings.error(
                "GEOMETRIC_ERROR",
                f"{name}: the tileset's geometricError {error} is below its root's "
                f"{node.get('geometricError')}",
            )
        if parent_error is not None and float(node.get("geometricError", 0.0)) > parent_error:
            self.findings.error(
                "GEOMETRIC_ERROR",
                f"{name}: root geometricError above the tile referring to it",
            )
        return True

    def glb(self, path: Path, where: str) -> np.ndarray | None:
        """The positions (glTF coordinates) of a GLB's primitives, its features checked."""
        try:
            document, blob = read_glb(path)
            return content_positions(document, blob, where, self.findings)
        except (ValueError, KeyError, IndexError, TypeError) as exc:
            self.findings.error("CONTENT", f"{where}: {path.name} cannot be read ({exc})")
            return None


def check_content(data: bytes, box: np.ndarray, where: str) -> list[Finding]:
    """The errors of a tile's GLB ``data``, as the tileset's check finds them, where its
    content's box in its frame is ``box`` (min and max corners): what the worker that made a
    tile checks of it (then the tileset's check reads no content: ``CheckOptions.contents``)."""
    findings = Findings(Path(where))
    try:
        document, blob = glb_parts(data)
        positions = content_positions(document, blob, where, findings)
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        findings.error("CONTENT", f"{where}: cannot be read ({exc})")
        return errors_of(findings.items)
    local = np.asarray(positions, dtype=np.float64) @ _GLTF_TO_Z_UP.T
    if len(local) and not (
        (local >= box[0] - TOLERANCE).all() and (local <= box[1] + TOLERANCE).all()
    ):
        findings.error("VOLUME", f"{where}: content lies outside its box")
    return errors_of(findings.items)


def content_positions(document: dict, blob: bytes, where: str, findings: Findings) -> np.ndarray:
    """A GLB's positions; its feature ids and property tables checked into ``findings``."""
    found = []
    tables = document.get("extensions", {}).get("EXT_structural_metadata", {})
    for mesh, (translation, scale) in _mesh_transforms(document):
        for primitive in mesh["primitives"]:
            steps = accessor_values(document, blob, primitive["attributes"]["POSITION"])
            found.append(translation + scale * steps.astype(np.float64))
            features = primitive.get("extensions", {}).get("EXT_mesh_features", {})
            for ids in features.get("featureIds", []):
                name = f"_FEATURE_ID_{ids['attribute']}"
                values = accessor_values(document, blob, primitive["attributes"][name])
                if len(values) and values.max() >= ids["featureCount"]:
                    findings.error(
                        "FEATURE_ID", f"{where}: feature id {values.max():g} ≥ featureCount"
                    )
                table = tables["propertyTables"][ids["propertyTable"]]
                if table["count"] != ids["featureCount"]:
                    findings.error("PROPERTY_TABLE", f"{where}: table count is not featureCount")
    if tables:
        _tables(document, tables, where, findings)
    return np.concatenate(found) if found else np.zeros((0, 3))


def _tables(document: dict, metadata: dict, where: str, findings: Findings) -> None:
    """Each property table: columns of its class's properties, required ones present,
    each long enough for its ``count``."""
    classes = metadata["schema"]["classes"]
    views = document["bufferViews"]
    for table in metadata["propertyTables"]:
        properties = classes[table["class"]]["properties"]
        count = table["count"]
        if set(table["properties"]) - set(properties):
            findings.error("PROPERTY_TABLE", f"{where}: columns not in the class")
        for name, definition in properties.items():
            column = table["properties"].get(name)
            if column is None:
                if definition.get("required"):
                    findings.error("PROPERTY_TABLE", f"{where}: no column {name}")
                continue
            length = views[column["values"]]["byteLength"]
            kind = definition["type"]
            if kind == "STRING":
                wanted = 4 * (count + 1)
                if views[column["stringOffsets"]]["byteLength"] < wanted:
                    findings.error("PROPERTY_TABLE", f"{where}: {name} offsets short")
                continue
            if kind == "BOOLEAN":
                wanted = (count + 7) // 8
            else:
                wanted = _BYTES.get(definition.get("componentType", ""), 1) * count
            if length < wanted:
                findings.error("PROPERTY_TABLE", f"{where}: column {name} too short")


def _mesh_transforms(document: dict) -> list[tuple[dict, tuple[np.ndarray, np.ndarray]]]:
    """Each mesh of a GLB as we write them (one node a mesh, with at most a translation and
    a scale: those of quantized positions) with that node's translation and scale."""
    meshes = document.get("meshes", [])
    placed = []
    for node in document.get("nodes", []):
        if "mesh" in node:
            translation = np.asarray(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
            scale = np.asarray(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)
            placed.append((meshes[node["mesh"]], (translation, scale)))
    return placed


def _external(tile: Tile) -> bool:
    """Whether ``tile``'s content is an external tileset."""
    return any(str(content.uri).endswith(".json") for content in tile.contents)


class _BoxTest:
    """Whether ECEF points lie in an oriented box of a tile's frame."""

    def __init__(self, frame: np.ndarray, centre: np.ndarray, axes: np.ndarray) -> None:
        self.frame, self.centre, self.axes = frame, centre, axes

    def __call__(self, ecef: np.ndarray) -> bool:
        """Whether every point lies in the box (within :data:`TOLERANCE`)."""
        if not len(ecef):
            return True
        local = (ecef - self.frame[:3, 3]) @ np.linalg.inv(self.frame[:3, :3]).T - self.centre
        lengths = np.linalg.norm(self.axes, axis=1)
        safe = np.where(lengths > 0, lengths, 1.0)
        along = np.abs(local @ (self.axes / safe[:, None] ** 2).T) * safe
        return bool((along <= lengths + TOLERANCE).all())


def frame_points(frame: np.ndarray, gltf_positions: np.ndarray) -> np.ndarray:
    """ECEF of a tile's glTF content positions (y-up) under the tile's ``frame``."""
    local = np.asarray(gltf_positions, dtype=np.float64) @ _GLTF_TO_Z_UP.T
    return local @ frame[:3, :3].T + frame[:3, 3]


def _corners(frame: np.ndarray, box: list[float]) -> np.ndarray:
    """The 8 corners (ECEF) of a ``box`` in ``frame``."""
    centre, axes = np.asarray(box[:3], float), np.asarray(box[3:], float).reshape(3, 3)
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    local = centre + signs @ axes
    return local @ frame[:3, :3].T + frame[:3, 3]


def read_glb(path: Path) -> tuple[dict, bytes]:
    """A GLB's JSON document and binary chunk (``ValueError`` for a file that is not one)."""
    return glb_parts(path.read_bytes())


def glb_parts(data: bytes) -> tuple[dict, bytes]:
    """The JSON document and binary chunk of GLB ``data`` (``ValueError`` if it is not one,
    or if its JSON nests deeper than :data:`.tree.MAX_DEPTH`)."""
    text, blob = split_glb(data)
    deep = ValueError(f"its JSON nests arrays and objects over {MAX_DEPTH} deep")
    if too_deep(Source(text, 0, len(text), None), MAX_DEPTH):
        raise deep
    try:
        document = json.loads(bytes(text))
    except RecursionError:  # an encoding other than UTF-8 can hide brackets from too_deep
        raise deep from None
    return document, bytes(blob)
