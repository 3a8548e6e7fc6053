"""Every module of the package imports on its own, as in a fresh interpreter: no import cycle
hides behind the order in which other modules happen to be imported first. Each is imported in
a child forked from an interpreter that has loaded what the package imports from elsewhere but
none of the package's own modules."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

from .conftest import ROOT

PACKAGE = ROOT / "lodconvert"
ALONE = r"""
import importlib, os, sys, traceback

def forked(body):
    # run body() in a child of this process; its exit status and what it printed to a pipe
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        try:
            text, status = body() or "", 0
        except BaseException:
            text, status = traceback.format_exc().strip().splitlines()[-1], 1
        os.write(write, text.encode())
        os._exit(status)
    os.close(write)
    with os.fdopen(read, "rb") as pipe:
        text = pipe.read().decode()
    return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]), text

def others():
    for module in sys.argv[1:]:
        try:
            importlib.import_module(module)
        except BaseException:
            pass
    return "\n".join(sorted(n for n in sys.modules if n.split(".")[0] != "lodconvert"))

# what the package imports from elsewhere is loaded once, here, so that each child imports
# only the package's own modules, and those from none but the one it is asked for
for name in forked(others)[1].split():
    try:
        importlib.import_module(name)
    except BaseException:
        pass
assert not any(n.split(".")[0] == "lodconvert" for n in sys.modules)
for module in sys.argv[1:]:
    status, text = forked(lambda: importlib.import_module(module) and None)
    if status:
        print(f"{module}: {text}")
"""


def _modules() -> list[str]:
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__main__":
            continue  # running it is the CLI
        if parts[-1] == "__init__":
            parts.pop()
        names.append(".".join(parts))
    return names


def test_every_module_imports_alone_in_a_fresh_interpreter() -> None:
    modules = _modules()
    assert "lodconvert.io.x3d.check" in modules and len(modules) > 50
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run(
        [sys.executable, "-c", ALONE, *modules],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == ""


NUMBA_SCIPY = (
    "import sys, numba, numpy\n"
    "numba.njit(lambda a: a.sum())(numpy.ones(2))\n"
    "print(sorted(n for n in sys.modules if n.startswith('scipy')))"
)
"""What of scipy numba loads by itself to run a function (its BLAS bindings)."""


def _loaded_converting(source: Path, output: Path, shown: str) -> str:
    """What ``shown`` (an expression over ``sys.modules``) prints after converting ``source``
    into ``output`` with one worker in a fresh interpreter."""
    code = (
        "import sys\nfrom lodconvert.cli import main\n"
        f"status = main([{str(source)!r}, '-o', {str(output)!r}, '--workers', '1', '-q'])\n"
        f"assert status == 0, status\nprint({shown})\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr
    assert output.stat().st_size > 0
    return run.stdout.strip().splitlines()[-1]


def test_a_city_converts_without_loading_scipy(tmp_path: Path) -> None:
    """Converting a city model of buildings (plot radii, prisms from footprints that need a
    union) loads no scipy module beyond what numba loads by itself (the guard's loops): none of
    the subpackages that are slow to import in every process (spatial, sparse, ndimage)."""
    from .conftest import SHARED, shared_data

    source = shared_data(SHARED / "data" / "citygml" / "kit_testcases_lod2_100bldg_v3.gml")
    shown = "sorted(n for n in sys.modules if n.split('.')[0] == 'scipy')"
    loaded = set(ast.literal_eval(_loaded_converting(source, tmp_path / "kit.x3d", shown)))
    alone = subprocess.run([sys.executable, "-c", NUMBA_SCIPY], capture_output=True, text=True)
    assert loaded <= set(ast.literal_eval(alone.stdout.strip())), loaded
    assert not {n.split(".")[1] for n in loaded if "." in n} & {"spatial", "sparse", "ndimage"}


def test_a_city_with_its_own_lod1_converts_without_loading_numba(tmp_path: Path) -> None:
    """Delft's buildings have LoD 1 of their own: no prism is judged, so numba, which takes
    a few tenths of a second to import, is never loaded."""
    from .conftest import SHARED, shared_data

    source = shared_data(SHARED / "data" / "cityjson" / "delft.city.json")
    assert _loaded_converting(source, tmp_path / "delft.x3d", "'numba' in sys.modules") == "False"


def test_a_worker_converting_a_city_into_x3d_loads_no_gltf_format_and_no_pillow(
    monkeypatch, tmp_path
) -> None:
    """A worker process starts by importing what its tasks use; one that read, baked and
    wrote the X3D text of a city's buildings (untextured) has loaded neither the glTF format
    (its reader and checks) nor Pillow, which only textures need."""
    from .conftest import SHARED, shared_data
    from .worker_probe import imported_by_workers

    source = shared_data(SHARED / "data" / "citygml" / "kit_testcases_lod2_100bldg_v3.gml")
    imported = imported_by_workers(monkeypatch, source, tmp_path / "kit.x3d")
    assert {"lodconvert.io.citygml.parallel", "lodconvert.io.x3d.writer"} <= set(imported)
    assert [n for n in imported if n.startswith(("lodconvert.io.gltf", "PIL"))] == []


def _import_graph() -> dict[str, set[str]]:
    """Each module of the package → the modules of the package it imports, anywhere in it
    (inside functions too: an import put off until a call still ties the two)."""
    modules = {name: ROOT / "/".join(name.split(".")) for name in _modules()}
    paths = {
        name: (path / "__init__.py" if path.is_dir() else path.with_suffix(".py"))
        for name, path in modules.items()
    }

    def known(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found.update(filter(None, (known(alias.name) for alias in node.names)))
            elif isinstance(node, ast.ImportFrom):
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                prefix = ".".join([*base, node.module] if node.module else base)
                prefix = node.module or "" if node.level == 0 else prefix
                subs = [f"{prefix}.{alias.name}" for alias in node.names]
                found.update(filter(None, (known(sub) for sub in subs)))
                if not all(sub in modules for sub in subs):  # names the module itself defines
                    found.update(filter(None, [known(prefix)]))
        graph[name] = found - {name}
    return graph


def _cycle(graph: dict[str, set[str]], start: str) -> list[str] | None:
    """A path of imports from ``start`` back to it, if there is one."""
    paths = {start: [start]}
    queue = [start]
    while queue:
        name = queue.pop(0)
        for other in sorted(graph[name]):
            if other == start:
                return [*paths[name], start]
            if other not in paths:
                paths[other] = [*paths[name], other]
                queue.append(other)
    return None


def test_no_module_imports_itself_back_through_others() -> None:
    graph = _import_graph()
    assert {"lodconvert.chain", "lodconvert.city.levels"} <= graph.keys()
    cycles = [" → ".join(path) for name in graph if (path := _cycle(graph, name))]
    assert cycles == []


def test_no_module_imports_a_folder_that_imports_it_back() -> None:
    """Rooms stay apart: a module outside a folder (``chain.py``) may import from it (``city/``)
    or be imported by it, not both."""
    graph = _import_graph()
    folders = {name for name in graph if (PACKAGE.parent / name.replace(".", "/")).is_dir()}
    found = []
    for name, imported in graph.items():
        for folder in folders - {"lodconvert"}:
            inside = {other for other in graph if other == folder or other.startswith(f"{folder}.")}
            if name in inside or not imported & inside:
                continue
            back = sorted(other for other in inside if name in graph[other])
            if back:
                found.append(f"{name} imports {folder}, which imports it back ({back[0]})")
    assert found == []
