"""The set-up scripts' apt_install (scripts/_env.sh) waits while another process holds apt's or
dpkg's lock instead of failing: run against a lock file of the test's own, held by a child
process, with stand-ins for dpkg, apt-get and sudo on PATH (nothing is installed, no root).
scripts/test.sh lets tests skip what is absent; only CI (.ci/run) makes them fail instead."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import ROOT

HOLDER = """
import fcntl, os, sys, time
fd = os.open(sys.argv[1], os.O_RDWR)
fcntl.lockf(fd, fcntl.LOCK_EX)  # as apt and dpkg lock: fcntl
print("locked", flush=True)
time.sleep(float(sys.argv[2]))
with open(sys.argv[3], "w") as out:
    out.write(repr(time.time()))
"""
"""Lock file argv[1], hold it argv[2] seconds, write when it lets go into argv[3], exit."""

STAND_INS = {
    "dpkg": "exit 1",  # every package is missing
    "apt-get": 'echo "$(date +%s.%N) $*" >> "$APT_LOG"',
    "sudo": 'exec "$@"',
}


@pytest.fixture
def stand_ins(tmp_path: Path) -> dict[str, str]:
    """The environment of a run with the stand-ins first on PATH; apt-get logs its calls."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name, body in STAND_INS.items():
        (bin_dir / name).write_text(f"#!/bin/sh\n{body}\n")
        (bin_dir / name).chmod(0o755)
    path = f"{bin_dir}{os.pathsep}{os.environ['PATH']}"
    return {**os.environ, "PATH": path, "APT_LOG": str(tmp_path / "apt.log")}


def _apt_install(lock: Path, env: dict[str, str], wait_s: int) -> subprocess.CompletedProcess:
    """``apt_install chromium`` of scripts/_env.sh with ``lock`` as the only apt lock."""
    script = f'source scripts/_env.sh; APT_LOCKS=("{lock}"); apt_install chromium'
    env = {**env, "APT_LOCK_WAIT_S": str(wait_s)}
    return subprocess.run(
        ["bash", "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120
    )


def _hold(lock: Path, seconds: float, released: Path) -> subprocess.Popen:
    """A child process holding ``lock`` for ``seconds``, once it holds it."""
    lock.touch()
    child = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(lock), str(seconds), str(released)],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert child.stdout is not None and child.stdout.readline() == "locked\n"
    return child


def test_apt_install_waits_for_a_held_lock(tmp_path: Path, stand_ins: dict[str, str]) -> None:
    lock, released = tmp_path / "lock-frontend", tmp_path / "released"
    child = _hold(lock, 2.0, released)
    try:
        run = _apt_install(lock, stand_ins, wait_s=60)
    finally:
        child.wait()
    assert run.returncode == 0, run.stderr
    assert f"waiting for process {child.pid} (python" in run.stderr
    assert f"to release {lock}" in run.stderr
    calls = Path(stand_ins["APT_LOG"]).read_text().splitlines()
    assert [call.split(" ", 1)[1] for call in calls] == [
        "-o DPkg::Lock::Timeout=60 update -qq",
        "-o DPkg::Lock::Timeout=60 install -y -qq --no-install-recommends chromium",
    ]
    assert float(calls[0].split()[0]) >= float(released.read_text())


def test_apt_install_gives_up_after_the_wait(tmp_path: Path, stand_ins: dict[str, str]) -> None:
    """A lock held past APT_LOCK_WAIT_S (1 s of its 30): one line naming the lock and its
    holder, exit 1, and apt-get is never run."""
    lock = tmp_path / "lock"
    child = _hold(lock, 30.0, tmp_path / "released")
    try:
        run = _apt_install(lock, stand_ins, wait_s=1)
    finally:
        child.kill()
        child.wait()
    assert run.returncode == 1, run.stderr
    assert f"{lock} is still held by process {child.pid} after 1 s" in run.stderr
    assert not Path(stand_ins["APT_LOG"]).exists()


REQUIRE_FLAGS = (
    "LODCONVERT_REQUIRE_VALIDATORS",
    "LODCONVERT_REQUIRE_GL",
    "LODCONVERT_REQUIRE_BROWSER",
)

FAKE_ENV = """set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
apt_install() { :; }
make_venv() { :; }
npm_install_pinned() { :; }
"""
"""scripts/_env.sh with nothing installed."""

FAKE_PYTHON = """#!/bin/sh
echo "$2" $(env | grep '^LODCONVERT_REQUIRE_' | sort) >> "$(dirname "$0")/../../calls.log"
"""
""".venv/bin/python that logs, per call, the module it runs (pytest, ruff) and the
LODCONVERT_REQUIRE_* flags it runs with."""


def _flags_of(tmp_path: Path, script: str) -> list[str]:
    """The LODCONVERT_REQUIRE_* flags the pytest of ``script`` (scripts/test.sh or .ci/run,
    copied into a tree with stand-ins for _env.sh and the venv) ran with."""
    for name in ("scripts/test.sh", ".ci/run"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text((ROOT / name).read_text())
    (tmp_path / "scripts" / "_env.sh").write_text(FAKE_ENV)
    python = tmp_path / ".venv" / "bin" / "python"
    python.parent.mkdir(parents=True)
    python.write_text(FAKE_PYTHON)
    python.chmod(0o755)
    env = {k: v for k, v in os.environ.items() if not k.startswith("LODCONVERT_REQUIRE_")}
    run = subprocess.run(
        ["bash", script], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stderr
    calls = [line.split() for line in (tmp_path / "calls.log").read_text().splitlines()]
    (pytest_flags,) = [flags for module, *flags in calls if module == "pytest"]
    return pytest_flags


def test_the_test_script_lets_tests_skip_what_is_absent(tmp_path: Path) -> None:
    """scripts/test.sh on a fresh clone (no ../shared, no validators) runs pytest with no
    LODCONVERT_REQUIRE_* flag, so the tests that need what is absent skip."""
    assert _flags_of(tmp_path, "scripts/test.sh") == []


def test_ci_requires_validators_gl_and_a_browser(tmp_path: Path) -> None:
    """.ci/run runs scripts/test.sh's pytest with every LODCONVERT_REQUIRE_* flag set, so that
    a missing validator, GL context or Chromium fails the run."""
    assert _flags_of(tmp_path, ".ci/run") == sorted(f"{flag}=1" for flag in REQUIRE_FLAGS)
