"""The two readers: a ``.json`` document, whose objects are read :data:`BATCH` at a time, and a
CityJSONSeq file, whose header is read first and whose ``CityJSONFeature`` lines are then read
in batches of :data:`BATCH` objects, their nodes yielded lazily."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import closing
from dataclasses import dataclass
from itertools import chain
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import InputError
from ...limits import Limits
from ...model import Node, PackedNode, Scene, with_geometry
from ...semantics import Palette
from ..crs import crs_attributes
from ..geometry_checks import InputTally, attach_tally
from ..images import Images
from .geometry import SURFACE_DEPTH
from .objects import Objects, checked_node, checked_nodes
from .parallel import ObjectsReading, SequenceReading
from .ranges import SequenceRanges
from .sequence import Line, long_line, sequence_lines
from .source import (
    Context,
    cityjson_object,
    context_of,
    declared_crs,
    load_document,
    materials_of,
    parsed,
    texture_vertices_of,
    textures_of,
    unreadable,
)
from .triangulation import triangulate_batch
from .vertices import vertices_of

if TYPE_CHECKING:
    from ...context import RunContext

BATCH = 64
"""City objects whose polygons are triangulated together (a CityJSONSeq reader holds the
features they come in until then)."""


def _object_nodes(
    objects: dict[str, Any], ctx: Context, types: frozenset[str] | None
) -> list[Node]:
    """The root nodes of ``objects`` (:meth:`~.objects.Objects.roots`), read :data:`BATCH`
    objects at a time."""
    tree = Objects(objects, types)
    nodes: dict[str, Node | None] = {}
    for at in range(0, len(tree.order), BATCH):
        keys = tree.order[at : at + BATCH]
        nodes.update(zip(keys, checked_nodes([tree.read(key, ctx) for key in keys]), strict=True))
    return tree.roots(nodes.__getitem__)


def read_document(
    path: Path,
    limits: Limits,
    types: frozenset[str] | None,
    palette: Palette,
    crs: str | None,
    context: RunContext | None = None,
    theme: str | None = None,
) -> Scene:
    """A ``.json`` CityJSON file: every node built before the scene is returned (with
    ``context``, by the workers of its executor: :mod:`.parallel`; a file with textures is
    read in this process, beside its images)."""
    tally = InputTally(str(path), limits)
    data = load_document(path, limits, tally)
    declared = declared_crs(data.get("metadata"), crs, str(path))
    images = Images(path, limits, tally.warn)
    ctx = context_of(data, tally, declared, palette, images, theme)
    objects = data.get("CityObjects") or {}

    def checked(nodes: list[Node | PackedNode]) -> int:
        """How many nodes with geometry ``nodes`` hold; :class:`InputError` for none."""
        size = sum(1 for _ in with_geometry(nodes))
        if not size and not tally.skipped:
            if tally.dropped_faces:
                raise tally.nothing_left()
            which = f"of type {', '.join(sorted(types))} " if types is not None else ""
            raise InputError(f"has no CityObject {which}with surfaces", str(path))
        return size

    if context is not None and _any_surface(objects, types) and not ctx.textures:
        reading = ObjectsReading(
            objects, ctx, types, lambda: _object_nodes(objects, ctx, types), checked,
            lambda: read_document(path, limits, types, palette, crs, theme=theme),
        )  # fmt: skip
        executor = context.executor
        reading.use(executor.results, context.progress, executor.task_seconds)
        scene = Scene(source=str(path), nodes=reading.nodes(), crs=ctx.crs, city=True)
        if reading.roots is not None:
            scene.size = checked(reading.roots)
    else:
        nodes = _object_nodes(objects, ctx, types)
        scene = Scene(str(path), nodes, crs=ctx.crs, size=checked(nodes), city=True)
    scene.attributes.update(crs_attributes(ctx.declared))
    scene.attributes["cityjson_version"] = str(data.get("version"))
    if ctx.textures or ctx.materials:
        scene.attributes["appearance"] = images
    return attach_tally(scene, tally)


def _any_surface(objects: dict[str, Any], types: frozenset[str] | None) -> bool:
    """Whether any of ``objects`` (of ``types``, where given) holds a surface geometry with
    boundaries: a file with none is read at once, so that its error comes as it is read."""
    for obj in objects.values():
        if not isinstance(obj, dict) or not isinstance(obj.get("geometry"), list):
            continue
        kind = obj.get("type")
        if types is not None and not (isinstance(kind, str) and kind in types):
            continue
        for geometry in obj["geometry"]:
            shape = geometry.get("type") if isinstance(geometry, dict) else None
            if isinstance(shape, str) and shape in SURFACE_DEPTH and geometry.get("boundaries"):
                return True
    return False


@dataclass
class _Feature:
    """A CityJSONSeq line waiting in a batch: a feature's context and objects, or the problem
    that has the line skipped."""

    where: str
    ctx: Context | None = None
    tree: Objects | None = None
    problem: InputError | None = None


def _feature(
    line: bytes | None,
    where: str,
    header: dict[str, Any],
    ctx: Context,
    types: frozenset[str] | None,
) -> _Feature:
    """The ``CityJSONFeature`` of a line (``None``: one too long to read), against the
    header's transform and context."""
    try:
        if line is None:
            raise InputError(long_line(ctx.tally.limits), where)
        try:
            text = line.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise InputError(f"is not UTF-8 text ({exc})", where) from None
        feature = cityjson_object(parsed(text, where), "CityJSONFeature", where)
        local = Context(
            tally=ctx.tally,
            vertices=vertices_of(
                feature.get("vertices"), header.get("transform"), where, ctx.declared
            ),
            declared=ctx.declared,
            materials=materials_of(feature, where) or ctx.materials,
            templates=ctx.templates,
            template_vertices=ctx.template_vertices,
            shared=ctx.shared,
            counted=ctx.counted,
            palette=ctx.palette,
            textures=textures_of(feature, where) or ctx.textures,
            texture_vertices=(
                own if len(own := texture_vertices_of(feature, where)) else ctx.texture_vertices
            ),
            images=ctx.images,
            theme=ctx.theme,
        )
    except InputError as exc:
        return _Feature(where, problem=exc)
    return _Feature(where, local, Objects(feature.get("CityObjects") or {}, types))


def _feature_nodes(
    lines: Iterator[Line],
    header: dict[str, Any],
    ctx: Context,
    types: frozenset[str] | None,
) -> Iterator[Node]:
    """The nodes of each ``CityJSONFeature`` line, a line that is not one (or is too long to
    read) recorded as skipped. Lines are read until they hold :data:`BATCH` objects (or are
    that many, or ``sequence_line_bytes`` of text), whose polygons are triangulated together;
    their nodes are then yielded feature by feature, so memory holds one batch of features at
    a time."""
    waiting: list[_Feature] = []
    objects = held = 0
    with closing(lines):
        for number, line in lines:
            feature = _feature(line, f"line {number}", header, ctx, types)
            waiting.append(feature)
            objects += len(feature.tree.objects) if feature.tree is not None else 0
            held += len(line or b"")
            full = held >= ctx.tally.limits.sequence_line_bytes
            if objects >= BATCH or len(waiting) >= BATCH or full:
                yield from _finished_features(waiting, ctx.tally)
                waiting, objects, held = [], 0, 0
        yield from _finished_features(waiting, ctx.tally)


def _finished_features(waiting: list[_Feature], tally: InputTally) -> Iterator[Node]:
    """The root nodes of a batch of features, in line order, their polygons triangulated
    together; each feature's vertices are counted, and its objects finished, as it comes."""
    reads = [
        [f.tree.read(key, f.ctx) for key in f.tree.order]
        if f.ctx is not None and f.tree is not None
        else []
        for f in waiting
    ]
    triangulate_batch([lod for each in reads for read in each for lod in read.lods])
    for feature, each in zip(waiting, reads, strict=True):
        if feature.ctx is None or feature.tree is None:
            tally.add_skipped(feature.where, str(feature.problem))
            continue
        tally.count(len(feature.ctx.vertices), 0, declared=True)
        nodes = {read.key: checked_node(read) for read in each}
        yield from feature.tree.roots(nodes.__getitem__)


def read_sequence(
    path: Path,
    limits: Limits,
    types: frozenset[str] | None,
    palette: Palette,
    crs: str | None,
    context: RunContext | None = None,
    theme: str | None = None,
) -> Scene:
    """A CityJSONSeq file: the header read now, the features' nodes yielded lazily (with
    ``context``, by the workers of its executor: :mod:`.parallel`)."""
    lines = sequence_lines(path, limits)
    try:
        number, first = next(lines, (1, b""))
        if first is None:
            raise InputError(f"line {number} {long_line(limits)}", str(path))
        try:
            text = first.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise unreadable(path, exc) from None
        header = cityjson_object(parsed(text, str(path)), "CityJSON", str(path))
        tally = InputTally(str(path), limits)
        declared = declared_crs(header.get("metadata"), crs, str(path))
        images = Images(path, limits, tally.warn)
        ctx = context_of(header, tally, declared, palette, images, theme)
    except InputError:
        lines.close()
        raise
    reading: SequenceReading | SequenceRanges | None = None
    if context is not None:

        def again() -> Iterator[Node]:
            return iter(read_sequence(path, limits, types, palette, crs, theme=theme).nodes)

        reading = SequenceReading(lines, header, ctx, types, _feature_nodes, again)
        if path.name.lower().endswith(".jsonl"):  # plain: read from ranges
            reading = SequenceRanges(path, reading)
        executor = context.executor
        reading.use(executor.results, context.progress, executor.task_seconds)
    nodes = reading.nodes() if reading is not None else _feature_nodes(lines, header, ctx, types)
    first_node = next(nodes, None)  # its vertices centre a geographic CRS's local frame
    scene = Scene(
        source=str(path),
        nodes=chain(() if first_node is None else (first_node,), nodes),
        crs=ctx.crs,
        city=True,
    )
    scene.attributes.update(crs_attributes(ctx.declared))
    scene.attributes["cityjson_version"] = str(header.get("version"))
    scene.attributes["appearance"] = images
    return attach_tally(scene, tally)
