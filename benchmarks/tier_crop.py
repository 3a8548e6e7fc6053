"""A coarse tier's cells as they occur in a large district, baked without the rest of it.

A 100× TUM Munich tileset takes about 20 minutes here; its 1000 m cells are full of buildings
where the 10× district's are mostly partial. This script writes only the copies of TUM Munich
(placed as ``benchmarks/city.py`` places them for ``--factor``) that reach the chosen coarse
cells, keeps the buildings whose ground centre lies in them (the cells' grid is anchored at the
CRS origin, so they are the same buildings, in the same finer cells, as in the whole
district), and bakes them with ``--hlod`` cells in this process on one core:

    python benchmarks/tier_crop.py                            # 100×, cell 4470,5336
    python benchmarks/tier_crop.py --factor 100 --cells 4470,5336 4469,5335 --kind auto

Printed: per tier, the far levels' vertices + points and bytes (as the glTF writer lays them
out, :func:`lodconvert.plan.level_bytes`) against their children's (what a REPLACE parent is
loaded instead of: a finer cell's far level, a building's coarsest level), with the ratio and
the far levels' silhouette F; then each coarse cell's facts (kind kept, why, each candidate's
F, count and bytes, the simplification). Buildings near a chosen cell's edge may get another
plot radius than in the whole district (their nearest neighbour across the edge is missing).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from city import TUM, Template, tum_document  # noqa: E402
from hlod import tier_rows  # noqa: E402
from tables import markdown_table  # noqa: E402

HERE = Path(__file__).resolve().parent
MARGIN_M = 50.0
"""Copies reaching this close to a chosen cell are written (a building's centre may lie in the
cell while its copy's extent, as measured, just misses it)."""


def copies_reaching(
    template: Template, factor: int, cells: list[tuple[int, int]], size: float
) -> list[tuple[int, int, int]]:
    """The copies (index, x and y shift in metres) of a ``factor``× district whose extent comes
    within :data:`MARGIN_M` of one of ``cells`` (keys of ``size`` m cells)."""
    low = template.low
    columns = math.ceil(math.sqrt(factor))
    chosen = []
    for k in range(factor):
        row, column = divmod(k, columns)
        dx, dy = column * template.extent[0], row * template.extent[1]
        x0, y0 = low[0] + dx - MARGIN_M, low[1] + dy - MARGIN_M
        x1, y1 = x0 + template.extent[0] + 2 * MARGIN_M, y0 + template.extent[1] + 2 * MARGIN_M
        if any(
            x0 < (cx + 1) * size and x1 > cx * size and y0 < (cy + 1) * size and y1 > cy * size
            for cx, cy in cells
        ):
            chosen.append((k, dx, dy))
    return chosen


def write_copies(template: Template, copies: list[tuple[int, int, int]], path: Path) -> None:
    """Write the chosen copies as one CityGML file."""
    with path.open("w", encoding="utf-8", buffering=1 << 20) as out:
        out.write(template.head)
        for k, dx, dy in copies:
            out.writelines(template.copy(k, dx, dy))
        out.write(template.tail)


def in_cells(path: Path, cells: list[tuple[int, int]], size: float):
    """The scene of ``path`` with only the top-level objects whose ground centre lies in one of
    ``cells``."""
    import numpy as np

    from lodconvert.io import read_scene

    scene = read_scene(path)
    kept = []
    for node in scene.nodes:
        if node.geometry is None:
            continue
        x, y = node.offset[:2] + np.asarray(node.geometry.bounds).mean(axis=0)[:2]
        if (math.floor(x / size), math.floor(y / size)) in cells:
            kept.append(node)
    scene.nodes, scene.size = kept, None
    return scene


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--factor", type=int, default=100, help="copies of TUM Munich")
    parser.add_argument(
        "--cells", nargs="+", default=["4470,5336"], help="coarse cells' keys: column,row"
    )
    parser.add_argument("--sizes", default="250,1000", help="--hlod cell sizes")
    parser.add_argument("--kind", default="auto", help="--hlod-kind")
    parser.add_argument("--facts", type=Path, help="write every cell's facts here (JSON)")
    args = parser.parse_args(argv)
    if not TUM.is_file():
        print(f"skipped: {TUM} is absent")
        return 0
    sys.path.insert(0, str(HERE.parent))
    from lodconvert.bake import get_backend
    from lodconvert.bakery import iter_chains
    from lodconvert.chain import ChainOptions
    from lodconvert.city.hlod import HlodOptions, parse_sizes
    from lodconvert.context import RunContext
    from lodconvert.model import CellChain

    sizes = parse_sizes(args.sizes)
    assert sizes is not None
    cells = [tuple(int(v) for v in text.split(",")) for text in args.cells]
    template = Template(tum_document())
    copies = copies_reaching(template, args.factor, cells, sizes[-1])
    started = time.process_time()
    with tempfile.TemporaryDirectory(prefix="lodconvert-crop-") as tmp:
        path = Path(tmp) / "crop.gml"
        write_copies(template, copies, path)
        scene = in_cells(path, cells, sizes[-1])
        objects = len(scene.nodes)
        hlod = HlodOptions(sizes, args.kind)
        items = list(
            iter_chains(scene, ChainOptions(), RunContext.here(get_backend("numpy")), hlod=hlod)
        )
    seconds = time.process_time() - started
    found = [cell for item in items if isinstance(item, CellChain) for cell in item.cells()]
    print(
        f"{args.factor}× TUM Munich, cells {' '.join(args.cells)} of {sizes[-1]:g} m: "
        f"{len(copies)} copies written, {objects:,} buildings, {len(found)} cells, "
        f"{seconds:.0f} CPU s"
    )
    header = [
        "cells (m)", "far kind", "tier", "cells", "merged vertices", "far vertices + points",
        "children's (coarsest / finest)", "far / children", "far kB",
        "children's kB (coarsest / finest)", "far / children (bytes)", "min F",
    ]  # fmt: skip
    plain = [cell for cell in found if not cell.facts.get("beside")]
    print(markdown_table(header, tier_rows(args.sizes, args.kind, plain), 2))
    for cell in found:
        if cell.tier == len(sizes):
            print(cell.cell_id, json.dumps({k: v for k, v in cell.facts.items() if k != "seam"}))
    if args.facts is not None:
        facts = {cell.cell_id: {"tier": cell.tier, **cell.facts} for cell in found}
        args.facts.write_text(json.dumps(facts, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
