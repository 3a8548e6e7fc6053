"""The guard against GL renders: every derived level a city keeps (LOD1 prisms, LOD parents'
far levels) rendered with OpenGL (Mesa llvmpipe here) in perspective, 1080 px tall with a 45°
field of view, from the guard's 24 views of the upper hemisphere (8 azimuths at 0, 30 and 60°
elevation: :mod:`lodconvert.views`) at the distance where it switches in, looking at its frame's
origin, against the source (the finest level; a cell's buildings' finest geometry):

    python benchmarks/guard_render.py                  # writes results/guard_render.md
    python benchmarks/guard_render.py --input FILE.gml --hlod 250,1000

Per kind of level: how many are kept, how many render below F 0.95 in their worst view, the
least rendered F, and the largest difference between the F the planner states (``--report``'s
``silhouette_f``) and the rendered one. The render is the evaluation code's
(:class:`lodconvert.analysis.silhouette.SilhouetteRenderer`), not the guard's rasteriser.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np
from city import TUM
from tables import machine_line, markdown_table, write_results

from lodconvert.analysis.silhouette import SilhouetteRenderer
from lodconvert.bake import get_backend
from lodconvert.bakery import iter_chains
from lodconvert.chain import ChainOptions
from lodconvert.city.far_mesh import finest_mesh, merge
from lodconvert.city.hlod import HlodOptions
from lodconvert.context import RunContext
from lodconvert.io import read_scene
from lodconvert.model import CellChain, LodChain, Mesh
from lodconvert.views import guard_views, towards_camera

HERE = Path(__file__).resolve().parent
MIN_F = 0.95


def levels(path: Path, hlod: tuple[float, ...]) -> list[tuple[str, str, Mesh, Mesh, float, float]]:
    """Every kept derived level of ``path``'s city: kind, name, source, level, the distance
    where it switches in and the F the planner states."""
    found = []
    context = RunContext.here(get_backend("numpy"))
    for item in iter_chains(read_scene(path), ChainOptions(), context, HlodOptions(hlod, "auto")):
        cells = [item] if isinstance(item, CellChain) else []
        while cells:
            cell = cells.pop()
            cells += [m for m in cell.members if isinstance(m, CellChain)]
            kind = cell.facts["kind"]
            source = merge([finest_mesh(c) for c in cell.objects()]).translated(-cell.origin)
            if cell.far.mesh is not None:
                stated = cell.facts["silhouette_f"][kind]
                found.append((f"far ({kind})", cell.cell_id, source, cell.far.mesh,
                              cell.cutoffs[0], stated))  # fmt: skip
            chains = [m for m in cell.members if isinstance(m, LodChain)]
            found += _prisms(chains)
        if isinstance(item, LodChain):
            found += _prisms([item])
    return found


def _prisms(chains: list[LodChain]) -> list[tuple[str, str, Mesh, Mesh, float, float]]:
    """The kept LOD1 prisms of ``chains`` with their sources and switch-in distances."""
    found = []
    for chain in chains:
        for index, level in enumerate(chain.levels):
            if level.kind == "prism" and index and level.silhouette_f is not None:
                source = chain.levels[0].mesh
                assert source is not None and level.mesh is not None
                distance = chain.cutoffs[index - 1]
                found.append(("prism", chain.object_id, source, level.mesh, distance,
                              level.silhouette_f))  # fmt: skip
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--input", type=Path, default=TUM)
    parser.add_argument("--hlod", default="250,1000", help="cell sizes, metres (250,1000)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "guard_render.md")
    args = parser.parse_args()
    load, began = os.getloadavg()[0], time.perf_counter()
    hlod = tuple(float(s) for s in args.hlod.split(","))
    found = levels(args.input, hlod)
    renderer = SilhouetteRenderer(1080)
    directions = np.stack([towards_camera(a, e) for a, e in guard_views()])
    results: dict[str, list[tuple[str, float, float]]] = {}
    try:
        for kind, name, source, level, distance, stated in found:
            f = renderer.least_f(source, level, distance, directions)
            results.setdefault(kind, []).append((name, stated, f))
    finally:
        renderer.release()
    rows = []
    for kind, items in sorted(results.items()):
        rendered = [f for _, _, f in items]
        gaps = [abs(s - f) for _, s, f in items]
        worst = min(items, key=lambda t: t[2])
        rows.append(
            [
                kind,
                f"{len(items):,}",
                f"{sum(f < MIN_F for f in rendered):,}",
                f"{min(rendered):.4f} ({worst[0]})",
                f"{statistics.median(rendered):.4f}",
                f"{max(gaps):.4f}",
                f"{sum(g > 0.005 for g in gaps):,}",
            ]
        )
    header = ["level", "kept", "rendered F < 0.95", "least rendered F", "median"]
    header += ["largest gap to the stated F", "gaps over 0.005"]
    command = f"python benchmarks/guard_render.py --input {args.input} --hlod {args.hlod}"
    text = "\n".join(
        [
            "# The guard's F against GL renders of its views",
            "",
            machine_line(load, time.perf_counter() - began),
            f"Command: `{command}`. Renderer: OpenGL via EGL (Mesa llvmpipe here), 1080 × 1080 px,"
            " 45° vertical field of view, 24 views (azimuths 0–315° by 45°,"
            " elevations 0, 30, 60°), each level at the distance where it switches in, looking"
            " at its frame's origin.",
            "",
            markdown_table(header, rows, 1),
            "",
        ]
    )
    write_results(args.out, text)


if __name__ == "__main__":
    main()
