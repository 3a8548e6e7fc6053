"""What the glTF checks hold a file to, shared by the checks element by element
(:mod:`.elements`) and the summary checks (:mod:`.summary`): how much accessor data the value
checks read, and the rules of a LOD chain's ``extras`` (``MSFT_screencoverage``, and the
``lodconvert`` levels and cutoffs).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Iterator
from typing import Any

READ_BUDGET = 4
"""Accessor data the value checks read, in multiples of buffer 0's size: accessors that share
their bytes many times over are not all read."""


def _finite(values: Iterable[Any]) -> bool:
    """Whether every value is a finite JSON number."""
    return all(isinstance(v, int | float) and math.isfinite(v) for v in values)


Found = Iterator[tuple[str, str, str]]
"""Findings as (severity, code, message)."""


def lod_extras_findings(name: str, extras: dict[str, Any], ids: int) -> Found:
    """``extras`` of a node with ``ids`` MSFT_lod ids: its screen coverages, one more than the
    ids and falling, and its ``lodconvert`` facts."""
    coverage = extras.get("MSFT_screencoverage")
    if coverage is None:
        yield "warning", "MSFT_LOD_COVERAGE", f"{name} has no extras.MSFT_screencoverage"
    elif len(coverage) != ids + 1:
        yield (
            "error",
            "MSFT_LOD_COVERAGE",
            f"{name} has {len(coverage)} screen coverages for {ids} ids (needs {ids + 1})",
        )
    elif not _finite(coverage) or min(coverage) < 0:
        yield "error", "MSFT_LOD_COVERAGE", f"{name} screen coverages are not all >= 0"
    elif any(b >= a for a, b in itertools.pairwise(coverage)):
        yield (
            "error",
            "MSFT_LOD_COVERAGE",
            f"{name} screen coverages do not fall strictly: {coverage}",
        )
    facts = extras.get("lodconvert")
    if isinstance(facts, dict):
        yield from chain_facts_findings(name, facts, ids)


def chain_facts_findings(name: str, facts: dict[str, Any], ids: int) -> Found:
    """``extras.lodconvert`` of a finest node: one level per node, cutoffs as the chain (a LOD
    parent's near node: one far node, the near level being its members)."""
    levels, cutoffs = facts.get("levels", []), facts.get("cutoffs", [])
    if "cell_id" in facts:
        if ids != 1:
            yield "error", "LODCONVERT_CELL", f"{name} is a LOD parent with {ids} far nodes, not 1"
    elif len(levels) != ids + 1:
        yield (
            "error",
            "LODCONVERT_LEVELS",
            f"{name} extras list {len(levels)} levels for {ids + 1} nodes",
        )
    expected = ids + int(bool(facts.get("culled")))
    if len(cutoffs) != expected or any(b <= a for a, b in itertools.pairwise(cutoffs)):
        yield (
            "error",
            "LODCONVERT_CUTOFFS",
            f"{name} extras cutoffs {cutoffs} are not {expected} increasing distances",
        )


def chain_facts(node: dict[str, Any]) -> dict[str, Any] | None:
    """``extras.lodconvert`` of a chain's finest node (the one that lists the ``levels``)."""
    extras = node.get("extras")
    facts = extras.get("lodconvert") if isinstance(extras, dict) else None
    return facts if isinstance(facts, dict) and "levels" in facts else None
