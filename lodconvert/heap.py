"""The heaps of a conversion's processes: how glibc's allocator is tuned for a run
(:func:`tune_heap`), handing freed memory back after work that made and freed many small C
objects (a large city object's XML elements, the shapely geometries of its footprint), and
how often the main process's cyclic garbage collector runs (:func:`tune_collector`)."""

from __future__ import annotations

import ctypes
import functools
import gc
import sys
from typing import Any

M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3
"""glibc ``mallopt`` parameters."""
MAPPED_BYTES = 32 << 20
"""Blocks from this size up get mappings of their own (:func:`tune_heap`)."""
TRIM_BYTES = 64 << 20
"""The heap is trimmed when this much is free at its top."""
TOP_PAD_BYTES = 16 << 20
"""The heap grows by this much more than a request needs."""
COLLECTOR_THRESHOLDS = (50_000, 20, 100)
"""The cyclic garbage collector's thresholds in a conversion's main process (Python's: 700,
10, 10): a young pass once 50,000 more containers were made than freed."""


def tune_heap() -> None:
    """Tune glibc's allocator for a conversion, in the main process and in every worker: a
    conversion makes and frees numpy arrays of every size object after object; glibc's
    defaults map and unmap each one above 128 KiB, or, once it raised that bar, keep what it
    freed. Here arrays below :data:`MAPPED_BYTES` come from the heap and go back to it for the
    next, which is trimmed once :data:`TRIM_BYTES` lie free at its top, so that the heap
    neither faults its pages in anew for every object nor grows with the city (10× TUM Munich
    to a tileset on one core: 17.5 CPU s, 57,000 minor page faults and 344 MiB at the peak,
    against 22.8 s, 100,000 and 400 MiB with every array over 64 KiB mapped apart; to X3D about
    4 % less CPU). Other C libraries are left as they are."""
    mallopt = _libc_function("mallopt")
    if mallopt is not None:
        mallopt(M_MMAP_THRESHOLD, MAPPED_BYTES)
        mallopt(M_TRIM_THRESHOLD, TRIM_BYTES)
        mallopt(M_TOP_PAD, TOP_PAD_BYTES)


def tune_collector() -> None:
    """Run the cyclic garbage collector of a conversion's main process less often: what it
    holds for long (chains until they are written, cells, records) grows with the city, and
    each pass that reaches it scans it all again, while the run makes almost no cycles. On
    100× TUM Munich to a tileset with 2 workers, 1,394 passes took 0.47 of the main process's
    7.1 CPU s, against 2 passes and 0.01 s with these thresholds; 10× TUM on one core peaks at
    the same memory either way."""
    gc.set_threshold(*COLLECTOR_THRESHOLDS)


def return_freed_heap() -> None:
    """Hand the pages of the heap that freed memory leaves back to the system: glibc gives
    back only the heap's top by itself, and the arrays made later are mapped apart (see
    ``lodconvert.cli``), so what such work freed would stay resident for the rest of the run.
    Nothing where the C library is not glibc."""
    trim = _libc_function("malloc_trim")
    if trim is not None:
        trim(0)


@functools.cache
def _libc_function(name: str) -> Any:
    """glibc's function ``name``, or None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return getattr(ctypes.CDLL("libc.so.6"), name)
    except (OSError, AttributeError):
        return None
