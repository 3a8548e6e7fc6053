"""The read stage: the scene of a run's inputs, each read by its format, put in one CRS and
merged into one scene (city objects of the same id are one object), and what the readers
skipped; docs/cities.md."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .context import Message, RunContext, quiet
from .errors import InputError, UsageError
from .io import Format, input_format
from .io.crs import checked_crs_option
from .io.geometry_checks import InputTally, attach_tally, tally_of
from .limits import DEFAULT_LIMITS, Limits
from .model import Node, Scene
from .model.lods import source_levels
from .reproject import SOURCE_CRS_KEYS, in_one_crs


def read_inputs(
    inputs: Sequence[str | Path],
    read_options: dict[str, Any] | None = None,
    limits: Limits = DEFAULT_LIMITS,
    sources: Sequence[Any] | None = None,
    warn: Message = quiet,
    georeferenced: bool = False,
    context: RunContext | None = None,
) -> tuple[Scene, dict[str, Any]]:
    """The scene of ``inputs`` (one, or several in one CRS and merged: :func:`merged`), each
    read by its format (in ``sources`` where the caller found them) with the options it takes
    (on the executor of ``context``, where given and the format reads on workers), and the
    report's ``crs`` (:func:`~.reproject.in_one_crs`; ``georeferenced``: for an output placed
    on the globe by its CRS, an input without one beside one with one is an error)."""
    if (read_options or {}).get("crs") is not None:
        checked_crs_option(read_options["crs"])
    sources = sources or [input_format(path) for path in inputs]
    if (read_options or {}).get("up") is not None:
        _check_up(inputs, sources)
    scenes = [
        source.read_file(path, context, limits=limits, **(read_options or {}))
        for source, path in zip(sources, inputs, strict=True)
    ]
    for scene in scenes if (read_options or {}).get("crs") is not None else ():
        if not scene.city:
            warn(
                f"{scene.source}: not a city model: --crs is not applied (a mesh keeps its own "
                "axes and coordinates)"
            )
    one_crs = in_one_crs(scenes, warn, georeferenced)
    return merged(one_crs.scenes), one_crs.record


def _check_up(inputs: Sequence[str | Path], sources: Sequence[Format]) -> None:
    """:class:`UsageError` where an up axis is given for an input whose reader takes none: a
    city model, z-up by definition and turned y-up by its frame (:mod:`.io.frame`)."""
    for path, source in zip(inputs, sources, strict=True):
        if "up" not in source.read_options:
            raise UsageError(
                f"is for mesh files; {path} is a city model, z-up by definition (its scene is "
                "turned y-up already)",
                "up",
            )


def merged(scenes: Sequence[Scene]) -> Scene:
    """One scene of several inputs. City objects (nodes with their own LoDs) of the same id
    are one object whose LoDs are merged: the first keeps its attributes and children, takes
    the LoD labels it lacks from the later ones, and its geometry is its finest LoD. Other
    objects all stay, in input order (the writers keep their names apart). The first declared
    CRS is the scene's, with its vertical CRS and local frame (:func:`~.reproject.in_one_crs`
    puts every input in it first); a scene of one input is returned as it is."""
    if len(scenes) == 1:
        return scenes[0]
    nodes: list[Node] = []
    cities: dict[str, Node] = {}
    for scene in scenes:
        for node in scene.nodes:
            first = cities.setdefault(node.id, node) if node.lods else node
            if first is node:
                nodes.append(node)
                continue
            for label, mesh in node.lods.items():
                first.lods.setdefault(label, mesh)
            levels = source_levels(first.lods)
            first.geometry = levels[max(levels)][1] if levels else first.geometry
    declaring = next((scene for scene in scenes if scene.crs), None)
    crs = declaring.crs if declaring is not None else None
    whole = Scene(" + ".join(scene.source for scene in scenes), nodes, crs)
    if declaring is not None:  # its vertical CRS and local frame, where the reader found them
        whole.attributes.update(
            {k: v for k, v in declaring.attributes.items() if k in SOURCE_CRS_KEYS}
        )
    whole.city = any(scene.city for scene in scenes)
    tallies = [tally for scene in scenes if (tally := tally_of(scene)) is not None]
    if tallies:  # complete: every input's nodes have been read
        tally = InputTally(whole.source, tallies[0].limits)
        for part in tallies:
            tally.dropped_faces += part.dropped_faces
            tally.dropped_by_object.update(part.dropped_by_object)
            for entry in part.skipped:
                tally.add_skipped(entry["id"], entry["reason"])
            tally.unlisted += part.unlisted
            for text in part.warnings:
                tally.warn(text)
            tally.unlisted_warnings += part.unlisted_warnings
        attach_tally(whole, tally)
    return whole


def reader_skipped(scene: Scene, skipped: list[dict[str, str]], warn: Message) -> InputTally | None:
    """Add the objects the reader of ``scene`` skipped to ``skipped``, each told to ``warn``
    (with nothing converted, the run's error says it), those past the listed ones in one
    line, after the reader's warnings; ``scene``'s tally."""
    tally = tally_of(scene)
    for text in tally.warnings if tally is not None else ():
        warn(text)
    if tally is not None and tally.unlisted_warnings:
        warn(f"{scene.source}: {tally.unlisted_warnings:,} more warnings (not listed)")
    for entry in tally.skipped if tally is not None else ():
        warn(f"{scene.source}: object {entry['reason']} — skipped")
        skipped.append(entry)
    if tally is not None and tally.unlisted:
        warn(f"{scene.source}: {tally.unlisted:,} more objects skipped (not listed)")
    return tally


def none_converted(skipped: list[dict[str, str]], source: str) -> InputError:
    """The error of a run in which no object of ``source`` could be converted (``skipped``:
    why)."""
    reason = (
        skipped[0]["reason"]
        if len(skipped) == 1
        else f"none of its {len(skipped)} objects could be converted"
    )
    return InputError(reason, source)
