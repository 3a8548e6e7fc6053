"""Render docs/levels.png: the bundled sample's four levels side by side, same scale.

    python docs/make_levels_picture.py

A small CPU renderer: the mesh level is ray-cast with the numpy baker's axis rasteriser (one
slab, seen from +z), point levels are splatted as squares of their grid pitch with a z-buffer.
Colours are the baked colours, shaded by the normal's facing ratio.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from lodconvert.bake import NumpyBackend
from lodconvert.bake.grid import Grid
from lodconvert.chain import ChainOptions, bake_chain
from lodconvert.io import read_scene
from lodconvert.model import Mesh, Surface

ROOT = Path(__file__).resolve().parents[1]
PANEL = 360
TILT = np.radians(35.0)


def view_rotation() -> np.ndarray:
    """Rotate the scene 35° about x so the view along -z shows the knot's depth."""
    c, s = np.cos(TILT), np.sin(TILT)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def shade(rgb: np.ndarray, normals: np.ndarray) -> np.ndarray:
    facing = np.abs(normals[:, 2])[:, None]
    return np.clip(rgb * (0.35 + 0.65 * facing), 0, 255)


def render_mesh(surface, lo: np.ndarray, pitch: float) -> np.ndarray:
    grid = Grid(lo=lo, pitch=pitch, slab=1e9, cells=(PANEL, PANEL, 1), slabs=(1, 1, 1))
    hits = next(h for h in NumpyBackend().rasterize(surface, grid) if h.axis == 2 and h.sign < 0)
    image = np.full((PANEL, PANEL, 3), 255.0)
    points = hits.positions(grid)
    rgb = surface.colors_at(hits.face, points)[:, :3].astype(float)
    image[hits.iv, hits.iu] = shade(rgb, surface.face_normals(hits.face))
    return image


def render_points(cloud, rotation, lo: np.ndarray, pitch: float, size_world: float) -> np.ndarray:
    p = cloud.positions @ rotation.T
    n = cloud.normals @ rotation.T
    rgb = shade(cloud.colors[:, :3].astype(float), n)
    half = max(1, int(np.ceil(size_world / pitch / 2)))
    image = np.full((PANEL, PANEL, 3), 255.0)
    depth = np.full((PANEL, PANEL), -np.inf)
    col = ((p[:, 0] - lo[0]) / pitch).astype(int)
    row = ((p[:, 1] - lo[1]) / pitch).astype(int)
    for i in np.argsort(p[:, 2]):  # far to near: nearer points overwrite
        r0, r1 = max(0, row[i] - half), min(PANEL, row[i] + half)
        c0, c1 = max(0, col[i] - half), min(PANEL, col[i] + half)
        image[r0:r1, c0:c1] = rgb[i]
        depth[r0:r1, c0:c1] = p[i, 2]
    return image


def main() -> None:
    obj = next(read_scene(ROOT / "samples" / "torus_knot.ply").with_geometry())
    chain = bake_chain(obj, ChainOptions(), NumpyBackend())
    rotation = view_rotation()
    mesh = chain.levels[0].mesh
    rotated = Mesh.of(Surface(mesh.vertices @ rotation.T, mesh.faces, mesh.vertex_colors))
    extent = np.ptp(rotated.vertices, axis=0)[:2].max() * 1.05
    pitch = extent / PANEL
    lo = rotated.vertices.min(axis=0) - (extent - np.ptp(rotated.vertices, axis=0)) / 2
    lo[2] = rotated.vertices[:, 2].min() - 1.0
    panels, labels = (
        [render_mesh(rotated, lo, pitch)],
        [f"LOD4 mesh · {mesh.vertices.shape[0]:,} v"],
    )
    for level in chain.levels[1:]:
        panels.append(render_points(level.points, rotation, lo, pitch, level.spacing))
        labels.append(f"{level.name} · {level.count:,} points · T3={level.params.resolution}")
    # rows of the renders run along +y; flip so that +y is up
    strip = np.concatenate([p[::-1] for p in panels], axis=1).astype(np.uint8)
    canvas = Image.new("RGB", (strip.shape[1], strip.shape[0] + 28), "white")
    canvas.paste(Image.fromarray(strip), (0, 28))
    draw = ImageDraw.Draw(canvas)
    for i, text in enumerate(labels):
        draw.text((i * PANEL + 8, 8), text, fill=(30, 30, 30))
    out = ROOT / "docs" / "levels.png"
    canvas.save(out, optimize=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
