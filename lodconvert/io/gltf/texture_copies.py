"""Copies of a glTF texture's image in a lighter format, which a viewer that reads them
prefers, the PNG or JPEG staying for those that do not (``--texture-format``,
docs/textures.md): WebP (``EXT_texture_webp``) or KTX2 with Basis Universal
(``KHR_texture_basisu``, :mod:`..ktx2`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...errors import UsageError
from ..images import webp_encoded

WEBP = "EXT_texture_webp"
BASISU = "KHR_texture_basisu"
COPIES = {"webp": (WEBP, "image/webp"), "ktx2": (BASISU, "image/ktx2")}
"""By ``--texture-format`` name: the extension that names a texture's copy, and its MIME type."""
TEXTURE_FORMATS = ("default", *COPIES)
"""The ``--texture-format`` choices: PNG or JPEG alone (:func:`~..images.encoded`), or with a
copy of :data:`COPIES`."""


class TextureCopy(NamedTuple):
    """A texture's image in another format: its bytes, MIME type and the extension naming it."""

    data: bytes
    mime: str
    extension: str


def check_texture_format(name: str) -> str:
    """The copy textures get (a key of :data:`COPIES`, "" for none) by ``--texture-format``
    ``name``; :class:`UsageError` for a name not in :data:`TEXTURE_FORMATS`, or ``ktx2``
    without its encoder (:func:`~..ktx2.encoder`)."""
    if name not in TEXTURE_FORMATS:
        choices = ", ".join(TEXTURE_FORMATS)
        raise UsageError(f"--texture-format must be one of {choices}, got {name!r}")
    if name == "ktx2":
        from ..ktx2 import encoder

        encoder()
    return name if name in COPIES else ""


def texture_copy(rgba: np.ndarray, photographic: bool, kind: str) -> TextureCopy | None:
    """The ``kind`` (:func:`check_texture_format`) copy of an RGBA uint8 image (top row
    first), ``photographic`` or not; None for no copy."""
    if not kind:
        return None
    extension, mime = COPIES[kind]
    if kind == "ktx2":
        from ..ktx2 import ktx2_encoded

        return TextureCopy(ktx2_encoded(rgba), mime, extension)
    return TextureCopy(webp_encoded(rgba, photographic), mime, extension)
