"""PCD baking: one interface (:class:`~.pcd.Backend`), two backends giving the same points.

``numpy`` rasterises axis rays on the CPU and needs no system packages; ``gl`` renders FBO slabs
with moderngl through EGL, as in the paper. ``auto`` picks ``gl`` only when the GL renderer is a
real GPU: on software renderers (llvmpipe, softpipe, swrast) numpy is an order of magnitude
faster for the same cells.
"""

from __future__ import annotations

from .grid import Grid, SlabHits
from .numpy import NumpyBackend
from .pcd import Backend, bake_points

SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast")
BACKENDS = ("auto", "numpy", "gl")


def get_backend(name: str = "auto") -> Backend:
    """The backend called ``name``; ``auto`` tries GL and keeps it only on a hardware renderer.

    Raises :class:`~lodconvert.errors.LodConvertError` when ``gl`` is asked for and no GL
    context can be made (with the packages to install).
    """
    if name == "numpy":
        return NumpyBackend()
    if name not in ("gl", "auto"):
        raise ValueError(f"unknown backend {name!r}")
    from .gl import GLBackend, gl_unavailable_reason

    if name == "gl":
        return GLBackend()
    if gl_unavailable_reason() is None:
        backend = GLBackend()
        if not any(s in backend.renderer.lower() for s in SOFTWARE_RENDERERS):
            return backend
        backend.release()
    return NumpyBackend()


__all__ = ["BACKENDS", "Backend", "Grid", "NumpyBackend", "SlabHits", "bake_points", "get_backend"]
