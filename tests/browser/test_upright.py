"""A city glb stands upright in a plain three.js page (GLTFLoader, no lodconvert code): glTF is
+Y up, so the district's world bounding box is as high as its buildings along +Y, and a camera
straight above it sees roofs. A city X3D starts in X_ITE at its own Viewpoint, the district in
view."""

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


def _tum(site: Path, suffix: str) -> str:
    """TUM Munich (EPSG:31468, LoD2 roofs, walls and ground) converted into the test site."""
    if not TUM.exists():
        pytest.skip(f"{TUM} is absent (shared test data not checked out)")
    convert(TUM, site / f"upright_tum{suffix}", backend="numpy")
    return f"upright_tum{suffix}"


@pytest.fixture(scope="module")
def tum_glb(site: Path) -> str:
    return _tum(site, ".glb")


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


def test_x_ite_starts_with_the_district_in_view(site: Path, drive: Drive, measure) -> None:
    """No "view all" needed: X_ITE binds the file's Viewpoint at load and draws the district
    (before, with no Viewpoint, it started at (0, 0, 10), 4.5 million metres from TUM's
    buildings: black). test_scene_frame checks that every building lies in its view."""
    out = drive("x_ite", file=_tum(site, ".x3d"), start=True)
    start = out["result"]["start"]
    message = f"{start}\n{console_text(out)}"
    assert start["foreground"] > 0.05 * 400 * 300, message  # the test page's canvas
    assert not _errors(out), message
    measure("X_ITE, TUM Munich x3d at its Viewpoint", f"{start['foreground']} pixels drawn")
