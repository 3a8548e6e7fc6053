"""The conversion session: read → bake each object → stream chains into the writer → rename.

Readers are free of processing and writers of baking; this module joins them, times each step
and collects what the ``--report`` file records. One object that cannot be baked is reported and
skipped; when none can, the conversion fails and no output file appears.
"""

from __future__ import annotations

import platform
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .bake import Backend, get_backend
from .chain import ChainOptions, bake_chain
from .errors import InputError
from .io import OutputInfo, reader_for, writer_for
from .io.atomic import atomic_output
from .model import LodChain, Scene
from .validate import check_written

Message = Callable[[str], None]


def _quiet(_: str) -> None:
    """Discard a message."""


def options_record(options: ChainOptions) -> dict[str, Any]:
    """The chain options as JSON-able values (recorded in outputs and reports)."""
    record = asdict(options)
    record["view"] = {"height_px": options.view.height_px, "fov_y_deg": options.view.fov_y_deg}
    record["xs"] = list(options.exponents)
    return {k: list(v) if isinstance(v, tuple) else v for k, v in record.items()}


def chain_record(chain: LodChain) -> dict[str, Any]:
    """What the report says of one baked object."""
    levels = []
    for level in chain.levels:
        entry: dict[str, Any] = {"name": level.name, "kind": level.kind, "count": level.count}
        if not level.is_points:
            assert level.mesh is not None
            entry["faces"] = len(level.mesh.faces)
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
    }


def read_scene(path: str | Path) -> Scene:
    """Read any supported input into a Scene (the registry picks the reader by suffix)."""
    return reader_for(path)(Path(path))


def iter_chains(
    scene: Scene,
    options: ChainOptions,
    backend: Backend,
    progress: Message = _quiet,
    warn: Message = _quiet,
    skipped: list[dict[str, str]] | None = None,
) -> Iterator[LodChain]:
    """Bake the scene's objects one at a time; objects with bad geometry are reported through
    ``warn``, recorded in ``skipped`` and left out."""
    total = len(scene.nodes) if isinstance(scene.nodes, list) else "?"
    for i, obj in enumerate(scene.with_geometry(), start=1):
        try:
            chain = bake_chain(
                obj,
                options,
                backend,
                progress=lambda m, i=i: progress(f"[{i}/{total}] {m}"),
                warn=warn,
            )
        except InputError as exc:
            if total != 1:
                warn(f"{scene.source}: object {exc} — skipped")
            if skipped is not None:
                skipped.append({"id": obj.id, "reason": str(exc)})
            continue
        yield chain


def convert(
    input_path: str | Path,
    output_path: str | Path,
    options: ChainOptions | None = None,
    backend: str = "auto",
    progress: Message = _quiet,
    warn: Message = _quiet,
) -> dict[str, Any]:
    """Convert ``input_path`` into ``output_path`` and return the report (a JSON-able dict).

    The written file passes :func:`~lodconvert.validate.check_written` (structural checks of
    X3D and glTF) before it is renamed into place. Raises
    :class:`~lodconvert.errors.UsageError` for bad options and
    :class:`~lodconvert.errors.LodConvertError` for unreadable input, when no object could be
    baked or when the output fails validation; in all cases ``output_path`` is left untouched.
    """
    options = options or ChainOptions()
    options.check()
    writer = writer_for(output_path)
    timings: dict[str, float] = {}
    start = time.perf_counter()
    scene = read_scene(input_path)
    timings["read"] = time.perf_counter() - start
    baker = get_backend(backend)
    info = OutputInfo(
        generator=f"lodconvert {__version__}",
        source=Path(input_path).name,
        crs=scene.crs,
        view=options.view,
        options=options_record(options),
    )
    records: list[dict[str, Any]] = []
    skipped: list[dict[str, str]] = []

    def recorded(chains: Iterator[LodChain]) -> Iterator[LodChain]:
        for chain in chains:
            records.append(chain_record(chain))
            yield chain

    def validated(tmp: Path) -> None:
        started = time.perf_counter()
        progress(f"validating {Path(output_path).name}")
        check_written(tmp, output_path)
        timings["validate"] = time.perf_counter() - started

    start = time.perf_counter()
    with atomic_output(output_path, check=validated) as handle:
        writer(recorded(iter_chains(scene, options, baker, progress, warn, skipped)), handle, info)
        if not records:
            reason = (
                skipped[0]["reason"]
                if len(skipped) == 1
                else f"none of its {len(skipped)} objects could be converted"
            )
            raise InputError(reason, str(input_path))
    timings["bake_and_write"] = time.perf_counter() - start - timings["validate"]
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
            "points": int(
                sum(lv["count"] for r in records for lv in r["levels"] if lv["kind"] == "pcd")
            ),
        },
        "timings": {k: round(v, 4) for k, v in timings.items()},
    }


def object_ranges(scene: Scene, options: ChainOptions) -> list[dict[str, Any]]:
    """α, γ and cutoffs of every object of a scene, without baking."""
    from .ranges import cutoffs

    options.check()
    rows = []
    for obj in scene.with_geometry():
        bounds = obj.geometry.bounds
        alpha = float(np.linalg.norm(bounds[1] - bounds[0]))
        xs = list(options.exponents) + ([options.cull] if options.cull is not None else [])
        rows.append(
            {
                "id": obj.id,
                "alpha": alpha,
                "beta": options.beta,
                "gamma": options.gamma,
                "xs": xs,
                "cutoffs": cutoffs(alpha, options.beta, options.gamma, xs) if alpha > 0 else [],
            }
        )
    return rows
