"""City levels: the triangles per-building LOD draws beyond each cutoff, and the LOD1 prisms kept.

Bakes the LoD2 districts of ``../shared/data`` (TUM Munich, KIT's 100 buildings, and
``--factors`` larger districts of shifted copies of TUM Munich, made as ``benchmarks/city.py``
makes them) with the default options, in this process on one core:

    python benchmarks/city_levels.py               # writes results/city_levels.md
    python benchmarks/city_levels.py --factors 10 --sweep

Per district: the triangles drawn with every building seen from beyond its cutoff Y(x), for
each default exponent x, against every building at its finest level (no per-building LOD);
the prisms kept and left out, and why (no fewer triangles than the level before, silhouette F
below 0.95 where they would switch in, no footprint); the silhouette F of the kept prisms at
their switch-in distance (the planner's estimate, :func:`lodconvert.plan.mesh_silhouette_estimate`:
axis-aligned masks at the pixel size of that distance, 1080-px reference view); the CPU time of
reading and baking every chain, and of it the F estimates. ``--sweep`` adds, on TUM Munich, the
prisms kept and the triangles beyond Y(1.0) for other roof percentiles and footprint tolerances.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from lodconvert.model import LodChain

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from city import DATA, TUM, Template, tum_document, write_district  # noqa: E402
from tables import markdown_table, one_core_facts, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "city_levels.md"
KIT = DATA / "citygml" / "kit_testcases_lod2_100bldg_v3.gml"
SWEEP = [(50.0, 0.5), (70.0, 0.5), (80.0, 0.5), (90.0, 0.5), (100.0, 0.5), (90.0, 1.0), (90.0, 2.0)]
"""(roof percentile, footprint tolerance in pixels) pairs tried by ``--sweep``."""


class Measured:
    """What one district's chains draw and keep."""

    def __init__(self, path: Path) -> None:
        import lodconvert.chain
        from lodconvert.bake import get_backend
        from lodconvert.bakery import iter_chains
        from lodconvert.chain import ChainOptions
        from lodconvert.context import RunContext
        from lodconvert.io import read_scene
        from lodconvert.ranges import default_xs

        estimate = lodconvert.chain.mesh_silhouette_estimate
        self.f_seconds = 0.0

        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.process_time()
            try:
                return estimate(*args, **kwargs)
            finally:
                self.f_seconds += time.process_time() - start

        options = ChainOptions()
        self.xs = default_xs(options.levels - 1)
        self.finest = 0
        self.beyond = [0] * len(self.xs)
        self.buildings = 0
        self.kept: list[float | None] = []
        self.costlier = 0
        self.dropped: Counter[str] = Counter()
        start = time.process_time()
        lodconvert.chain.mesh_silhouette_estimate = timed
        try:
            for chain in iter_chains(
                read_scene(path), options, RunContext.here(get_backend("numpy"))
            ):
                self._count(chain)
        finally:
            lodconvert.chain.mesh_silhouette_estimate = estimate
        self.seconds = time.process_time() - start

    def _count(self, chain: LodChain) -> None:
        from lodconvert.city.prisms import LOW_F, MORE_TRIANGLES

        triangles = [lv.mesh.face_count if lv.mesh is not None else 0 for lv in chain.levels]
        self.buildings += 1
        self.finest += triangles[0]
        switches = chain.xs[: len(chain.levels) - 1]
        for i, x in enumerate(self.xs):
            self.beyond[i] += triangles[sum(1 for s in switches if s <= x + 1e-9)]
        self.kept += [lv.silhouette_f for lv in chain.levels if lv.kind == "prism"]
        self.costlier += sum(
            1
            for i, level in enumerate(chain.levels[1:], 1)
            if level.kind == "prism"
            and chain.levels[i - 1].mesh
            and triangles[i] >= triangles[i - 1]
        )
        why = chain.dropped.get("LOD1", "")
        for reason, text in (("more triangles", MORE_TRIANGLES), ("F < 0.95", LOW_F)):
            if why.startswith(text):
                self.dropped[reason] += 1
        if why.startswith("no footprint"):
            self.dropped["no footprint"] += 1

    def row(self, name: str) -> list[str]:
        """The district's table row."""
        kept = [f for f in self.kept if f is not None]
        return [
            name,
            f"{self.buildings:,}",
            f"{self.finest:,}",
            *(f"{b:,} ({1 - b / self.finest:.1%} fewer)" for b in self.beyond),
            f"{len(self.kept):,}",
            f"{self.costlier:,}",
            ", ".join(f"{n} {why}" for why, n in sorted(self.dropped.items())) or "none",
            f"{min(kept):.3f} / {statistics.median(kept):.3f}" if kept else "–",
            f"{self.seconds:.1f}",
            f"{self.f_seconds:.1f}",
        ]


def sweep(path: Path) -> list[list[str]]:
    """Rows of TUM Munich's prisms kept and triangles beyond Y(1.0) per :data:`SWEEP` pair."""
    import lodconvert.chain
    import lodconvert.city.prisms

    defaults = lodconvert.city.prisms.ROOF_PERCENTILE, lodconvert.chain.FOOTPRINT_TOLERANCE_PX
    rows = []
    try:
        for percentile, tolerance in SWEEP:
            lodconvert.city.prisms.ROOF_PERCENTILE = percentile
            lodconvert.chain.FOOTPRINT_TOLERANCE_PX = tolerance
            got = Measured(path)
            chosen = " (default)" if (percentile, tolerance) == defaults else ""
            rows.append(
                [
                    f"{percentile:g}{chosen}",
                    f"{tolerance:g}",
                    f"{len(got.kept):,}",
                    f"{got.beyond[-1]:,} ({1 - got.beyond[-1] / got.finest:.1%} fewer)",
                ]
            )
            print(" | ".join(rows[-1]), flush=True)
    finally:
        lodconvert.city.prisms.ROOF_PERCENTILE, lodconvert.chain.FOOTPRINT_TOLERANCE_PX = defaults
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--factors", default="10", help="larger districts, × TUM Munich")
    parser.add_argument("--sweep", action="store_true", help="other percentiles, tolerances")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    if not TUM.is_file():
        print(f"skipped: {TUM} is absent")
        return 0
    sys.path.insert(0, str(HERE.parent))
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    started = time.perf_counter()
    rows = []
    districts = [("TUM Munich", TUM), *([("KIT 100 buildings", KIT)] if KIT.is_file() else [])]
    for name, path in districts:
        rows.append(Measured(path).row(name))
        print(" | ".join(rows[-1]), flush=True)
    with tempfile.TemporaryDirectory(prefix="lodconvert-levels-") as tmp:
        template = Template(tum_document())
        for factor in (int(f) for f in args.factors.split(",") if f.strip()):
            path = Path(tmp) / f"district_{factor}.gml"
            write_district(template, factor, path)
            rows.append(Measured(path).row(f"{factor}× TUM Munich"))
            print(" | ".join(rows[-1]), flush=True)
    from lodconvert.chain import ChainOptions
    from lodconvert.ranges import default_xs

    header = [
        "district", "buildings", "triangles, no LOD",
        *(f"beyond Y({x:g})" for x in default_xs(ChainOptions().levels - 1)),
        "prisms kept", "kept with ≥ the finer level's triangles", "prisms left out",
        "F of kept (min / median)", "CPU s", "of it F s",
    ]  # fmt: skip
    sections = [markdown_table(header, rows, 1), ""]
    if args.sweep:
        sweep_rows = sweep(TUM)
        sections += [
            "## Roof percentile and footprint tolerance on TUM Munich",
            "",
            markdown_table(
                ["roof percentile", "tolerance (px)", "prisms kept", "triangles beyond Y(1)"],
                sweep_rows,
                0,
            ),
            "",
        ]
    command = f"python benchmarks/city_levels.py {' '.join(argv or sys.argv[1:])}".rstrip()
    text = "\n".join(
        [
            "# City levels: triangles beyond each cutoff, and the LOD1 prisms that pay",
            "",
            *one_core_facts(command, time.perf_counter() - started),
            "- Triangles beyond Y(x): every building seen from beyond its cutoff at exponent x "
            "(the level it shows there); no LOD: every building at its finest level. A prism is "
            "kept only where it has fewer triangles than the level before it and silhouette F "
            "≥ 0.95 against the finest level where it switches in (F: the planner's estimate, "
            "axis views at that distance's pixel size); else the finer level stays on. CPU s: "
            "reading and baking every chain; of it F s: the F estimates.",
            "",
            *sections,
        ]
    )
    write_results(args.output, text)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
