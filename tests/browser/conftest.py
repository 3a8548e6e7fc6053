"""Browser-test fixtures: a test site served on 127.0.0.1, the node drivers, the files under
test, and the measurements printed at the end of the run.

The site is a temporary folder holding links to ``node_modules`` (the viewer libraries npm
installed at the repository root) and ``pages`` (this folder's test pages), and the files the
tests write; :func:`lodconvert.viewer.serve` serves it, as ``lodconvert view --serve`` does.
Without Chromium, node or the npm packages the tests skip, or fail where
``LODCONVERT_REQUIRE_BROWSER=1`` (as ``.ci/run`` sets).
"""

from __future__ import annotations

import functools
import itertools
import json
import os
import shutil
import subprocess
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from lodconvert import convert
from lodconvert.chain import ChainOptions
from lodconvert.viewer import LIBRARIES, page_path, serve, write_page

from ..conftest import ROOT, SAMPLE, require

HERE = Path(__file__).resolve().parent
CHROMIUM = Path(os.environ.get("LODCONVERT_CHROMIUM", "/usr/bin/chromium"))
PACKAGES = ("playwright-core", "x_ite", "x3dom", "three", "@babylonjs/core", "@babylonjs/loaders")
REQUIRE = "LODCONVERT_REQUIRE_BROWSER"
SAFETY_S = 600
"""Guard against a hung browser: a driver run with no result after this long fails. Far beyond
a normal run (the full dragon takes under a minute on a loaded 2-core machine); no test has a
time limit of its own, as a loaded machine is slower, not wrong."""
MEASUREMENTS: list[tuple[str, str]] = []
"""(what, value) rows printed in the terminal summary."""


def pytest_terminal_summary(terminalreporter: Any) -> None:
    """Print the viewer measurements (time to first frame, file sizes) of this run."""
    if not MEASUREMENTS:
        return
    terminalreporter.section("viewer measurements")
    width = max(len(what) for what, _ in MEASUREMENTS)
    for what, value in MEASUREMENTS:
        terminalreporter.write_line(f"{what:<{width}}  {value}")


@pytest.fixture
def measure(record_property: Callable[[str, object], None]) -> Callable[[str, str], None]:
    """Record a measurement: printed in the terminal summary and kept as a test property."""

    def record(what: str, value: str) -> None:
        MEASUREMENTS.append((what, value))
        record_property(what, value)

    return record


@pytest.fixture(scope="session")
def browser_tools() -> str:
    """The node executable, once Chromium and the npm packages are known to be there."""
    node = shutil.which("node")
    require(CHROMIUM.exists(), f"{CHROMIUM} is absent (apt-get install chromium)", REQUIRE)
    require(node is not None, "node is not on PATH", REQUIRE)
    missing = [p for p in PACKAGES if not (ROOT / "node_modules" / p / "package.json").exists()]
    require(
        not missing,
        f"npm packages {', '.join(missing)} are not installed under {ROOT}/node_modules "
        "(scripts/test.sh installs them)",
        REQUIRE,
    )
    assert node is not None
    return node


@pytest.fixture(scope="session")
def site(tmp_path_factory: pytest.TempPathFactory, browser_tools: str) -> Path:
    """The folder the browser sees: links to node_modules and the test pages, plus outputs."""
    root = tmp_path_factory.mktemp("site")
    (root / "node_modules").symlink_to(ROOT / "node_modules", target_is_directory=True)
    (root / "pages").symlink_to(HERE / "pages", target_is_directory=True)
    return root


@pytest.fixture(scope="session")
def base_url(site: Path) -> Iterator[str]:
    with serve(site) as url:
        yield url


Drive = Callable[..., dict[str, Any]]
"""A node driver's runner: its output for a scenario and params (see ``_runner``)."""
Driver = Callable[[str], Drive]
"""The runner of a node driver of this folder, by file name."""


def console_text(out: dict[str, Any]) -> str:
    """The browser console of a driver run, for failure messages."""
    lines = out.get("console") or ["(empty)"]
    return "browser console:\n  " + "\n  ".join(lines)


def _runner(node: str, site_url: str, script: str) -> Drive:
    """``run(*args, base=None, **params)``: run ``node SCRIPT *args BASE_URL PARAMS_JSON``
    (``args``: the scenario, none for prism.mjs) on the test site at ``site_url``, or on the
    server at ``base``; returns its output, or fails with its error and the browser console."""

    def run(*args: str, base: str | None = None, **params: Any) -> dict[str, Any]:
        what = " ".join((script, *args))
        params["safety_ms"] = SAFETY_S * 1000
        command = [node, str(HERE / script), *args, base or site_url, json.dumps(params)]
        try:
            # The driver ends itself after SAFETY_S; this only catches a driver that cannot.
            proc = subprocess.run(
                command, capture_output=True, text=True, timeout=SAFETY_S + 120, check=False
            )
        except subprocess.TimeoutExpired:
            pytest.fail(f"{what}: the browser driver hung (no exit in {SAFETY_S + 120} s)")
        lines = proc.stdout.strip().splitlines()
        try:
            out = json.loads(lines[-1])
        except (IndexError, json.JSONDecodeError):
            pytest.fail(f"{what}: the driver printed no result\n{proc.stderr[-4000:]}")
        if not out["ok"]:
            pytest.fail(f"{what}: {out['error']}\n{console_text(out)}")
        return out

    return run


@pytest.fixture(scope="session")
def driver(browser_tools: str, base_url: str) -> Driver:
    """The runner of a node driver of this folder, by file name: ``driver("hlod.mjs")("stops",
    page=...)`` runs a scenario of hlod.mjs on the test site (see ``_runner``)."""
    return functools.partial(_runner, browser_tools, base_url)


@pytest.fixture(scope="session")
def drive(driver: Driver) -> Drive:
    """Run a scenario of drive.mjs: ``drive(scenario, base=None, **params)``."""
    return driver("drive.mjs")


@dataclass
class Chain:
    """An output in the site and what the converter reported of its object (its first, or
    the one at ``index``)."""

    name: str
    size: int
    report: dict[str, Any]
    index: int = 0

    @property
    def page(self) -> str:
        """Its viewer page in the site (the default name, beside it)."""
        return page_path(self.name).name

    @property
    def obj(self) -> dict[str, Any]:
        return self.report["objects"][self.index]

    def stops(self) -> list[dict[str, Any]]:
        """A distance inside each range (the first at half the first cutoff, the last at 1.5×
        the last cutoff), with the level index a viewer should show there."""
        cuts = self.obj["cutoffs"]
        distances = [cuts[0] / 2]
        distances += [(a * b) ** 0.5 for a, b in itertools.pairwise(cuts)]
        distances.append(1.5 * cuts[-1])
        return [{"distance": d, "level": k} for k, d in enumerate(distances)]

    def level_names(self) -> list[str]:
        names = [level["name"] for level in self.obj["levels"]]
        return names + (["nothing (culled)"] if self.obj["culled"] else [])


def make_chain(site: Path, source: Path, name: str, **options: Any) -> Chain:
    """Convert ``source`` into ``site/name`` (numpy backend) and write its viewer page beside
    it (default name) using the npm-installed library."""
    out = site / name
    report = convert(source, out, ChainOptions(**options), backend="numpy")
    kind = "x3d" if out.suffix == ".x3d" else "gltf"
    write_page(out, library=str(site / "node_modules" / LIBRARIES[kind].package))
    return Chain(name, out.stat().st_size, report)


@pytest.fixture(scope="session")
def knot(site: Path) -> dict[str, Chain]:
    """The bundled torus knot as .x3d and .glb with a cull distance (nothing beyond it)."""
    return {s: make_chain(site, SAMPLE, f"knot.{s}", cull=1.5) for s in ("x3d", "glb")}


@pytest.fixture(scope="session")
def pair(site: Path) -> dict[str, Chain]:
    """Two objects as .x3d and .glb, culled: the torus knot at 1/4 scale (first, its ranges
    reach 220) and at 4× scale 30 units beside it (ranges reaching 3,500)."""
    knot = trimesh.load(SAMPLE, process=False, force="mesh")
    scene = trimesh.Scene()
    beside = np.eye(4)
    beside[:3, 3] = (30.0, 0.0, 0.0)
    for name, scale, transform in (("a_small", 0.25, np.eye(4)), ("b_large", 4.0, beside)):
        scene.add_geometry(knot.copy().apply_scale(scale), node_name=name, transform=transform)
    source = site / "pair_source.glb"
    scene.export(source)
    return {s: make_chain(site, source, f"pair.{s}", cull=1.5) for s in ("x3d", "glb")}
