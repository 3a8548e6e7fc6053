"""Render docs/prisms_{LABEL}_{200,600}m.png: TUM Munich in its ``--html`` viewer page
(three.js, headless Chromium) from 200 m and 600 m.

    python docs/make_prism_pictures.py after
    python docs/make_prism_pictures.py before --tree /tmp/lodconvert-old   # another checkout

Converts ``../shared/data/citygml/tum_munich_lod2_v2.zip`` to ``.glb`` with the ``lodconvert``
of ``--tree`` (default: this one), serves the page and drives it with
``tests/browser/drive.mjs`` (Chromium and ``node_modules`` as the browser tests use them);
each screenshot is stored with a 256-colour palette to stay small.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image

from lodconvert.viewer import serve

ROOT = Path(__file__).resolve().parents[1]
TUM = ROOT.parent / "shared" / "data" / "citygml" / "tum_munich_lod2_v2.zip"
DISTANCES = (200, 600)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("label", help="picture names: docs/prisms_LABEL_200m.png …")
    parser.add_argument("--tree", type=Path, default=ROOT, help="checkout whose lodconvert runs")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="lodconvert-prisms-") as tmp:
        folder = Path(tmp)
        (folder / "node_modules").symlink_to(ROOT / "node_modules")
        model = folder / "tum.glb"
        env = {**os.environ, "PYTHONPATH": str(args.tree.resolve())}
        subprocess.run(
            [sys.executable, "-m", "lodconvert", str(TUM), "-o", str(model), "--html", "-q",
             "--viewer-lib", str(folder / "node_modules" / "three")],
            cwd=args.tree, env=env, check=True,
        )  # fmt: skip
        shots = {d: folder / f"{d}.png" for d in DISTANCES}
        stops = [{"distance": d, "shot": str(shot)} for d, shot in shots.items()]
        with serve(folder) as base:
            params = json.dumps({"page": f"{model.name}.html", "stops": stops})
            subprocess.run(
                ["node", str(ROOT / "tests" / "browser" / "drive.mjs"), "viewer", base, params],
                check=True,
                stdout=subprocess.DEVNULL,
            )
        for distance, shot in shots.items():
            out = ROOT / "docs" / f"prisms_{args.label}_{distance}m.png"
            Image.open(shot).convert("RGB").quantize(256).save(out, optimize=True)
            print(f"wrote {out} ({out.stat().st_size:,} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
