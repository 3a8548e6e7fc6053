"""A full 1000 m cell of the 100× TUM Munich district, cut out by benchmarks/tier_crop.py: it
holds the same buildings as in the whole district, and its far level pays (3D Tiles REPLACE:
it is loaded instead of its children)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from lodconvert.bake import get_backend
from lodconvert.bakery import iter_chains
from lodconvert.chain import ChainOptions
from lodconvert.city.far_choice import MIN_CELL_F
from lodconvert.city.hlod import HlodOptions
from lodconvert.context import RunContext
from lodconvert.model import CellChain, Level
from lodconvert.plan import level_bytes
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


@pytest.mark.slow
def test_a_full_1000_m_cell_holds_under_two_fifths_of_its_children_at_f_095(
    tmp_path: Path,
) -> None:
    """Parents that pay on a full 1000 m cell (660 buildings in 16 cells of 250 m and beside
    them): its far level holds at most two fifths of the vertices and bytes of what it
    replaces (its 250 m cells' far levels, the buildings only it admits) at silhouette F ≥ 0.95
    over the guard's views of the upper hemisphere (measured: 0.36 and 0.35, blocks with three
    members' own far content; with the axis views alone, blocks at 0.26 and 0.25)."""
    cell = _full_cell(tmp_path, (4470, 5336))
    children = _children(cell)
    assert cell.far.count <= sum(level.count for level in children) * 2 / 5
    assert level_bytes(cell.far) <= sum(map(level_bytes, children)) * 2 / 5
    assert cell.facts["silhouette_f"][cell.facts["kind"]] >= MIN_CELL_F


@pytest.mark.slow
def test_a_cell_whose_blocks_miss_f_095_keeps_blocks_with_the_buildings_that_cost_it(
    tmp_path: Path,
) -> None:
    """A full 1000 m cell in the district's last full row, whose block proxies of each member
    apart miss F 0.95 over the guard's views: it keeps blocks with the member that costs it as
    its own far content, at F ≥ 0.95 and under half the vertices and bytes of its children
    (measured: 6,881 vertices, 0.36 of its children's, F 0.951), where a simplified merged mesh
    takes 14,536."""
    cell = _full_cell(tmp_path, (4470, 5338))
    children = _children(cell)
    own = cell.facts["blocks"]["own_far"]
    assert cell.facts["kind"] == "blocks" and own["members"] + own["objects"] >= 1
    assert cell.facts["silhouette_f"]["blocks"] >= MIN_CELL_F
    assert cell.far.count <= sum(level.count for level in children) / 2
    assert level_bytes(cell.far) <= sum(map(level_bytes, children)) / 2


def _full_cell(tmp_path: Path, key: tuple[int, int]) -> CellChain:
    """The 1000 m cell ``key`` of the 100× district, baked alone with ``--hlod 250,1000``."""
    shared_data(city.TUM)
    template = city.Template(city.tum_document())
    crop = tmp_path / "crop.gml"
    tier_crop.write_copies(template, tier_crop.copies_reaching(template, 100, [key], 1000.0), crop)
    scene = tier_crop.in_cells(crop, [key], 1000.0)
    hlod = HlodOptions((250.0, 1000.0), "auto")
    items = list(
        iter_chains(scene, ChainOptions(), RunContext.here(get_backend("numpy")), hlod=hlod)
    )
    (cell,) = [i for i in items if isinstance(i, CellChain) and not i.facts.get("beside")]
    assert cell.tier == 2 and len(cell.objects()) > 600
    return cell


def _children(cell: CellChain) -> list[Level]:
    """What a cell's far level replaces: its finer cells' far levels, its other members'
    coarsest levels."""
    return [m.far if isinstance(m, CellChain) else m.levels[-1] for m in cell.members]
