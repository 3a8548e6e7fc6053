"""The checks of a glTF document element by element (:class:`ElementChecks`): buffers, buffer
views and accessors inside what holds them, a primitive's counts, indices and declared bounds,
every reference inside its array, and the MSFT_lod rules of the scene graph, each broken rule a
finding of its own. They read the JSON as parsed objects (or element by element, where the
arrays are too large to hold) and are run where the summary checks (:mod:`.summary`) find
something.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from typing import Any

import numpy as np

from ..findings import Findings
from .binary import (
    COMPONENT_DTYPES,
    COMPONENT_SIZES,
    MESHOPT,
    TRIANGLES,
    WIDTHS,
    GlbError,
    unpacked_view,
)
from .lod import MSFT_LOD
from .rules import (
    READ_BUDGET,
    chain_facts,
    chain_facts_findings,
    lod_extras_findings,
)
from .stream import LazyArray

_MODES = ("ATTRIBUTES", "TRIANGLES", "INDICES")
_FILTERS = ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL")
"""The modes and filters of ``EXT_meshopt_compression``."""


def _is_uint(value: Any) -> bool:
    """Whether ``value`` is a JSON integer >= 0 (``true`` is not)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


class ElementChecks:
    """The checks of one parsed glTF document (``doc``, the JSON; ``blob``, buffer 0)."""

    def __init__(self, doc: dict[str, Any], blob: memoryview | bytes, findings: Findings) -> None:
        self.doc, self.blob, self.findings = doc, blob, findings
        self.bad_views: set[int] = set()
        self.bad_accessors: set[int] = set()
        self.read_budget = READ_BUDGET * len(blob)
        self._arrays: dict[str, list[dict[str, Any]]] = {}

    def array(self, key: str) -> list[dict[str, Any]]:
        """The top-level array ``key`` ([] when absent, or, with an error, when it is not an
        array of objects)."""
        if key not in self._arrays:
            items = self.doc.get(key, [])
            if isinstance(items, LazyArray):
                objects = items.all_objects
            else:
                objects = isinstance(items, list) and all(isinstance(i, dict) for i in items)
            if not objects:
                self.findings.error("GLTF_STRUCTURE", f"{key} is not an array of objects")
                items = []
            self._arrays[key] = items
        return self._arrays[key]

    def ref(self, value: Any, key: str, where: str) -> bool:
        """Whether ``value`` indexes the array ``key``; an error when it does not."""
        size = len(self.array(key))
        if _is_uint(value) and value < size:
            return True
        self.findings.error(
            "REFERENCE", f"{where} refers to {key} {value!r}, outside {key} ({size})"
        )
        return False

    def node_name(self, index: int) -> str:
        """``node {index}``, with the node's name where it has one (for messages)."""
        name = self.array("nodes")[index].get("name")
        return f"node {index}" + (f" ({name})" if name else "")

    def run(self) -> None:
        """Run every check: the asset version, buffers, views and accessors, each mesh's
        primitives, the scene graph and the LOD chains, in that order."""
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
        """Buffer 0 holding its declared length, then every buffer view and accessor (those
        that cannot be used go into ``bad_views`` and ``bad_accessors``)."""
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
            where = f"bufferView {i}"
            if not self.ref(view.get("buffer"), "buffers", where) or not self.check_view(
                where, view, lengths[view["buffer"]]
            ):
                self.bad_views.add(i)
        for i, accessor in enumerate(self.array("accessors")):
            if not self.check_accessor(i, accessor):
                self.bad_accessors.add(i)

    def check_view(self, where: str, view: dict[str, Any], buffer_length: int) -> bool:
        """Whether the view's offset, length and stride are usable (an error when not); one
        past the end of its buffer is an error but stays usable for the accessor checks."""
        offset, length = view.get("byteOffset", 0), view.get("byteLength")
        if not (_is_uint(offset) and _is_uint(length) and length > 0):
            self.findings.error(
                "BUFFER_VIEW", f"{where} needs a byteOffset >= 0 and a byteLength >= 1"
            )
            return False
        stride = view.get("byteStride")
        if stride is not None and not (_is_uint(stride) and 4 <= stride <= 252 and stride % 4 == 0):
            self.findings.error(
                "BUFFER_VIEW_STRIDE",
                f"{where} byteStride is {stride!r}, not a multiple of 4 from 4 to 252",
            )
            return False
        if offset + length > buffer_length:
            self.findings.error(
                "BUFFER_VIEW_BOUNDS",
                f"{where} ends at byte {offset + length}, past buffer {view['buffer']} "
                f"({buffer_length} bytes)",
            )
        packed = (view.get("extensions") or {}).get(MESHOPT)
        return packed is None or self.check_packed(where, view, packed)

    def check_packed(self, where: str, view: dict[str, Any], packed: Any) -> bool:
        """Whether a view's ``EXT_meshopt_compression`` object is usable: its fields of their
        types, its data inside buffer 0, its count × byteStride the view's byteLength."""
        fields = ("byteOffset", "byteLength", "byteStride", "count")
        if not (
            isinstance(packed, dict)
            and packed.get("buffer", 0) == 0
            and all(_is_uint(packed.get(k, 0)) for k in fields)
            and packed.get("mode") in _MODES
            and packed.get("filter", "NONE") in _FILTERS
        ):
            self.findings.error("MESHOPT", f"{where} has an {MESHOPT} object that is not usable")
            return False
        if packed["count"] * packed["byteStride"] != view["byteLength"]:
            self.findings.error(
                "MESHOPT",
                f"{where} holds {view['byteLength']} bytes but its {MESHOPT} data "
                f"{packed['count']} × {packed['byteStride']}",
            )
            return False
        if packed.get("byteOffset", 0) + packed["byteLength"] > len(self.blob):
            self.findings.error("MESHOPT", f"{where} has {MESHOPT} data past buffer 0")
            return False
        return True

    def check_accessor(self, index: int, accessor: dict[str, Any]) -> bool:
        """Whether the accessor's data lies inside its view (and can be read)."""
        where = f"accessor {index}"
        width = WIDTHS.get(accessor.get("type"))
        size = COMPONENT_SIZES.get(accessor.get("componentType"))
        count, offset = accessor.get("count"), accessor.get("byteOffset", 0)
        if not (width and size and _is_uint(count) and count > 0 and _is_uint(offset)):
            self.findings.error(
                "ACCESSOR", f"{where} has a bad type, componentType, count or byteOffset"
            )
            return False
        if "bufferView" not in accessor:
            return False  # all zeros by the spec: nothing to read
        if not self.ref(accessor["bufferView"], "bufferViews", where):
            return False
        if accessor["bufferView"] in self.bad_views:
            return False
        view = self.array("bufferViews")[accessor["bufferView"]]
        stride = view.get("byteStride", size * width)
        if stride < size * width:
            self.findings.error(
                "ACCESSOR_STRIDE",
                f"{where} elements have {size * width} bytes, more than the byteStride {stride} "
                f"of bufferView {accessor['bufferView']}",
            )
            return False
        end = offset + stride * (count - 1) + size * width
        if end > view["byteLength"]:
            self.findings.error(
                "ACCESSOR_BOUNDS",
                f"{where} needs {end} bytes of bufferView {accessor['bufferView']}, which has "
                f"{view['byteLength']}",
            )
            return False
        for bound in ("min", "max"):
            if bound in accessor and len(accessor[bound]) != width:
                self.findings.error("ACCESSOR_MIN_MAX", f"{where} {bound} needs {width} values")
                return False
        in_blob = view.get("byteOffset", 0) + view["byteLength"] <= len(self.blob)
        return view.get("buffer") == 0 and in_blob

    def data(self, index: int) -> np.ndarray | None:
        """The accessor's values as (count, width) in their stored type; ``None`` when they
        cannot be read (an error was reported, or they are not in buffer 0) or the data read
        so far has used up :data:`READ_BUDGET` (a warning, once)."""
        if index in self.bad_accessors:
            return None
        accessor = self.array("accessors")[index]
        if "bufferView" not in accessor:
            return None
        view = self.array("bufferViews")[accessor["bufferView"]]
        dtype = COMPONENT_DTYPES[accessor["componentType"]]
        width = WIDTHS[accessor["type"]]
        start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
        stride = view.get("byteStride", dtype.itemsize * width)
        source = self.blob
        packed = (view.get("extensions") or {}).get(MESHOPT)
        if packed is not None:
            source = self._unpacked(index, packed)
            if source is None:
                return None
            start = accessor.get("byteOffset", 0)
        elif view.get("buffer", 0) != 0:
            return None
        left = self.read_budget
        self.read_budget -= stride * accessor["count"]
        if self.read_budget < 0:
            if left >= 0:
                self.findings.warning(
                    "ACCESSOR_DATA_UNCHECKED",
                    f"accessors read buffer 0 more than {READ_BUDGET} times over: the values "
                    f"of accessor {index} and later reads are not checked",
                )
            return None
        return np.ndarray(
            (accessor["count"], width), dtype, source, start, (stride, dtype.itemsize)
        )

    def _unpacked(self, index: int, packed: dict[str, Any]) -> bytes | None:
        """The decoded bytes of accessor ``index``'s packed view; ``None`` (an error, or a
        warning for a filter lodconvert does not decode) where they cannot be had."""
        try:
            return unpacked_view(self.blob, packed)
        except GlbError as exc:
            if packed.get("filter", "NONE") != "QUATERNION":
                self.findings.error("MESHOPT", f"accessor {index}: {exc}")
            else:
                self.findings.warning("MESHOPT_UNCHECKED", f"accessor {index}: {exc}")
            self.bad_accessors.add(index)
            return None

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
        """A primitive's attributes (inside ``accessors``, equal in count, POSITION's bounds
        as declared) and its indices."""
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
        """A primitive's indices: whole triangles (in triangle mode), none past its
        ``vertices``."""
        index = primitive["indices"]
        count = self.array("accessors")[index].get("count", 0)
        if primitive.get("mode", TRIANGLES) == TRIANGLES and count % 3:
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
        """Nodes' children and meshes, the default scene and scenes' roots inside their
        arrays."""
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
        """The LOD chains: at least one; MSFT_lod used but not required; each MSFT_lod node's
        rules and each one-level chain's ``extras.lodconvert``."""
        nodes = self.array("nodes")
        used = self.doc.get("extensionsUsed", [])
        required = self.doc.get("extensionsRequired", [])
        roots = {r for scene in self.array("scenes") for r in scene.get("nodes", [])}
        children = {c for node in nodes for c in node.get("children", [])}
        holders = [i for i, node in enumerate(nodes) if MSFT_LOD in node.get("extensions", {})]
        finest = {i: facts for i, node in enumerate(nodes) if (facts := chain_facts(node))}
        if not holders and not finest:
            self.findings.error(
                "NO_LOD_CHAIN",
                f"no lodconvert LOD chain: no node has {MSFT_LOD} or extras.lodconvert levels",
            )
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
        for i, facts in finest.items():
            if i not in holders:  # a one-level chain: no coarser nodes
                self.check_chain_facts(self.node_name(i), facts, 0)

    def check_lod_node(
        self, index: int, node: dict[str, Any], roots: set[int], children: set[int]
    ) -> None:
        """MSFT_lod node ``index``: its ids inside ``nodes``, distinct, neither scene
        ``roots`` nor ``children``; its extras."""
        name = self.node_name(index)
        ids = node["extensions"][MSFT_LOD].get("ids", [])
        size = len(self.array("nodes"))
        listed = Counter(lod for lod in ids if _is_uint(lod))
        for lod in ids:
            if not (_is_uint(lod) and lod < size):
                self.findings.error(
                    "MSFT_LOD_ID_RANGE", f"{name} MSFT_lod id {lod!r} is outside nodes ({size})"
                )
            elif lod == index or listed[lod] > 1:
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
        self.report(lod_extras_findings(name, extras, len(ids)))

    def check_chain_facts(self, name: str, facts: dict[str, Any], ids: int) -> None:
        """``extras.lodconvert`` of a finest node with ``ids`` coarser nodes."""
        self.report(chain_facts_findings(name, facts, ids))

    def report(self, findings: Iterable[tuple[str, str, str]]) -> None:
        """Record (severity, code, message) findings as they come (an exception after some
        leaves those recorded)."""
        for severity, code, message in findings:
            getattr(self.findings, severity)(code, message)
