"""Compiled functions work where numba cannot cache them (a read-only install)."""

from __future__ import annotations

from lodconvert.compiled import compiled


def test_a_function_numba_cannot_cache_is_compiled_all_the_same() -> None:
    namespace: dict[str, object] = {}
    exec("def twice(x):\n    return 2 * x\n", namespace)  # no file: nowhere to cache it
    twice = compiled(namespace["twice"])  # type: ignore[arg-type]
    assert twice(21) == 42
