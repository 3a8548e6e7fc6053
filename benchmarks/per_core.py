"""CPU seconds per building on one core, against an earlier commit installed beside: 10× TUM
Munich (CityGML 2.0, 2,900 LoD2 buildings) to ``.x3d``, ``.glb`` and a 3D Tiles tileset, and
10× Delft (CityJSON) to ``.x3d`` and ``.glb``, each with ``--workers 1`` in a fresh child
process pinned to core 0 (``taskset``), the two checkouts interleaved run by run (this
machine is shared: load falls on both alike), after one untimed conversion each:

    git worktree add /tmp/wt-base cfac5c1
    python benchmarks/per_core.py --baseline /tmp/wt-base          # writes results/per_core.md
    python benchmarks/per_core.py --baseline /tmp/wt-base --runs 5 --formats x3d

Both checkouts run with this interpreter and its packages, the baseline's code first on
``PYTHONPATH``. Per configuration, medians of ``--runs``: CPU seconds of the child (user +
system, its ``wait4`` rusage: :func:`scale.convert_once`), wall seconds, peak RSS (sampled
every 50 ms), buildings per CPU second, and the ratio
of the CPU seconds (this checkout over the baseline) against the target (:data:`TARGETS`). The
floor is what reading alone costs on the same file, in this process: lxml's ``iterparse`` over
its members, and that with every ``posList``/``pos`` turned into floats; its share is the
floor's CPU over this checkout's.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from city import Template, tum_document, write_district
from scale import DELFT, Run, convert_once, write_delft_district
from tables import commit_of, machine_line, markdown_table, write_results

HERE = Path(__file__).resolve().parent
PINNED = ("taskset", "-c", "0")
"""Every conversion runs on core 0."""
ROOT = HERE.parent
TARGETS = {("TUM", "x3d"): 1 / 3, ("TUM", "glb"): 1 / 3, ("TUM", "tiles"): 1 / 4}
"""The CPU per building aimed at, as a share of cfac5c1's (the commit measured against);
Delft: 1/2."""


def convert(tree: Path, source: Path, fmt: str, folder: Path) -> Run:
    """Convert ``source`` to ``fmt`` with the code of ``tree`` on core 0, one worker."""
    out = folder / f"out_{os.getpid()}_{time.monotonic_ns()}"
    target = out / "tileset.json" if fmt == "tiles" else out.with_suffix(f".{fmt}")
    report = folder / "report.json"
    run = convert_once(source, target, "1", root=tree, report=report, prefix=PINNED)
    shutil.rmtree(out, ignore_errors=True)
    target.unlink(missing_ok=True)
    return run


def floors(source: Path) -> tuple[float, float]:
    """CPU seconds of lxml's ``iterparse`` over ``source`` with each ``cityObjectMember`` freed
    as it ends, and that with every ``posList``/``pos`` parsed into floats as well."""
    from lxml import etree

    member = "{http://www.opengis.net/citygml/2.0}cityObjectMember"
    coordinates = ("{http://www.opengis.net/gml}posList", "{http://www.opengis.net/gml}pos")

    def walk(parse: bool) -> float:
        tags = (member, *coordinates) if parse else (member,)
        start = time.process_time()
        for _, element in etree.iterparse(str(source), tag=tags, resolve_entities=False):
            if element.tag == member:
                element.clear()
                while element.getprevious() is not None:
                    del element.getparent()[0]
            else:
                np.array(element.text.split(), dtype=np.float64)
        return time.process_time() - start

    return walk(False), walk(True)


def results_head(
    title: str, command: str, baseline: Path, runs: int, load: float, began: float
) -> list[str]:
    """The title, machine and command lines of a results file that sets this checkout beside
    ``baseline``, medians of ``runs`` interleaved runs on core 0 (``load``: the load average
    at the start; ``began``: its ``perf_counter``)."""
    return [
        f"# {title}",
        "",
        machine_line(load, time.perf_counter() - began),
        f"Command: `{command}` (baseline: {commit_of(baseline)}, this: {commit_of(ROOT)}); "
        f"medians of {runs} interleaved runs, each pinned to core 0 with `--workers 1`.",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", type=Path, required=True, help="checkout to compare with")
    parser.add_argument("--runs", type=int, default=3, help="runs per checkout (3)")
    parser.add_argument("--formats", default="x3d,glb,tiles", help="x3d,glb,tiles")
    parser.add_argument("--factor", type=int, default=10, help="copies of each city (10)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "per_core.md")
    args = parser.parse_args()
    formats = args.formats.split(",")
    trees = {"baseline": args.baseline.resolve(), "this": ROOT}
    load, began = os.getloadavg()[0], time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="per_core_") as tmp:
        folder = Path(tmp)
        tum = write_district(Template(tum_document()), args.factor, folder / "tum.gml")
        inputs = {"TUM": (tum.path, tum.buildings)}
        if DELFT.is_file():
            delft = write_delft_district(args.factor, folder / "delft.city.json")
            inputs["Delft"] = (delft.path, delft.buildings)
        configs = [(name, fmt) for name in inputs for fmt in formats]
        configs = [(n, f) for n, f in configs if not (n == "Delft" and f == "tiles")]
        for tree in trees.values():  # untimed: bytecode, page cache
            convert(tree, inputs["TUM"][0], formats[0], folder)
        runs: dict[tuple[str, str, str], list[Run]] = {}
        for _ in range(args.runs):
            for name, fmt in configs:
                for label, tree in trees.items():
                    key = (name, fmt, label)
                    runs.setdefault(key, []).append(convert(tree, inputs[name][0], fmt, folder))
                    print(key, runs[key][-1], flush=True)
        iterparse, parsed = floors(inputs["TUM"][0])
    rows = []
    for name, fmt in configs:
        buildings = inputs[name][1]
        cpu = {k: statistics.median(r.cpu for r in runs[name, fmt, k]) for k in trees}
        wall = {k: statistics.median(r.wall for r in runs[name, fmt, k]) for k in trees}
        rss = {k: statistics.median(r.peak_mib for r in runs[name, fmt, k]) for k in trees}
        target = TARGETS.get((name, fmt), 1 / 2)
        ratio = cpu["this"] / cpu["baseline"]
        floor = f"{parsed / cpu['this']:.0%}" if name == "TUM" else ""
        rows.append(
            [
                f"{args.factor}× {name} ({buildings:,} buildings)",
                fmt,
                f"{cpu['baseline']:.2f}",
                f"{cpu['this']:.2f}",
                f"{wall['baseline']:.2f}",
                f"{wall['this']:.2f}",
                f"{buildings / cpu['baseline']:.0f}",
                f"{buildings / cpu['this']:.0f}",
                f"{rss['baseline']:.0f}",
                f"{rss['this']:.0f}",
                f"{ratio:.2f}",
                f"≤ {target:.2f}",
                "yes" if ratio <= target else "no",
                floor,
            ]
        )
    header = ["input", "output", "base CPU s", "CPU s", "base wall s", "wall s"]
    header += ["base bldg/CPU s", "bldg/CPU s", "base RSS MiB", "RSS MiB", "ratio", "target"]
    header += ["met", "floor share"]
    command = (
        f"python benchmarks/per_core.py --baseline {args.baseline} --runs {args.runs} "
        f"--formats {args.formats} --factor {args.factor}"
    )
    text = "\n".join(
        [
            *results_head(
                "CPU per building on one core, against an earlier commit",
                command,
                trees["baseline"],
                args.runs,
                load,
                began,
            ),
            "",
            markdown_table(header, rows, 2),
            "",
            f"Floor on {args.factor}× TUM, in one process: lxml's `iterparse` alone "
            f"{iterparse:.2f} CPU s ({inputs['TUM'][1] / iterparse:,.0f} buildings/CPU s), with "
            f"every `posList`/`pos` parsed into floats {parsed:.2f} CPU s "
            f"({inputs['TUM'][1] / parsed:,.0f}/CPU s). Floor share: that over this checkout's "
            "CPU s. Ratio: this checkout's CPU s over the baseline's; target: the share of "
            "the baseline's aimed at.",
            "",
        ]
    )
    write_results(args.out, text)


if __name__ == "__main__":
    main()
