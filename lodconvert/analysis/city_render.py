"""A city drawn frame by frame: :class:`CityRenderer` uploads every draw part once and times
each frame's draw calls; :func:`walk` runs cameras through several modes, interleaved frame by
frame, and gathers per mode the counts and frame times. See ``docs/render-bench.md``
(drawing and timing).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .bench import GridRenderer
from .city_cameras import Camera
from .city_draw import CityDraw
from .city_select import Mode, Selection, select

if TYPE_CHECKING:
    import moderngl


class CityRenderer(GridRenderer):
    """Draws a :class:`CityDraw`'s selected parts, one draw call each, on the 1920×1080
    framebuffer of a :class:`~.bench.GridRenderer` (its program, unlit vertex colours, depth
    test, no face culling). Raises :class:`~lodconvert.errors.LodConvertError` when no EGL
    OpenGL 3.3 context can be made."""

    def __init__(self) -> None:
        super().__init__()
        self.city: CityDraw | None = None
        self._objects: list[Any] = []
        self._triangles: moderngl.VertexArray | None = None
        self._points: moderngl.VertexArray | None = None

    def load(self, city: CityDraw) -> None:
        """Upload ``city``'s geometry (freeing the previous city's)."""
        self.unload()
        g = city.geometry
        offset = self._buffer(np.zeros(3, dtype=np.float32))
        if len(g.triangle_indices):
            self._triangles = self._vertex_array(
                g.triangle_positions, g.triangle_colors, offset, g.triangle_indices
            )
        if len(g.point_positions):
            self._points = self._vertex_array(g.point_positions, g.point_colors, offset)
        self.city = city

    def unload(self) -> None:
        """Free the loaded city's buffers."""
        for gl_object in reversed(self._objects):
            gl_object.release()
        self._objects, self._triangles, self._points, self.city = [], None, None, None

    def _buffer(self, array: np.ndarray) -> moderngl.Buffer:
        buffer = self.ctx.buffer(np.ascontiguousarray(array).tobytes())
        self._objects.append(buffer)
        return buffer

    def _vertex_array(
        self,
        positions: np.ndarray,
        colors: np.ndarray,
        offset: moderngl.Buffer,
        indices: np.ndarray | None = None,
    ) -> moderngl.VertexArray:
        content = [
            (self._buffer(positions), "3f", "in_pos"),
            (self._buffer(colors), "4f1", "in_color"),
            (offset, "3f/i", "in_offset"),
        ]
        index = self._buffer(indices) if indices is not None else None
        vao = self.ctx.vertex_array(self.program, content, index_buffer=index, index_element_size=4)
        self._objects.append(vao)
        return vao

    def draw(self, selection: Selection, camera: Camera) -> float:
        """Clear and draw ``selection`` as ``camera`` sees it; the frame's seconds."""
        city = self.city
        if city is None:
            raise RuntimeError("no city loaded")
        g = city.geometry
        view_proj = camera.view_proj(city.far_plane(camera.eye))
        self.program["view_proj"].write(view_proj.T.astype(np.float32).tobytes())
        self.program["eye"].value = tuple(float(v) for v in camera.eye)
        self.program["max_point_size"].value = self.max_point_size
        parts = np.sort(selection.parts)
        points = g.points[parts]
        triangles, clouds = parts[~points], parts[points]
        self.ctx.finish()
        start = time.perf_counter()
        self.fbo.use()
        self.fbo.clear(0.6, 0.7, 0.8, 1.0)
        if self._triangles is not None and len(triangles):
            self.program["point_size"].value = 1.0
            self.program["design_distance"].value = 0.0
            render = self._triangles.render
            firsts, counts = g.first[triangles].tolist(), g.count[triangles].tolist()
            for first, count in zip(firsts, counts, strict=True):
                render(self.ctx.TRIANGLES, vertices=count, first=first, instances=1)
        if self._points is not None:
            for part in clouds.tolist():
                self.program["point_size"].value = float(g.point_size[part]) * camera.view_scale
                self.program["design_distance"].value = float(g.design_distance[part])
                self._points.render(
                    self.ctx.POINTS, vertices=int(g.count[part]), first=int(g.first[part]),
                    instances=1,
                )  # fmt: skip
        self.ctx.finish()
        return time.perf_counter() - start

    def release(self) -> None:
        """Free the city's buffers and the context."""
        self.unload()
        super().release()


@dataclass
class PathStats:
    """One mode along one path: per frame the vertices + points and draw calls submitted, the
    frame times (with a renderer), and every cell shown as its far level at least once."""

    vertices: list[int] = field(default_factory=list)
    calls: list[int] = field(default_factory=list)
    frame_seconds: list[float] = field(default_factory=list)
    far_cells: set[int] = field(default_factory=set)

    @property
    def median_ms(self) -> float | None:
        """Median frame time in ms (None when not timed)."""
        return 1e3 * statistics.median(self.frame_seconds) if self.frame_seconds else None

    @property
    def low_ms(self) -> float | None:
        """The "5 % low" frame time in ms: the 95th percentile, which 5 % of frames exceed
        (the 5th percentile of the frame rate); None when not timed."""
        if not self.frame_seconds:
            return None
        return 1e3 * float(np.percentile(self.frame_seconds, 95))

    def record(self) -> dict[str, Any]:
        """Medians and maxima of the counts, the frame-time figures (JSON-able)."""
        return {
            "frames": len(self.calls),
            "vertices_median": statistics.median(self.vertices),
            "vertices_max": max(self.vertices),
            "calls_median": statistics.median(self.calls),
            "calls_max": max(self.calls),
            "median_ms": self.median_ms,
            "low_ms": self.low_ms,
        }


def walk(
    city: CityDraw,
    cameras: Sequence[Camera],
    modes: Sequence[Mode],
    scale: float = 1.0,
    renderer: CityRenderer | None = None,
) -> dict[str, PathStats]:
    """Every camera of a path in every mode (cutoffs times ``scale`` where the mode asks for
    the LOD scale), modes interleaved frame by frame with their order turning; with a
    ``renderer`` (``city`` loaded in it) each frame is drawn and timed after one untimed frame
    per mode. Returns the statistics per mode name."""
    stats = {mode.name: PathStats() for mode in modes}
    if renderer is not None and cameras:
        for mode in modes:
            renderer.draw(select(city, cameras[0], mode, _scale(mode, scale)), cameras[0])
    for k, camera in enumerate(cameras):
        turn = k % len(modes)
        for mode in [*modes[turn:], *modes[:turn]]:
            selection = select(city, camera, mode, _scale(mode, scale))
            entry = stats[mode.name]
            entry.vertices.append(selection.vertices(city))
            entry.calls.append(selection.calls)
            entry.far_cells.update(selection.far_cells.tolist())
            if renderer is not None:
                entry.frame_seconds.append(renderer.draw(selection, camera))
    return stats


def _scale(mode: Mode, scale: float) -> float:
    return scale if mode.los_scale else 1.0
