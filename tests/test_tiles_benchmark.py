"""benchmarks/tiles.py's measures of a tileset: what it counts and where it finds the vertices."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import ROOT, SHARED, shared_data

sys.path.insert(0, str(ROOT / "benchmarks"))
import tiles


@pytest.fixture(scope="module")
def tileset(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The ten multi-LoD buildings (RD New + NAP) as a tileset with two tiers of cells."""
    source = shared_data(SHARED / "data" / "cityjson" / "multi_lod_10bldg.city.json")
    output = tmp_path_factory.mktemp("tiles") / "out" / "tileset.json"
    command = [sys.executable, "-m", "lodconvert", str(source), "-o", str(output), "-qq"]
    subprocess.run([*command, "--crs", "EPSG:7415", "--hlod", "250,1000"], check=True, cwd=ROOT)
    return source, output


def test_survey_counts_every_tile_and_byte(tileset: tuple[Path, Path]) -> None:
    _, output = tileset
    survey = tiles.survey(output)
    files = [p for p in output.parent.rglob("*") if p.is_file()]
    assert survey.tiles == sum(p.suffix == ".glb" for p in files)
    assert survey.bytes == sum(p.stat().st_size for p in files)
    # every far tile refines into content of its own: both sides counted
    assert survey.far and all(survey.far[t].vertices > 0 for t in survey.far)
    assert all(survey.children[t].vertices > 0 for t in survey.far)


def test_positions_of_our_tileset_within_a_millimetre(tileset: tuple[Path, Path]) -> None:
    source, output = tileset
    _, largest = tiles.position_error(
        tiles.tileset_positions(output), tiles.source_vertices(source, 200)
    )
    assert largest < 1e-3


def test_content_without_its_transform_is_found_misplaced(tileset: tuple[Path, Path]) -> None:
    source, output = tileset
    leaf = next(output.parent.glob("tiles/*_finest.glb"))
    placed = tiles.content_positions(leaf.read_bytes(), np.eye(4))
    median, _ = tiles.position_error(placed, tiles.source_vertices(source, 200))
    assert median > 1e6  # local metres read as ECEF: thousands of km off


def test_cesium_columns_say_not_measured_without_the_browser_hook() -> None:
    assert tiles.cesium_cell(None, "tiles") == "not measured"
    assert tiles.cesium_cell({"near": {"tiles": 3}, "far": {"tiles": 1}}, "tiles") == "3 / 1"
