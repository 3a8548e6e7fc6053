"""glTF 2.0 output (``.glb`` and self-contained ``.gltf``) with levels chained by ``MSFT_lod``.
The chains go into a :class:`~.document.Document` as they come, their nodes laid out by
:class:`~.lod.LodScene` and their buffers as workers made them (:mod:`.buffers`) where they
did; the file is then written from the document's temporary files: a GLB's JSON and BIN chunks
(:mod:`.binary`), or a ``.gltf`` with the buffer as a data URI (:mod:`.json_text`). What the
file holds, and why: ``docs/gltf.md``."""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import Iterable, Iterator
from typing import BinaryIO

from ...model import LodChain
from ...sinks import writing_temporary
from .. import OutputInfo, Pieces
from .binary import pack_glb
from .compression import NONE, check_compression
from .document import SPOOL_BYTES, Document
from .json_text import COMPACT, INDENTED, Layout, write_json
from .lod import LodScene
from .texture_copies import check_texture_format


@contextlib.contextmanager
def _scene(
    chains: Iterable[LodChain],
    info: OutputInfo,
    layout: Layout,
    pieces: Pieces | None,
    compress: str,
    texture_format: str,
) -> Iterator[LodScene]:
    """A document holding ``chains`` (with the buffers workers made of them in ``pieces``),
    compressed as ``compress`` says, textures as ``texture_format`` says; its temporary files
    are deleted when the block ends."""
    doc = Document(layout, check_compression(compress), check_texture_format(texture_format))
    try:
        scene = LodScene(doc, info, pieces or Pieces())
        with writing_temporary():
            for item in chains:
                scene.add(item)
            doc.flush_blob()
        yield scene
    finally:
        doc.close()


def write_glb(
    chains: Iterable[LodChain],
    handle: BinaryIO,
    info: OutputInfo,
    pieces: Pieces | None = None,
    compress: str = NONE,
    texture_format: str = "default",
) -> None:
    """Write ``chains`` as binary glTF (one JSON chunk, one BIN chunk) to ``handle``, its
    geometry compressed as ``compress`` says (docs/compression.md), its textures with a copy
    where ``texture_format`` asks for one (``webp``, ``ktx2``); the part of a chain in
    ``pieces`` (made by a worker, :class:`.chain_part.ChainParts`) is taken as it is."""
    with (
        _scene(chains, info, COMPACT, pieces, compress, texture_format) as scene,
        tempfile.SpooledTemporaryFile(SPOOL_BYTES) as text,
    ):
        with writing_temporary():
            write_json(scene.json_value(data_uri=False), text, COMPACT)
        pack_glb(handle, text, scene.doc.blob)


def write_gltf(
    chains: Iterable[LodChain],
    handle: BinaryIO,
    info: OutputInfo,
    pieces: Pieces | None = None,
    compress: str = NONE,
    texture_format: str = "default",
) -> None:
    """Write ``chains`` as one self-contained glTF JSON file (buffer as a base64 data URI), as
    :func:`write_glb` takes ``pieces``, ``compress`` and ``texture_format``."""
    with _scene(chains, info, INDENTED, pieces, compress, texture_format) as scene:
        write_json(scene.json_value(data_uri=True), handle, INDENTED)
    handle.write(b"\n")
