"""The fuzz loop: rounds of hypothesis examples over every reader the registry knows, each
case read in a :class:`~.worker.Worker` child, until a time budget is spent.

Hypothesis drives the mutations and, when a case fails, shrinks it to a small one (re-run in
the child too); the budget bounds how long to fuzz, never whether a case passes.
"""

from __future__ import annotations

import time
from collections import Counter

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from .mutations import mutated
from .seeds import gzipped, reader_suffixes, seeds_for
from .worker import Worker

ROUND = 25
"""Examples per reader per round."""


def fuzz_round(worker: Worker, suffix: str, examples: int, counts: Counter[str]) -> None:
    """Read ``examples`` mutations of ``suffix``'s seeds (plain or ``.gz``); raise
    ``AssertionError`` with the shrunk input and the child's verdict on the first offender."""

    @settings(
        max_examples=examples,
        deadline=None,
        database=None,
        phases=(Phase.generate, Phase.shrink),
        suppress_health_check=list(HealthCheck),
    )
    @given(data=mutated(seeds_for(suffix)), gz=st.booleans())
    def case(data: bytes, gz: bool) -> None:
        name = f"{suffix}.gz" if gz else suffix
        verdict = worker.read(name, gzipped(data) if gz else data)
        counts[name] += 1
        assert verdict.ok, f"{name}: {verdict.problem}\n{verdict.detail}"

    case()


def fuzz(worker: Worker, seconds: float) -> Counter[str]:
    """Fuzz every reader for about ``seconds`` (at least one round each); cases per suffix."""
    counts: Counter[str] = Counter()
    deadline = time.monotonic() + seconds
    while True:
        for suffix in reader_suffixes():
            fuzz_round(worker, suffix, ROUND, counts)
        if time.monotonic() >= deadline:
            return counts
