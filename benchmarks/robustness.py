"""Robustness of the readers: fuzzing rate, the cost of each reader limit, the hostile cases.

    python benchmarks/robustness.py                     # writes results/robustness.md and
                                                        # docs/hostile_input.md
    python benchmarks/robustness.py --fuzz-seconds 120 --scale 1000000

1. Fuzzing: :func:`tests.fuzz.harness.fuzz` for ``--fuzz-seconds`` (every registered reader,
   plain and ``.gz``, each case read in one long-lived child under a 2 GiB address-space
   limit); cases per reader and per second.
2. Limits, scaled down with ``--limit`` so that each runs in seconds: a grid mesh of about
   ``--scale`` vertices as OBJ (``vertices``, ``faces``) and as binary PLY in a ``.gz``
   (``decompressed_bytes``), converted with the limit set exactly at the file's count (it
   converts) and one below (it is refused); time and peak RSS of the child (``wait4``), which
   may take 8 GiB of address space (the bake of the file at the limit is included).
3. Every case of :data:`tests.fuzz.cases.CASES` through the command line in a child: exit
   code, the one-line message, whether any output or temporary file was left, peak RSS;
   written as the table of ``docs/hostile_input.md``.
"""

from __future__ import annotations

import argparse
import datetime
import gzip
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tables import markdown_table  # noqa: E402

from lodconvert.limits import DEFAULT_LIMITS  # noqa: E402
from tests.fuzz.cases import CASES, grid_obj  # noqa: E402
from tests.fuzz.harness import fuzz  # noqa: E402
from tests.fuzz.worker import CliRun, Worker, run_cli  # noqa: E402

MIB = 1 << 20
LIMIT_BUDGET = 8 << 30
"""Address space of a child converting a file at a limit (a full bake of a million vertices
takes more than the fuzzing's 2 GiB)."""


def _mib(n: int) -> str:
    return f"{n / MIB:,.0f}"


def fuzz_rows(seconds: float) -> tuple[list[list[str]], str]:
    """Cases per reader in ``seconds`` of fuzzing, and a summary line."""
    worker = Worker()
    start = time.perf_counter()
    try:
        counts = fuzz(worker, seconds)
    finally:
        worker.close()
    elapsed = time.perf_counter() - start
    rows = [[name, f"{n:,}", f"{n / elapsed:,.0f}"] for name, n in sorted(counts.items())]
    total = sum(counts.values())
    return rows, f"{total:,} cases in {elapsed:.0f} s ({total / elapsed:,.0f}/s), none failed"


def _grid_ply_gz(side: int) -> tuple[bytes, int]:
    """A binary PLY of a ``side`` × ``side`` grid, gzipped, and its inflated size."""
    import numpy as np
    import trimesh

    y, x = np.divmod(np.arange(side * side), side)
    vertices = np.stack([x, y, np.zeros_like(x)], axis=1).astype(np.float64)
    a = (np.arange(side - 1)[None, :] + side * np.arange(side - 1)[:, None]).ravel()
    faces = np.concatenate(
        [np.stack([a, a + 1, a + side], 1), np.stack([a + 1, a + side + 1, a + side], 1)]
    )
    data = trimesh.Trimesh(vertices, faces, process=False).export(file_type="ply")
    return gzip.compress(data, compresslevel=1, mtime=0), len(data)


def _limit_run(path: Path, folder: Path, name: str, value: int) -> CliRun:
    """Convert ``path`` with limit ``name`` set to ``value`` (the baker's memory is not what is
    measured here: the child may take ``LIMIT_BUDGET``)."""
    args = ("-o", folder / "out.glb", "-q", "--limit", f"{name}={value}")
    return run_cli(path, *args, budget=LIMIT_BUDGET)


def limit_rows(scale: int, folder: Path) -> list[list[str]]:
    """Time and peak memory at each reader limit (exactly at it, and one below)."""
    side = max(2, int(scale**0.5))
    obj = folder / "grid.obj"
    obj.write_bytes(grid_obj(side))
    gz = folder / "grid.ply.gz"
    packed, inflated = _grid_ply_gz(side)
    gz.write_bytes(packed)
    vertices, faces = side * side, 2 * (side - 1) ** 2
    rows = []
    for name, path, value in (
        ("vertices", obj, vertices),
        ("faces", obj, faces),
        ("decompressed_bytes", gz, inflated),
    ):
        for setting in (value, value - 1):
            run = _limit_run(path, folder, name, setting)
            message = run.stderr.strip().splitlines()[-1:] or [""]
            verdict = "converted" if run.code == 0 else f"exit {run.code}: `{message[0]}`"
            verdict = verdict.replace(f"{folder}/", "")
            rows.append(
                [
                    name,
                    path.name,
                    f"{setting:,}",
                    verdict,
                    f"{run.seconds:.2f}",
                    _mib(run.peak_bytes),
                ]
            )
    return rows


def baker_rows(folder: Path) -> list[list[str]]:
    """Time and peak memory at the baker's limits: a 2,562-vertex sphere baked as one point
    level of 512³ cells with ``grid_cells`` exactly at that and one below (refused: the
    resolution was given), and one triangle repeated 100,000 times baked as points at 512 with
    the default ``memory_bytes`` and with 64 MiB (chunks: time, not memory)."""
    import trimesh

    sphere = folder / "sphere.ply"
    trimesh.creation.icosphere(subdivisions=4).export(sphere)
    repeated = folder / "repeated.obj"
    repeated.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n" + b"f 1 2 3\n" * 100_000)
    points = ("--no-mesh", "--levels", "2", "--resolution", "512,256")
    cells = 512**3
    rows = []
    for name, path, value in (
        ("grid_cells", sphere, cells),
        ("grid_cells", sphere, cells - 1),
        ("memory_bytes", repeated, DEFAULT_LIMITS.memory_bytes),
        ("memory_bytes", repeated, 64 << 20),
    ):
        args = ("-o", folder / "out.glb", "-q", *points, "--limit", f"{name}={value}")
        run = run_cli(path, *args)
        message = run.stderr.strip().splitlines()[-1:] or [""]
        verdict = "converted" if run.code == 0 else f"exit {run.code}: `{message[0]}`"
        rows.append(
            [name, path.name, f"{value:,}", verdict, f"{run.seconds:.2f}", _mib(run.peak_bytes)]
        )
    return rows


def hostile_rows(folder: Path) -> list[list[str]]:
    """Each hostile case through the CLI in a child: the docs table's rows."""
    rows = []
    for number, case in enumerate(CASES):
        work = folder / f"{number:02d}_{case.name.replace('.', '_')}"
        work.mkdir()
        src = case.write(work)
        run = run_cli(src, "-o", work / "out.x3d", *case.args)
        lines = run.stderr.strip().splitlines()
        message = (lines[-1] if lines else "").replace(f"{work}/", "")
        left = sorted(
            p.name for p in work.iterdir() if p != src and (run.code or p.suffix == ".tmp")
        )
        options = " ".join(case.args)
        rows.append(
            [
                case.what,
                f"`{case.name}`" + (f" `{options}`" if options else ""),
                str(run.code),
                f"`{message}`",
                "yes" if not left else f"NO: {', '.join(left)}",
                _mib(run.peak_bytes),
            ]
        )
    return rows


def main() -> None:
    """Run the three measurements and write the results and the docs table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fuzz-seconds", type=float, default=60.0)
    parser.add_argument("--scale", type=int, default=250_000, help="vertices at the limits")
    parser.add_argument("--results", type=Path, default=ROOT / "benchmarks/results/robustness.md")
    parser.add_argument("--docs", type=Path, default=ROOT / "docs/hostile_input.md")
    args = parser.parse_args()
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        hostile = hostile_rows(folder)
        limits = limit_rows(args.scale, folder) + baker_rows(folder)
        fuzzed, fuzz_summary = fuzz_rows(args.fuzz_seconds)
    command = "python benchmarks/robustness.py " + " ".join(sys.argv[1:])
    header = [
        f"- Date: {datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds')}",
        f"- Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"{platform.platform()}, Python {platform.python_version()}; load average (1 min) "
        f"{os.getloadavg()[0]:.1f} at the end",
        f"- Command: `{command.strip()}` ({time.perf_counter() - start:.0f} s)",
        "- Each command-line run is a fresh child process under a 2 GiB address-space limit "
        "(`RLIMIT_AS`); time = its wall clock from spawn to exit (imports included), peak = its "
        "max RSS (`wait4`).",
    ]
    hostile_table = markdown_table(
        [
            "input",
            "file and options",
            "exit",
            "message (stderr, last line)",
            "no output or temporary file left",
            "peak MiB",
        ],
        hostile,
        5,
    )
    results = "\n\n".join(
        [
            "# Reader robustness",
            "\n".join(header),
            f"## Fuzzing ({args.fuzz_seconds:.0f} s)\n\n{fuzz_summary}. Every registered "
            "reader, plain and `.gz`; byte, token and structure mutations of small generated "
            "seeds (`tests/fuzz`), each case read in one long-lived child process.",
            markdown_table(["suffix", "cases", "cases/s"], fuzzed, 1),
            "## Limits\n\nReader limits: a grid mesh converted with the limit set exactly at the "
            "file's count (converts) and one below (refused); scaled down with `--limit`. "
            "Baker limits: see `baker_rows` (a grid of 512³ cells exactly at `grid_cells` and "
            "one below; 100,000 repeated triangles baked at 512 with the default `memory_bytes` "
            "and with 64 MiB).",
            markdown_table(
                ["limit", "file", "--limit value", "result", "s", "peak MiB"], limits, 4
            ),
            "## Hostile cases\n\nAs in [docs/hostile_input.md](../../docs/hostile_input.md).",
            hostile_table,
        ]
    )
    args.results.write_text(results + "\n")
    args.docs.write_text(
        "# Hostile input\n\n"
        "What `lodconvert FILE -o out.x3d` does with each hostile or degenerate input that "
        "`tests/test_hostile_input.py` checks: the exit code, the one line on stderr (the "
        "summary line for a run that converts), and whether any output or temporary file was "
        "left behind. Generated by `python benchmarks/robustness.py` (each case run in a child "
        f"process); {header[0][2:].lower()}.\n\n"
        "The reader checks (`lodconvert/io/geometry_checks.py`, used by every reader): 3-D, "
        "finite vertices of magnitude at most 1e15; objects at least 1e-8 across and wide "
        "enough for float64 to keep 7 significant digits across them; face indices that exist; "
        "faces without area (zero area, a repeated index) dropped and counted "
        "(`totals.dropped_faces` and per object in the `--report`), an object left with none "
        "skipped, a file left with none refused; header counts matched against the data and "
        "the `vertices` / `faces` limits before anything is allocated; `.gz` inflated in a "
        "stream that stops at `decompressed_bytes`.\n\n" + hostile_table + "\n"
    )
    print(f"wrote {args.results} and {args.docs}")


if __name__ == "__main__":
    main()
