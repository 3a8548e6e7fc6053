"""An object's attributes survive the round trip through our outputs: both writers store
``chain.metadata`` (glTF as the root node's ``extras.attributes``, X3D as JSON in a
``MetadataString``), ``read_back`` restores it beside its own key (``"x3d"``/``"gltf"``), and the
viewer page is told each object's attributes (what it shows of a clicked object)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lxml import etree

from lodconvert import convert
from lodconvert.chain import ChainOptions
from lodconvert.errors import InputError
from lodconvert.io import OutputInfo, read_chains, read_scene
from lodconvert.io.gltf import write_glb, write_gltf
from lodconvert.io.x3d import write_x3d
from lodconvert.model import Level, LodChain, Surface
from lodconvert.viewer.config import page_config

from .conftest import SHARED

WRITERS = {"x3d": write_x3d, "glb": write_glb, "gltf": write_gltf}
FORMAT_KEYS = {"x3d": "x3d", "glb": "gltf", "gltf": "gltf"}
"""Suffix → the key under which its read_back keeps where a chain lies in the file."""

ATTRIBUTES = {
    "id": "DEBY_1",
    "type": "Building",
    "name": 'Haus "Nord" \\ Süd <&>',
    "function": "1001",
    "measuredHeight": 12.5,
    "storeysAboveGround": 3,
    "heights": [{"value": 12.5, "kind": "measured"}],
    "generic": {"Kennung": "", "Qualitaet": 2.7, "saniert": True, "Abriss": None},
}
"""A city object's attributes, with what X3D text and JSON must escape."""


def _chain(metadata: dict[str, Any]) -> LodChain:
    """A one-level chain (a triangle) carrying ``metadata``."""
    triangle = Surface(
        vertices=np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float64),
        faces=np.array([[0, 1, 2]], dtype=np.int64),
    )
    return LodChain(
        object_id="DEBY_1",
        levels=[Level(name="LOD2", kind="source", mesh=triangle)],
        cutoffs=[],
        origin=np.array([4467921.0, 5334702.0, 520.0]),
        center=np.zeros(3),
        alpha=2**0.5,
        beta=3.0,
        gamma=4.0,
        xs=[],
        metadata=metadata,
    )


def _write(folder: Path, suffix: str, metadata: dict[str, Any]) -> Path:
    path = folder / f"object.{suffix}"
    with path.open("wb") as handle:
        WRITERS[suffix]([_chain(metadata)], handle, OutputInfo(generator="tests", source="x"))
    return path


def _attributes(chain: LodChain, suffix: str) -> dict[str, Any]:
    """The read-back chain's metadata without the format's own key."""
    return {k: v for k, v in chain.metadata.items() if k != FORMAT_KEYS[suffix]}


@pytest.mark.parametrize("suffix", sorted(WRITERS))
def test_attributes_read_back_as_written(tmp_path: Path, suffix: str) -> None:
    (chain,) = read_chains(_write(tmp_path, suffix, ATTRIBUTES), geometry=False)
    assert _attributes(chain, suffix) == ATTRIBUTES
    assert FORMAT_KEYS[suffix] in chain.metadata  # where the chain lies, as before


@pytest.mark.parametrize("suffix", sorted(WRITERS))
def test_an_object_without_attributes_reads_back_without(tmp_path: Path, suffix: str) -> None:
    (chain,) = read_chains(_write(tmp_path, suffix, {}), geometry=False)
    assert _attributes(chain, suffix) == {}


@pytest.mark.parametrize("suffix", sorted(WRITERS))
def test_page_config_holds_each_objects_attributes(tmp_path: Path, suffix: str) -> None:
    (obj,) = page_config(_write(tmp_path, suffix, ATTRIBUTES))["objects"]
    assert obj["id"] == "DEBY_1" and obj["attributes"] == ATTRIBUTES


@pytest.mark.parametrize(
    ("declared", "message"),
    [("{not json", "attributes are not JSON"), ("[1, 2]", "attributes are a list, not an object")],
)
def test_malformed_x3d_attributes_are_an_input_error(
    tmp_path: Path, declared: str, message: str
) -> None:
    path = _write(tmp_path, "x3d", ATTRIBUTES)
    tree = etree.parse(str(path))
    (entry,) = tree.iterfind(".//MetadataString[@name='attributes']")
    entry.set("value", f'"{declared}"')
    tree.write(str(path))
    with pytest.raises(InputError, match=rf"object 'DEBY_1'.*{re.escape(message)}"):
        read_chains(path, geometry=False)


def test_gltf_attributes_that_are_no_object_are_an_input_error(tmp_path: Path) -> None:
    path = _write(tmp_path, "gltf", ATTRIBUTES)
    document = json.loads(path.read_text(encoding="utf-8"))
    (root,) = [node for node in document["nodes"] if "attributes" in node.get("extras", {})]
    root["extras"]["attributes"] = ["DEBY_1"]
    path.write_text(json.dumps(document), encoding="utf-8")
    with pytest.raises(InputError, match=r"object 'DEBY_1'.*attributes are a list, not an object"):
        read_chains(path, geometry=False)


CITIES = [
    SHARED / "data" / "citygml" / "tum_munich_lod2_v2.zip",
    SHARED / "data" / "cityjson" / "multi_lod_10bldg.city.json",
]


@pytest.mark.parametrize("source", CITIES, ids=lambda path: path.name)
@pytest.mark.parametrize("suffix", ["x3d", "glb"])
def test_converted_city_reads_back_with_its_attributes(
    tmp_path: Path, source: Path, suffix: str
) -> None:
    """Every object of a converted city reads back with the attributes its reader gave it
    (as JSON holds them)."""
    if not source.exists():
        pytest.skip(f"{source} is absent (shared test data not checked out)")
    out = tmp_path / f"city.{suffix}"
    convert(source, out, ChainOptions(), backend="numpy")
    read = {
        chain.object_id: _attributes(chain, suffix) for chain in read_chains(out, geometry=False)
    }
    source_nodes = [node for node in read_scene(source).walk() if node.geometry is not None]
    expected = {node.id: json.loads(json.dumps(node.attributes)) for node in source_nodes}
    assert len(read) > 1 and read == expected
    assert all(attributes["id"] == object_id for object_id, attributes in read.items())
