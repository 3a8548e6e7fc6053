"""Every module of the package imports on its own in a fresh interpreter: no import cycle hides
behind the order in which other modules happen to be imported first."""

from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

from .conftest import ROOT

PACKAGE = ROOT / "lodconvert"


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


def _import_alone(module: str) -> tuple[str, str] | None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run(
        [sys.executable, "-c", f"import {module}"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    return None if run.returncode == 0 else (module, run.stderr.strip().splitlines()[-1])


def test_every_module_imports_alone_in_a_fresh_interpreter() -> None:
    modules = _modules()
    assert "lodconvert.io.x3d.check" in modules and len(modules) > 50
    with ThreadPoolExecutor(max_workers=4) as pool:
        failed = [f for f in pool.map(_import_alone, modules) if f is not None]
    assert failed == []
