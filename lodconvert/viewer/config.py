"""What the viewer page needs to know about an output, read back by the output's own format
(:func:`lodconvert.io.read_chains`, without geometry): per object its id, attributes (what the
page shows of a clicked object), centre, diagonal α, cutoffs, level names and point sizes and,
for glTF, the level nodes; for X3D the ``LOD`` node.

Raises :class:`~lodconvert.errors.InputError` for files lodconvert did not write.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..io import own_format, read_chains
from ..model import LodChain
from ..ranges import REFERENCE_VIEW

FORMAT_KINDS = {"x3d": "x3d", "gltf": "gltf"}
"""Registry format name → the page script that shows it."""


def _object(chain: LodChain, fmt: str) -> dict[str, Any]:
    """The viewer entry of one chain read back by the format named ``fmt``, whose
    ``read_back`` keeps where the chain lies in the file under ``chain.metadata[fmt]``, beside
    the object's attributes."""
    entry: dict[str, Any] = {
        "id": chain.object_id,
        "attributes": {k: v for k, v in chain.metadata.items() if k != fmt},
        "center": (chain.origin + chain.center).tolist(),
        "local_center": np.asarray(chain.center, dtype=np.float64).tolist(),
        "alpha": chain.alpha,
        "cutoffs": list(chain.cutoffs),
        "culled": chain.culled,
        "levels": [level.name for level in chain.levels],
        "points": [
            {"px": level.params.point_size, "distance": level.design_distance}
            if level.params is not None and level.design_distance
            else None
            for level in chain.levels
        ],
    }
    entry.update(chain.metadata.get(fmt, {}))
    return entry


def page_config(path: Path) -> dict[str, Any]:
    """The page's configuration (without the asset URL): format, reference view, objects."""
    path = Path(path)
    fmt = own_format(path).name
    kind = FORMAT_KINDS.get(fmt)
    if kind is None:
        raise InputError("has no viewer page", str(path))
    if not path.is_file():
        raise InputError("no such file", str(path))
    objects = [_object(chain, fmt) for chain in read_chains(path, geometry=False)]
    if not objects:
        raise InputError("holds no LOD chain written by lodconvert", str(path))
    view = {"height_px": REFERENCE_VIEW.height_px, "fov_y_deg": REFERENCE_VIEW.fov_y_deg}
    return {"format": kind, "view": view, "objects": objects}
