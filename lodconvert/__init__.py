"""lodconvert: bake CityGML-style level-of-detail chains and write them as X3D or glTF.

Library API (the command line is a thin layer over it)::

    import lodconvert
    report = lodconvert.convert("bunny.ply", "bunny.x3d")
    scene = lodconvert.read("bunny.ply")
    chains = [lodconvert.bake(node) for node in scene.with_geometry()]
    lodconvert.write(chains, "bunny.glb", source="bunny.ply")
    lodconvert.cutoffs(alpha=0.25, gamma=10)          # Y = α·β·γˣ
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from .chain import ChainOptions
from .errors import InputError, LodConvertError, UsageError
from .model import LodChain, Node, Scene
from .ranges import cutoffs
from .version import __version__


def read(path: str | Path, **options: Any) -> Scene:
    """Read a supported input file into a :class:`Scene` of nodes (the format's reader
    options, such as ``merge_groups`` for OBJ, pass through)."""
    from .io import read_scene

    return read_scene(path, **options)


def bake(obj: Node, options: ChainOptions | None = None, backend: str = "auto") -> LodChain:
    """Bake one object's LOD chain (see :mod:`lodconvert.chain` for how defaults are derived)."""
    from .bake import get_backend
    from .plans import bake_chain

    return bake_chain(obj, options or ChainOptions(), get_backend(backend))


def write(
    chains: Iterable[LodChain],
    path: str | Path,
    source: str = "",
    crs: str | None = None,
    **options: Any,
) -> None:
    """Write chains to ``path`` (format from the suffix) as the command line does: the path is
    checked first, the file is staged, checked by its format and only then put in place; on any
    failure nothing is written and an existing file is left as it was."""
    from .io import OutputInfo, output_format
    from .sinks import Outputs
    from .validate import check_written

    target = output_format(path)
    info = OutputInfo(generator=f"lodconvert {__version__}", source=source, crs=crs)
    with Outputs() as outputs:
        sink = outputs.file(path)
        target.write_chains(chains, sink, info, **options)
        sink.with_staged(lambda staged: check_written(staged, path))


def convert(
    input_path: str | Path | Sequence[str | Path],
    output_path: str | Path,
    options: ChainOptions | None = None,
    **kwargs: Any,
) -> dict:
    """Read, bake and write in one call, with every guarantee of the command line; return the
    report (the other keyword arguments are the fields of :class:`lodconvert.pipeline.RunOptions`:
    ``workers``, ``report_path``, ``hlod``…; one given as ``None`` takes its default)."""
    from .pipeline import RunOptions
    from .pipeline import convert as run

    given = {name: value for name, value in kwargs.items() if value is not None}
    return run(input_path, output_path, RunOptions(options or ChainOptions(), **given))


__all__ = [
    "ChainOptions",
    "InputError",
    "LodChain",
    "LodConvertError",
    "Scene",
    "UsageError",
    "__version__",
    "bake",
    "convert",
    "cutoffs",
    "read",
    "write",
]
