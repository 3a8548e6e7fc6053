"""glTF checks (``.glb``, ``.gltf`` with an embedded buffer): GLB framing; buffer views inside
their buffer and accessors inside their view; a primitive's attributes with equal counts, its
indices inside them, declared ``min``/``max`` equal to the data; every reference inside its
array; and the ``MSFT_lod`` rules lodconvert follows (DESIGN.md): ``ids`` inside ``nodes`` and
distinct, coarser nodes neither scene roots nor children, ``extras.MSFT_screencoverage``
strictly falling with one value more than ``ids``, the extension in ``extensionsUsed`` but not
required, and ``extras.lodconvert`` levels and cutoffs consistent with the chain.
"""

from __future__ import annotations

import itertools
import math
import struct
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from ..errors import InputError
from ..io.gltf import MSFT_LOD
from ..io.gltf import _parse as parse_gltf_bytes
from .findings import Findings

_COMPONENT_SIZES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_COMPONENT_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_TRIANGLES = 4


def _finite(values: Iterable[Any]) -> bool:
    """Whether every value is a finite JSON number."""
    return all(isinstance(v, int | float) and math.isfinite(v) for v in values)


class _Gltf:
    """The checks of one parsed glTF document (``doc``, the JSON; ``blob``, buffer 0)."""

    def __init__(self, doc: dict[str, Any], blob: bytes, findings: Findings) -> None:
        self.doc, self.blob, self.findings = doc, blob, findings
        self.bad_accessors: set[int] = set()
        self._arrays: dict[str, list[dict[str, Any]]] = {}

    def array(self, key: str) -> list[dict[str, Any]]:
        """The top-level array ``key`` ([] when absent, or, with an error, when it is not an
        array of objects)."""
        if key not in self._arrays:
            items = self.doc.get(key, [])
            if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
                self.findings.error("GLTF_STRUCTURE", f"{key} is not an array of objects")
                items = []
            self._arrays[key] = items
        return self._arrays[key]

    def ref(self, value: Any, key: str, where: str) -> bool:
        """Whether ``value`` indexes the array ``key``; an error when it does not."""
        size = len(self.array(key))
        if isinstance(value, int) and not isinstance(value, bool) and 0 <= value < size:
            return True
        self.findings.error(
            "REFERENCE", f"{where} refers to {key} {value!r}, outside {key} ({size})"
        )
        return False

    def node_name(self, index: int) -> str:
        name = self.array("nodes")[index].get("name")
        return f"node {index}" + (f" ({name})" if name else "")

    def run(self) -> None:
        version = self.doc.get("asset", {}).get("version")
        if version != "2.0":
            self.findings.error("ASSET_VERSION", f"asset.version is {version!r}, not '2.0'")
        self.check_buffers()
        for i, mesh in enumerate(self.array("meshes")):
            for k, primitive in enumerate(mesh.get("primitives", [])):
                self.check_primitive(primitive, f"mesh {i} primitive {k}")
        self.check_graph()
        self.check_msft_lod()

    # buffers, views, accessors

    def check_buffers(self) -> None:
        lengths = []
        for i, buffer in enumerate(self.array("buffers")):
            length = buffer.get("byteLength")
            lengths.append(length if isinstance(length, int) else 0)
            if i == 0 and isinstance(length, int) and length > len(self.blob):
                self.findings.error(
                    "BUFFER_LENGTH",
                    f"buffer 0 declares {length} bytes but the file holds {len(self.blob)}",
                )
        for i, view in enumerate(self.array("bufferViews")):
            if not self.ref(view.get("buffer"), "buffers", f"bufferView {i}"):
                continue
            end = view.get("byteOffset", 0) + view.get("byteLength", 0)
            if end > lengths[view["buffer"]]:
                self.findings.error(
                    "BUFFER_VIEW_BOUNDS",
                    f"bufferView {i} ends at byte {end}, past buffer {view['buffer']} "
                    f"({lengths[view['buffer']]} bytes)",
                )
        for i, accessor in enumerate(self.array("accessors")):
            if not self.check_accessor(i, accessor):
                self.bad_accessors.add(i)

    def check_accessor(self, index: int, accessor: dict[str, Any]) -> bool:
        """Whether the accessor's data lies inside its view (and can be read)."""
        where = f"accessor {index}"
        width = _WIDTHS.get(accessor.get("type"))
        size = _COMPONENT_SIZES.get(accessor.get("componentType"))
        count = accessor.get("count")
        if width is None or size is None or not isinstance(count, int) or count < 1:
            self.findings.error("ACCESSOR", f"{where} has a bad type, componentType or count")
            return False
        if "bufferView" not in accessor:
            return False  # all zeros by the spec: nothing to read
        if not self.ref(accessor["bufferView"], "bufferViews", where):
            return False
        view = self.array("bufferViews")[accessor["bufferView"]]
        stride = view.get("byteStride", size * width)
        end = accessor.get("byteOffset", 0) + stride * (count - 1) + size * width
        if end > view.get("byteLength", 0):
            self.findings.error(
                "ACCESSOR_BOUNDS",
                f"{where} needs {end} bytes of bufferView {accessor['bufferView']}, which has "
                f"{view.get('byteLength', 0)}",
            )
            return False
        for bound in ("min", "max"):
            if bound in accessor and len(accessor[bound]) != width:
                self.findings.error("ACCESSOR_MIN_MAX", f"{where} {bound} needs {width} values")
                return False
        in_blob = view.get("byteOffset", 0) + view.get("byteLength", 0) <= len(self.blob)
        return view.get("buffer") == 0 and in_blob

    def data(self, index: int) -> np.ndarray | None:
        """The accessor's values as (count, width) in their stored type; ``None`` when they
        cannot be read (an error was reported, or they are not in buffer 0)."""
        if index in self.bad_accessors:
            return None
        accessor = self.array("accessors")[index]
        if "bufferView" not in accessor:
            return None
        view = self.array("bufferViews")[accessor["bufferView"]]
        dtype = np.dtype(_COMPONENT_DTYPES[accessor["componentType"]])
        width = _WIDTHS[accessor["type"]]
        start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
        stride = view.get("byteStride", dtype.itemsize * width)
        return np.ndarray(
            (accessor["count"], width), dtype, self.blob, start, (stride, dtype.itemsize)
        )

    def check_bounds(self, index: int, where: str) -> None:
        """Declared ``min``/``max`` equal the data's (POSITION must declare them)."""
        accessor = self.array("accessors")[index]
        values = self.data(index)
        if values is None:
            return
        for bound, actual in (("min", values.min(axis=0)), ("max", values.max(axis=0))):
            if bound not in accessor:
                self.findings.error(
                    "ACCESSOR_MIN_MAX", f"{where} POSITION accessor {index} has no {bound}"
                )
                continue
            declared = np.array(accessor[bound], dtype=np.float64).astype(values.dtype)
            if not np.array_equal(declared, actual):
                self.findings.error(
                    "ACCESSOR_MIN_MAX",
                    f"{where} accessor {index} declares {bound} {accessor[bound]} but its data "
                    f"has {actual.tolist()}",
                )

    def check_primitive(self, primitive: dict[str, Any], where: str) -> None:
        attributes = primitive.get("attributes", {})
        counts = {}
        for name, index in attributes.items():
            if self.ref(index, "accessors", f"{where} {name}"):
                counts[name] = self.array("accessors")[index].get("count")
        if len(set(counts.values())) > 1:
            listed = ", ".join(f"{name} {count}" for name, count in counts.items())
            self.findings.error("PRIMITIVE_COUNT", f"{where} attributes differ in count: {listed}")
        if "POSITION" in counts:
            self.check_bounds(attributes["POSITION"], where)
        if "indices" in primitive and self.ref(
            primitive["indices"], "accessors", f"{where} indices"
        ):
            self.check_indices(primitive, counts.get("POSITION"), where)

    def check_indices(self, primitive: dict[str, Any], vertices: int | None, where: str) -> None:
        index = primitive["indices"]
        count = self.array("accessors")[index].get("count", 0)
        if primitive.get("mode", _TRIANGLES) == _TRIANGLES and count % 3:
            self.findings.error("INDEX_COUNT", f"{where} has {count} indices, not whole triangles")
        values = self.data(index)
        if (
            values is not None
            and vertices is not None
            and values.size
            and int(values.max()) >= vertices
        ):
            self.findings.error(
                "INDEX_RANGE",
                f"{where} index {int(values.max())} is outside its {vertices} vertices",
            )

    # scene graph and MSFT_lod

    def check_graph(self) -> None:
        nodes = self.array("nodes")
        for i, node in enumerate(nodes):
            for child in node.get("children", []):
                self.ref(child, "nodes", f"{self.node_name(i)} child")
            if "mesh" in node:
                self.ref(node["mesh"], "meshes", self.node_name(i))
        scenes = self.array("scenes")
        if "scene" in self.doc:
            self.ref(self.doc["scene"], "scenes", "scene")
        for i, scene in enumerate(scenes):
            for root in scene.get("nodes", []):
                self.ref(root, "nodes", f"scene {i}")

    def check_msft_lod(self) -> None:
        nodes = self.array("nodes")
        used = self.doc.get("extensionsUsed", [])
        required = self.doc.get("extensionsRequired", [])
        roots = {r for scene in self.array("scenes") for r in scene.get("nodes", [])}
        children = {c for node in nodes for c in node.get("children", [])}
        holders = [i for i, node in enumerate(nodes) if MSFT_LOD in node.get("extensions", {})]
        if holders and MSFT_LOD not in used:
            self.findings.error("MSFT_LOD_NOT_USED", f"{MSFT_LOD} is missing from extensionsUsed")
        if MSFT_LOD in required:
            self.findings.warning(
                "MSFT_LOD_REQUIRED",
                f"{MSFT_LOD} is in extensionsRequired: clients without it cannot load the file",
            )
        if not set(required) <= set(used):
            self.findings.error(
                "EXTENSIONS", "extensionsRequired lists extensions not in extensionsUsed"
            )
        for i in holders:
            self.check_lod_node(i, nodes[i], roots, children)

    def check_lod_node(
        self, index: int, node: dict[str, Any], roots: set[int], children: set[int]
    ) -> None:
        name = self.node_name(index)
        ids = node["extensions"][MSFT_LOD].get("ids", [])
        size = len(self.array("nodes"))
        for lod in ids:
            if not (isinstance(lod, int) and 0 <= lod < size):
                self.findings.error(
                    "MSFT_LOD_ID_RANGE", f"{name} MSFT_lod id {lod!r} is outside nodes ({size})"
                )
            elif lod == index or ids.count(lod) > 1:
                self.findings.error(
                    "MSFT_LOD_ID_DUPLICATE", f"{name} MSFT_lod lists node {lod} twice"
                )
            elif lod in roots:
                self.findings.error(
                    "MSFT_LOD_SCENE_ROOT",
                    f"{name} MSFT_lod level {self.node_name(lod)} is a scene root",
                )
            elif lod in children:
                self.findings.error(
                    "MSFT_LOD_CHILD",
                    f"{name} MSFT_lod level {self.node_name(lod)} is another node's child",
                )
        extras = node.get("extras", {}) if isinstance(node.get("extras"), dict) else {}
        coverage = extras.get("MSFT_screencoverage")
        if coverage is None:
            self.findings.warning("MSFT_LOD_COVERAGE", f"{name} has no extras.MSFT_screencoverage")
        elif len(coverage) != len(ids) + 1:
            self.findings.error(
                "MSFT_LOD_COVERAGE",
                f"{name} has {len(coverage)} screen coverages for {len(ids)} ids "
                f"(needs {len(ids) + 1})",
            )
        elif not _finite(coverage) or min(coverage) < 0:
            self.findings.error("MSFT_LOD_COVERAGE", f"{name} screen coverages are not all >= 0")
        elif any(b >= a for a, b in itertools.pairwise(coverage)):
            self.findings.error(
                "MSFT_LOD_COVERAGE", f"{name} screen coverages do not fall strictly: {coverage}"
            )
        facts = extras.get("lodconvert")
        if isinstance(facts, dict):
            self.check_chain_facts(name, facts, len(ids))

    def check_chain_facts(self, name: str, facts: dict[str, Any], ids: int) -> None:
        """``extras.lodconvert`` of a finest node: one level per node, cutoffs as the chain."""
        levels, cutoffs = facts.get("levels", []), facts.get("cutoffs", [])
        if len(levels) != ids + 1:
            self.findings.error(
                "LODCONVERT_LEVELS", f"{name} extras list {len(levels)} levels for {ids + 1} nodes"
            )
        expected = ids + int(bool(facts.get("culled")))
        if len(cutoffs) != expected or any(b <= a for a, b in itertools.pairwise(cutoffs)):
            self.findings.error(
                "LODCONVERT_CUTOFFS",
                f"{name} extras cutoffs {cutoffs} are not {expected} increasing distances",
            )


def check_gltf(path: Path, findings: Findings, _: etree.XMLSchema | None) -> None:
    """Parse the GLB (or embedded-buffer glTF) and run every check; malformed JSON structure
    becomes one finding, never an exception."""
    try:
        doc, blob = parse_gltf_bytes(path.read_bytes())
    except InputError as exc:
        findings.error("GLTF_FORMAT", str(exc))
        return
    except (ValueError, struct.error) as exc:  # JSON or UTF-8 errors, short chunk headers
        findings.error("GLTF_FORMAT", f"not glTF: {exc}")
        return
    if not isinstance(doc, dict):
        findings.error("GLTF_STRUCTURE", "the JSON is not an object")
        return
    try:
        _Gltf(doc, blob, findings).run()
    except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
        findings.error("GLTF_STRUCTURE", f"malformed glTF JSON ({type(exc).__name__}: {exc})")
