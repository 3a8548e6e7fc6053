"""CRS safety: ``--crs`` checked, a geographic CRS on projected coordinates, the missing-CRS
warning of a streamed CityGML file."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from .test_citygml import SIG3D
from .test_citygml import sample as citygml_sample
from .test_cityjson import delft
from .test_cli import assert_one_line_error, run


@pytest.mark.parametrize("given", ["foo", "EPSG:99999"])
def test_crs_option_must_name_a_crs(given: str, tmp_path: Path) -> None:
    out = tmp_path / "city.glb"
    result = run(delft(), "-o", out, "--crs", given)
    assert_one_line_error(result, 2, "--crs", given)
    assert not out.exists()


def test_geographic_crs_on_projected_coordinates_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "city.glb"
    for path in (delft(), citygml_sample(SIG3D.format(2))):
        result = run(path, "-o", out, "--crs", "EPSG:4326")
        assert_one_line_error(result, 1, path.name, "not latitude and longitude", "EPSG:4326")
        assert "proj=" not in result.stderr
    assert not out.exists()


def test_a_streamed_citygml_file_without_crs_is_warned_of_alone_and_twice(tmp_path: Path) -> None:
    text = citygml_sample(SIG3D.format(2)).read_text(encoding="utf-8")
    bare = [tmp_path / "a.gml", tmp_path / "b.gml"]
    for path in bare:
        path.write_text(re.sub(r' srsName="[^"]*"', "", text), encoding="utf-8")
    for inputs in (bare[:1], bare):
        result = run(*inputs, "-o", tmp_path / "house.x3d")
        assert result.returncode == 0, result.stderr
        assert "b.gml: declares no CRS" in result.stderr or len(inputs) == 1
        assert "a.gml" in result.stderr and "declares no CRS" in result.stderr
