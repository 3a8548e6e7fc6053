"""The summary checks: what a glTF file of any size reduces to, checked with numpy. As
:mod:`.stream` reads the JSON window by window, the sinks of :data:`SINKS` keep compact int64
columns of the accessors, buffer views, meshes and nodes (not the elements themselves);
:func:`clean` decides from them, and from the accessor values read a block at a time
(:mod:`.extrema`), that the checks element by element would find nothing. Where it cannot, or
where the file is not as lodconvert writes it, those checks run.
"""

from __future__ import annotations

import itertools
from array import array
from typing import Any

import numpy as np

from .binary import COMPONENT_DTYPES, COMPONENT_SIZES, FLOAT, TRIANGLES, WIDTHS
from .extrema import extrema, groups
from .lod import MSFT_LOD
from .rules import (
    READ_BUDGET,
    chain_facts,
    chain_facts_findings,
    lod_extras_findings,
)
from .stream import LazyArray, Source

_BIG = 1 << 40
"""Numbers from here on are left to :class:`~.elements.ElementChecks` (so that no sum of them
overflows int64)."""
_SIZE_TABLE = np.zeros(max(COMPONENT_SIZES) + 1, np.int64)
_SIZE_TABLE[list(COMPONENT_SIZES)] = list(COMPONENT_SIZES.values())


def _uint(value: Any) -> bool:
    """A JSON integer in [0, :data:`_BIG`) (``true`` is not)."""
    return type(value) is int and 0 <= value < _BIG


def _all_uint(values: list[Any]) -> bool:
    """Whether every value is a JSON integer in [0, :data:`_BIG`)."""
    if not values:
        return True
    return set(map(type, values)) == {int} and min(values) >= 0 and max(values) < _BIG


def _all_numbers(values: list[Any]) -> bool:
    """Whether every value is a JSON number that is exactly a float64."""
    kinds = set(map(type, values))
    if not kinds <= {float, int}:
        return False
    whole = [v for v in values if type(v) is int] if int in kinds else []
    return not whole or (min(whole) >= -(2**53) and max(whole) <= 2**53)


def _numbers(value: Any, width: int) -> bool:
    """A list of ``width`` JSON numbers, each exactly a float64."""
    return type(value) is list and len(value) == width and _all_numbers(value)


class _Facts:
    """What the summary checks need of one top-level array, in int64 columns, gathered as its
    elements are read; ``regular`` stays true while every element has the types lodconvert
    writes (else :class:`~.elements.ElementChecks` checks the file)."""

    columns: tuple[str, ...] = ()

    def __init__(self) -> None:
        self.regular = True
        self.size = 0
        for name in self.columns:
            setattr(self, name, array("q"))

    def add(self, first: int, items: list[Any]) -> None:
        """The sink of :func:`~.stream.read_object`: take the facts of elements ``first`` on."""
        self.size += len(items)
        if self.regular and items and set(map(type, items)) != {dict}:
            self.regular = False
        if self.regular:
            self.regular = self.take_all(first, items)

    def take_all(self, first: int, items: list[dict[str, Any]]) -> bool:
        """Take the facts of elements ``first`` on (objects); whether they are regular."""
        return all(self.take(index, item) for index, item in enumerate(items, first))

    def take(self, index: int, item: dict[str, Any]) -> bool:
        raise NotImplementedError

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.frombuffer(getattr(self, name), np.int64) for name in self.columns}


class _Accessors(_Facts):
    columns = ("view", "offset", "ctype", "count", "width", "bounds")

    def __init__(self) -> None:
        super().__init__()
        self.declared = array("d")  # min then max of the accessors that declare them

    def take_all(self, first: int, items: list[dict[str, Any]]) -> bool:
        view = [item.get("bufferView") for item in items]
        offset = [item.get("byteOffset", 0) for item in items]
        ctype = [item.get("componentType") for item in items]
        count = [item.get("count") for item in items]
        width = [WIDTHS.get(k, 0) if type(k) is str else 0 for k in (i.get("type") for i in items)]
        if not (_all_uint(view) and _all_uint(offset) and _all_uint(count) and all(width)):
            return False
        if min(count, default=1) <= 0:
            return False
        if set(map(type, ctype)) != {int} or not set(ctype) <= COMPONENT_SIZES.keys():
            return False
        bounds = [-1] * len(items)
        declared: list[Any] = []
        at = len(self.declared)
        for k, item in enumerate(items):
            if "min" in item or "max" in item:
                low, high = item.get("min"), item.get("max")
                if not (type(low) is type(high) is list and len(low) == len(high) == width[k]):
                    return False
                bounds[k] = at + len(declared)
                declared += low
                declared += high
        if not _all_numbers(declared):
            return False
        self.declared.extend(declared)
        self.view.extend(view)
        self.offset.extend(offset)
        self.ctype.extend(ctype)
        self.count.extend(count)
        self.width.extend(width)
        self.bounds.extend(bounds)
        return True

    def take(self, index: int, item: dict[str, Any]) -> bool:
        view, offset = item.get("bufferView"), item.get("byteOffset", 0)
        ctype, count, kind = item.get("componentType"), item.get("count"), item.get("type")
        width = WIDTHS.get(kind, 0) if type(kind) is str else 0
        if not (
            width
            and _uint(view)
            and _uint(offset)
            and type(ctype) is int
            and ctype in COMPONENT_SIZES
            and _uint(count)
            and count > 0
        ):
            return False
        bounds = -1
        if "min" in item or "max" in item:
            low, high = item.get("min"), item.get("max")
            if not (_numbers(low, width) and _numbers(high, width)):
                return False
            bounds = len(self.declared)
            self.declared.extend(low)
            self.declared.extend(high)
        self.view.append(view)
        self.offset.append(offset)
        self.ctype.append(ctype)
        self.count.append(count)
        self.width.append(width)
        self.bounds.append(bounds)
        return True


class _Views(_Facts):
    columns = ("buffer", "offset", "length", "stride")

    def take_all(self, first: int, items: list[dict[str, Any]]) -> bool:
        if any("extensions" in item for item in items):
            return False  # meshopt-packed: the checks element by element decode them
        if any("byteStride" in item for item in items):
            return super().take_all(first, items)  # not all as lodconvert writes them
        buffer = [item.get("buffer") for item in items]
        offset = [item.get("byteOffset", 0) for item in items]
        length = [item.get("byteLength") for item in items]
        if not (_all_uint(buffer) and _all_uint(offset) and _all_uint(length)):
            return False
        if min(length, default=1) <= 0:
            return False
        self.buffer.extend(buffer)
        self.offset.extend(offset)
        self.length.extend(length)
        self.stride.frombytes(bytes(8 * len(items)))
        return True

    def take(self, index: int, item: dict[str, Any]) -> bool:
        if "extensions" in item:
            return False
        buffer, offset = item.get("buffer"), item.get("byteOffset", 0)
        length, stride = item.get("byteLength"), item.get("byteStride", 0)
        if "byteStride" in item and not (type(stride) is int and 4 <= stride <= 252):
            return False
        if not (
            _uint(buffer) and _uint(offset) and _uint(length) and length > 0 and stride % 4 == 0
        ):
            return False
        self.buffer.append(buffer)
        self.offset.append(offset)
        self.length.append(length)
        self.stride.append(stride)
        return True


class _Meshes(_Facts):
    """Per primitive: its POSITION and indices accessors (-1: none) and whether it is made of
    triangles; per attribute: its primitive and accessor."""

    columns = ("position", "indices", "triangles", "attribute_of", "attribute")

    def take(self, index: int, item: dict[str, Any]) -> bool:
        primitives = item.get("primitives", [])
        if type(primitives) is not list:
            return False
        for primitive in primitives:
            if type(primitive) is not dict:
                return False
            attributes = primitive.get("attributes", {})
            indices, mode = primitive.get("indices", -1), primitive.get("mode", TRIANGLES)
            if type(attributes) is not dict or type(mode) is not int:
                return False
            if "indices" in primitive and not _uint(indices):
                return False
            if not all(_uint(a) for a in attributes.values()):
                return False
            at = len(self.position)
            for accessor in attributes.values():
                self.attribute_of.append(at)
                self.attribute.append(accessor)
            self.position.append(attributes.get("POSITION", -1))
            self.indices.append(indices)
            self.triangles.append(mode == TRIANGLES)
        return True


class _Nodes(_Facts):
    """Per node its mesh (-1: none); all nodes' children and MSFT_lod ids; how many hold
    MSFT_lod and how many are one-level chains. A node whose own MSFT_lod rules (ids, extras)
    give a finding is not regular."""

    columns = ("mesh", "children", "ids")

    def __init__(self) -> None:
        super().__init__()
        self.holders = self.chains = 0

    def take(self, index: int, item: dict[str, Any]) -> bool:
        children, mesh = item.get("children", []), item.get("mesh", -1)
        extensions = item.get("extensions", {})
        if type(children) is not list or not all(_uint(c) for c in children):
            return False
        if ("mesh" in item and not _uint(mesh)) or type(extensions) is not dict:
            return False
        try:
            if MSFT_LOD in extensions:
                lod = extensions[MSFT_LOD]
                ids = lod.get("ids", []) if type(lod) is dict else None
                if type(ids) is not list or not all(_uint(i) for i in ids):
                    return False
                if index in ids or len(set(ids)) < len(ids):
                    return False
                extras = item.get("extras", {}) if isinstance(item.get("extras"), dict) else {}
                if any(True for _ in lod_extras_findings("", extras, len(ids))):
                    return False
                self.ids.extend(ids)
                self.holders += 1
            elif (facts := chain_facts(item)) is not None:
                if any(True for _ in chain_facts_findings("", facts, 0)):
                    return False
                self.chains += 1
        except (AttributeError, KeyError, IndexError, TypeError, ValueError):
            return False
        self.mesh.append(mesh)
        self.children.extend(children)
        return True


def _sink(kind: type[_Facts]) -> Any:
    def make() -> tuple[_Facts, Any]:
        facts = kind()
        return facts, facts.add

    return make


SINKS = {
    "accessors": _sink(_Accessors),
    "bufferViews": _sink(_Views),
    "meshes": _sink(_Meshes),
    "nodes": _sink(_Nodes),
}
"""The sinks of :func:`~.stream.read_object`: for each top-level array whose facts the summary
checks need, a maker of those facts and of the sink its elements go to."""


def _facts(doc: dict[str, Any], key: str, kind: type[_Facts]) -> _Facts | None:
    """The facts of top-level array ``key`` (empty when absent); ``None`` when it is not a
    regular array of objects."""
    if key not in doc:
        return kind()
    items = doc[key]
    if not (isinstance(items, LazyArray) and items.all_objects and isinstance(items.facts, kind)):
        return None
    return items.facts if items.facts.regular else None


def _ints(value: Any) -> bool:
    return type(value) is list and all(_uint(v) for v in value)


def _strings(value: Any) -> bool:
    return type(value) is list and all(type(v) is str for v in value)


def clean(doc: dict[str, Any], blob: Source) -> bool:
    """Whether :class:`~.elements.ElementChecks` would find nothing in ``doc`` and ``blob``,
    decided from the facts gathered as the JSON was read (and the accessor values, read a block
    at a time); false also wherever the file is not as lodconvert writes it (the checks element
    by element then decide)."""
    parts = [
        _facts(doc, key, kind)
        for key, kind in (
            ("accessors", _Accessors),
            ("bufferViews", _Views),
            ("meshes", _Meshes),
            ("nodes", _Nodes),
        )
    ]
    if any(part is None for part in parts):
        return False
    accessor_facts, view_facts, mesh_facts, node_facts = parts
    assert isinstance(accessor_facts, _Accessors) and isinstance(node_facts, _Nodes)
    asset = doc.get("asset", {})
    if not (type(asset) is dict and asset.get("version") == "2.0"):
        return False
    buffers = doc.get("buffers", [])
    if type(buffers) is not list or not all(type(b) is dict for b in buffers):
        return False
    lengths = [b.get("byteLength") for b in buffers]
    if not all(_uint(n) for n in lengths) or (lengths and lengths[0] > len(blob)):
        return False
    # buffer views and accessors
    views = view_facts.arrays()
    if len(views["buffer"]) and int(views["buffer"].max()) >= len(buffers):
        return False
    view_end = views["offset"] + views["length"]
    if (view_end > np.array(lengths, np.int64)[views["buffer"]]).any():
        return False
    acc = accessor_facts.arrays()
    if len(acc["view"]) and int(acc["view"].max()) >= len(view_end):
        return False
    element = _SIZE_TABLE[acc["ctype"]] * acc["width"]
    stride = views["stride"][acc["view"]]
    stride = np.where(stride > 0, stride, element)
    if (stride < element).any():
        return False
    if (acc["offset"] + stride * (acc["count"] - 1) + element > views["length"][acc["view"]]).any():
        return False
    usable = (views["buffer"][acc["view"]] == 0) & (view_end[acc["view"]] <= len(blob))
    start = views["offset"][acc["view"]] + acc["offset"]
    # primitives
    mesh = mesh_facts.arrays()
    count = acc["count"]
    if len(mesh["attribute"]) and int(mesh["attribute"].max()) >= len(count):
        return False
    if len(mesh["indices"]) and int(mesh["indices"].max()) >= len(count):
        return False
    primitives = len(mesh["position"])
    counts = count[mesh["attribute"]]
    most = np.full(primitives, -1, np.int64)
    least = np.full(primitives, _BIG, np.int64)
    np.maximum.at(most, mesh["attribute_of"], counts)
    np.minimum.at(least, mesh["attribute_of"], counts)
    if ((most >= 0) & (most != least)).any():
        return False
    indexed = mesh["indices"] >= 0
    if (indexed & (mesh["triangles"] == 1) & (count[mesh["indices"]] % 3 != 0)).any():
        return False
    placed = mesh["position"] >= 0
    read_position = placed & usable[mesh["position"]]
    read_indices = indexed & usable[mesh["indices"]]
    cost = stride * count
    spent = int(cost[mesh["position"][read_position]].sum())
    spent += int(cost[mesh["indices"][read_indices]].sum())
    if spent > READ_BUDGET * len(blob):
        return False
    positions = np.unique(mesh["position"][read_position])
    index_accessors = np.unique(mesh["indices"][read_indices])
    if (acc["bounds"][positions] < 0).any() or (acc["ctype"][index_accessors] == FLOAT).any():
        return False
    declared = np.frombuffer(accessor_facts.declared, np.float64)
    largest = np.zeros(len(count), np.int64)
    wanted = np.union1d(positions, index_accessors)
    for (ctype, width), members in groups(wanted, acc["ctype"], acc["width"]):
        dtype = COMPONENT_DTYPES[ctype]
        low, high = extrema(members, start, count, stride, dtype, width, blob)
        bounded = np.isin(members, positions)
        at = acc["bounds"][members[bounded]][:, None] + np.arange(width)
        if not (
            np.array_equal(declared[at].astype(dtype), low[bounded])
            and np.array_equal(declared[at + width].astype(dtype), high[bounded])
        ):
            return False
        indexing = np.isin(members, index_accessors)
        largest[members[indexing]] = high[indexing].max(axis=1)
    checked = read_indices & placed
    if (largest[mesh["indices"][checked]] >= count[mesh["position"][checked]]).any():
        return False
    # scene graph and MSFT_lod
    nodes = node_facts.arrays()
    size = node_facts.size
    for key, limit in (("children", size), ("ids", size), ("mesh", mesh_facts.size)):
        if len(nodes[key]) and int(nodes[key].max()) >= limit:
            return False
    scenes = doc.get("scenes", [])
    if type(scenes) is not list or not all(type(scene) is dict for scene in scenes):
        return False
    if "scene" in doc and not (_uint(doc["scene"]) and doc["scene"] < len(scenes)):
        return False
    roots = [scene.get("nodes", []) for scene in scenes]
    if not all(_ints(r) for r in roots) or any(r >= size for r in itertools.chain(*roots)):
        return False
    taken = np.zeros(size, bool)  # scene roots and children: no MSFT_lod level may be one
    taken[list(itertools.chain(*roots))] = True
    taken[nodes["children"]] = True
    if taken[nodes["ids"]].any():
        return False
    used, required = doc.get("extensionsUsed", []), doc.get("extensionsRequired", [])
    if not (_strings(used) and _strings(required)) or not set(required) <= set(used):
        return False
    if not (node_facts.holders or node_facts.chains) or MSFT_LOD in required:
        return False
    return not node_facts.holders or MSFT_LOD in used
