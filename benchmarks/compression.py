"""Compressed tiles (``--compress``, docs/compression.md): TUM Munich to a tileset by the
lodconvert of another checkout (``--before``: the commit before compression, whose tilesets
are what "today's" means) and by this one with each ``--compress``, runs interleaved, one
worker pinned to one core:

    git worktree add /tmp/before 25f3095
    python benchmarks/compression.py --before /tmp/before            # 3 rounds
    python benchmarks/compression.py --before /tmp/before --rounds 5

Measured per run: CPU seconds of the child and the tileset's bytes; once per setup: its bytes
by part (positions, normals, colours, feature ids, indices, metadata, JSON), the bytes
CesiumJS requests from 300 m and 4 km (``benchmarks/tiles.py``'s cameras, headless Chromium)
and the largest position error the tiles state. Writes ``results/compression.md``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections import Counter
from pathlib import Path
from statistics import median

from scale import convert_once
from tables import machine_line, markdown_table, write_results
from tiles import CAMERAS, cesium_metrics

from lodconvert.io.tiles.check import read_glb

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
TUM = ROOT.parent / "shared" / "data" / "citygml" / "tum_munich_lod2_v2.zip"
PIN = ("taskset", "-c", "0")
MESHOPT = "EXT_meshopt_compression"
SETUPS = ("before", "none", "meshopt", "quantize")
PARTS = ("POSITION", "NORMAL", "COLOR_0", "_FEATURE_ID_0", "TEXCOORD_0", "indices")


def parts(tileset: Path) -> tuple[Counter, float]:
    """Bytes of a tileset by part (each buffer view as stored: packed where it is), and the
    largest position error its tiles state."""
    found: Counter = Counter()
    error = 0.0
    found["tileset JSON"] = sum(p.stat().st_size for p in tileset.parent.glob("*.json"))
    for path in sorted((tileset.parent / "tiles").glob("*.glb")):
        document, blob = read_glb(path)
        named: dict[int, str] = {}
        for mesh in document["meshes"]:
            for primitive in mesh["primitives"]:
                for name, accessor in primitive["attributes"].items():
                    named[document["accessors"][accessor]["bufferView"]] = name
                if "indices" in primitive:
                    named[document["accessors"][primitive["indices"]]["bufferView"]] = "indices"
        images = {image["bufferView"] for image in document.get("images", [])}
        for k, view in enumerate(document["bufferViews"]):
            packed = view.get("extensions", {}).get(MESHOPT)
            part = named.get(k, "images" if k in images else "metadata")
            found[part] += packed["byteLength"] if packed else view["byteLength"]
        found["GLB JSON and padding"] += path.stat().st_size - len(blob)
        extras = document["asset"].get("extras", {}).get("lodconvert", {})
        error = max(error, extras.get("position_error", 0.0))
    return found, error


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, required=True, help="the earlier checkout")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    started, load = time.perf_counter(), os.getloadavg()[0]
    cpu: dict[str, list[float]] = {setup: [] for setup in SETUPS}
    with tempfile.TemporaryDirectory(prefix="compression-") as folder:
        out = {setup: Path(folder) / setup / "tileset.json" for setup in SETUPS}
        for _ in range(args.rounds):
            for setup in SETUPS:
                root = args.before if setup == "before" else ROOT
                options = () if setup == "before" else ("--compress", setup)
                report = Path(folder) / f"{setup}.report.json"
                run = convert_once(
                    TUM, out[setup], "1", root=root, options=options, report=report, prefix=PIN
                )
                cpu[setup].append(run.cpu)
        found = {setup: parts(out[setup]) for setup in SETUPS}
        seen = {setup: cesium_metrics(out[setup]) for setup in SETUPS}
    total = {setup: sum(found[setup][0].values()) for setup in SETUPS}
    base = total["before"]
    rows = []
    for setup in SETUPS:
        metrics = seen[setup]
        requests = [
            "not measured" if metrics is None else f"{metrics[name]['bytes']:,}" for name in CAMERAS
        ]
        share = [
            "—" if metrics is None or seen["before"] is None
            else f"{metrics[name]['bytes'] / seen['before'][name]['bytes']:.0%}"
            for name in CAMERAS
        ]  # fmt: skip
        rows.append(
            [setup, f"{total[setup]:,}", f"{total[setup] / base:.1%}", requests[0], share[0],
             requests[1], share[1], f"{median(cpu[setup]):.2f}",
             f"{median(cpu[setup]) / median(cpu['before']):.2f}",
             f"{found[setup][1] * 1000:.4f}"]
        )  # fmt: skip
    header = ["setup", "tileset bytes", "of before", "CesiumJS 300 m bytes", "of before",
              "CesiumJS 4 km bytes", "of before", "CPU s (median)", "CPU of before",
              "largest position error (mm)"]  # fmt: skip
    names = sorted({name for counter, _ in found.values() for name in counter})
    part_rows = [[name, *(f"{found[setup][0][name]:,}" for setup in SETUPS)] for name in names]
    text = "\n\n".join(
        [
            "# Compressed tiles: TUM Munich (290 LoD2 buildings) to a tileset",
            "Command: `python benchmarks/compression.py --before CHECKOUT "
            f"--rounds {args.rounds}`; before = the lodconvert of `{args.before}` (its default "
            "tileset), the others this checkout with `--compress SETUP` (meshopt is the "
            "default). Each run `--workers 1` pinned to one core (`taskset -c 0`), the four "
            "setups interleaved in each round. CesiumJS bytes: the tile and tileset files it "
            "requested from cameras 300 m and 4 km from the tileset's centre, 35° down "
            "(`tests/browser/tiles.mjs`, headless Chromium, `benchmarks/tiles.py`).",
            markdown_table(header, rows, 1),
            "Bytes by part (each buffer view as stored, packed where it is):",
            markdown_table(["part", *SETUPS], part_rows, 1),
            machine_line(load, time.perf_counter() - started),
        ]
    )
    write_results(HERE / "results" / "compression.md", text + "\n")


if __name__ == "__main__":
    main()
