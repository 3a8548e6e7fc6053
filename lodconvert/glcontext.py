"""Headless OpenGL contexts (moderngl through EGL) with one-line, actionable errors.

Contexts are made on demand, never at import: on Mesa llvmpipe a process forked after its
parent made a context deadlocks at its first GL call, so workers that use GL must be started
with the ``spawn`` method and make their own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .errors import LodConvertError

if TYPE_CHECKING:
    import moderngl

APT_INSTALL = "apt-get install -y --no-install-recommends libegl1 libgl1 libgl1-mesa-dri"
PIP_INSTALL = "pip install moderngl"
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast")
"""Names in ``GL_RENDERER`` of renderers that run on the CPU."""


def create_context(purpose: str, require: int = 330) -> moderngl.Context:
    """A standalone EGL context of at least OpenGL ``require`` (330 = 3.3 core).

    Raises :class:`LodConvertError` with one line naming ``purpose`` (e.g. "GL backend
    unavailable") and the packages to install when moderngl or EGL is missing.
    """
    try:
        import moderngl
    except ImportError as exc:
        raise LodConvertError(
            f"{purpose}: moderngl is not installed ({exc}); run: {PIP_INSTALL}"
        ) from exc
    try:
        return moderngl.create_standalone_context(backend="egl", require=require)
    except Exception as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        version = f"{require // 100}.{require // 10 % 10}"
        raise LodConvertError(
            f"{purpose}: no EGL OpenGL {version} context ({reason}); "
            f"install Mesa EGL with: {APT_INSTALL}"
        ) from exc
