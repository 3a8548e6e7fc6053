"""Functions compiled to machine code by numba (the guard's silhouettes, a prism's roof
percentile, a far level's texture bake, a far mesh's colour distances): cached on disk where
numba finds a place for its cache (beside the module, else the user's cache folder), compiled
anew in each process where it finds none (a read-only install without a writable home).
Importing this module loads numba: a few tenths of a second and about 130 MiB of memory in
each process that does."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numba

F = TypeVar("F", bound=Callable[..., Any])


def compiled(function: F) -> F:
    """``function`` compiled with numba (no Python objects, the GIL released), its machine code
    cached on disk where that can be."""
    try:
        return numba.njit(cache=True, nogil=True)(function)
    except RuntimeError:  # numba found nowhere to keep its cache
        return numba.njit(nogil=True)(function)
