"""Fast, deterministic number formatting for text formats (X3D attributes, reports).

Large arrays (hundreds of thousands of vertices) are written without a per-number Python call:
the digits are computed with numpy straight into a byte buffer. Geometry is printed in fixed
point with trailing zeros trimmed (``0.125``, ``-3``, ``12.5``), at a number of decimals that
keeps a given count of significant digits on the array's largest magnitude, so the rounding
error is at most half a unit in that last digit for every value. Scalars that must survive
exactly (a georeferenced origin in the millions, metadata) use Python's shortest round-trip
``repr``. The same input always gives the same text.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

GEOMETRY_DIGITS = 7
"""Significant digits kept on an array's largest magnitude: float32-level precision."""
MAX_DECIMALS = 308
"""Most decimals printed (10^308 is the largest power of ten a float64 holds); magnitudes below
1e-302 print with fewer than :data:`GEOMETRY_DIGITS` significant digits."""
_FAST_LIMIT = 2.0**62
"""Scaled magnitudes below this are formatted with int64 digit arithmetic, larger ones exactly
with Python's decimal conversion."""

_POW10 = 10 ** np.arange(19, dtype=np.int64)
_SPACE, _MINUS, _DOT, _ZERO = (ord(c) for c in " -.0")
_UNIT_BYTES = np.array([f"{i / 255:.4f}".rstrip("0").rstrip(".") for i in range(256)], dtype=object)


def decimals_for(max_abs: float, significant: int = GEOMETRY_DIGITS) -> int:
    """Decimals that give ``max_abs`` ``significant`` significant digits (never negative, at
    most :data:`MAX_DECIMALS`).

    >>> decimals_for(0.0781), decimals_for(123.4), decimals_for(5e9)
    (8, 4, 0)
    """
    if not (math.isfinite(max_abs) and max_abs > 0):
        return 0
    return min(MAX_DECIMALS, max(0, significant - 1 - math.floor(math.log10(max_abs))))


def geometry_decimals(
    values: np.ndarray | Iterable[float], significant: int = GEOMETRY_DIGITS
) -> int:
    """Decimals that give the largest magnitude among ``values`` ``significant`` significant
    digits (see :func:`decimals_for`; 0 for no values): the precision :func:`format_floats`
    prints at, for formatting parts of one array alike with :func:`format_fixed`.

    >>> geometry_decimals([[0.5, -12.25], [3.0, 0.0]])
    5
    """
    flat = np.asarray(values, dtype=np.float64).ravel()
    return decimals_for(float(np.abs(flat).max()) if len(flat) else 0.0, significant)


def _digit_counts(values: np.ndarray) -> np.ndarray:
    """Decimal digits of non-negative int64 ``values`` (0 has one digit)."""
    return np.maximum(np.searchsorted(_POW10, values, side="right"), 1)


def _put_digits(buf: np.ndarray, ends: np.ndarray, values: np.ndarray, widths: np.ndarray) -> None:
    """Write each of ``values`` as ``widths`` digits (zero-padded) ending before ``ends``."""
    rest = values.copy()
    for place in range(int(widths.max(initial=0))):
        live = widths > place
        buf[ends[live] - 1 - place] = _ZERO + rest[live] % 10
        rest //= 10


def _join(
    negative: np.ndarray, whole: np.ndarray, fraction: np.ndarray, fraction_digits: np.ndarray
) -> str:
    """Space-separated ``[-]whole[.fraction]`` tokens; ``fraction`` has ``fraction_digits``
    digits (zero-padded on the left), and no fraction part is written where that count is 0."""
    if len(whole) == 0:
        return ""
    whole_digits = _digit_counts(whole)
    has_fraction = fraction_digits > 0
    lengths = negative + whole_digits + has_fraction * (1 + fraction_digits)
    starts = np.zeros(len(lengths), dtype=np.int64)
    np.cumsum(lengths[:-1] + 1, out=starts[1:])
    buf = np.full(int(starts[-1] + lengths[-1]), _SPACE, dtype=np.uint8)
    buf[starts[negative]] = _MINUS
    point = starts + negative + whole_digits
    _put_digits(buf, point, whole, whole_digits)
    buf[point[has_fraction]] = _DOT
    _put_digits(buf, starts + lengths, fraction, fraction_digits)
    return buf.tobytes().decode("ascii")


def format_ints(values: np.ndarray | Iterable[int]) -> str:
    """Integers separated by single spaces (any shape, flattened in C order)."""
    flat = np.asarray(values, dtype=np.int64).ravel()
    zeros = np.zeros(len(flat), dtype=np.int64)
    return _join(flat < 0, np.abs(flat), zeros, zeros)


def format_fixed(values: np.ndarray | Iterable[float], decimals: int) -> str:
    """Finite floats rounded to ``decimals`` places (0 to :data:`MAX_DECIMALS`), trailing zeros
    and ``-0`` dropped, separated by single spaces (any shape, flattened in C order). Every
    finite float64 is written, within half a unit in the last place (plus float64 rounding of
    the scaling, 2⁻⁵² of the value): digits beyond int64 come from Python's exact conversion.

    >>> format_fixed([0.5, -2.0, 1e-9, -0.000049, 1234.56789], 4)
    '0.5 -2 0 0 1234.5679'
    >>> format_fixed([1e20, -2.5e30], 0)
    '100000000000000000000 -2499999999999999908974073741312'
    """
    if not 0 <= decimals <= MAX_DECIMALS:
        raise ValueError(f"decimals must be between 0 and {MAX_DECIMALS}, got {decimals}")
    flat = np.asarray(values, dtype=np.float64).ravel()
    if not np.isfinite(flat).all():
        raise ValueError("cannot format NaN or infinite values")
    with np.errstate(over="ignore"):  # overflows go the exact way below
        scaled = np.rint(flat * 10.0**decimals)
    if len(flat) and float(np.abs(scaled).max()) >= _FAST_LIMIT:
        return " ".join(_exact_fixed(float(v), decimals) for v in flat)
    scaled = scaled.astype(np.int64)
    magnitude = np.abs(scaled)
    if decimals < len(_POW10):
        whole, fraction = np.divmod(magnitude, _POW10[decimals])
    else:  # below 2^62 < 10^19: no whole part
        whole, fraction = np.zeros_like(magnitude), magnitude
    trailing = np.zeros(len(flat), dtype=np.int64)
    for place in range(1, min(decimals, len(_POW10) - 1) + 1):
        trailing += (fraction % _POW10[place]) == 0
    fraction_digits = np.where(fraction == 0, 0, decimals - trailing)
    return _join(scaled < 0, whole, fraction // _POW10[trailing], fraction_digits)


def _exact_fixed(value: float, decimals: int) -> str:
    """``value`` rounded to ``decimals`` places from its exact binary value, trailing zeros and
    ``-0`` dropped."""
    text = f"{value:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return "0" if text == "-0" else text


def format_floats(values: np.ndarray | Iterable[float], significant: int = GEOMETRY_DIGITS) -> str:
    """Floats in fixed point with ``significant`` digits on the largest magnitude
    (see :func:`decimals_for`); every value is within half a unit of that last digit.

    >>> format_floats([0.1234567891, -0.001, 12.0], significant=4)
    '0.12 0 12'
    """
    flat = np.asarray(values, dtype=np.float64)
    return format_fixed(flat, geometry_decimals(flat, significant))


def format_unit_bytes(values: np.ndarray) -> str:
    """uint8 values as fractions of 255 with at most 4 decimals (``0``, ``0.502``, ``1``):
    colour channels that read back to the same byte with ``rint(x * 255)``."""
    return " ".join(_UNIT_BYTES[np.asarray(values, dtype=np.uint8).ravel()].tolist())


def format_exact(values: Iterable[float]) -> str:
    """Floats with Python's shortest round-trip ``repr`` (full float64 precision), for the few
    numbers that must survive exactly, such as a georeferenced origin."""
    return " ".join(repr(float(v)) for v in values)
