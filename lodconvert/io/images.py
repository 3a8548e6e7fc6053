"""The texture images a city model's appearances name (:class:`Images`), and images encoded
for writing (:func:`encoded`). Each image read is resolved
against the input's folder (or, in a ``.zip``, the folder of the city model inside it), never
outside it, through a link or over a network; held to the run's ``image_bytes`` and
``image_pixels`` limits (the pixels from the image's header, before it is decoded); decoded
once; an image that cannot be used is warned of once, naming the first object that uses it.
What is read and why: ``docs/textures.md``."""

from __future__ import annotations

import io
import os
import re
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING
from urllib.parse import unquote

import numpy as np

from .. import nofollow
from ..errors import InputError
from ..limits import Limits
from .archive import member_name

if TYPE_CHECKING:
    import PIL.Image

_SCHEME = re.compile(r"[A-Za-z][A-Za-z0-9+.-]+:")
"""A URI's scheme (``http:``, ``file:``, ``data:``; one letter is a Windows drive)."""


class Images:
    """The images of one input file ``source`` (a city model, or a ``.zip`` holding one),
    by the URI its appearances give; ``warn`` hears each one that cannot be used."""

    def __init__(self, source: Path, limits: Limits, warn: Callable[[str], None]) -> None:
        self.source, self.limits, self.warn = source, limits, warn
        self._found: dict[str, np.ndarray | None] = {}
        self._photographs: set[str] = set()
        self.used: list[str] = []
        """The URIs of the images decoded, in the order they were first asked for."""
        self.unusable: list[str] = []
        """The URIs of the images that could not be used (each warned of)."""
        self.theme: str | None = None
        self.themes: list[str] = []
        """The appearance theme read and every theme the input holds (its reader's)."""

    @property
    def met(self) -> bool:
        """Whether the input had anything of appearances to say (a theme, an image)."""
        return bool(self.themes or self.used or self.unusable)

    def record(self) -> dict[str, object]:
        """What ``--report`` says of the input's appearances."""
        return {
            "theme": self.theme,
            "themes": list(self.themes),
            "images": list(self.used),
            "unusable_images": list(self.unusable),
        }

    def photographic(self, uri: str) -> bool:
        """Whether the image ``uri`` (read by :meth:`image`) was given as a photograph
        (JPEG)."""
        return uri in self._photographs

    def image(self, uri: str, where: str) -> np.ndarray | None:
        """The image ``uri`` names, (h, w, 4) uint8 RGBA, top row first; ``None`` (warned
        of once, naming ``where``: the object that asks first) where it cannot be used."""
        if uri not in self._found:
            found, problem, photograph = self._read(uri)
            if photograph:
                self._photographs.add(uri)
            if problem is not None:
                self.unusable.append(uri)
                self.warn(
                    f"{where}: texture image {uri!r} {problem}; its surfaces take their "
                    "material or class colour"
                )
            else:
                self.used.append(uri)
            self._found[uri] = found
        return self._found[uri]

    def _read(self, uri: str) -> tuple[np.ndarray | None, str | None, bool]:
        """The decoded image of ``uri`` and whether it is a JPEG, or why it cannot be used."""
        text = uri.strip().replace("\\", "/")
        if _SCHEME.match(text):
            return None, "is not a file beside the input (a URI is not read over a network)", False
        relative = PurePosixPath(unquote(text))
        if relative.is_absolute() or ".." in relative.parts or not relative.parts:
            return None, "lies outside the input's folder (not read)", False
        data, problem = self._bytes(relative)
        if data is None:
            return None, problem, False
        return _decoded(data, self.limits)

    def _bytes(self, relative: PurePosixPath) -> tuple[bytes | None, str | None]:
        """The bytes of the file ``relative`` beside the input, or why they cannot be read."""
        limit = self.limits.image_bytes
        too_large = (
            f"is larger than the limit of {limit:,} bytes (raise it with --limit image_bytes=N)"
        )
        if self.source.name.lower().endswith(".zip"):
            return _zip_bytes(self.source, relative, limit, too_large)
        try:
            folder = nofollow.open_folder(self.source.parent)
        except OSError:
            return None, "cannot be read (the input's folder cannot be opened)"
        try:
            data = nofollow.read(folder, str(relative), limit + 1)
        finally:
            os.close(folder)
        if data is None:
            return None, "is not found in the input's folder (or is a link, which is not followed)"
        if len(data) > limit:
            return None, too_large
        return data, None


def _zip_bytes(
    archive_path: Path, relative: PurePosixPath, limit: int, too_large: str
) -> tuple[bytes | None, str | None]:
    """The bytes of ``relative`` beside the city model inside the zip ``archive_path``."""
    try:
        folder = PurePosixPath(member_name(archive_path)).parent
        with zipfile.ZipFile(archive_path) as archive:
            name = str(folder / relative) if str(folder) != "." else str(relative)
            try:
                member = archive.getinfo(name)
            except KeyError:
                return None, "is not found in the zip beside the city model"
            if member.file_size > limit:
                return None, too_large
            if member.flag_bits & 0x1:
                return None, "is encrypted in the zip (not read)"
            with archive.open(member) as stream:
                data = stream.read(limit + 1)
    except (OSError, zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError) as exc:
        return None, f"cannot be read from the zip ({exc})"
    except InputError as exc:
        return None, f"cannot be read from the zip ({exc})"
    if len(data) > limit:
        return None, too_large
    return data, None


def _decoded(data: bytes, limits: Limits) -> tuple[np.ndarray | None, str | None, bool]:
    """The RGBA pixels of the image file ``data`` and whether it is a JPEG, or why it cannot
    be decoded: its size is checked against ``limits.image_pixels`` from its header, before
    its pixels are."""
    from PIL import Image, UnidentifiedImageError

    kept, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None  # checked here, from the header
    try:
        with Image.open(io.BytesIO(data)) as image:
            width, height = image.size
            if width * height > limits.image_pixels:
                return (
                    None,
                    (
                        f"has {width:,} × {height:,} pixels, over the limit of "
                        f"{limits.image_pixels:,} (raise it with --limit image_pixels=N)"
                    ),
                    False,
                )
            photograph = image.format in ("JPEG", "MPO")
            rgba = np.asarray(image.convert("RGBA"), dtype=np.uint8)
    except UnidentifiedImageError:
        return None, "is not an image lodconvert can decode (PNG, JPEG, WebP…)", False
    except (OSError, SyntaxError, ValueError, EOFError) as exc:
        return None, f"cannot be decoded ({str(exc) or type(exc).__name__})", False
    finally:
        Image.MAX_IMAGE_PIXELS = kept
    return np.ascontiguousarray(rgba), None, photograph


JPEG_QUALITY = 90
"""Quality of a photograph written as JPEG."""


def webp_encoded(rgba: np.ndarray, photographic: bool) -> bytes:
    """Deterministic WebP bytes of an RGBA uint8 image (top row first): lossy (quality
    :data:`JPEG_QUALITY`) for a ``photographic`` one whose texels are all opaque, else
    lossless (transparent texels' colours kept)."""
    out = io.BytesIO()
    if photographic and int(rgba[..., 3].min(initial=255)) == 255:
        _pillow(rgba, opaque=True).save(out, format="WEBP", quality=JPEG_QUALITY, method=4)
    else:
        image = _pillow(rgba, opaque=False)
        image.save(out, format="WEBP", lossless=True, quality=100, method=4, exact=True)
    return out.getvalue()


def encoded(rgba: np.ndarray, photographic: bool) -> tuple[bytes, str]:
    """Deterministic bytes of an RGBA uint8 image (top row first) and their MIME type: JPEG
    (quality :data:`JPEG_QUALITY`, no metadata) for a ``photographic`` one whose texels are all
    opaque, else PNG (lossless, no timestamp or text chunk)."""
    out = io.BytesIO()
    if photographic and int(rgba[..., 3].min(initial=255)) == 255:
        rgb = _pillow(rgba, opaque=True)
        rgb.save(out, format="JPEG", quality=JPEG_QUALITY, optimize=False, progressive=False)
        return out.getvalue(), "image/jpeg"
    _pillow(rgba, opaque=False).save(out, format="PNG")
    return out.getvalue(), "image/png"


def _pillow(rgba: np.ndarray, opaque: bool) -> PIL.Image.Image:
    """A Pillow image of an RGBA uint8 image, RGB where ``opaque`` (its alpha dropped by
    Pillow: a numpy slice of three channels would be copied texel by texel first)."""
    from PIL import Image

    image = Image.fromarray(np.ascontiguousarray(rgba, dtype=np.uint8), "RGBA")
    return image.convert("RGB") if opaque else image
