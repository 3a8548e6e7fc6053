"""Render docs/low_poly.png: a box, a lone triangle and a 10×10 district of box buildings in
the viewer page, near and far, as X3D (X_ITE) and glTF (three.js). Each keeps its mesh at every
distance (no point level is both cheaper and faithful for a few triangles).

    LODCONVERT_REQUIRE_BROWSER=1 python docs/make_low_poly_picture.py

The screenshots are those of the browser test that checks it
(``tests/browser/test_viewers.py::test_low_poly_objects_keep_their_mesh_near_and_far``), which
needs what ``scripts/test.sh`` installs (Chromium, the npm viewers).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image, ImageDraw

ROOT = Path(__file__).resolve().parents[1]
TEST = "tests/browser/test_viewers.py::test_low_poly_objects_keep_their_mesh_near_and_far"
SCENES = ("box", "triangle", "district")
COLUMNS = (("x3d", "near"), ("x3d", "far"), ("glb", "near"), ("glb", "far"))
TILE = (320, 240)
LABEL = 22


def main() -> int:
    """Run the browser test keeping its screenshots, then lay them out in a grid."""
    with tempfile.TemporaryDirectory() as shots:
        env = {**os.environ, "LODCONVERT_SHOTS": shots}
        command = [sys.executable, "-m", "pytest", "-q", "-m", "browser", TEST]
        if subprocess.run(command, cwd=ROOT, env=env, check=False).returncode:
            return 1
        width, height = TILE[0] * len(COLUMNS), (TILE[1] + LABEL) * len(SCENES)
        sheet = Image.new("RGB", (width, height), (255, 255, 255))
        draw = ImageDraw.Draw(sheet)
        for row, scene in enumerate(SCENES):
            top = row * (TILE[1] + LABEL)
            for col, (suffix, where) in enumerate(COLUMNS):
                shot = Image.open(Path(shots) / f"{scene}_{suffix}_{where}.png").convert("RGB")
                sheet.paste(shot.resize(TILE), (col * TILE[0], top + LABEL))
                text = f"{scene}, .{suffix}, {where}"
                draw.text((col * TILE[0] + 6, top + 5), text, fill=(0, 0, 0))
        out = ROOT / "docs" / "low_poly.png"
        sheet.save(out, optimize=True)
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
