"""benchmarks/tier_crop.py: a coarse cell cut out of a district of TUM Munich copies holds the
same buildings as in the whole district."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, shared_data

sys.path.insert(0, str(ROOT / "benchmarks"))
import city
import tier_crop


@pytest.mark.slow
def test_a_crop_keeps_the_buildings_of_its_cell_and_writes_fewer_copies(tmp_path: Path) -> None:
    shared_data(city.TUM)
    template = city.Template(city.tum_document())
    cells = [(4467, 5334)]  # the 4× district's south-west 1000 m cell
    whole = tmp_path / "whole.gml"
    city.write_district(template, 4, whole)
    copies = tier_crop.copies_reaching(template, 4, cells, 1000.0)
    crop = tmp_path / "crop.gml"
    tier_crop.write_copies(template, copies, crop)
    assert [k for k, _, _ in copies] == [0, 2]
    expected = [node.id for node in tier_crop.in_cells(whole, cells, 1000.0).nodes]
    found = [node.id for node in tier_crop.in_cells(crop, cells, 1000.0).nodes]
    assert found == expected and 100 < len(found) < 2 * template.buildings
