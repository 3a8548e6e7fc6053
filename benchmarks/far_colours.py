"""Colours of LOD parents' far levels: how far block proxies' and simplified merged meshes'
roofs and walls lie from the source's.

Bakes TUM Munich with ``--hlod 250,1000`` once per far-level kind (``blocks``, ``mesh``), in
this process, and compares each cell's far level with its buildings' finest geometry
(:func:`lodconvert.analysis.colour_error.class_delta_e`: the area-weighted mean CIE76 ΔE of
the far level's roofs, faces facing up, against the source's roof colour, and of its walls,
steeper faces, against its wall colour):

    python benchmarks/far_colours.py               # writes results/far_colours.md

Per kind and cell: the far level's vertices, the roof and wall ΔE; and per kind their means
over cells and the vertices in all.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from city import TUM  # noqa: E402
from tables import markdown_table, one_core_facts, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "far_colours.md"
KINDS = ("blocks", "mesh")
CLASSES = ("roof", "wall")


def measure(path: Path, kind: str) -> list[list[str]]:
    """Rows of the table for ``path`` baked into cells of 250 and 1000 m, far levels of
    ``kind``: one per cell, then their mean."""
    from lodconvert.analysis.colour_error import class_delta_e
    from lodconvert.bake import get_backend
    from lodconvert.bakery import iter_chains
    from lodconvert.chain import ChainOptions
    from lodconvert.city.far_mesh import finest_mesh, merge
    from lodconvert.city.hlod import HlodOptions
    from lodconvert.context import RunContext
    from lodconvert.io import read_scene
    from lodconvert.model import CellChain

    hlod = HlodOptions((250.0, 1000.0), kind)
    items = iter_chains(read_scene(path), ChainOptions(), RunContext.here(get_backend("numpy")),
                        hlod=hlod)  # fmt: skip
    cells = [cell for item in items if isinstance(item, CellChain) for cell in item.cells()]
    rows, errors, vertices = [], [], 0
    for cell in cells:
        assert cell.far.mesh is not None
        source = merge([finest_mesh(chain) for chain in cell.objects()]).translated(-cell.origin)
        found = class_delta_e(source, cell.far.mesh)
        errors.append([found[c] for c in CLASSES])
        vertices += cell.far.mesh.vertex_count
        rows.append([kind, cell.cell_id, cell.facts["kind"], f"{cell.far.mesh.vertex_count:,}",
                     *(f"{e:.1f}" for e in errors[-1])])  # fmt: skip
    means = [sum(e[i] for e in errors) / len(errors) for i in range(len(CLASSES))]
    rows.append([f"**{kind}**", "mean", "", f"{vertices:,}", *(f"{m:.1f}" for m in means)])
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    if not TUM.is_file():
        print(f"needs {TUM}", file=sys.stderr)
        return 1
    start = time.process_time()
    rows = [row for kind in KINDS for row in measure(TUM, kind)]
    header = ["kind", "cell", "far level", "vertices", "roof ΔE", "wall ΔE"]
    command = "python benchmarks/far_colours.py"
    text = "\n".join(
        [
            "# Far levels' colours against their source's",
            "",
            *one_core_facts(command, time.process_time() - start),
            "",
            __doc__.split("\n\n")[1],
            "",
            markdown_table(header, rows, 3),
            "",
        ]
    )
    write_results(args.output, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
