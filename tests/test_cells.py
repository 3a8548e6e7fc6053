"""LOD parent cells baked as tasks on the run's executor (:mod:`lodconvert.city.cells`): worker
processes bake the cells of one process, tier by tier, and a cell whose workers die is
reported while its members are drawn on their own."""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np
import pytest

from lodconvert.bake import get_backend
from lodconvert.bakery import iter_chains
from lodconvert.chain import ChainOptions
from lodconvert.city.cells import CellBaker
from lodconvert.city.hlod import HlodOptions, plan_cells
from lodconvert.context import RunContext
from lodconvert.io import read_scene
from lodconvert.limits import DEFAULT_LIMITS
from lodconvert.model import CellChain, Level, LodChain
from lodconvert.tasks import PoolExecutor, SerialExecutor

from .conftest import SHARED, shared_data
from .test_workers import _KillsItsWorker, _scene

MULTI_LOD = SHARED / "data" / "cityjson" / "multi_lod_10bldg.city.json"


def _level(level: Level) -> tuple[Any, ...]:
    """What a far level draws: its kind, count and the hash of its geometry."""
    digest = hashlib.sha256()
    arrays = (
        (level.mesh.vertices, level.mesh.faces, level.mesh.vertex_colors)
        if level.mesh is not None
        else (level.points.positions, level.points.colors)
    )
    for array in arrays:
        digest.update(np.ascontiguousarray(array).tobytes())
    return level.kind, level.count, digest.hexdigest()


def _summary(item: LodChain | CellChain) -> Any:
    """What the writers take of an item: an object's id, a cell's id, switch, far level,
    facts and members, finer cells' in turn."""
    if isinstance(item, LodChain):
        return item.object_id
    return (
        item.cell_id,
        item.cutoffs,
        item.origin.tolist(),
        _level(item.far),
        item.facts,
        [_summary(m) for m in item.members],
    )


@pytest.mark.slow
def test_cells_baked_by_worker_processes_are_the_cells_of_one_process() -> None:
    """Two tiers (20 m cells in 80 m cells) of a real city: the same cells, far levels and
    members from two worker processes as from this one."""
    scene_path = shared_data(MULTI_LOD)
    backend, hlod = get_backend("numpy"), HlodOptions((20.0, 80.0), "auto")
    found = {}
    for workers in (1, 2):
        executor = SerialExecutor(backend) if workers == 1 else PoolExecutor(2, "numpy")
        warnings: list[str] = []
        with executor:
            items = iter_chains(
                read_scene(scene_path), ChainOptions(levels=2),
                RunContext(executor, backend, warn=warnings.append), hlod=hlod,
            )  # fmt: skip
            found[workers] = ([_summary(item) for item in items], warnings)
    assert found[2] == found[1]
    tiers = [item[0].split("_")[0] for item in found[1][0] if isinstance(item, tuple)]
    assert "cell2" in tiers
    assert any(isinstance(m, tuple) for item in found[1][0] for m in item[-1])  # tier-1 inside


def _town(
    trap: str | None = None, sizes: tuple[float, ...] = (20.0,)
) -> tuple[list[Any], list[LodChain]]:
    """Eight objects baked in this process, in two 20 m cells 40 m apart (obj0–3 and obj4–7)
    (with ``sizes``, in the cells of those sizes), and their chains in the cells' order
    (``trap``: that object's chain kills the worker taking it)."""
    chains = list(
        iter_chains(_scene(), ChainOptions(levels=2), RunContext.here(get_backend("numpy")))
    )
    for i, chain in enumerate(chains):
        chain.origin = np.array([40.0 * (i // 4) + 2.0 * (i % 4), 0.0, 0.0])
        if chain.object_id == trap:
            chain.metadata["trap"] = _KillsItsWorker()
    centres = np.array([(np.asarray(c.origin) + c.center)[:2] for c in chains])
    plans = plan_cells(centres, sizes)
    return plans, [chains[i] for plan in plans for i in plan.object_indices()]


def _cells(trap: str | None, workers: int) -> tuple[list[LodChain | CellChain], list[str]]:
    """The cells of :func:`_town` baked by ``workers`` processes, and the warnings told."""
    plans, chains = _town(trap)
    warnings: list[str] = []
    backend = get_backend("numpy")
    with SerialExecutor(backend) if workers == 1 else PoolExecutor(workers, "numpy") as executor:
        baker = CellBaker(
            executor.results, ChainOptions(levels=2), "mesh", DEFAULT_LIMITS, warnings.append,
            "town",
        )  # fmt: skip
        return list(baker.cells(plans, iter(chains))), warnings


def test_a_cell_whose_worker_is_killed_twice_is_reported_and_its_members_drawn_alone() -> None:
    one, told = _cells(None, 1)
    assert told == []
    first = [_summary(item) for item in one if item.cell_id.startswith("cell1_0_0")]
    assert len(first) < len(one)  # the other cell's items follow
    items, warnings = _cells("obj5", 2)
    assert [_summary(item) for item in items] == [*first, "obj4", "obj5", "obj6", "obj7"]
    assert warnings == [
        "town: LOD parent cell1_2_0: the worker process converting it died twice "
        "(signal SIGKILL) — its members are drawn on their own"
    ]


def test_a_cell_is_made_of_the_very_chains_it_was_given() -> None:
    """The main process puts a cell baked elsewhere together of its own member chains (the
    pieces workers formatted of them stay theirs): none is shipped back, in either tier."""
    plans, chains = _town(sizes=(20.0, 80.0))
    with PoolExecutor(2, "numpy") as pool:
        baker = CellBaker(pool.results, ChainOptions(levels=2), "mesh", DEFAULT_LIMITS, print, "")
        items = list(baker.cells(plans, iter(chains)))
    assert all(isinstance(item, CellChain) for item in items)
    assert {cell.tier for item in items for cell in item.cells()} == {1, 2}
    objects = [id(chain) for item in items for chain in item.objects()]
    assert sorted(objects) == sorted(id(chain) for chain in chains)
