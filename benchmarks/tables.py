"""Markdown helpers shared by the benchmark scripts."""

from __future__ import annotations


def markdown_table(header: list[str], rows: list[list[str]], text_columns: int) -> str:
    """A markdown table; the columns after the first ``text_columns`` right-aligned."""
    align = ["---" if i < text_columns else "---:" for i in range(len(header))]
    return "\n".join("| " + " | ".join(line) + " |" for line in [header, align, *rows])
