"""GL backend: the paper's FBO slab rendering, with moderngl through headless EGL.

For each axis and each slab of the level grid the mesh is drawn with an orthographic camera
looking along the axis, near/far planes clipping the slab and no face culling, into an image of
``grid.image_shape(axis)`` pixels (pixel ``(iu, iv)`` is column ``iu``, row ``iv`` from the
bottom, so the image covers ``cells[u]·pitch × cells[v]·pitch`` from ``lo``). The depth test
keeps the nearest surface per pixel: ``<`` for the view from the low side (sign +1), ``>=``
after clearing the depth to 0 for the view from the high side (sign -1). Two colour attachments
receive the hit depth (R32F: the interpolated coordinate along the axis, not the depth buffer)
and the face (R32I: ``gl_PrimitiveID`` + 1, 0 = empty). The first slab's near plane and the last
slab's far plane are opened up, as :meth:`Grid.slab_of` clamps depths into range.

Work per slab stays small: each axis draws its faces sorted by the first slab they reach, so a
slab draws only a window of faces (plus the few faces spanning many slabs); faces that cover no
pixel centre and slabs that no face reaches are skipped. Slabs are rendered as tiles of one tall
framebuffer per axis and read back a batch of tiles at a time.

Contexts are made when a :class:`GLBackend` is created, never at import: on Mesa llvmpipe a
process forked after its parent made a context (even a released one) deadlocks in GL calls.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import LodConvertError
from .grid import Grid, SlabHits
from .numpy import EPS

if TYPE_CHECKING:
    import moderngl

APT_INSTALL = "apt-get install -y --no-install-recommends libegl1 libgl1 libgl1-mesa-dri"
PIP_INSTALL = "pip install moderngl"
# Framebuffer bytes per pixel of a slab tile: depth (R32F), face (R32I), depth buffer (24/32 bit).
TILE_BYTES = 12
# Framebuffer memory of one batch of slab tiles (rendered, then read back at once).
BATCH_BYTES = 1 << 27
# A face is drawn in the slabs it reaches within this fraction of a slab (float32 rounding).
SLAB_TOL = 1e-4

VERTEX_SHADER = """
#version 330
uniform int axis;
uniform vec2 u_map;
uniform vec2 v_map;
uniform vec2 z_map;
in vec3 in_pos;
out float v_depth;
void main() {
    v_depth = in_pos[axis];
    gl_Position = vec4(
        in_pos[(axis + 1) % 3] * u_map.x + u_map.y,
        in_pos[(axis + 2) % 3] * v_map.x + v_map.y,
        v_depth * z_map.x + z_map.y,
        1.0);
}
"""

FRAGMENT_SHADER = """
#version 330
uniform int first;
in float v_depth;
layout(location = 0) out float out_depth;
layout(location = 1) out int out_face;
void main() {
    out_depth = v_depth;
    out_face = first + gl_PrimitiveID + 1;
}
"""


def _create_context() -> moderngl.Context:
    """A standalone EGL context (OpenGL 3.3 core or later), or a one-line LodConvertError."""
    try:
        import moderngl
    except ImportError as exc:
        raise LodConvertError(
            f"GL backend unavailable: moderngl is not installed ({exc}); run: {PIP_INSTALL}"
        ) from exc
    try:
        return moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise LodConvertError(
            f"GL backend unavailable: no EGL OpenGL 3.3 context ({reason}); "
            f"install Mesa EGL with: {APT_INSTALL}"
        ) from exc


@functools.cache
def gl_unavailable_reason() -> str | None:
    """None when an EGL GL context can be made in this process, else the one-line reason.

    Probes once per process with a throwaway context; a process that forks workers should not
    call this before forking (see the module docstring).
    """
    try:
        ctx = _create_context()
    except LodConvertError as exc:
        return str(exc)
    ctx.release()
    return None


@dataclass
class _AxisPlan:
    """What to draw along one axis. ``order`` holds face indices in draw order: first the
    ``n_long`` faces that span many slabs, then the others sorted by their first slab. Per
    rendered slab ``slabs[i]``: draw the long faces when ``long[i]``, and ``count[i]`` sorted
    faces from entry ``start[i]`` of ``order``, clipped to depths ``near[i] … far[i]``."""

    order: np.ndarray
    n_long: int
    slabs: np.ndarray
    long: np.ndarray
    start: np.ndarray
    count: np.ndarray
    near: np.ndarray
    far: np.ndarray


def _covers_centre(p: np.ndarray, n: int) -> np.ndarray:
    """Per face (pixel coordinates ``p`` (m, 3), centres at integers), whether the bounding
    range of its corners holds a pixel centre in ``0 … n-1`` (with the numpy backend's EPS)."""
    first = np.maximum(np.ceil(p.min(axis=1) - EPS), 0)
    last = np.minimum(np.floor(p.max(axis=1) + EPS), n - 1)
    return last >= first


def _plan_axis(tri: np.ndarray, grid: Grid, axis: int) -> _AxisPlan:
    """Sort the faces for slab-by-slab drawing along ``axis`` (see :class:`_AxisPlan`)."""
    u, v = grid.plane_axes(axis)
    rows, cols = grid.image_shape(axis)
    n_slabs = grid.slabs[axis]
    keep = _covers_centre((tri[:, :, u] - grid.lo[u]) / grid.pitch - 0.5, cols)
    keep &= _covers_centre((tri[:, :, v] - grid.lo[v]) / grid.pitch - 0.5, rows)
    ids = np.flatnonzero(keep)
    w = tri[ids][:, :, axis]
    w_min, w_max = w.min(axis=1), w.max(axis=1)
    tol = SLAB_TOL * grid.slab
    s0 = grid.slab_of(axis, w_min - tol)
    s1 = grid.slab_of(axis, w_max + tol)
    span = s1 - s0 + 1
    # Window W: faces spanning more than W slabs are drawn for every slab, the others in the W
    # slabs from their first; pick the W with the fewest faces drawn in all.
    n_within = np.cumsum(np.bincount(span, minlength=n_slabs + 1))
    windows = np.arange(n_slabs + 1)
    cost = n_slabs * (len(ids) - n_within) + windows * n_within
    window = int(np.argmin(cost[1:])) + 1
    is_long = span > window
    short = np.flatnonzero(~is_long)
    short = short[np.argsort(s0[short], kind="stable")]
    short_s0 = s0[short]
    n_long = int(is_long.sum())
    slab_ids = np.arange(n_slabs)
    start = np.searchsorted(short_s0, slab_ids - window + 1, side="left")
    count = np.searchsorted(short_s0, slab_ids, side="right") - start
    reach = np.zeros(n_slabs + 1, dtype=np.int64)
    np.add.at(reach, s0[is_long], 1)
    np.add.at(reach, s1[is_long] + 1, -1)
    long = np.cumsum(reach[:-1]) > 0
    rendered = np.flatnonzero(long | (count > 0))
    lo_a = grid.lo[axis]
    near = lo_a + rendered * grid.slab
    far = near + grid.slab
    if len(ids):
        # Open the outer planes: depths beyond the first/last slab are clamped into them.
        near[rendered == 0] = min(lo_a, w_min.min()) - grid.slab
        far[rendered == n_slabs - 1] = max(lo_a + n_slabs * grid.slab, w_max.max()) + grid.slab
    return _AxisPlan(
        order=np.concatenate([ids[is_long], ids[short]]),
        n_long=n_long,
        slabs=rendered,
        long=long[rendered],
        start=start[rendered] + n_long,
        count=count[rendered],
        near=near,
        far=far,
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
    line, with what to install) when that fails. Call :meth:`release` when done.
    """

    name = "gl"

    def __init__(self) -> None:
        self._ctx: moderngl.Context | None = _create_context()
        self.renderer: str = self._ctx.info["GL_RENDERER"]
        self._max_size = int(self._ctx.info["GL_MAX_RENDERBUFFER_SIZE"])
        self._prog = self._ctx.program(
            vertex_shader=VERTEX_SHADER, fragment_shader=FRAGMENT_SHADER
        )

    def release(self) -> None:
        """Free the GL context (idempotent); the backend cannot rasterise afterwards."""
        if self._ctx is not None:
            self._prog.release()
            self._ctx.release()
            self._ctx = None

    def rasterize(self, vertices: np.ndarray, faces: np.ndarray, grid: Grid) -> list[SlabHits]:
        """Covered pixels of all 6 view directions (+x, -x, +y, -y, +z, -z)."""
        if self._ctx is None:
            raise LodConvertError("GL backend used after release()")
        tri = vertices[faces]
        plans = [_plan_axis(tri, grid, axis) for axis in range(3)]
        if not any(len(p.slabs) for p in plans):
            return [_hits(axis, sign, []) for axis in range(3) for sign in (1, -1)]
        # Geometry relative to the grid centre, so float32 keeps the precision of large
        # (georeferenced) coordinates; depths get the centre back in float64.
        origin = grid.lo + 0.5 * np.asarray(grid.cells, dtype=np.float64) * grid.pitch
        ctx = self._ctx
        with ctx:
            vbo = ctx.buffer((vertices - origin).astype(np.float32))
            ibo = ctx.buffer(np.concatenate([faces[p.order] for p in plans]).astype(np.int32))
            vao = ctx.vertex_array(
                self._prog, [(vbo, "3f", "in_pos")], index_buffer=ibo, index_element_size=4
            )
            ctx.enable(ctx.DEPTH_TEST)
            try:
                hits: list[SlabHits] = []
                base = 0
                for axis, plan in enumerate(plans):
                    hits.extend(self._render_axis(vao, grid, axis, plan, base, origin))
                    base += len(plan.order)
            finally:
                vao.release()
                ibo.release()
                vbo.release()
        return hits

    def _render_axis(
        self,
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
        assert self._ctx is not None
        ctx = self._ctx
        rows, cols = grid.image_shape(axis)
        per_batch = max(
            1,
            min(len(plan.slabs), self._max_size // rows, BATCH_BYTES // (rows * cols * TILE_BYTES)),
        )
        size = (cols, rows * per_batch)
        depth_rb = ctx.renderbuffer(size, 1, dtype="f4")
        face_rb = ctx.renderbuffer(size, 1, dtype="i4")
        zbuf = ctx.depth_renderbuffer(size)
        fbo = ctx.framebuffer([depth_rb, face_rb], zbuf)
        u, v = grid.plane_axes(axis)
        self._prog["axis"].value = axis
        self._prog["u_map"].value = _ndc_map(grid.lo[u] - origin[u], cols * grid.pitch)
        self._prog["v_map"].value = _ndc_map(grid.lo[v] - origin[v], rows * grid.pitch)
        first = self._prog["first"]
        z_map = self._prog["z_map"]
        out = []
        try:
            fbo.use()
            for sign, func, clear_depth in ((1, "<", 1.0), (-1, ">=", 0.0)):
                ctx.depth_func = func
                parts = []
                for b in range(0, len(plan.slabs), per_batch):
                    tiles = range(b, min(b + per_batch, len(plan.slabs)))
                    fbo.clear(depth=clear_depth)
                    for k, i in enumerate(tiles):
                        ctx.viewport = (0, k * rows, cols, rows)
                        z_map.value = _ndc_map(
                            plan.near[i] - origin[axis], plan.far[i] - plan.near[i]
                        )
                        if plan.long[i]:
                            first.value = 0
                            vao.render(vertices=3 * plan.n_long, first=3 * base)
                        if plan.count[i]:
                            first.value = int(plan.start[i])
                            vao.render(
                                vertices=3 * int(plan.count[i]),
                                first=3 * (base + int(plan.start[i])),
                            )
                    part = self._read_batch(fbo, plan, b, len(tiles), rows, cols, origin[axis])
                    if part is not None:
                        parts.append(part)
                out.append(_hits(axis, sign, parts))
        finally:
            fbo.release()
            zbuf.release()
            face_rb.release()
            depth_rb.release()
        return out

    @staticmethod
    def _read_batch(
        fbo: moderngl.Framebuffer,
        plan: _AxisPlan,
        first_tile: int,
        n_tiles: int,
        rows: int,
        cols: int,
        offset: float,
    ) -> tuple[np.ndarray, ...] | None:
        """(slab, iu, iv, depth, face) of the covered pixels of a batch of tiles, or None."""
        viewport = (0, 0, cols, rows * n_tiles)
        face = fbo.read(viewport=viewport, components=1, attachment=1, dtype="i4")
        face = np.frombuffer(face, dtype=np.int32).reshape(rows * n_tiles, cols)
        r, c = np.nonzero(face)
        if len(r) == 0:
            return None
        depth = fbo.read(viewport=viewport, components=1, attachment=0, dtype="f4")
        depth = np.frombuffer(depth, dtype=np.float32).reshape(rows * n_tiles, cols)
        return (
            plan.slabs[first_tile + r // rows],
            c.astype(np.int64),
            (r % rows).astype(np.int64),
            depth[r, c].astype(np.float64) + offset,
            plan.order[face[r, c] - 1].astype(np.int64),
        )
