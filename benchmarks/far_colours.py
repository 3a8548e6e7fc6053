"""Colours of LOD parents' far levels: how far block proxies' and simplified merged meshes'
roofs and walls lie from the source's.

Bakes TUM Munich with ``--hlod 250,1000`` once per far-level kind (``blocks``, ``mesh``), in
this process, and compares each cell's far level with its buildings' finest geometry
(:func:`lodconvert.analysis.colour_error.class_delta_e`: the area-weighted mean CIE76 ΔE of
the far level's roofs, faces facing up, against the source's roof colour, and of its walls,
steeper faces, against its wall colour):

    python benchmarks/far_colours.py               # writes results/far_colours.md
    python benchmarks/far_colours.py --textured 20 # results/far_colours_textured.md

With ``--textured N`` the city is N copies of the textured PLATEAU building
(``textured_district.py``), ΔE is CIEDE2000, the source's colours are the area-weighted means
of its texture, and each building's LOD1 prism is measured too (tier ``prism``).

Per kind and cell: the far level's vertices, the roof and wall ΔE; and per kind their means
over cells and the vertices in all.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from city import TUM  # noqa: E402
from tables import markdown_table, one_core_facts, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "far_colours.md"
KINDS = ("blocks", "mesh")
CLASSES = ("roof", "wall")


def measure(path: Path, kind: str, difference: Any = None) -> list[list[str]]:
    """Rows of the table for ``path`` baked into cells of 250 and 1000 m, far levels of
    ``kind``: one per cell, then their mean (``difference``: the ΔE, CIE76 by default); with
    ``kind`` ``prism``, each object's LOD1 prism against its finest level instead."""
    from lodconvert.analysis.colour_error import class_delta_e
    from lodconvert.bake import get_backend
    from lodconvert.bakery import iter_chains
    from lodconvert.chain import ChainOptions
    from lodconvert.city.far_mesh import finest_mesh, merge
    from lodconvert.city.hlod import HlodOptions
    from lodconvert.colors import delta_e
    from lodconvert.context import RunContext
    from lodconvert.io import read_scene
    from lodconvert.model import CellChain

    hlod = HlodOptions((250.0, 1000.0), "blocks" if kind == "prism" else kind)
    items = iter_chains(read_scene(path), ChainOptions(), RunContext.here(get_backend("numpy")),
                        hlod=hlod)  # fmt: skip
    cells = [cell for item in items if isinstance(item, CellChain) for cell in item.cells()]
    if kind == "prism":
        return _prisms(cells, difference or delta_e)
    rows, errors, vertices = [], [], 0
    for cell in cells:
        assert cell.far.mesh is not None
        source = merge([finest_mesh(chain) for chain in cell.objects()]).translated(-cell.origin)
        found = class_delta_e(source, cell.far.mesh, difference or delta_e)
        errors.append([found[c] for c in CLASSES])
        vertices += cell.far.mesh.vertex_count
        rows.append([kind, cell.cell_id, cell.facts["kind"], f"{cell.far.mesh.vertex_count:,}",
                     *(f"{e:.1f}" for e in errors[-1])])  # fmt: skip
    means = [sum(e[i] for e in errors) / len(errors) for i in range(len(CLASSES))]
    rows.append([f"**{kind}**", "mean", "", f"{vertices:,}", *(f"{m:.1f}" for m in means)])
    return rows


def _prisms(cells: list[Any], difference: Any) -> list[list[str]]:
    """One row per object with a LOD1 prism: its vertices and ΔE against its finest level;
    then their mean."""
    from lodconvert.analysis.colour_error import class_delta_e

    rows, errors, vertices = [], [], 0
    for chain in {id(c): c for cell in cells for c in cell.objects()}.values():
        meshes = [level.mesh for level in chain.levels if level.mesh is not None]
        prism = next((lv.mesh for lv in chain.levels if lv.name == "LOD1" and lv.mesh), None)
        if prism is None or prism is meshes[0]:
            continue
        found = class_delta_e(meshes[0], prism, difference)
        errors.append([found[c] for c in CLASSES])
        vertices += prism.vertex_count
        rows.append(["prism", chain.object_id, "LOD1", f"{prism.vertex_count:,}",
                     *(f"{e:.1f}" for e in errors[-1])])  # fmt: skip
    means = [sum(e[i] for e in errors) / max(len(errors), 1) for i in range(len(CLASSES))]
    rows.append(["**prism**", "mean", "", f"{vertices:,}", *(f"{m:.1f}" for m in means)])
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output", type=Path, default=None)
    parser.add_argument(
        "--textured", type=int, default=0, metavar="N", help="N textured PLATEAU copies, not TUM"
    )
    args = parser.parse_args(argv)
    if not args.textured and not TUM.is_file():
        print(f"needs {TUM}", file=sys.stderr)
        return 1
    start = time.process_time()
    if args.textured:
        from textured_district import district

        from lodconvert.colors import delta_e_2000

        with tempfile.TemporaryDirectory(prefix="far_colours_") as tmp:
            source = district(args.textured, Path(tmp), textured=True)
            rows = [r for kind in ("prism", *KINDS) for r in measure(source, kind, delta_e_2000)]
        title = f"# Far levels' colours against the textures of {args.textured} PLATEAU copies"
        about = (
            "Here ΔE is CIEDE2000, against the area-weighted means of the buildings' textures "
            "(each face's texture mean over 16 points), roofs and walls apart; tier `prism` is "
            "each building's LOD1 (the source's lod1Solid, in its textures' colours)."
        )
        command = f"python benchmarks/far_colours.py --textured {args.textured}"
        output = args.output or RESULTS.with_name("far_colours_textured.md")
    else:
        rows = [row for kind in KINDS for row in measure(TUM, kind)]
        title, command = (
            "# Far levels' colours against their source's",
            "python benchmarks/far_colours.py",
        )
        about = __doc__.split("\n\n")[1].split("\n\n")[0]
        output = args.output or RESULTS
    header = ["kind", "cell", "far level", "vertices", "roof ΔE", "wall ΔE"]
    text = "\n".join(
        [
            title,
            "",
            *one_core_facts(command, time.process_time() - start),
            "",
            about,
            "",
            markdown_table(header, rows, 3),
            "",
        ]
    )
    write_results(output, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
