"""A run's ``--report``: what it records of each object, LOD parent and option, the records
kept compact, and the report written as JSON.

A city of tens of thousands of objects gives as many records; as Python dictionaries each
would hold a few kilobytes for the whole run. :class:`Records` keeps each as its compact JSON
text and decodes it when read, and :func:`report_text` writes a report holding one without
building all its records at once.
"""

from __future__ import annotations

import json
import platform
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

from .chain import ChainOptions
from .model import CellChain, LodChain
from .version import __version__

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


def report_text(report: dict[str, Any]) -> Iterator[str]:
    """``report`` as JSON text indented by two spaces (as ``json.dumps(report, indent=2)``
    writes it, and a newline at the end), in pieces: a :class:`Records` value one record at a
    time."""
    yield "{"
    for n, (key, value) in enumerate(report.items()):
        yield ("," if n else "") + f"\n  {json.dumps(key)}: "
        if isinstance(value, Records):
            yield "[" if value else "[]"
            for i, record in enumerate(value):
                yield ("," if i else "") + "\n    " + _indented(record, 4)
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


def run_report(
    input_path: str | Path,
    output_path: str | Path,
    baker: Backend,
    options: ChainOptions,
    records: Records,
    skipped: list[dict[str, str]],
    timings: dict[str, float],
    tally: InputTally | None = None,
) -> dict[str, Any]:
    """What ``--report`` records of a run; ``tally``: what the reader's checks dropped."""
    reduced = points = 0
    for record in records:
        reduced += bool(record["dropped"])
        points += sum(lv["count"] for lv in record["levels"] if lv["kind"] == "pcd")
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
            "fewer_levels": reduced,
            "dropped_faces": tally.dropped_faces if tally is not None else 0,
            "points": int(points),
        },
        "timings": {k: round(v, 4) for k, v in timings.items()},
    }
