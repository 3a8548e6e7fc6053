"""The stages of a run that stream into one another are timed apart: each second counts once,
for the innermost stage running then, so the report's timings add up to the run."""

from __future__ import annotations

import itertools

import pytest

from lodconvert import clock
from lodconvert.clock import Clock


def test_streamed_stages_count_each_second_once(monkeypatch: pytest.MonkeyPatch) -> None:
    ticks = itertools.count()  # each reading of the clock: one second later
    monkeypatch.setattr(clock.time, "perf_counter", lambda: float(next(ticks)))
    timer = Clock("read", "plan", "write")

    def planned() -> list[int]:
        return [1, 2]

    with timer("write"):
        items = list(timer.iterate("plan", planned()))
    assert items == [1, 2]
    assert timer.timings["read"] == 0.0  # named, never run
    assert list(timer.timings) == ["read", "plan", "write"]
    # the clock read 1 entering "write" and 8 leaving it: 7 s, each counted for one stage
    assert sum(timer.timings.values()) == 7.0
    assert timer.timings["plan"] == 3.0  # three calls (two items and the end), a second each
