"""A run's ``--report``: what it records of each object, LOD parent and option, the records
kept compact, and the report written as JSON.

A city of tens of thousands of objects gives as many records; as Python dictionaries each
would hold a few kilobytes for the whole run. :class:`Records` keeps each as its compact JSON
text and decodes it when read, and :func:`report_text` writes a report holding one with each
record on a line of its own, as that text (never decoded and encoded again).
"""

from __future__ import annotations

import json
import platform
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from .chain import ChainOptions
from .city.hlod import HlodOptions, draw_counts
from .clock import Clock
from .io import OutputInfo
from .io.frame import SceneFrame, scene_frame
from .io.geometry_checks import tally_of
from .model import CellChain, LodChain, Scene
from .version import __version__
from .views import guard_record

if TYPE_CHECKING:
    from .bake import Backend
    from .io.geometry_checks import InputTally


class Records(Sequence[dict[str, Any]]):
    """JSON-able records in the order added, each stored as compact JSON text; reading one
    gives a fresh dictionary."""

    def __init__(self, records: Iterable[dict[str, Any]] = ()) -> None:
        self._texts: list[bytes] = []
        self.extend(records)

    def append(self, record: dict[str, Any]) -> None:
        """Add ``record`` (later changes to it are not seen)."""
        self._texts.append(json.dumps(record, separators=(",", ":")).encode())

    def extend(self, records: Iterable[dict[str, Any]]) -> None:
        """Add each of ``records``."""
        for record in records:
            self.append(record)

    def __len__(self) -> int:
        return len(self._texts)

    @overload
    def __getitem__(self, index: int) -> dict[str, Any]: ...

    @overload
    def __getitem__(self, index: slice) -> list[dict[str, Any]]: ...

    def __getitem__(self, index: int | slice) -> dict[str, Any] | list[dict[str, Any]]:
        if isinstance(index, slice):
            return [json.loads(text) for text in self._texts[index]]
        return json.loads(self._texts[index])

    def __iter__(self) -> Iterator[dict[str, Any]]:
        for text in self._texts:
            yield json.loads(text)

    def texts(self) -> Iterator[str]:
        """Each record's compact JSON text (ASCII), in the order added."""
        for text in self._texts:
            yield text.decode("ascii")


def report_text(report: dict[str, Any]) -> Iterator[str]:
    """``report`` as JSON text indented by two spaces (as ``json.dumps(report, indent=2)``
    writes it, and a newline at the end), in pieces, except that each record of a
    :class:`Records` value is one line of compact JSON."""
    yield "{"
    for n, (key, value) in enumerate(report.items()):
        yield ("," if n else "") + f"\n  {json.dumps(key)}: "
        if isinstance(value, Records):
            yield "[" if value else "[]"
            for i, record in enumerate(value.texts()):
                yield ("," if i else "") + "\n    " + record
            yield "\n  ]" if value else ""
        else:
            yield _indented(value, 2)
    yield "\n}\n"


def _indented(value: Any, depth: int) -> str:
    """``value`` as indented JSON whose lines after the first start ``depth`` spaces in."""
    return json.dumps(value, indent=2).replace("\n", "\n" + " " * depth)


def options_record(options: ChainOptions) -> dict[str, Any]:
    """The chain options as JSON-able values (recorded in outputs and reports)."""
    record = asdict(options)
    record["view"] = {"height_px": options.view.height_px, "fov_y_deg": options.view.fov_y_deg}
    record["xs"] = list(options.exponents)
    return {k: list(v) if isinstance(v, tuple) else v for k, v in record.items()}


def cell_record(cell: CellChain) -> dict[str, Any]:
    """What the report says of one LOD parent."""
    return {
        "id": cell.cell_id,
        "tier": cell.tier,
        "size": cell.size,
        "members": cell.member_ids(),
        "cutoffs": list(cell.cutoffs),
        "alpha": cell.alpha,
        "gamma": cell.gamma,
        "far": {"kind": cell.far.kind, "count": cell.far.count},
        **{key: value for key, value in cell.facts.items() if key != "members"},
    }


def chain_record(chain: LodChain) -> dict[str, Any]:
    """What the report says of one baked object."""
    levels = []
    for level in chain.levels:
        entry: dict[str, Any] = {"name": level.name, "kind": level.kind, "count": level.count}
        if not level.is_points:
            entry["faces"] = level.faces
            if level.silhouette_f is not None:
                entry["silhouette_f"] = round(level.silhouette_f, 4)
        else:
            assert level.params is not None
            entry.update(
                resolution=level.params.resolution,
                slices=level.params.slices,
                point_size_px=level.params.point_size,
                filter=level.params.filter,
                spacing=level.spacing,
                design_distance=level.design_distance,
                bake_seconds=round(level.bake_seconds, 4),
            )
        levels.append(entry)
    return {
        "id": chain.object_id,
        "alpha": chain.alpha,
        "beta": chain.beta,
        "gamma": chain.gamma,
        "xs": list(chain.xs),
        "cutoffs": list(chain.cutoffs),
        "culled": chain.culled,
        "origin": [float(v) for v in chain.origin],
        "levels": levels,
        "dropped": dict(chain.dropped),
        "unused": dict(chain.unused),
        **({"cut": list(chain.cut)} if chain.cut else {}),
    }


@dataclass
class ObjectCounts:
    """The objects' records counted as they are recorded (so that the totals need not read
    them again): objects that dropped levels, by the levels they keep; objects with source
    LoDs that no level is made from, and those LoDs; the points of all levels."""

    fewer: Counter[int] = field(default_factory=Counter)
    unused: Counter[str] = field(default_factory=Counter)
    with_unused: int = 0
    points: int = 0

    def add(self, record: dict[str, Any]) -> None:
        """Count an object's ``record`` (:func:`chain_record`)."""
        if record["dropped"]:
            self.fewer[len(record["levels"])] += 1
        if record["unused"]:
            self.with_unused += 1
            self.unused.update(record["unused"].keys())
        self.points += sum(lv["count"] for lv in record["levels"] if lv["kind"] == "pcd")


def run_report(
    input_path: str | Path,
    output_path: str | Path,
    baker: Backend,
    options: ChainOptions,
    records: Records,
    counts: ObjectCounts,
    skipped: list[dict[str, str]],
    timings: dict[str, float],
    tally: InputTally | None = None,
) -> dict[str, Any]:
    """What ``--report`` records of a run (``counts``: of ``records``); ``tally``: what the
    reader's checks dropped."""
    return {
        "lodconvert": __version__,
        "input": str(input_path),
        "output": str(output_path),
        "backend": baker.name,
        "renderer": baker.renderer,
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
        "options": options_record(options),
        "objects": records,
        "skipped": skipped,
        "totals": {
            "objects": len(records),
            "skipped": len(skipped) + (tally.unlisted if tally is not None else 0),
            "fewer_levels": sum(counts.fewer.values()),
            "levels_kept": {str(n): counts.fewer[n] for n in sorted(counts.fewer)},
            "with_unused_lods": counts.with_unused,
            "unused_lods": {label: counts.unused[label] for label in sorted(counts.unused)},
            "dropped_faces": tally.dropped_faces if tally is not None else 0,
            "points": int(counts.points),
        },
        "timings": {k: round(v, 4) for k, v in timings.items()},
    }


def _add_counts(total: dict[str, int], more: dict[str, int]) -> None:
    for key, value in more.items():
        total[key] = total.get(key, 0) + value


@dataclass
class Assembly:
    """What the run records of each baked item as the writer takes it: the objects' records,
    the LOD parents and their draw counts, and the writers' scene frame (at the first object)."""

    scene: Scene
    info: OutputInfo
    hlod: HlodOptions | None
    records: Records = field(default_factory=Records)
    counts: ObjectCounts = field(default_factory=ObjectCounts)
    cells: list[dict[str, Any]] = field(default_factory=list)
    draw: dict[str, dict[str, int]] = field(default_factory=lambda: {"without": {}, "with": {}})
    frame: SceneFrame | None = None
    started: bool = False

    def first_at(self, centre: np.ndarray) -> None:
        """Where the input's first object lies: the scene frame's origin, for the writer too
        (:attr:`~.io.OutputInfo.origin`), whatever the LOD parents bake first."""
        self.info.origin = centre

    def recorded(self, items: Iterable[LodChain | CellChain]) -> Iterator[LodChain | CellChain]:
        """``items``, each recorded as it passes."""
        tally = tally_of(self.scene)
        dropped = tally.dropped_by_object if tally is not None else {}
        for item in items:
            if not self.started:
                frame = scene_frame(self.info.framed, item, self.info.origin)
                self.frame, self.started = frame, True
            objects = item.objects()
            for chain in objects:
                record = {**chain_record(chain), "dropped_faces": dropped.get(chain.object_id, 0)}
                self.counts.add(record)
                self.records.append(record)
            if isinstance(item, CellChain):
                self.cells.extend(cell_record(cell) for cell in item.cells())
            if self.hlod is not None:
                _add_counts(self.draw["without"], draw_counts(objects))
                _add_counts(self.draw["with"], draw_counts([item]))
            yield item

    def report(
        self,
        named: str,
        output_path: str | Path,
        baker: Backend,
        options: ChainOptions,
        up: str | None,
        skipped: list[dict[str, str]],
        clock: Clock,
        tally: InputTally | None,
        crs_record: dict[str, Any],
    ) -> dict[str, Any]:
        """The ``--report`` of the run (``up``: the up axis its meshes were read with)."""
        report = run_report(
            named, output_path, baker, options, self.records, self.counts, skipped,
            clock.timings, tally,
        )  # fmt: skip
        report["crs"] = crs_record
        report["up"] = "z" if self.info.city else up or "y"
        if self.info.city:
            report["guard"] = guard_record()  # the views derived city levels are judged over
        appearance = self.scene.attributes.get("appearance")
        if appearance is not None and appearance.met:
            report["appearance"] = appearance.record()  # a city model's (io/images.Images)
        report["frame"] = self.frame.record() if self.frame is not None else None
        if self.hlod is not None:
            report["hlod"] = {"kind": self.hlod.kind, "cells": self.cells, "draw": self.draw}
        return report
