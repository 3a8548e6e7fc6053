"""Seconds spent in each stage of a run, stages that stream into one another included: each
second counts for the stage running then (the innermost), so the stages add up to the run."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")
_END = object()


class Clock:
    """Exclusive seconds per stage, in ``timings``: the ``stages`` named, in that order, then
    others in the order they first ran."""

    def __init__(self, *stages: str) -> None:
        self.timings: dict[str, float] = dict.fromkeys(stages, 0.0)
        self._running: list[str] = []
        self._mark = time.perf_counter()

    def _lap(self) -> None:
        """Count the seconds since the last lap for the stage running now."""
        now = time.perf_counter()
        if self._running:
            stage = self._running[-1]
            self.timings[stage] = self.timings.get(stage, 0.0) + now - self._mark
        self._mark = now

    @contextlib.contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        """Time the block as ``stage`` (pausing the stage around it)."""
        self._lap()
        self.timings.setdefault(stage, 0.0)
        self._running.append(stage)
        try:
            yield
        finally:
            self._lap()
            self._running.pop()

    def iterate(self, stage: str, items: Iterable[T]) -> Iterator[T]:
        """``items``, the time taken to produce each counted as ``stage``."""
        source = iter(items)
        while True:
            with self(stage):
                item = next(source, _END)
            if item is _END:
                return
            yield item  # type: ignore[misc]
