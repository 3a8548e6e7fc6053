"""Markdown helpers shared by the benchmark scripts."""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
from pathlib import Path


def markdown_table(header: list[str], rows: list[list[str]], text_columns: int) -> str:
    """A markdown table; the columns after the first ``text_columns`` right-aligned."""
    align = ["---" if i < text_columns else "---:" for i in range(len(header))]
    return "\n".join("| " + " | ".join(line) + " |" for line in [header, align, *rows])


def write_results(path: Path, text: str) -> None:
    """Write a results file (making its folder) and print it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    print(text)


def machine_line(load: float, seconds: float) -> str:
    """The machine line of a results file run on every core: the cores usable, Python, the
    load average at the start (``load``) and now, and the run's ``seconds``."""
    return (
        f"Machine: {len(os.sched_getaffinity(0))} cores usable ({os.uname().machine}, "
        f"{os.cpu_count()} in all, Python {platform.python_version()}); load average "
        f"{load:.1f} at the start, {os.getloadavg()[0]:.1f} at the end; {seconds:.0f} s in all."
    )


def one_core_facts(command: str, seconds: float) -> list[str]:
    """The date, machine, software and command lines of a one-core results file."""
    import lodconvert

    return [
        f"- Date: {datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds')}",
        f"- Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"{platform.platform()}; one core (affinity), in one process",
        f"- Software: Python {platform.python_version()}, lodconvert {lodconvert.__version__}",
        f"- Command: `{command}` ({seconds:.0f} s)",
    ]


def commit_of(tree: Path) -> str:
    """The short commit of ``tree``'s HEAD (and whether it has changes)."""
    head = subprocess.run(
        ["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    dirty = subprocess.run(
        ["git", "-C", str(tree), "status", "--porcelain", "--untracked-files=no"],
        capture_output=True,
        text=True,
    ).stdout.strip()
    return head + (" with changes" if dirty else "")
