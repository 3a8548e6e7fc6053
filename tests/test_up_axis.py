"""``convert --up AXIS``: a mesh whose up axis is not glTF's +y (a z-up scan, Lucy among the
Stanford models) is turned as it is read, so that it stands along +Y in the X3D and glTF it
becomes; its placements (instances) turn with it; the report records the axis; a city model,
z-up by definition and turned already, refuses the option."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import pygltflib as gl
import pytest
import trimesh

from lodconvert.analysis.bench import up_rotation
from lodconvert.io import read_chains, read_scene
from lodconvert.io.frame import ROTATION, UP_AXES, y_up

from .conftest import ROOT
from .test_cityjson import city, square, surface_object, write_json
from .test_cli import assert_one_line_error, run
from .test_mesh_reader import primitive, write_glb


def _axis(up: str) -> np.ndarray:
    """The unit vector of axis ``up`` (``-z`` → (0, 0, −1))."""
    vector = np.zeros(3)
    vector["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
    return vector


def _cone(up: str) -> trimesh.Trimesh:
    """A cone 10 high and 2 wide whose apex points along axis ``up``."""
    cone = trimesh.creation.cone(radius=1.0, height=10.0, sections=16)  # apex at +z
    turn = np.eye(4)
    turn[:3, :3] = np.linalg.inv(y_up(up)) @ ROTATION  # +z → +y → ``up``
    return cone.apply_transform(turn)


def _apex_up(vertices: np.ndarray) -> None:
    """``vertices`` (a cone's) stand along +y, the apex (one vertex) highest."""
    extent = np.ptp(vertices, axis=0)
    assert extent[1] == pytest.approx(10.0) and extent[[0, 2]] == pytest.approx([2.0, 2.0])
    assert np.count_nonzero(vertices[:, 1] > vertices[:, 1].max() - 1e-6) == 1


@pytest.mark.parametrize("up", UP_AXES)
def test_each_up_axis_is_turned_to_plus_y_as_the_mesh_is_read(tmp_path: Path, up: str) -> None:
    assert y_up(up) @ _axis(up) == pytest.approx([0.0, 1.0, 0.0])
    assert np.linalg.det(y_up(up)) == pytest.approx(1.0)  # a turn, not a mirror
    path = tmp_path / "cone.ply"
    _cone(up).export(path)
    (node,) = read_scene(path, up=up).nodes
    _apex_up(node.geometry.vertices)


@pytest.mark.parametrize("suffix", ["glb", "x3d"])
def test_a_z_up_mesh_converted_with_up_z_stands_along_y(tmp_path: Path, suffix: str) -> None:
    """The tall axis of a z-up cone is the output's +Y with ``--up z``, and stays its Z
    without (a mesh keeps its axes)."""
    source = tmp_path / "tall.ply"
    _cone("z").export(source)
    upright, lying = tmp_path / f"upright.{suffix}", tmp_path / f"lying.{suffix}"
    assert run(source, "-o", upright, "--up", "z", "-q").returncode == 0
    assert run(source, "-o", lying, "-q").returncode == 0
    (chain,) = read_chains(upright)
    _apex_up(chain.levels[0].mesh.vertices)
    (chain,) = read_chains(lying)
    assert np.ptp(chain.levels[0].mesh.vertices, axis=0)[2] == pytest.approx(10.0)


def test_instances_turn_with_their_placements(tmp_path: Path) -> None:
    """A mesh placed by two nodes (5 apart along z) stays shared; with ``--up z`` each
    placement is turned: the second stands 5 above the first."""
    shape = _cone("z")
    nodes = [
        gl.Node(name="a", mesh=0),
        gl.Node(name="b", mesh=0, translation=[0.0, 0.0, 5.0]),
    ]
    path = write_glb(tmp_path / "pair.glb", [[primitive(shape)]], nodes)
    a, b = read_scene(path, up="z").nodes
    assert a.geometry is b.geometry
    assert np.allclose(a.transform[:3, :3], ROTATION) and np.allclose(a.transform[:3, 3], 0)
    assert np.allclose(b.transform[:3, 3], [0.0, 5.0, 0.0])


def test_the_report_records_the_up_axis(tmp_path: Path) -> None:
    schema = json.loads((ROOT / "schemas" / "report.schema.json").read_text())
    source = tmp_path / "tall.ply"
    _cone("z").export(source)
    for flags, up in (((), "y"), (("--up=-x",), "-x")):
        report = tmp_path / "report.json"
        result = run(source, "-o", tmp_path / "out.glb", "--report", report, *flags, "-q")
        assert result.returncode == 0, result.stderr
        data = json.loads(report.read_text())
        jsonschema.validate(data, schema)
        assert data["up"] == up


def test_up_for_a_city_model_is_a_usage_error(tmp_path: Path) -> None:
    """A city model is z-up by definition and turned y-up by its scene frame: ``--up`` is
    refused in one line naming the file, before anything is written."""
    vertices = square(0.0) + square(3.0)
    building = surface_object([[0, 1, 2, 3]], [[7, 6, 5, 4]])
    source = write_json(tmp_path / "one.city.json", city({"b1": building}, vertices))
    out = tmp_path / "out.glb"
    result = run(source, "-o", out, "--up", "z")
    assert_one_line_error(result, 2, "--up is for mesh files", "one.city.json", "z-up")
    assert not out.exists()
    # the city converts without it, turned y-up as always
    assert run(source, "-o", out, "-q").returncode == 0


def test_bench_turns_a_model_to_z_up_as_convert_turns_it_to_y_up() -> None:
    """``bench --up`` (its world is z-up) takes the same axes as ``convert --up``."""
    assert np.allclose(up_rotation("z"), np.eye(3))
    assert np.allclose(up_rotation("y"), [[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    for up in UP_AXES:
        assert up_rotation(up) @ _axis(up) == pytest.approx([0.0, 0.0, 1.0])
