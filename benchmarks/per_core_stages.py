"""Where one core's CPU goes in a city run, part by part, and the least this design can take:
10× TUM Munich (CityGML 2.0, 2,900 LoD2 buildings) to ``.x3d`` with ``--workers 1``, each run
in a fresh child process pinned to core 0, against an earlier commit installed beside (as
``per_core.py`` does, runs interleaved):

    git worktree add /tmp/wt-base cfac5c1
    python benchmarks/per_core_stages.py --baseline /tmp/wt-base   # results/per_core_stages.md

The parts, medians of ``--runs``: a process's **start** (fitted from runs on 1× and 10× TUM:
what a run costs before its first building; of it, importing the dependencies and numba's
first compiled call, measured alone); the **parse floor** (lxml's ``iterparse`` with every
``posList``/``pos`` parsed into floats, in this process: ``per_core.floors``); **reading** above
that floor (the CityGML reader's generator, triangulation included); the **LOD1 prisms**
(:func:`lodconvert.city.prisms.prism`); the **guard** (:func:`lodconvert.plan.view_estimate`,
compiled loops, numba's first call made before the run); the **output check**
(the report's ``validate`` stage); and the **rest** (planning, writing the X3D, the report).
The child runs :func:`lodconvert.pipeline.convert` with those functions wrapped in CPU
timers. The **bound** is start + parse floor + guard: this design's CPU with every other
part free, set against the target, a third of the baseline's CPU.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from city import Template, tum_document, write_district
from per_core import PINNED, convert, floors, results_head
from tables import markdown_table, write_results

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
TARGET = 1 / 3
"""The CPU per building aimed at for ``.x3d``, as a share of the baseline's."""
STARTED = (
    "import numpy as np, lxml.etree, shapely, pyproj, mapbox_earcut\n"
    "import lodconvert.cli, lodconvert.pipeline\n"
    "from lodconvert.city.roof_heights import area_percentile\n"
    "area_percentile(np.ones((1, 3)), np.ones(1), 0.5)\n"
)
"""What a city run imports and compiles before its first building, alone."""


def child(source: Path, output: Path) -> None:
    """Convert ``source`` to ``output`` in this process with the parts wrapped in CPU timers;
    print their CPU seconds as JSON."""
    import numpy as np

    from lodconvert.city import levels
    from lodconvert.io.citygml import document
    from lodconvert.model import Mesh, Surface
    from lodconvert.pipeline import RunOptions, convert

    spent: Counter[str] = Counter()

    def timed(name: str, function: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            start = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                spent[name] += time.process_time() - start

        return wrapper

    def timed_items(name: str, function: Callable[..., Iterator[Any]]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Iterator[Any]:
            items = function(*args, **kwargs)
            while True:
                start = time.process_time()
                try:
                    item = next(items)
                except StopIteration:
                    return
                finally:
                    spent[name] += time.process_time() - start
                yield item

        return wrapper

    cube = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    tetra = Mesh([Surface(cube, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))])
    levels.view_estimate(tetra, tetra, 100.0)  # numba's first calls: the start's, not the guard's
    levels.prism = timed("prisms", levels.prism)
    levels.view_estimate = timed("guard", levels.view_estimate)
    document.Document.read = timed_items("reading", document.Document.read)
    start = time.process_time()
    report = convert(source, output, RunOptions(workers=1))
    spent["total"] = time.process_time() - start
    spent["check"] = report["timings"]["validate"]
    print(json.dumps(spent))


def stages(source: Path, output: Path) -> dict[str, float]:
    """The parts' CPU seconds of one run of :func:`child` on core 0, with this checkout."""
    command = [*PINNED, sys.executable, __file__, "--child", str(source), str(output)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(HERE)])}
    done = subprocess.run(command, capture_output=True, text=True, env=env, check=True)
    output.unlink(missing_ok=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def started() -> float:
    """CPU seconds of a process on core 0 that only imports and compiles what a city run
    does before its first building (:data:`STARTED`)."""
    before = os.times()
    subprocess.run([*PINNED, sys.executable, "-c", STARTED], check=True, cwd=ROOT)
    after = os.times()
    return (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", type=Path, help="checkout to compare with")
    parser.add_argument("--runs", type=int, default=3, help="runs of each (3)")
    parser.add_argument("--child", nargs=2, type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, default=HERE / "results" / "per_core_stages.md")
    args = parser.parse_args()
    if args.child:
        child(*args.child)
        return
    if args.baseline is None:
        parser.error("--baseline is required")
    load, began = os.getloadavg()[0], time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="per_core_stages_") as tmp:
        folder = Path(tmp)
        template = Template(tum_document())
        ten = write_district(template, 10, folder / "tum10.gml")
        one = write_district(template, 1, folder / "tum1.gml")
        base = args.baseline.resolve()
        for tree in (base, ROOT):  # untimed: bytecode, page cache
            convert(tree, one.path, "x3d", folder)
        cpu: dict[str, list[float]] = {}
        parts: list[dict[str, float]] = []
        for _ in range(args.runs):
            cpu.setdefault("base", []).append(convert(base, ten.path, "x3d", folder).cpu)
            cpu.setdefault("ten", []).append(convert(ROOT, ten.path, "x3d", folder).cpu)
            cpu.setdefault("one", []).append(convert(ROOT, one.path, "x3d", folder).cpu)
            cpu.setdefault("started", []).append(started())
            parts.append(stages(ten.path, folder / "staged.x3d"))
            print(cpu, parts[-1], flush=True)
        floor = floors(ten.path)[1]
    median = {k: statistics.median(v) for k, v in cpu.items()}
    part = {k: statistics.median(p[k] for p in parts) for k in parts[0]}
    n, m = ten.buildings, one.buildings
    fixed = (n * median["one"] - m * median["ten"]) / (n - m)  # the fit's value at 0 buildings
    rows_in = [
        ("start (fitted; a run's CPU at 0 buildings)", fixed),
        (" of which imports and numba's first call, alone", median["started"]),
        ("parse floor", floor),
        ("reading above the floor", part["reading"] - floor),
        ("LOD1 prisms", part["prisms"]),
        ("guard (24 views, compiled)", part["guard"]),
        ("output check", part["check"]),
        (
            "rest (planning, X3D writing, report)",
            median["ten"]
            - fixed
            - part["reading"]
            - part["prisms"]
            - part["guard"]
            - part["check"],
        ),
        ("this checkout, in all", median["ten"]),
        ("baseline, in all", median["base"]),
    ]
    rows = [
        [
            name,
            f"{seconds:.2f}",
            "" if name.startswith(("start", " of")) else f"{1000 * seconds / n:.3f}",
            f"{seconds / median['ten']:.0%}",
        ]
        for name, seconds in rows_in
    ]
    bound = fixed + floor + part["guard"]
    target = TARGET * median["base"]
    text = "\n".join(
        [
            *results_head(
                "Where one core's CPU goes in a city run, and the least this design can take",
                f"python benchmarks/per_core_stages.py --baseline {args.baseline} "
                f"--runs {args.runs}",
                base,
                args.runs,
                load,
                began,
            ),
            f"Input: 10× TUM ({n:,} buildings) to `.x3d`; the start fitted from 1× ({m:,} "
            f"buildings, {median['one']:.2f} CPU s) and 10× ({median['ten']:.2f} CPU s).",
            "",
            __doc__.split("\n\n")[2].replace("\n", " "),
            "",
            markdown_table(["part", "CPU s", "ms a building", "share"], rows, 1),
            "",
            f"Bound (start + parse floor + guard): {bound:.2f} CPU s, "
            f"{bound / median['base']:.2f} of the baseline's; target ({TARGET:.2f} of the "
            f"baseline's): {target:.2f} CPU s, which leaves {target - bound:.2f} CPU s "
            f"({1000 * (target - bound) / n:.3f} ms a building) for reading above the floor, "
            "the prisms, the output check, planning and writing together.",
            "",
        ]
    )
    write_results(args.out, text)


if __name__ == "__main__":
    main()
