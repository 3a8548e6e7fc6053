"""lodconvert: bake CityGML-style level-of-detail chains and write them as X3D or glTF.

Library API (the command line is a thin layer over it)::

    import lodconvert
    report = lodconvert.convert("bunny.ply", "bunny.x3d")
    scene = lodconvert.read("bunny.ply")
    chains = [lodconvert.bake_levels(obj) for obj in scene]
    lodconvert.write(chains, "bunny.glb", source="bunny.ply")
    lodconvert.cutoffs(alpha=0.25, gamma=10)          # Y = α·β·γˣ
"""

from __future__ import annotations

__version__ = "0.1.0"

from collections.abc import Iterable
from pathlib import Path

from .chain import ChainOptions
from .errors import InputError, LodConvertError, UsageError
from .model import LodChain, Node, Scene
from .ranges import cutoffs


def read(path: str | Path) -> Scene:
    """Read a supported input file into a :class:`Scene` of objects."""
    from .pipeline import read_scene

    return read_scene(path)


def bake_levels(obj: Node, options: ChainOptions | None = None, backend: str = "auto") -> LodChain:
    """Bake one object's LOD chain (see :mod:`lodconvert.chain` for how defaults are derived)."""
    from .bake import get_backend
    from .chain import bake_chain

    return bake_chain(obj, options or ChainOptions(), get_backend(backend))


def write(
    chains: Iterable[LodChain], path: str | Path, source: str = "", crs: str | None = None
) -> None:
    """Write chains to ``path`` (format from the suffix), atomically."""
    from .io import OutputInfo, writer_for
    from .io.atomic import atomic_output

    writer = writer_for(path)
    info = OutputInfo(generator=f"lodconvert {__version__}", source=source, crs=crs)
    with atomic_output(path) as handle:
        writer(chains, handle, info)


def convert(input_path: str | Path, output_path: str | Path, **kwargs: object) -> dict:
    """Read, bake and write in one call; return the report (see :mod:`lodconvert.convert`)."""
    from .pipeline import convert as _convert

    return _convert(input_path, output_path, **kwargs)  # type: ignore[arg-type]


__all__ = [
    "ChainOptions",
    "InputError",
    "LodChain",
    "LodConvertError",
    "Scene",
    "UsageError",
    "__version__",
    "bake_levels",
    "convert",
    "cutoffs",
    "read",
    "write",
]
