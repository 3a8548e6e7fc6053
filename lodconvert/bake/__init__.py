"""PCD baking: one interface (:class:`~.pcd.Backend`), two backends giving the same points.

``numpy`` rasterises axis rays on the CPU and needs no system packages; ``gl`` renders FBO slabs
with moderngl through EGL, as in the paper. ``auto`` picks ``gl`` only when the GL renderer is a
real GPU: on software renderers (llvmpipe, softpipe, swrast) numpy is an order of magnitude
faster for the same cells. Without a GPU device node no renderer but a software one can exist,
so ``auto`` then makes no GL context at all (Mesa's llvmpipe takes about 0.7 s to make one).
"""

from __future__ import annotations

import glob

from ..errors import LodConvertError
from ..glcontext import SOFTWARE_RENDERERS
from .grid import Grid, SlabHits
from .numpy import NumpyBackend
from .pcd import Backend, bake_points

BACKENDS = ("auto", "numpy", "gl")
GPU_DEVICES = ("/dev/dri/renderD*", "/dev/nvidia[0-9]*", "/dev/dxg")
"""Device nodes through which EGL reaches a GPU: DRM render nodes (Mesa's hardware drivers),
NVIDIA's driver and WSL's GPU paravirtualisation."""


def gpu_device_present() -> bool:
    """Whether this machine shows a device node through which EGL could reach a GPU."""
    return any(glob.glob(pattern) for pattern in GPU_DEVICES)


def get_backend(name: str = "auto") -> Backend:
    """The backend called ``name``; ``auto`` tries GL where a GPU device node exists and keeps it
    only on a hardware renderer.

    Raises :class:`~lodconvert.errors.LodConvertError` when ``gl`` is asked for and no GL
    context can be made (with the packages to install).
    """
    if name == "numpy":
        return NumpyBackend()
    if name not in ("gl", "auto"):
        raise ValueError(f"unknown backend {name!r}")
    from .gl import GLBackend

    if name == "gl":
        return GLBackend()
    if not gpu_device_present():
        return NumpyBackend()
    try:
        backend = GLBackend()
    except LodConvertError:
        return NumpyBackend()
    if not any(s in backend.renderer.lower() for s in SOFTWARE_RENDERERS):
        return backend
    backend.release()
    return NumpyBackend()


__all__ = [
    "BACKENDS",
    "Backend",
    "Grid",
    "NumpyBackend",
    "SlabHits",
    "bake_points",
    "get_backend",
    "gpu_device_present",
]
