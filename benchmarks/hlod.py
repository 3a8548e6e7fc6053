"""LOD parents side by side: far levels of points, simplified merged meshes and block proxies
(and ``auto``).

Bakes TUM Munich (and ``--factors`` larger districts of shifted copies, made as
``benchmarks/city.py`` makes them) with ``--hlod`` cells of each size set in ``--sizes``, once
per far-level kind, in this process on one core:

    python benchmarks/hlod.py                      # writes results/hlod.md
    python benchmarks/hlod.py --factors 1,10 --sizes 250 250,1000 auto

Per configuration: cells, the far view (every cell and object beyond all its cutoffs) — draw
calls and vertices + points drawn, with and without the LOD parents — the silhouette F of each
cell's far level against its buildings' finest geometry where it switches in (the planner's
estimate, :func:`lodconvert.plan.silhouette_estimate`; minimum and median over cells), how many
cells reach F ≥ 0.95, and the bake time. Frame times of the same districts along flight paths
are in ``city_render.md`` (``benchmarks/city_render.py``).

Per tier, whether a parent pays (3D Tiles REPLACE: the far level is loaded instead of its
children): the far levels' vertices + points and bytes against their children's — each member's
coarsest content (a finer cell's far level, a building's coarsest level) and the buildings'
finest levels — with the merged meshes' vertices before simplification and the far levels' F.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from city import TUM, Template, tum_document, write_district  # noqa: E402
from tables import markdown_table, one_core_facts, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "hlod.md"
KINDS = ("points", "mesh", "blocks", "auto")


def tier_rows(sizes: str, kind: str, cells: list) -> list[list[str]]:
    """Rows of the per-tier table: the far content of ``cells`` (every cell baked) against
    their children's."""
    from lodconvert.model import CellChain
    from lodconvert.plan import level_bytes

    rows = []
    for tier in sorted({cell.tier for cell in cells}):
        found = [cell for cell in cells if cell.tier == tier]
        far = [cell.far for cell in found]
        coarse = [
            m.far if isinstance(m, CellChain) else m.levels[-1] for c in found for m in c.members
        ]
        fine = [chain.levels[0] for cell in found for chain in cell.objects()]
        merged = [
            c.facts["simplified"]["vertices_before"] for c in found if "simplified" in c.facts
        ]
        counts = [sum(level.count for level in group) for group in (far, coarse, fine)]
        sizes_b = [sum(level_bytes(level) for level in group) for group in (far, coarse, fine)]
        scores = [cell.facts["silhouette_f"][cell.facts["kind"]] for cell in found]
        rows.append(
            [
                sizes,
                kind,
                str(tier),
                f"{len(found):,}",
                f"{sum(merged):,}" if merged else "–",
                f"{counts[0]:,}",
                f"{counts[1]:,} / {counts[2]:,}",
                f"{counts[0] / counts[1]:.2f} / {counts[0] / counts[2]:.2f}",
                f"{sizes_b[0] / 1e3:,.0f}",
                f"{sizes_b[1] / 1e3:,.0f} / {sizes_b[2] / 1e3:,.0f}",
                f"{sizes_b[0] / sizes_b[1]:.2f} / {sizes_b[0] / sizes_b[2]:.2f}",
                f"{min(scores):.3f}",
            ]
        )
    return rows


def measure(path: Path, sizes: str, kind: str) -> tuple[list[str], list[list[str]]]:
    """One table row (``path`` baked into cells of ``sizes`` with far levels of ``kind``) and
    its rows of the per-tier table."""
    from lodconvert.bake import get_backend
    from lodconvert.bakery import iter_chains
    from lodconvert.chain import ChainOptions
    from lodconvert.city.far_choice import MIN_CELL_F
    from lodconvert.city.hlod import HlodOptions, draw_counts, parse_sizes
    from lodconvert.context import RunContext
    from lodconvert.io import read_scene
    from lodconvert.model import CellChain

    hlod = HlodOptions(parse_sizes(sizes), kind)
    start = time.process_time()
    cells = []
    with_cells = {"far_draw_calls": 0, "far_vertices_and_points": 0}
    without = dict(with_cells)
    scene = read_scene(path)
    alone = 0
    for item in iter_chains(
        scene, ChainOptions(), RunContext.here(get_backend("numpy")), hlod=hlod
    ):
        is_cell = isinstance(item, CellChain)
        for key, value in draw_counts([item]).items():
            if key in with_cells:
                with_cells[key] += value
        for key, value in draw_counts(item.objects() if is_cell else [item]).items():
            if key in without:
                without[key] += value
        alone += 0 if is_cell else 1
        cells += item.cells() if is_cell else []
    seconds = time.process_time() - start
    chosen = [cell.facts["silhouette_f"][cell.facts["kind"]] for cell in cells]
    kinds = {k: sum(1 for cell in cells if cell.facts["kind"] == k) for k in KINDS[:-1]}
    row = [
        sizes,
        kind,
        f"{len(cells):,}",
        f"{alone:,}",
        ", ".join(f"{n} {k}" for k, n in kinds.items() if n),
        f"{without['far_draw_calls']:,} → {with_cells['far_draw_calls']:,}",
        f"{without['far_vertices_and_points']:,} → {with_cells['far_vertices_and_points']:,}",
        f"{min(chosen):.3f}",
        f"{statistics.median(chosen):.3f}",
        f"{sum(f >= MIN_CELL_F for f in chosen)}/{len(chosen)}",
        f"{seconds:.1f}",
    ]
    return row, tier_rows(sizes, kind, cells)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--factors", default="1,10", help="district sizes, × TUM Munich")
    parser.add_argument("--sizes", nargs="+", default=["250", "250,1000", "auto"])
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    if not TUM.is_file():
        print(f"skipped: {TUM} is absent")
        return 0
    sys.path.insert(0, str(HERE.parent))
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    header = [
        "cells (m)", "far kind", "cells", "objects on their own", "kinds kept",
        "far draw calls (without → with)", "far vertices + points (without → with)", "min F",
        "median F", "F ≥ 0.95", "CPU s",
    ]  # fmt: skip
    tier_header = [
        "cells (m)", "far kind", "tier", "cells", "merged vertices", "far vertices + points",
        "children's (coarsest / finest)", "far / children", "far kB",
        "children's kB (coarsest / finest)", "far / children (bytes)", "min F",
    ]  # fmt: skip
    sections = []
    started = time.perf_counter()
    template = Template(tum_document())
    with tempfile.TemporaryDirectory(prefix="lodconvert-hlod-") as tmp:
        for factor in (int(f) for f in args.factors.split(",")):
            path = Path(tmp) / f"district_{factor}.gml"
            write_district(template, factor, path)
            rows, tiers = [], []
            for sizes in args.sizes:
                for kind in KINDS:
                    row, more = measure(path, sizes, kind)
                    rows.append(row)
                    tiers += more
                    print(" | ".join(row), flush=True)
            title = f"## {factor}× TUM Munich ({factor * template.buildings:,} buildings)"
            sections.append(f"{title}\n\n{markdown_table(header, rows, 2)}\n")
            sections.append(
                f"### Far content per tier, {factor}×\n\n{markdown_table(tier_header, tiers, 2)}\n"
            )
    text = "\n".join(
        [
            "# LOD parents: far levels of points, simplified merged meshes and block proxies",
            "",
            *one_core_facts(
                f"python benchmarks/hlod.py {' '.join(argv or sys.argv[1:])}".rstrip(),
                time.perf_counter() - started,
            ),
            "- Far view: every cell and building seen from beyond all its cutoffs; *without* is "
            "the same buildings with their own chains only. Objects on their own: those no cell "
            "admitted (they would delay its switch past its formula distance). F: silhouette F "
            "of the kept far level against the cell's buildings (finest geometry) at its "
            "switch-in distance, 1080-px reference view (the planner's estimate). CPU s: "
            "reading, baking every building and every cell.",
            "- Far content per tier: the far levels of the tier's cells against their children's "
            "content: each member's coarsest (a finer cell's far level, a building's coarsest "
            "level: what a REPLACE parent is loaded instead of) and the buildings' finest levels. "
            "Merged vertices: the merged far meshes before simplification (to within 8, 4, 2 or "
            "1 px at the switch distance, the coarsest that keeps F ≥ 0.95; a cell of finer "
            "cells also from what it replaces, the lighter kept). Blocks: the members' "
            "footprints unioned into blocks, extruded in height bands (the lightest of 4, 2 or 1 "
            "px outlines and one band, 6, 3 or 1 m bands that keeps F ≥ 0.95). Bytes: geometry "
            "as the glTF writer lays it out (`lodconvert.plan.level_bytes`: float32 positions and "
            "normals, none on merged far meshes; uint16 colours and indices). Numpy baker, no "
            "GPU; a 2-core shared AMD EPYC.",
            "",
            *sections,
            "",
        ]
    )
    write_results(args.output, text)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
