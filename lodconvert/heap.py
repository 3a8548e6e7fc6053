"""Handing freed heap memory back to the system after work that made and freed many small C
objects: a large city object's XML elements, the shapely geometries of its footprint."""

from __future__ import annotations

import ctypes
import functools
import sys
from typing import Any


def return_freed_heap() -> None:
    """Hand the pages of the heap that freed memory leaves back to the system: glibc gives
    back only the heap's top by itself, and the arrays made later are mapped apart (see
    ``lodconvert.cli``), so what such work freed would stay resident for the rest of the run.
    Nothing where the C library is not glibc."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


@functools.cache
def _malloc_trim() -> Any:
    """glibc's ``malloc_trim``, or None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None
