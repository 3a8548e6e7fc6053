"""Markdown helpers shared by the benchmark scripts."""

from __future__ import annotations

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
