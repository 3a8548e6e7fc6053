"""Generate the bundled sample: a vertex-coloured (3, 2) torus knot tube, ``torus_knot.ply``.

Run ``python samples/make_samples.py`` to rebuild it; the output is deterministic.
"""

from __future__ import annotations

import colorsys
from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent


def torus_knot(p: int = 3, q: int = 2, along: int = 480, around: int = 24, tube: float = 0.35):
    """A closed tube around the (p, q) torus knot, coloured by position along the knot."""
    t = np.linspace(0.0, 2 * np.pi, along, endpoint=False)
    r = 2.0 + np.cos(p * t)
    centre = np.stack([r * np.cos(q * t), r * np.sin(q * t), np.sin(p * t)], axis=1)
    tangent = np.roll(centre, -1, axis=0) - np.roll(centre, 1, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.cross(tangent, [0.0, 0.0, 1.0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)
    s = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    ring = np.cos(s)[None, :, None] * normal[:, None] + np.sin(s)[None, :, None] * binormal[:, None]
    vertices = (centre[:, None, :] + tube * ring).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(along), np.arange(around), indexing="ij")
    a = i * around + j
    b = ((i + 1) % along) * around + j
    c = ((i + 1) % along) * around + (j + 1) % around
    d = i * around + (j + 1) % around
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    hue = np.repeat(t / (2 * np.pi), around)
    shade = 0.75 + 0.25 * np.tile(np.cos(s), along)
    rgb = np.array([colorsys.hsv_to_rgb(h, 0.7, 1.0) for h in hue]) * shade[:, None]
    colors = np.concatenate([np.rint(rgb * 255), np.full((len(rgb), 1), 255)], axis=1)
    return trimesh.Trimesh(vertices, faces, vertex_colors=colors.astype(np.uint8), process=False)


if __name__ == "__main__":
    mesh = torus_knot()
    (HERE / "torus_knot.ply").write_bytes(trimesh.exchange.ply.export_ply(mesh, encoding="binary"))
    print(f"torus_knot.ply: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces")
