"""GL backend: the paper's FBO slab rendering, with moderngl through headless EGL.

For each axis and slab of the level grid the mesh is drawn orthographically along the axis,
clipped to the slab, from both sides; two colour attachments receive the hit depth and face.
A geometry shader hands each triangle's depth plane to the fragment shader, which evaluates it
at the exact pixel centre (vertex snapping would move it), so hits match the numpy backend's to
float32 precision. Each slab draws only the faces that reach it, and a compute shader lists the
covered pixels so that only they are read back. How and why: ``docs/baking.md``.

Contexts are made when a :class:`GLBackend` is created, never at import: on Mesa llvmpipe a
process forked after its parent made a context (even a released one) deadlocks in GL calls.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import LodConvertError
from ..glcontext import SOFTWARE_RENDERERS, create_context
from ..model import Mesh
from .grid import Grid, SlabHits
from .numpy import EPS

if TYPE_CHECKING:
    import moderngl

# Framebuffer bytes per pixel of a slab tile: depth (R32F), face (R32I), depth buffer.
TILE_BYTES = 12
# Framebuffer memory of one batch of slab tiles (rendered, then read back at once).
BATCH_BYTES = 1 << 27
# A face is drawn in the slabs it reaches within this fraction of a slab (float32 rounding).
SLAB_TOL = 1e-4
# Clip planes lie this fraction of a slab outside the slab, so that fragments the rasteriser's
# vertex snapping moves across a slab face still reach the exact per-pixel depth test.
CLIP_MARGIN = 0.5
# Stands for an unbounded depth in shader uniforms.
FLOAT32_MAX = float(np.finfo(np.float32).max)

VERTEX_SHADER = """
#version 330
uniform int axis;
uniform vec2 u_map;
uniform vec2 v_map;
uniform vec2 z_map;
in vec3 in_pos;
out vec3 v_uvw;
void main() {
    v_uvw = vec3(in_pos[(axis + 1) % 3], in_pos[(axis + 2) % 3], in_pos[axis]);
    gl_Position = vec4(
        v_uvw.x * u_map.x + u_map.y, v_uvw.y * v_map.x + v_map.y, v_uvw.z * z_map.x + z_map.y, 1.0
    );
}
"""

# Per triangle: its depth plane (a corner and the depth gradient over the image plane), so that
# fragments get the exact depth at their pixel centre whatever the rasteriser's vertex snapping.
GEOMETRY_SHADER = """
#version 330
layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;
in vec3 v_uvw[];
flat out vec3 g_corner;
flat out vec2 g_slope;
void main() {
    vec3 n = cross(v_uvw[1] - v_uvw[0], v_uvw[2] - v_uvw[0]);
    if (n.z == 0.0) return;
    for (int i = 0; i < 3; ++i) {
        gl_Position = gl_in[i].gl_Position;
        gl_PrimitiveID = gl_PrimitiveIDIn;
        g_corner = v_uvw[0];
        g_slope = -n.xy / n.z;
        EmitVertex();
    }
    EndPrimitive();
}
"""

FRAGMENT_SHADER = """
#version 330
uniform int first;
uniform vec2 u_pixel;
uniform vec3 v_pixel;
uniform vec2 keep;
uniform vec2 frag_depth;
flat in vec3 g_corner;
flat in vec2 g_slope;
layout(location = 0) out float out_depth;
layout(location = 1) out int out_face;
void main() {
    vec2 centre = vec2(
        u_pixel.x + gl_FragCoord.x * u_pixel.y, v_pixel.x + (gl_FragCoord.y - v_pixel.z) * v_pixel.y
    );
    float depth = g_corner.z + dot(g_slope, centre - g_corner.xy);
    if (!(depth >= keep.x && depth < keep.y)) discard;
    gl_FragDepth = depth * frag_depth.x + frag_depth.y;
    out_depth = depth;
    out_face = first + gl_PrimitiveID + 1;
}
"""


# Work-group side of the compute shader that lists covered pixels.
LIST_GROUP = 16

LIST_SHADER = f"""
#version 430
layout(local_size_x = {LIST_GROUP}, local_size_y = {LIST_GROUP}) in;
layout(binding = 0) uniform isampler2D face_image;
layout(binding = 1) uniform sampler2D depth_image;
layout(std430, binding = 0) buffer Count {{ uint count; }};
layout(std430, binding = 1) buffer Hits {{ int hits[]; }};
uniform ivec2 size;
uniform uint capacity;
void main() {{
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= size.x || p.y >= size.y) return;
    int face = texelFetch(face_image, p, 0).r;
    if (face == 0) return;
    uint i = atomicAdd(count, 1u);
    if (i < capacity) {{
        hits[3 * i] = p.y * size.x + p.x;
        hits[3 * i + 1] = face;
        hits[3 * i + 2] = floatBitsToInt(texelFetch(depth_image, p, 0).r);
    }}
}}
"""


@functools.cache
def gl_unavailable_reason() -> str | None:
    """None when an EGL GL context can be made in this process, else the one-line reason.

    Probes once per process with a throwaway context; a process that forks workers should not
    call this before forking (see the module docstring).
    """
    try:
        ctx = create_context("GL backend unavailable")
    except LodConvertError as exc:
        return str(exc)
    ctx.release()
    return None


@dataclass
class _AxisPlan:
    """What to draw along one axis. ``order`` holds face indices in draw order: first the
    ``n_long`` faces that span very many slabs, then one entry per (slab, face) for the others,
    sorted by slab. Per rendered slab ``slabs[i]``: draw the long faces when ``long[i]``, and the
    ``count[i]`` entries from ``start[i]`` of ``order``, clipped to depths ``clip[i]`` (low,
    high), keeping the fragments with depths in ``keep[i]`` (low inclusive, high exclusive)."""

    order: np.ndarray
    n_long: int
    slabs: np.ndarray
    long: np.ndarray
    start: np.ndarray
    count: np.ndarray
    keep: np.ndarray
    clip: np.ndarray


def _face_bounds(surface: Mesh, axis: int) -> dict[str, np.ndarray]:
    """Per face not degenerate in projection along ``axis`` (the numpy backend's test): its
    index and the bounds of its corners along u, v and the axis (world coordinates)."""
    tri = surface.triangles
    u, v = Grid.plane_axes(axis)
    pu, pv = tri[:, :, u], tri[:, :, v]
    area = (pu[:, 1] - pu[:, 0]) * (pv[:, 2] - pv[:, 0]) - (pv[:, 1] - pv[:, 0]) * (
        pu[:, 2] - pu[:, 0]
    )
    extent = float(np.ptp(surface.bounds, axis=0).max())
    idx = np.flatnonzero(np.abs(area) > 1e-15 * extent * extent)
    table = {"face": idx}
    for name, c in (("u", u), ("v", v), ("w", axis)):
        table[f"{name}min"] = tri[idx, :, c].min(axis=1)
        table[f"{name}max"] = tri[idx, :, c].max(axis=1)
    return table


def _covers_centre(
    lo: np.ndarray, hi: np.ndarray, origin: float, pitch: float, n: int
) -> np.ndarray:
    """Whether ``[lo, hi]`` (world) holds one of the pixel centres ``0 … n-1`` (with the numpy
    backend's tolerance): a face whose bounds hold none covers no pixel."""
    first = np.maximum(np.ceil((lo - origin) / pitch - 0.5 - EPS), 0)
    last = np.minimum(np.floor((hi - origin) / pitch - 0.5 + EPS), n - 1)
    return last >= first


def _plan_axis(table: dict[str, np.ndarray], grid: Grid, axis: int) -> _AxisPlan:
    """Sort the faces for slab-by-slab drawing along ``axis`` (see :class:`_AxisPlan`)."""
    u, v = grid.plane_axes(axis)
    rows, cols = grid.image_shape(axis)
    n_slabs = grid.slabs[axis]
    keep = _covers_centre(table["umin"], table["umax"], grid.lo[u], grid.pitch, cols)
    keep &= _covers_centre(table["vmin"], table["vmax"], grid.lo[v], grid.pitch, rows)
    ids = table["face"][keep]
    w_min, w_max = table["wmin"][keep], table["wmax"][keep]
    tol = SLAB_TOL * grid.slab
    s0 = grid.slab_of(axis, w_min - tol)
    s1 = grid.slab_of(axis, w_max + tol)
    span = s1 - s0 + 1
    # Faces reaching more than ``most`` slabs ("long") are drawn for every slab that any long
    # face reaches; the others get one entry per slab they reach. Pick the ``most`` that draws
    # the fewest faces in all.
    n_upto = np.cumsum(np.bincount(span, minlength=n_slabs + 1))
    entries_upto = np.cumsum(np.bincount(span, weights=span, minlength=n_slabs + 1))
    most = int(np.argmin(entries_upto + n_slabs * (len(ids) - n_upto)))
    is_long = span > most
    short = np.flatnonzero(~is_long)
    owner = np.repeat(short, span[short])
    first_entry = np.cumsum(span[short]) - span[short]
    entry_slab = s0[owner] + np.arange(len(owner)) - np.repeat(first_entry, span[short])
    by_slab = np.argsort(entry_slab, kind="stable")
    owner, entry_slab = owner[by_slab], entry_slab[by_slab]
    n_long = int(is_long.sum())
    start = np.searchsorted(entry_slab, np.arange(n_slabs), side="left")
    count = np.searchsorted(entry_slab, np.arange(n_slabs), side="right") - start
    reach = np.zeros(n_slabs + 1, dtype=np.int64)
    np.add.at(reach, s0[is_long], 1)
    np.add.at(reach, s1[is_long] + 1, -1)
    long = np.cumsum(reach[:-1]) > 0
    rendered = np.flatnonzero(long | (count > 0))
    # Depths kept in each slab: exactly the slab, the outer ones open as Grid.slab_of clamps.
    keep = grid.lo[axis] + np.stack([rendered, rendered + 1], axis=1) * grid.slab
    keep[rendered == 0, 0] = -FLOAT32_MAX
    keep[rendered == n_slabs - 1, 1] = FLOAT32_MAX
    # Clip planes: the slab widened for vertex snapping, the outer ones out to the geometry.
    clip = keep + np.array([-CLIP_MARGIN, CLIP_MARGIN]) * grid.slab
    if len(ids):
        clip[:, 0] = np.maximum(clip[:, 0], w_min.min() - CLIP_MARGIN * grid.slab)
        clip[:, 1] = np.minimum(clip[:, 1], w_max.max() + CLIP_MARGIN * grid.slab)
    return _AxisPlan(
        order=np.concatenate([ids[is_long], ids[owner]]),
        n_long=n_long,
        slabs=rendered,
        long=long[rendered],
        start=start[rendered] + n_long,
        count=count[rendered],
        keep=keep,
        clip=clip,
    )


def _ndc_map(start: float, length: float) -> tuple[float, float]:
    """(scale, offset) taking ``start … start + length`` to -1 … 1 (computed in float64)."""
    scale = 2.0 / length
    return scale, -1.0 - start * scale


def _hits(axis: int, sign: int, parts: list[tuple[np.ndarray, ...]]) -> SlabHits:
    """One direction's hits from per-batch (slab, iu, iv, depth, face) arrays."""
    if parts:
        slab, iu, iv, depth, face = (np.concatenate(p) for p in zip(*parts, strict=True))
    else:
        slab = iu = iv = face = np.zeros(0, dtype=np.int64)
        depth = np.zeros(0, dtype=np.float64)
    return SlabHits(axis=axis, sign=sign, slab=slab, iu=iu, iv=iv, depth=depth, face=face)


class GLBackend:
    """FBO slab renderer on an EGL OpenGL context (a GPU driver, or Mesa llvmpipe on the CPU).

    Creating one makes the context; raises :class:`~lodconvert.errors.LodConvertError` (one
    line, with what to install) when that fails. Call :meth:`release` when done. ``compact``
    chooses how covered pixels come back: a compute shader lists them on the GL side (needs
    OpenGL 4.3), or whole images are read back and scanned. By default a GPU lists them (whole
    images would cross the bus) and a software renderer scans (there reading back is a copy,
    cheaper than the compute pass).
    """

    name = "gl"

    def __init__(self, compact: bool | None = None) -> None:
        self._ctx: moderngl.Context | None = create_context("GL backend unavailable")
        self.renderer: str = self._ctx.info["GL_RENDERER"]
        info = self._ctx.info
        self._max_size = int(min(info["GL_MAX_TEXTURE_SIZE"], info["GL_MAX_RENDERBUFFER_SIZE"]))
        try:
            self._prog = self._ctx.program(
                vertex_shader=VERTEX_SHADER,
                geometry_shader=GEOMETRY_SHADER,
                fragment_shader=FRAGMENT_SHADER,
            )
            if compact is None:
                software = any(name in self.renderer.lower() for name in SOFTWARE_RENDERERS)
                compact = self._ctx.version_code >= 430 and not software
            self._lister = self._ctx.compute_shader(LIST_SHADER) if compact else None
        except Exception:
            self._ctx.release()
            raise

    def release(self) -> None:
        """Free the GL context (idempotent); the backend cannot rasterise afterwards."""
        if self._ctx is not None:
            if self._lister is not None:
                self._lister.release()
            self._prog.release()
            self._ctx.release()
            self._ctx = None

    def rasterize(self, surface: Mesh, grid: Grid, memory_bytes: int = 0) -> list[SlabHits]:
        """Covered pixels of all 6 view directions (+x, -x, +y, -y, +z, -z). The GPU keeps one
        hit per (slab, pixel) as it draws, so host memory follows the hits whatever
        ``memory_bytes`` allows."""
        if self._ctx is None:
            raise LodConvertError("GL backend used after release()")
        plans = [
            _plan_axis(
                surface.derived(f"gl-axis-{a}", lambda a=a: _face_bounds(surface, a)), grid, a
            )
            for a in range(3)
        ]
        if not any(len(p.slabs) for p in plans):
            return [_hits(axis, sign, []) for axis in range(3) for sign in (1, -1)]
        # Geometry relative to the grid centre, so float32 keeps the precision of large
        # (georeferenced) coordinates; depths get the centre back in float64.
        origin = grid.lo + 0.5 * np.asarray(grid.cells, dtype=np.float64) * grid.pitch
        ctx = self._ctx
        with ctx:
            vbo = ctx.buffer((surface.vertices - origin).astype(np.float32))
            ibo = ctx.buffer(
                np.concatenate([surface.faces[p.order] for p in plans]).astype(np.int32)
            )
            vao = ctx.vertex_array(
                self._prog, [(vbo, "3f", "in_pos")], index_buffer=ibo, index_element_size=4
            )
            ctx.enable(ctx.DEPTH_TEST)
            try:
                hits: list[SlabHits] = []
                base = 0
                for axis, plan in enumerate(plans):
                    hits.extend(self._render_axis(ctx, vao, grid, axis, plan, base, origin))
                    base += len(plan.order)
            finally:
                vao.release()
                ibo.release()
                vbo.release()
        return hits

    def _render_axis(
        self,
        ctx: moderngl.Context,
        vao: moderngl.VertexArray,
        grid: Grid,
        axis: int,
        plan: _AxisPlan,
        base: int,
        origin: np.ndarray,
    ) -> list[SlabHits]:
        """Both directions along ``axis``; ``base`` is the axis's first entry in the IBO."""
        if len(plan.slabs) == 0:
            return [_hits(axis, 1, []), _hits(axis, -1, [])]
        rows, cols = grid.image_shape(axis)
        per_batch = max(
            1,
            min(len(plan.slabs), self._max_size // rows, BATCH_BYTES // (rows * cols * TILE_BYTES)),
        )
        size = (cols, rows * per_batch)
        images = _Images(ctx, size)
        u, v = grid.plane_axes(axis)
        prog = self._prog
        prog["axis"].value = axis
        prog["u_map"].value = _ndc_map(grid.lo[u] - origin[u], cols * grid.pitch)
        prog["v_map"].value = _ndc_map(grid.lo[v] - origin[v], rows * grid.pitch)
        prog["u_pixel"].value = (grid.lo[u] - origin[u], grid.pitch)
        first, v_pixel, z_map, keep, frag_depth = (
            prog[k] for k in ("first", "v_pixel", "z_map", "keep", "frag_depth")
        )
        out = []
        try:
            for sign, func, clear_depth in ((1, "<", 1.0), (-1, ">=", 0.0)):
                parts = []
                for b in range(0, len(plan.slabs), per_batch):
                    tiles = range(b, min(b + per_batch, len(plan.slabs)))
                    images.fbo.use()
                    images.fbo.clear(depth=clear_depth)
                    ctx.depth_func = func
                    for k, i in enumerate(tiles):
                        ctx.viewport = (0, k * rows, cols, rows)
                        v_pixel.value = (grid.lo[v] - origin[v], grid.pitch, k * rows)
                        clip_lo, clip_hi = plan.clip[i] - origin[axis]
                        z_map.value = _ndc_map(clip_lo, clip_hi - clip_lo)
                        frag_depth.value = (
                            1.0 / (clip_hi - clip_lo),
                            -clip_lo / (clip_hi - clip_lo),
                        )
                        keep.value = tuple(plan.keep[i] - origin[axis])
                        if plan.long[i]:
                            first.value = 0
                            vao.render(vertices=3 * plan.n_long, first=3 * base)
                        if plan.count[i]:
                            first.value = int(plan.start[i])
                            vao.render(
                                vertices=3 * int(plan.count[i]),
                                first=3 * (base + int(plan.start[i])),
                            )
                    pixel, face, depth = (
                        images.scan(len(tiles) * rows)
                        if self._lister is None
                        else images.gather(self._lister, len(tiles) * rows)
                    )
                    r, c = np.divmod(pixel, cols)
                    parts.append(
                        (
                            plan.slabs[b + r // rows],
                            c,
                            r % rows,
                            depth.astype(np.float64) + origin[axis],
                            plan.order[face - 1],
                        )
                    )
                out.append(_hits(axis, sign, parts))
        finally:
            images.release()
        return out


class _Images:
    """The framebuffer of one batch of slab tiles: depth (R32F) and face (R32I) textures and a
    depth buffer, and a buffer for the list of covered pixels."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        self.ctx = ctx
        self.size = size
        self.depth = ctx.texture(size, 1, dtype="f4")
        self.face = ctx.texture(size, 1, dtype="i4")
        for texture in (self.depth, self.face):
            texture.filter = (ctx.NEAREST, ctx.NEAREST)
        self.zbuffer = ctx.depth_renderbuffer(size)
        self.fbo = ctx.framebuffer([self.depth, self.face], self.zbuffer)
        self.count = ctx.buffer(reserve=4)
        # Room for a covered pixel in 1 of 8 (grown when a batch has more).
        self.capacity = max(1024, size[0] * size[1] // 8)
        self.hits = ctx.buffer(reserve=12 * self.capacity)

    def scan(self, rows: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(pixel, face, depth) of the covered pixels of the first ``rows`` rows, by reading
        the whole images back; ``pixel`` is ``row * cols + col``."""
        viewport = (0, 0, self.size[0], rows)
        face = self.fbo.read(viewport=viewport, components=1, attachment=1, dtype="i4")
        face = np.frombuffer(face, dtype=np.int32)
        pixel = np.flatnonzero(face)
        depth = self.fbo.read(viewport=viewport, components=1, attachment=0, dtype="f4")
        return pixel, face[pixel], np.frombuffer(depth, dtype=np.float32)[pixel]

    def gather(
        self, lister: moderngl.ComputeShader, rows: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`scan`, but a compute shader lists the covered pixels on the GL side, so
        that only they come back."""
        cols = self.size[0]
        self.face.use(0)
        self.depth.use(1)
        self.count.bind_to_storage_buffer(0)
        lister["size"].value = (cols, rows)
        while True:
            self.count.write(b"\0\0\0\0")
            self.hits.bind_to_storage_buffer(1)
            lister["capacity"].value = self.capacity
            lister.run(-(-cols // LIST_GROUP), -(-rows // LIST_GROUP))
            self.ctx.memory_barrier(self.ctx.BUFFER_UPDATE_BARRIER_BIT)
            n = int(np.frombuffer(self.count.read(), dtype=np.uint32)[0])
            if n <= self.capacity:
                break
            self.hits.release()
            self.capacity = n
            self.hits = self.ctx.buffer(reserve=12 * n)
        listed = np.zeros((0, 3), dtype=np.int32)
        if n:
            listed = np.frombuffer(self.hits.read(size=12 * n), dtype=np.int32).reshape(n, 3)
        listed = listed[np.argsort(listed[:, 0])]
        return listed[:, 0].astype(np.int64), listed[:, 1], listed[:, 2].view(np.float32)

    def release(self) -> None:
        """Free the GL objects."""
        for obj in (self.fbo, self.zbuffer, self.face, self.depth, self.count, self.hits):
            obj.release()
