"""Prism switching (``--switching prism``): levels switched on boxes around each object by
ProximitySensor → BooleanFilter → IntegerTrigger → Switch, without a Script. The output is valid
X3D 4.0 and passes the checks, reads back as the same chains as LOD switching, keeps instances,
and is the same bytes for the same input; the option is refused for glTF."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh
from lxml import etree

from lodconvert import convert
from lodconvert.chain import ChainOptions
from lodconvert.errors import UsageError
from lodconvert.io import OutputInfo, read_chains
from lodconvert.io.x3d import prism_boxes, write_x3d
from lodconvert.model import LodChain
from lodconvert.validate import validate_file

from .conftest import SAMPLE, SHARED, X3D_SCHEMAS
from .test_cli import assert_one_line_error, run
from .test_instances import PLACEMENTS

CITY_SAMPLE = SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip"
MODES = ("lod", "prism")


def _convert_both(source: Path, folder: Path, **options: object) -> dict[str, Path]:
    """``source`` converted with each switching mode (numpy backend) into ``folder``."""
    outputs = {}
    for mode in MODES:
        outputs[mode] = folder / f"{source.name.split('.')[0]}_{mode}.x3d"
        convert(
            source,
            outputs[mode],
            ChainOptions(**options),
            backend="numpy",
            write_options={"switching": mode},
        )
    return outputs


@pytest.fixture(scope="module")
def city(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The Munich LoD2 district (CityGML 2.0 in a zip) with LOD and with prism switching."""
    if not CITY_SAMPLE.exists():
        pytest.skip(f"{CITY_SAMPLE} is absent (shared test data not checked out)")
    return _convert_both(CITY_SAMPLE, tmp_path_factory.mktemp("city"))


@pytest.fixture(scope="module")
def mesh(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The bundled torus knot, culled beyond Y(1.5), with LOD and with prism switching."""
    return _convert_both(SAMPLE, tmp_path_factory.mktemp("mesh"), cull=1.5)


@pytest.fixture(scope="module")
def instances(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One sphere placed by three nodes (moved, rotated, scaled), with both switching modes."""
    scene = trimesh.Scene()
    scene.add_geometry(
        trimesh.creation.icosphere(subdivisions=3), node_name="ball0", geom_name="ball"
    )
    for i, matrix in enumerate(PLACEMENTS):
        frame = {"frame_to": f"ball{i}", "frame_from": scene.graph.base_frame}
        scene.graph.update(**frame, matrix=matrix, geometry="ball")
    folder = tmp_path_factory.mktemp("instances")
    scene.export(folder / "balls.glb")
    return _convert_both(folder / "balls.glb", folder)


def _assert_same_chains(expected: list[LodChain], got: list[LodChain]) -> None:
    """The chains agree in everything read back: ids, switching data, placement, attributes and
    every level's facts and geometry."""
    assert len(got) == len(expected)
    for a, b in zip(expected, got, strict=True):
        assert (b.object_id, b.cutoffs, b.culled, b.xs) == (a.object_id, a.cutoffs, a.culled, a.xs)
        assert (b.alpha, b.beta, b.gamma) == (a.alpha, a.beta, a.gamma)
        np.testing.assert_array_equal(b.origin, a.origin)
        np.testing.assert_array_equal(b.center, a.center)
        assert (a.transform is None) == (b.transform is None)
        if a.transform is not None:
            np.testing.assert_array_equal(b.transform, a.transform)
        assert b.metadata == a.metadata
        for p, q in zip(a.levels, b.levels, strict=True):
            assert (q.name, q.kind, q.count, q.params) == (p.name, p.kind, p.count, p.params)
            if p.mesh is not None:
                np.testing.assert_array_equal(q.mesh.vertices, p.mesh.vertices)
                np.testing.assert_array_equal(q.mesh.faces, p.mesh.faces)
            else:
                np.testing.assert_array_equal(q.points.positions, p.points.positions)
                np.testing.assert_array_equal(q.points.colors, p.points.colors)


def _assert_valid_everywhere(path: Path, schema: etree.XMLSchema) -> None:
    """Valid against the official XSD, and without findings from ``lodconvert validate``."""
    document = etree.parse(str(path))
    assert schema.validate(document), "\n".join(str(e) for e in schema.error_log)
    assert validate_file(path, x3d_schema=X3D_SCHEMAS) == []


def _objects(path: Path) -> list[etree._Element]:
    """The Transforms holding each object's chain metadata (inside an instance's own one)."""
    return etree.parse(str(path)).xpath("//Transform[MetadataSet[@name='lodconvert']]")


def _floats(text: str) -> np.ndarray:
    return np.array(text.split(), dtype=np.float64)


def _assert_prism_structure(obj: etree._Element, chain: LodChain) -> None:
    """One object of a prism file: its LOD inside a Switch that draws nothing; nested Switches
    starting at their far choice, Switch k choosing between level k and Switch k+1, the last one
    between its level and the coarsest (nothing, culled); per cutoff a sensor box (the finest
    level's box grown by the cutoff) wired to its Switch through a BooleanFilter and two
    IntegerTriggers sending 0 (inside) and 1 (outside)."""
    (hidden,) = obj.findall("Switch[LOD]")
    assert hidden.get("whichChoice") == "-1"
    (node,) = [c for c in obj if c.tag in ("Switch", "Group") and c is not hidden]
    switches = []
    for k, level in enumerate(chain.levels[: len(chain.cutoffs)]):
        assert node.tag == "Switch" and node.get("whichChoice") == "1"
        assert node.get("DEF").endswith(f"_Switch{k}")
        switches.append(node)
        near, node = list(node)
        assert near.tag == "Group" and near.get("USE").endswith(f"_{level.name}")
    assert node.tag == "Group" and not len(node)
    if chain.culled:
        assert node.get("USE") is None
    else:
        assert node.get("USE").endswith(f"_{chain.levels[-1].name}")
    sensors = obj.findall("ProximitySensor")
    assert len(sensors) == len(chain.cutoffs)
    for sensor, switch, (centre, size) in zip(sensors, switches, prism_boxes(chain), strict=True):
        # the box of the finest level as read back: its vertices as written, to 7 digits
        np.testing.assert_allclose(_floats(sensor.get("center")), centre, atol=1e-6 * chain.alpha)
        np.testing.assert_allclose(_floats(sensor.get("size")), size, atol=1e-6 * chain.alpha)
        ((filter_, field),) = _routed(obj, sensor, "isActive")
        assert filter_.tag == "BooleanFilter" and field == "set_boolean"
        for output, choice in (("inputTrue", "0"), ("inputFalse", "1")):
            ((trigger, field),) = _routed(obj, filter_, output)
            assert trigger.tag == "IntegerTrigger" and field == "set_boolean"
            assert trigger.get("integerKey") == choice
            assert _routed(obj, trigger, "triggerValue") == [(switch, "set_whichChoice")]
    assert len(obj.findall("ROUTE")) == 5 * len(chain.cutoffs)


def _routed(
    obj: etree._Element, node: etree._Element, field: str
) -> list[tuple[etree._Element, str]]:
    """Where the ROUTEs of ``obj`` send ``node``'s ``field``: (node, field) pairs, each ROUTE
    after both nodes in the document."""
    order = {element: i for i, element in enumerate(obj.iter())}
    named = {element.get("DEF"): element for element in order if element.get("DEF")}
    targets = []
    for route in obj.iterfind("ROUTE"):
        if route.get("fromNode") == node.get("DEF") and route.get("fromField") == field:
            target = named[route.get("toNode")]
            assert order[node] < order[route] and order[target] < order[route]
            targets.append((target, route.get("toField")))
    return targets


@pytest.mark.slow
@pytest.mark.parametrize("sample", ["city", "mesh", "instances"])
def test_prism_output_is_valid_and_reads_back_as_lod_output(
    sample: str, request: pytest.FixtureRequest, schema: etree.XMLSchema
) -> None:
    outputs = request.getfixturevalue(sample)
    for path in outputs.values():
        _assert_valid_everywhere(path, schema)
    lod, prism = (read_chains(outputs[mode]) for mode in MODES)
    _assert_same_chains(lod, prism)
    document = etree.parse(str(outputs["prism"]))
    assert not document.xpath("//Script")
    assert document.getroot().get("profile") == "Interactive"
    meta = {m.get("name"): m.get("content") for m in document.iter("meta")}
    assert meta["switching"] == "prism"
    assert etree.parse(str(outputs["lod"])).xpath("//meta[@name='switching']/@content") == ["lod"]
    for obj, chain in zip(_objects(outputs["prism"]), prism, strict=True):
        _assert_prism_structure(obj, chain)


def test_instances_share_levels_but_sense_their_own_boxes(instances: dict[str, Path]) -> None:
    document = etree.parse(str(instances["prism"]))
    chains = read_chains(instances["prism"])
    assert len(document.findall(".//LOD[@DEF]")) == 1
    assert len(document.findall(".//LOD[@USE]")) == len(PLACEMENTS) - 1
    assert len(document.findall(".//Group[@DEF]")) == len(chains[0].levels)
    sensors = document.findall(".//ProximitySensor[@DEF]")  # a USEd one would sense a union
    assert len(sensors) == sum(len(chain.cutoffs) for chain in chains)


def test_same_input_gives_the_same_bytes(mesh: dict[str, Path], tmp_path: Path) -> None:
    again = _convert_both(SAMPLE, tmp_path, cull=1.5)
    assert again["prism"].read_bytes() == mesh["prism"].read_bytes()


def test_glb_with_prism_switching_is_a_usage_error(tmp_path: Path) -> None:
    missing = tmp_path / "not-read.ply"  # refused before any work: the input is never opened
    for suffix in ("glb", "gltf"):
        out = tmp_path / f"out.{suffix}"
        result = run(missing, "-o", out, "--switching", "prism")
        assert_one_line_error(result, 2, "usage error", "--switching prism", "X3D-only")
        assert not out.exists()


def test_cli_writes_prism_switching(tmp_path: Path) -> None:
    out = tmp_path / "knot.x3d"
    result = run(SAMPLE, "-o", out, "--switching", "prism", "--backend", "numpy", "-q")
    assert result.returncode == 0, result.stderr
    assert etree.parse(str(out)).xpath("//meta[@name='switching']/@content") == ["prism"]


def test_unknown_switching_mode_is_refused(mesh: dict[str, Path]) -> None:
    chains = read_chains(mesh["lod"])
    with pytest.raises(UsageError, match="switching must be lod or prism"):
        write_x3d(chains, io.BytesIO(), OutputInfo("tests", "knot"), switching="sphere")


def _findings(data: bytes, folder: Path) -> set[str]:
    """The codes of what ``lodconvert validate`` finds in the X3D document ``data``."""
    path = folder / "broken.x3d"
    path.write_bytes(data)
    return {finding.code for finding in validate_file(path)}


def test_check_wants_the_profile_of_the_sensors(mesh: dict[str, Path], tmp_path: Path) -> None:
    data = mesh["prism"].read_bytes().replace(b'profile="Interactive"', b'profile="Interchange"')
    assert "X3D_COMPONENT" in _findings(data, tmp_path)


def test_check_wants_routes_after_their_nodes(mesh: dict[str, Path], tmp_path: Path) -> None:
    data = mesh["prism"].read_bytes()
    route = re.search(rb"<ROUTE [^>]*/>", data).group(0)
    data = data.replace(route, b"", 1).replace(b"<Scene>", b"<Scene>" + route, 1)
    assert "ROUTE_NODE" in _findings(data, tmp_path)
