"""The viewer page of a city with LOD parents, without a browser: each format's ``read_cells``
reads back the cells its writer wrote (the same in X3D and glTF), and the page's configuration
lists them, nested, with what the page needs to find their nodes and which cell holds each
object; prism-switched objects name their Switches. The page at work is tested in
tests/browser/test_hlod_page.py."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

import lodconvert
from lodconvert.bake import get_backend
from lodconvert.bakery import iter_chains
from lodconvert.chain import ChainOptions
from lodconvert.city.hlod import HlodOptions
from lodconvert.context import RunContext
from lodconvert.errors import InputError
from lodconvert.io import own_format
from lodconvert.io.gltf import read_lod_gltf
from lodconvert.io.gltf.reader import _load as load_gltf
from lodconvert.model import CellChain, LodChain, Node, Scene
from lodconvert.viewer import page_config

from .test_lods import block

SIZES = (50.0, 200.0)
"""Cell sides: the district below spans three 50 m cells a side, in two 200 m cells."""
EAST, NORTH = 690_000.0, 5_336_000.0
"""Where the district lies (metres, as a projected CRS puts a city)."""


def _district() -> Scene:
    """16 box buildings, 8–20 m tall, on 30 m lots straddling a 200 m line, and a 90 m tower
    among them (too large for any cell to admit: it stands beside them)."""
    origin = np.array([EAST, NORTH, 500.0])
    nodes = []
    for i, j in itertools.product(range(4), range(4)):
        house = block(12.0, 16.0, 8.0 + 4.0 * ((i + 2 * j) % 4), 170.0 + 30.0 * i, 30.0 * j)
        nodes.append(Node(f"b{i}_{j}", house, "Building", origin=origin, lods={"lod2": house}))
    tower = block(16.0, 16.0, 90.0, 215.0, 15.0)
    nodes.append(Node("tower", tower, "Building", origin=origin, lods={"lod2": tower}))
    return Scene("district", nodes)


@pytest.fixture(scope="module")
def items() -> list:
    """The district baked into its cells (far levels: points, so that they carry sizes), with
    plot radii of 2 m: most buildings switch soon enough for their cells to admit them."""
    hlod = HlodOptions(SIZES, "points")
    options = ChainOptions(gamma=2.0)
    return list(iter_chains(_district(), options, RunContext.here(get_backend("numpy")), hlod=hlod))


@pytest.fixture(scope="module")
def written(items: list, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The district as .x3d, .glb and .gltf, and as .x3d with prism switching."""
    folder = tmp_path_factory.mktemp("district")
    paths = {suffix: folder / f"district.{suffix}" for suffix in ("x3d", "glb", "gltf")}
    for path in paths.values():
        lodconvert.write(items, path, source="district")
    paths["prism"] = folder / "prism.x3d"
    lodconvert.write(items, paths["prism"], source="district", switching="prism")
    return paths


def _cells(items: list) -> list[CellChain]:
    """Every cell among the baked ``items`` and inside them, coarsest first."""
    return [cell for item in items if isinstance(item, CellChain) for cell in item.cells()]


def _objects(items: list) -> list[LodChain]:
    """Every object among the baked ``items`` and inside their cells."""
    return [
        o for item in items for o in (item.objects() if isinstance(item, CellChain) else [item])
    ]


def _id(member: LodChain | CellChain) -> str:
    return member.cell_id if isinstance(member, CellChain) else member.object_id


def _read_cells(path: Path) -> list[dict]:
    entry = own_format(path)
    assert entry.read_cells is not None
    return entry.read_cells(path)


def test_read_cells_gives_the_cells_written_coarsest_first(
    items: list, written: dict[str, Path]
) -> None:
    cells = _cells(items)
    assert {cell.tier for cell in cells} == {1, 2} and len(cells) > 3
    for suffix in ("x3d", "glb", "gltf", "prism"):
        found = _read_cells(written[suffix])
        assert [c["cell_id"] for c in found] == [cell.cell_id for cell in cells], suffix
        for cell, entry in zip(cells, found, strict=True):
            assert entry["members"] == [_id(m) for m in cell.members]
            assert (entry["tier"], entry["size"], entry["key"]) == (
                cell.tier,
                cell.size,
                [*cell.key],
            )
            assert entry["cutoffs"] == pytest.approx(cell.cutoffs) and not entry["culled"]
            np.testing.assert_allclose(
                entry["center"], cell.origin + cell.center, rtol=0, atol=1e-6
            )
            assert entry["facts"]["kind"] == "points" == cell.facts["kind"]
            assert entry["far"]["point_size_px"] == pytest.approx(cell.far.params.point_size)
            assert entry["far"]["design_distance"] == pytest.approx(cell.far.design_distance)


def test_read_cells_says_where_the_cells_lie(written: dict[str, Path]) -> None:
    """X3D: the DEF of each cell's LOD, whose range is its cutoffs; glTF: its near node (the
    one with the cell's facts, MSFT_lod naming the far node) and far node."""
    doc = etree.parse(str(written["x3d"]))
    for cell in _read_cells(written["x3d"]):
        (lod,) = doc.xpath(f"//LOD[@DEF='{cell['x3d']['lod']}']")
        assert [float(v) for v in lod.get("range").split()] == pytest.approx(cell["cutoffs"])
        assert lod.getparent().get("DEF") == cell["cell_id"]
    obj, _ = load_gltf(written["glb"])
    for cell in _read_cells(written["glb"]):
        near, far = (obj["nodes"][cell["gltf"][k]] for k in ("near", "far"))
        assert near["name"] == f"{cell['cell_id']}_near"
        assert near["extensions"]["MSFT_lod"]["ids"] == [cell["gltf"]["far"]]
        assert (
            far["name"] == f"{cell['cell_id']}_FAR" and far["extras"]["lodconvert"] == cell["far"]
        )


def test_files_without_cells_have_none(tmp_path: Path) -> None:
    scene = Scene("one", [Node("house", block(10, 8, 6), "Building")])
    chains = list(iter_chains(scene, ChainOptions(), RunContext.here(get_backend("numpy"))))
    for suffix in ("x3d", "glb"):
        path = tmp_path / f"house.{suffix}"
        lodconvert.write(chains, path, source="house")
        assert _read_cells(path) == []
        config = page_config(path)
        assert config["cells"] == [] and [o["cell"] for o in config["objects"]] == [None]


def test_page_config_nests_cells_and_places_objects(items: list, written: dict[str, Path]) -> None:
    """Each cell names the cell holding it (``parent``), each object the cell holding it
    (``cell``): finer cells and objects in coarser cells, and the tower, which no cell admits,
    in the cell gathering what its 200 m cell left out."""
    cells = _cells(items)
    index = {cell.cell_id: i for i, cell in enumerate(cells)}
    holder = {_id(m): index[c.cell_id] for c in cells for m in c.members}
    direct = [m for c in cells if c.tier == 2 for m in c.members if isinstance(m, LodChain)]
    assert direct  # objects beside finer cells, in their coarser cell
    assert cells[holder["tower"]].facts.get("beside") and cells[holder["tower"]].members == [
        m for m in _objects(items) if m.object_id == "tower"
    ]
    configs = {suffix: page_config(written[suffix]) for suffix in ("x3d", "glb")}
    for suffix, config in configs.items():
        assert [c["id"] for c in config["cells"]] == list(index), suffix
        for cell, entry in zip(cells, config["cells"], strict=True):
            assert entry["parent"] == holder.get(cell.cell_id)
            assert entry["tier"] == cell.tier and entry["kind"] == "points"
            assert entry["points"] == {
                "px": pytest.approx(cell.far.params.point_size),
                "distance": pytest.approx(cell.far.design_distance),
            }
        assert {o["id"]: o["cell"] for o in config["objects"]} == {
            chain.object_id: holder.get(chain.object_id) for chain in _objects(items)
        }
    x3d, glb = (configs[s]["cells"] for s in ("x3d", "glb"))
    nodes = {i for o in read_lod_gltf(written["glb"]) for i in (o.node, *o.ids)}
    for a, b in zip(x3d, glb, strict=True):
        assert a["lod"] == f"{a['id']}_LOD" and {b["near"], b["far"]}.isdisjoint(nodes)
        same = ("lod", "near", "far", "center", "points")
        assert {k: v for k, v in a.items() if k not in same} == {
            k: v for k, v in b.items() if k not in same
        }
        np.testing.assert_allclose(a["center"], b["center"], rtol=0, atol=1e-6)


def test_objects_name_the_transform_their_prism_nodes_are_named_after(
    written: dict[str, Path],
) -> None:
    """The page finds an object's k-th prism Switch and sensor as ``<transform>_Switch{k}`` and
    ``<transform>_Prism{k}``: the first shows its finest level near, the second senses the
    box grown by its first cutoff. The X3D file with LOD switching names the same Transforms."""
    config = page_config(written["prism"])
    doc = etree.parse(str(written["prism"]))
    for obj in config["objects"]:
        (transform,) = doc.xpath(f"//Transform[@DEF='{obj['transform']}']")
        (switch,) = transform.xpath(f"Switch[@DEF='{obj['transform']}_Switch0']")
        assert switch.find("Group").get("USE") == f"{obj['transform']}_{obj['levels'][0]}"
        (sensor,) = transform.xpath(f"ProximitySensor[@DEF='{obj['transform']}_Prism0']")
        size = np.array(sensor.get("size").split(), dtype=float)
        assert min(size) > 2 * obj["cutoffs"][0] and len(obj["cutoffs"]) > 0
    lod = [o["transform"] for o in page_config(written["x3d"])["objects"]]
    assert lod == [o["transform"] for o in config["objects"]]


def test_a_cell_without_its_far_level_is_refused(written: dict[str, Path], tmp_path: Path) -> None:
    doc = etree.parse(str(written["x3d"]))
    first = doc.xpath("//Transform[substring(@DEF, string-length(@DEF) - 3) = '_far']")[0]
    first.getparent().remove(first)
    broken = tmp_path / "broken.x3d"
    doc.write(str(broken))
    with pytest.raises(InputError, match=r"broken\.x3d: .*cell 'cell\w+' has no far level"):
        _read_cells(broken)


def test_a_cell_naming_a_member_it_does_not_hold_is_refused(
    written: dict[str, Path], tmp_path: Path
) -> None:
    text = written["x3d"].read_text()
    start = text.index('name="members"')
    renamed = text[:start] + text[start:].replace("&quot;b", "&quot;x", 1)
    path = tmp_path / "renamed.x3d"
    path.write_text(renamed)
    with pytest.raises(InputError, match=r"renamed\.x3d: cell '\w+' names a member 'x"):
        page_config(path)
