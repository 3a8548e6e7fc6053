"""A textured district: N copies of the real textured PLATEAU building (CityGML 2.0, its image
shared, each copy's ids renamed and its coordinates shifted; generated here, removed after),
converted with its textures and, interleaved, as the same district without its appearances,
to ``.glb`` and to a 3D Tiles tileset, one worker pinned to one core:

    python benchmarks/textured_district.py                 # 20 and 100 copies, 3 rounds
    python benchmarks/textured_district.py --copies 50 --rounds 5
    python benchmarks/textured_district.py --baseline /tmp/wt-base   # its textured runs beside

Measured per run and size: CPU seconds of the child (its workers' included), peak RSS of the
tree and the output's bytes; between the sizes, the CPU of each further building (what a
process pays once left out); for the largest tileset, the texture bytes per tier (images in
each tile's GLB, by the tile's level: finest, coarsest, far) and the largest atlas page.
Writes ``results/textured_district.md``.
"""

from __future__ import annotations

import argparse
import io
import itertools
import json
import os
import re
import struct
import tempfile
import time
from pathlib import Path
from statistics import median

from scale import convert_once
from tables import commit_of, machine_line, markdown_table, write_results

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DATA = ROOT.parent / "shared" / "data" / "citygml"
SOURCE = DATA / "plateau_53394517_bldg_lod012_v2.gml"
IMAGE = "53394517_bldg_6697_appearance/stad0158.jpg"
STEP_DEG = 0.0012
"""How far apart the copies lie (degrees of latitude and longitude: some 110–130 m)."""
PIN = ("taskset", "-c", "0")


def district(copies: int, folder: Path, textured: bool) -> Path:
    """``copies`` of the PLATEAU building on a grid, in ``folder`` (the image copied beside
    it as the source has it); without its appearances where not ``textured``."""
    text = SOURCE.read_text(encoding="utf-8")
    head, rest = text.split("<core:cityObjectMember>", 1)
    member, rest = rest.split("</core:cityObjectMember>", 1)
    appearance = ""
    between = ""
    if "<app:appearanceMember>" in rest:
        between, rest = rest.split("<app:appearanceMember>", 1)
        appearance, rest = rest.split("</app:appearanceMember>", 1)
    tail = between + rest
    side = int(copies**0.5 + 0.999)
    members, appearances = [], []
    for k in range(copies):
        shift = ((k // side) * STEP_DEG, (k % side) * STEP_DEG)
        members.append(f"<core:cityObjectMember>{_copy(member, k, shift)}</core:cityObjectMember>")
        if textured and appearance:
            appearances.append(
                f"<app:appearanceMember>{_renamed(appearance, k)}</app:appearanceMember>"
            )
    path = folder / ("textured.gml" if textured else "plain.gml")
    folder.mkdir(parents=True, exist_ok=True)
    path.write_text(head + "".join(members) + "".join(appearances) + tail, encoding="utf-8")
    image = folder / IMAGE
    if not image.exists():
        image.parent.mkdir(parents=True, exist_ok=True)
        image.write_bytes((DATA / IMAGE).read_bytes())
    return path


def _renamed(text: str, k: int) -> str:
    """``text`` with every gml:id and every reference to one prefixed by copy ``k``."""
    text = re.sub(r'gml:id="', f'gml:id="c{k}_', text)
    return re.sub(r'((?:uri|ring|xlink:href)=")#', rf"\1#c{k}_", text)


def _copy(member: str, k: int, shift: tuple[float, float]) -> str:
    """Copy ``k`` of a member: renamed, its latitudes and longitudes moved by ``shift``."""

    def moved(match: re.Match[str]) -> str:
        values = match.group(2).split()
        out = []
        for i, value in enumerate(values):
            axis = i % 3
            number = float(value) + (shift[axis] if axis < 2 else 0.0)
            out.append(repr(number) if axis < 2 else value)
        return f"{match.group(1)}{' '.join(out)}{match.group(3)}"

    text = _renamed(member, k)
    return re.sub(r"(<gml:posList[^>]*>)([^<]*)(</gml:posList>)", moved, text)


def texture_bytes(tileset: Path) -> tuple[dict[str, int], int]:
    """Bytes of the images in the tiles of ``tileset`` by tier (the tile's name: finest,
    coarsest, far) and the largest side of an atlas page."""
    from PIL import Image

    tiers = {"finest": 0, "coarsest": 0, "far": 0}
    largest = 0
    for tile in sorted((tileset.parent / "tiles").glob("*.glb")):
        data = tile.read_bytes()
        length = struct.unpack_from("<I", data, 12)[0]
        document = json.loads(data[20 : 20 + length])
        start = 20 + length + 8
        tier = (
            "finest"
            if "_finest" in tile.name
            else "coarsest"
            if "_coarsest" in tile.name
            else "far"
        )
        for image in document.get("images", []):
            view = document["bufferViews"][image["bufferView"]]
            tiers[tier] += view["byteLength"]
            at = start + view.get("byteOffset", 0)
            with Image.open(io.BytesIO(data[at : at + view["byteLength"]])) as page:
                largest = max(largest, *page.size)
    return tiers, largest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--copies", default="20,100", help="district sizes, comma-separated")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=HERE / "results" / "textured_district.md")
    parser.add_argument(
        "--baseline",
        type=Path,
        help="an earlier checkout: its textured runs interleaved with these (before and after)",
    )
    args = parser.parse_args()
    kinds = ("textured", "plain", *(("baseline",) if args.baseline else ()))
    sizes = sorted({int(each) for each in args.copies.split(",")})
    load, began = os.getloadavg()[0], time.perf_counter()
    runs: dict[tuple[str, int, str], list] = {}
    outputs = {"glb": "out.glb", "tiles": "tiles/tileset.json"}
    with tempfile.TemporaryDirectory(prefix="textured_") as tmp:
        folder = Path(tmp)
        sources = {
            (copies, kind): district(copies, folder / str(copies), kind == "textured")
            for copies in sizes
            for kind in ("textured", "plain")
        }
        for _ in range(args.rounds):
            for output, name in outputs.items():
                for copies, kind in itertools.product(sizes, kinds):  # interleaved
                    source = sources[(copies, "plain" if kind == "plain" else "textured")]
                    root = args.baseline if kind == "baseline" else ROOT
                    target = folder / str(copies) / kind / name
                    target.parent.mkdir(parents=True, exist_ok=True)
                    report = folder / str(copies) / kind / f"{output}.json"
                    run = convert_once(source, target, "1", root=root, report=report, prefix=PIN)
                    size = (
                        sum(p.stat().st_size for p in target.parent.rglob("*") if p.is_file())
                        if output == "tiles" else target.stat().st_size
                    )  # fmt: skip
                    runs.setdefault((output, copies, kind), []).append((run, size))
        largest_size = str(sizes[-1])
        tiers, largest = texture_bytes(folder / largest_size / "textured/tiles/tileset.json")
        plain_tiers, _ = texture_bytes(folder / largest_size / "plain/tiles/tileset.json")
    cpu = {key: median(r.cpu for r, _ in found) for key, found in runs.items()}
    rows = []
    for output in outputs:
        for copies in sizes:
            key = (output, copies)
            peak = {k: max(r.peak_mib for r, _ in runs[(*key, k)]) for k in ("textured", "plain")}
            size = {k: runs[(*key, k)][-1][1] for k in ("textured", "plain")}
            plain, textured = cpu[(*key, "plain")], cpu[(*key, "textured")]
            before = (
                [f"{cpu[(*key, 'baseline')]:.2f}", f"{textured / cpu[(*key, 'baseline')]:.2f}"]
                if args.baseline
                else []
            )
            rows.append(
                [
                    output,
                    f"{copies}",
                    f"{plain:.2f}",
                    f"{textured:.2f}",
                    f"{textured / plain:.2f}",
                    f"{1000 * plain / copies:.0f}",
                    f"{1000 * textured / copies:.0f}",
                    f"{peak['plain']:.0f}",
                    f"{peak['textured']:.0f}",
                    f"{size['plain'] / 1e6:.2f}",
                    f"{size['textured'] / 1e6:.2f}",
                    *before,
                ]
            )
    header = ["output", "copies", "plain CPU s", "textured CPU s", "ratio", "plain ms/building",
              "textured ms/building", "plain peak MiB", "textured peak MiB", "plain MB",
              "textured MB"]  # fmt: skip
    if args.baseline:
        header += [f"baseline ({commit_of(args.baseline)}) textured CPU s", "textured / baseline"]
    marginal = []
    if len(sizes) > 1:
        few, many = sizes[0], sizes[-1]
        for output in outputs:
            slope = {
                k: (cpu[(output, many, k)] - cpu[(output, few, k)]) / (many - few)
                for k in ("plain", "textured")
            }
            marginal.append(
                [
                    output,
                    f"{1000 * slope['plain']:.1f}",
                    f"{1000 * slope['textured']:.1f}",
                    f"{slope['textured'] / slope['plain']:.2f}",
                ]
            )
    tier_rows = [[tier, f"{plain_tiers[tier]:,}", f"{tiers[tier]:,}"] for tier in tiers]
    text = "\n".join(
        [
            f"# A textured district: {' and '.join(map(str, sizes))} copies of the PLATEAU "
            "building",
            "",
            machine_line(load, time.perf_counter() - began),
            f"Command: `python benchmarks/textured_district.py --copies {args.copies} "
            f"--rounds {args.rounds}{' --baseline ' + str(args.baseline) if args.baseline else ''}`"
            f" (this: {commit_of(ROOT)}); each run `--workers 1` pinned to core 0 "
            "(`taskset -c 0`), textured and plain interleaved; CPU: medians of the child's "
            "rusage (its workers "
            "included); peak: the tree's largest sampled RSS.",
            "",
            markdown_table(header, rows, 2),
            "",
            *(
                [
                    f"CPU per building beyond the first {sizes[0]} (the slope from {sizes[0]} to "
                    f"{sizes[-1]} copies: what each further building costs, without what a "
                    "process pays once, such as loading numba for the texture bake):",
                    "",
                    markdown_table(
                        ["output", "plain ms/building", "textured ms/building", "ratio"],
                        marginal,
                        1,
                    ),
                    "",
                ]
                if marginal
                else []
            ),
            f"Texture bytes per tier of the textured tileset of {sizes[-1]} copies (images "
            f"inside each tile's GLB; largest atlas page {largest} texels a side, the default "
            "--atlas-size 4096):",
            "",
            markdown_table(["tier", "plain", "textured"], tier_rows, 1),
            "",
        ]
    )
    write_results(args.out, text)
    print(text)


if __name__ == "__main__":
    main()
