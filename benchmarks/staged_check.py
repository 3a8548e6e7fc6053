"""The last check of a staged output folder (``lodconvert.sinks``: every entry its runs did not
write refused) against the number of files in it, this checkout beside another installed
beside: a folder of N empty files (a tileset's tiles), all listed as written, checked by each
checkout in a child process of its own, the two interleaved run by run, CPU seconds of the
check alone (medians):

    python benchmarks/staged_check.py --baseline /tmp/base     # writes results/staged_check.md

A 1000× TUM Munich tileset has some 45,000 files, and 10⁷ buildings about 1.5 million.
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
from pathlib import Path

from tables import commit_of, machine_line, markdown_table, write_results

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
COUNTS = (3_000, 12_000, 48_000)
"""Files in the folder checked (a 100×, 300× and 1000× TUM tileset have about these)."""
CHILD = """
import json, os, sys, time
from lodconvert import sinks
folder = sys.argv[1]
written = set(os.listdir(os.path.join(folder, "tiles")))
written = {f"tiles/{name}" for name in written}
fd = os.open(folder, os.O_RDONLY)
start = time.process_time()
found = sinks._foreign(fd, written)
print(json.dumps({"cpu": time.process_time() - start, "found": found}))
"""
"""What each child runs: the check over ``folder``, every file listed as written."""


def checked(root: Path, folder: Path) -> float:
    """CPU seconds of the check of ``folder`` with the code of checkout ``root``."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    done = subprocess.run(
        [sys.executable, "-c", CHILD, str(folder)],
        env=env,
        cwd=folder,
        capture_output=True,
        text=True,
    )
    if done.returncode:
        raise SystemExit(done.stderr)
    result = json.loads(done.stdout)
    if result["found"] is not None:
        raise SystemExit(f"{root}: the check refused {result['found']}")
    return result["cpu"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", type=Path, required=True, help="checkout to compare with")
    parser.add_argument("--runs", type=int, default=3, help="runs per checkout (3)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "staged_check.md")
    args = parser.parse_args()
    load, began = os.getloadavg()[0], time.perf_counter()
    roots = [("base", args.baseline.resolve()), ("this", ROOT)]
    rows = []
    for count in COUNTS:
        with tempfile.TemporaryDirectory(prefix="staged_check_") as tmp:
            folder = Path(tmp)
            (folder / "tiles").mkdir()
            for i in range(count):
                (folder / "tiles" / f"{i}.glb").touch()
            cpu: dict[str, list[float]] = {name: [] for name, _ in roots}
            for _ in range(args.runs):
                for name, root in roots:
                    cpu[name].append(checked(root, folder))
        base, this = (statistics.median(cpu[name]) for name, _ in roots)
        rows.append([f"{count:,}", f"{base:.4f}", f"{this:.4f}", f"{base / this:,.0f}×"])
    header = ["files", "base CPU s", "CPU s", "base / this"]
    text = "\n\n".join(
        [
            "# The last check of a staged output folder, by the files in it",
            machine_line(load, time.perf_counter() - began)
            + f"\nCommand: `python benchmarks/staged_check.py --baseline … --runs {args.runs}` "
            f"(baseline: {commit_of(args.baseline)}, this: {commit_of(ROOT)}); medians of "
            f"{args.runs} runs interleaved, each in a child process of its own.",
            markdown_table(header, rows, 1),
            "Before de1ff34 the check made the union of the written names and its own two anew "
            "for every entry it met, so that its cost grew with the square of the files.",
        ]
    )
    write_results(args.out, text + "\n")


if __name__ == "__main__":
    main()
