"""A city glb stands upright in a plain three.js page (GLTFLoader, no lodconvert code): glTF is
+Y up, so the district's world bounding box is as high as its buildings along +Y, and a camera
straight above it sees roofs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lodconvert.pipeline import convert

from ..conftest import SHARED
from .conftest import Drive, console_text
from .test_viewers import _errors

pytestmark = pytest.mark.browser

TUM = SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip"


@pytest.fixture(scope="module")
def tum_glb(site: Path) -> str:
    """TUM Munich (EPSG:31468, LoD2 roofs, walls and ground) converted into the test site."""
    if not TUM.exists():
        pytest.skip(f"{TUM} is absent (shared test data not checked out)")
    convert(TUM, site / "upright_tum.glb", backend="numpy")
    return "upright_tum.glb"


def test_three_shows_a_city_glb_upright_with_its_roofs_on_top(
    tum_glb: str, drive: Drive, measure
) -> None:
    out = drive("three_upright", file=tum_glb)
    seen = out["result"]
    message = f"{seen}\n{console_text(out)}"
    size = np.subtract(seen["max"], seen["min"])
    # Up (+Y) spans the buildings' heights (tens of metres), the ground plane the district's
    # hundreds; every value stays small enough for float32 (no millions in the world box).
    assert size[1] < 100.0 < min(size[0], size[2]), message
    assert np.abs([*seen["min"], *seen["max"]]).max() < 1e5, message
    # From above, the district fills much of the view, and mostly with roof red.
    assert seen["drawn"] > 0.1 * seen["pixels"], message
    assert seen["red"] > 0.5 * seen["drawn"], message
    assert not _errors(out), message
    measure(
        "three.js, TUM Munich glb from above",
        f"world box {size[0]:.0f} × {size[1]:.0f} (up) × {size[2]:.0f} m; "
        f"{seen['drawn'] / seen['pixels']:.0%} of the view drawn, "
        f"{seen['red'] / seen['drawn']:.0%} of it roof red",
    )
