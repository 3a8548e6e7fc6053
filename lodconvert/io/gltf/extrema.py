"""The least and greatest values of accessors' components, read from buffer 0 a block at a time
(tightly packed accessors together), for the summary checks of declared bounds and index ranges.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from .stream import Source

_BLOCK = 1 << 21
"""Bytes of buffer read at a time for the value checks."""


def groups(
    members: np.ndarray, ctype: np.ndarray, width: np.ndarray
) -> Iterator[tuple[tuple[int, int], np.ndarray]]:
    """``members`` (accessor indices) grouped by component type and width."""
    keys = ctype[members] * 32 + width[members]
    for key in np.unique(keys):
        yield (int(key) // 32, int(key) % 32), members[keys == key]


def extrema(
    members: np.ndarray,
    start: np.ndarray,
    count: np.ndarray,
    stride: np.ndarray,
    dtype: np.dtype,
    width: int,
    blob: Source,
) -> tuple[np.ndarray, np.ndarray]:
    """Per accessor of ``members`` (all of ``dtype`` and ``width``) the least and greatest value
    of each component, as (len(members), width) arrays of ``dtype``: tightly packed accessors
    read together a block at a time, others (and long ones) on their own."""
    low = np.empty((len(members), width), dtype)
    high = np.empty((len(members), width), dtype)
    element = dtype.itemsize * width
    first = start[members]
    span = count[members] * element
    together = (stride[members] == element) & (first % dtype.itemsize == 0) & (span <= _BLOCK)
    for k in np.flatnonzero(~together):
        low[k], high[k] = _accessor_extrema(
            int(first[k]), int(count[members[k]]), int(stride[members[k]]), dtype, width, blob
        )
    rest = np.flatnonzero(together)
    rest = rest[np.argsort(first[rest], kind="stable")]
    at = 0
    while at < len(rest):
        begin = int(first[rest[at]])
        stop = at + int(np.searchsorted(first[rest[at:]], begin + _BLOCK, "left"))
        stop = max(stop, at + 1)
        block = rest[at:stop]
        end = int((first[block] + span[block]).max())
        values = np.frombuffer(blob.read(begin, end), dtype)
        lengths = span[block] // dtype.itemsize
        offsets = np.cumsum(lengths) - lengths
        gather = np.repeat((first[block] - begin) // dtype.itemsize - offsets, lengths)
        gather += np.arange(int(lengths.sum()))
        rows = values[gather].reshape(-1, width)
        low[block] = np.minimum.reduceat(rows, offsets // width, axis=0)
        high[block] = np.maximum.reduceat(rows, offsets // width, axis=0)
        at = stop
    return low, high


def _accessor_extrema(
    first: int, count: int, stride: int, dtype: np.dtype, width: int, blob: Source
) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest value of each component of one accessor, read :data:`_BLOCK` bytes
    at a time."""
    low = high = None
    rows = max(1, _BLOCK // stride)
    for row in range(0, count, rows):
        take = min(rows, count - row)
        at = first + row * stride
        data = blob.read(at, at + stride * (take - 1) + dtype.itemsize * width)
        values = np.ndarray((take, width), dtype, data, 0, (stride, dtype.itemsize))
        part_low, part_high = values.min(axis=0), values.max(axis=0)
        low = part_low if low is None else np.minimum(low, part_low)
        high = part_high if high is None else np.maximum(high, part_high)
    assert low is not None and high is not None
    return low, high
