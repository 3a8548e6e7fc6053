"""Meshes drawn in their own colours, unlit, as a viewer sees them from afar: textures sampled
with mipmaps (trilinear), times vertex colours and the base colour, each pixel also told
whether its face is a roof (facing up) or a wall (steep); and the colour error of a far level
against its source drawn so from the same views (:func:`class_delta_e_rendered`). Used by
``benchmarks/texture_colours.py``; ``docs/textures.md`` states what it measures."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..colors import ciede2000, delta_e_2000, lab, linear_rgba, srgb_rgba
from ..model import Mesh, Surface
from .render import OffscreenRenderer, look_at, perspective

STEEP = 0.5
"""A face is a roof where its normal's z exceeds this (less steep than 60°), a wall where
its |z| is below it."""
ROOF, WALL, OTHER = 1, 2, 3

_VERTEX = """
#version 330
uniform mat4 mvp;
in vec3 in_pos;
in vec2 in_uv;
in vec4 in_color;
in float in_kind;
out vec2 uv;
out vec4 color;
flat out float kind;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    uv = in_uv;
    color = in_color;
    kind = in_kind;
}
"""
_FRAGMENT = """
#version 330
uniform sampler2D image;
uniform bool textured;
in vec2 uv;
in vec4 color;
flat in float kind;
out vec4 albedo;
void main() {
    vec4 texel = textured ? texture(image, uv) : vec4(1.0);  // rows uploaded bottom first
    albedo = vec4((texel * color).rgb, kind / 255.0);
}
"""


@dataclass(frozen=True)
class Picture:
    """What one view shows: sRGB bytes (h, w, 3) and each pixel's face kind (0: nothing)."""

    rgb: np.ndarray
    kind: np.ndarray


class AlbedoRenderer(OffscreenRenderer):
    """Meshes in their unlit colours from perspective cameras of focal length ``focal_px``
    (the reference view's by default), each view framed to what it shows."""

    def __init__(self, focal_px: float = 1080 / (2 * math.tan(math.radians(22.5)))) -> None:
        super().__init__("colour renders unavailable")
        self.focal_px = focal_px
        self.program = self.ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self.ctx.enable(self.ctx.DEPTH_TEST)

    def pictures(
        self,
        mesh: Mesh,
        center: np.ndarray,
        distance: float,
        directions: np.ndarray,
        side: int,
        scale: int = 1,
    ) -> list[Picture]:
        """``mesh`` seen from ``center + distance · direction`` for each unit direction,
        looking at ``center``, on ``side`` × ``side`` pixels about it; with ``scale``, drawn on
        ``scale`` × ``scale`` times the pixels and each pixel the mean of its own
        (:func:`_downsampled`)."""
        fov = math.degrees(2 * math.atan(side / 2 / self.focal_px))
        side *= scale
        target = self.ctx.texture((side, side), 4)
        depth = self.ctx.depth_renderbuffer((side, side))
        fbo = self.ctx.framebuffer(color_attachments=[target], depth_attachment=depth)
        drawn = [self._part(part) for part in mesh.parts]
        radius = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0])) / 2 + 1.0
        out = []
        fbo.use()
        for direction in np.asarray(directions, dtype=np.float64).reshape(-1, 3):
            eye = center + distance * direction
            reach = float(np.linalg.norm(eye - center))
            near, far = max(reach - 2 * radius, reach * 1e-3), reach + 2 * radius
            mvp = perspective(fov, 1.0, near, far) @ look_at(eye, center)
            self.program["mvp"].write(mvp.T.astype(np.float32).tobytes())
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            for vao, texture in drawn:
                self.program["textured"].value = texture is not None
                if texture is not None:
                    texture.use(0)
                    self.program["image"].value = 0
                vao.render(self.ctx.TRIANGLES)
            data = np.frombuffer(fbo.read(components=4, alignment=1), dtype=np.uint8)
            image = data.reshape(side, side, 4)[::-1]
            out.append(_downsampled(image, scale))
        for vao, texture in drawn:
            vao.release()
            if texture is not None:
                texture.release()
        fbo.release()
        target.release()
        depth.release()
        return out

    def _part(self, part: Surface) -> tuple[object, object | None]:
        """A part's vertex array (a vertex per corner: its position, texture coordinates,
        colour times base colour, face kind) and its mipmapped texture."""
        faces = part.faces
        corners = part.vertices[faces].reshape(-1, 3)
        normals = Surface(part.vertices, faces).face_normals(np.arange(len(faces)))
        kind = np.where(
            normals[:, 2] > STEEP, ROOF, np.where(np.abs(normals[:, 2]) < STEEP, WALL, OTHER)
        )
        textured = part.texture is not None and part.uv is not None
        base = part.material_color.astype(np.float64) / 255
        colors = (
            part.vertex_colors[faces].reshape(-1, 4) / 255 * base
            if part.vertex_colors is not None
            else np.tile(base, (len(corners), 1))
        )
        uv = part.uv[faces].reshape(-1, 2) if textured else np.zeros((len(corners), 2))
        data = np.column_stack([corners, uv, colors, np.repeat(kind, 3)]).astype(np.float32)
        buffer = self.ctx.buffer(data.tobytes())
        vao = self.ctx.vertex_array(
            self.program, [(buffer, "3f 2f 4f 1f", "in_pos", "in_uv", "in_color", "in_kind")]
        )
        texture = None
        if textured:
            assert part.texture is not None
            image = np.ascontiguousarray(part.texture[::-1])
            texture = self.ctx.texture((image.shape[1], image.shape[0]), 4, image.tobytes())
            texture.build_mipmaps()
            texture.filter = (self.ctx.LINEAR_MIPMAP_LINEAR, self.ctx.LINEAR)
            texture.repeat_x = texture.repeat_y = True
        return vao, texture


def _downsampled(image: np.ndarray, scale: int) -> Picture:
    """The picture of RGBA bytes ``image`` (alpha: the face kind) on a ``scale`` times coarser
    grid: each pixel the mean colour, in linear light, of those of its ``scale`` × ``scale``
    that show something, and their most frequent kind (0: none shows anything)."""
    if scale == 1:
        return Picture(image[..., :3].copy(), image[..., 3].copy())
    side = image.shape[0] // scale
    blocks = image.reshape(side, scale, side, scale, 4).swapaxes(1, 2).reshape(side, side, -1, 4)
    kinds = blocks[..., 3]
    shown = kinds > 0
    counts = shown.sum(axis=2)
    linear = linear_rgba(blocks)[..., :3] * shown[..., None]
    mean = linear.sum(axis=2) / np.maximum(counts, 1)[..., None]
    rgb = srgb_rgba(np.concatenate([mean, np.ones((side, side, 1))], axis=2))[..., :3]
    votes = np.stack([(kinds == kind).sum(axis=2) for kind in (ROOF, WALL, OTHER)], axis=2)
    kind = np.where(counts > 0, votes.argmax(axis=2) + 1, 0).astype(np.uint8)
    return Picture(rgb, kind)


def class_delta_e_rendered(
    renderer: AlbedoRenderer,
    source: Mesh,
    far: Mesh,
    distance: float,
    directions: np.ndarray,
    supersample: int = 1,
) -> dict[str, float]:
    """How far ``far``'s colours lie from ``source``'s, both drawn in their colours
    (:class:`AlbedoRenderer`) from ``distance`` along each of ``directions`` towards their
    centre, over the pixels both show, ``roof`` and ``wall`` by the source's face there: the
    mean CIEDE2000 ΔE of the pixels (``roof``, ``wall``), of those where ``far`` shows a face
    of the same kind (``roof_same``, ``wall_same``: the colours, where the geometries agree),
    and the CIEDE2000 ΔE of their mean colours, in CIE L*a*b* (``roof_mean``,
    ``wall_mean``); and the mean CIEDE2000 ΔE of ``source``'s pixels of each kind from their
    mean colour (``roof_spread``, ``wall_spread``: how much its colours vary within a kind);
    NaN where no pixel is of a kind.
    With ``supersample``, each pixel is the mean of ``supersample`` × ``supersample`` drawn
    ones (at most 2,048 a side in all): what the surfaces under it show, where mipmaps alone
    blend a texture atlas's unrelated parts into a pixel that covers a building."""
    center = (source.bounds[0] + source.bounds[1]) / 2
    radius = float(np.linalg.norm(source.bounds[1] - source.bounds[0])) / 2
    side = max(16, 2 * math.ceil(radius * renderer.focal_px / max(distance - radius, 1e-9)) + 8)
    side = min(side, 2048)
    scale = max(1, min(supersample, 2048 // side))
    wanted = renderer.pictures(source, center, distance, directions, side, scale)
    seen = renderer.pictures(far, center, distance, directions, side, scale)
    pairs: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {
        name: [] for name in ("roof", "wall", "roof_same", "wall_same")
    }
    for want, got in zip(wanted, seen, strict=True):
        both = (want.kind > 0) & (got.kind > 0)
        for name, kind in (("roof", ROOF), ("wall", WALL)):
            chosen = both & (want.kind == kind)
            pairs[name].append((want.rgb[chosen], got.rgb[chosen]))
            same = chosen & (got.kind == kind)
            pairs[f"{name}_same"].append((want.rgb[same], got.rgb[same]))
    out: dict[str, float] = {}
    for name, found in pairs.items():
        a = np.concatenate([w for w, _ in found])
        b = np.concatenate([g for _, g in found])
        out[name] = float(delta_e_2000(a, b).mean()) if len(a) else float("nan")
        if name in ("roof", "wall"):
            wanted_lab = lab(a)
            mean = ciede2000(wanted_lab.mean(axis=0), lab(b).mean(axis=0)) if len(a) else np.nan
            out[f"{name}_mean"] = float(mean)
            spread = ciede2000(wanted_lab, wanted_lab.mean(axis=0)).mean() if len(a) else np.nan
            out[f"{name}_spread"] = float(spread)
    return out
