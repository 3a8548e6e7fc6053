"""Fast, deterministic number formatting for text formats (X3D attributes, reports), and
parsing of long texts of numbers (:func:`parse_floats`).

Large arrays (hundreds of thousands of vertices) are written without a Python statement per
number: numpy rounds a whole array to integers in units of the last decimal, and one ``%``
format call prints them all (``%g`` of the units scaled back, which drops trailing zeros).
Geometry is printed in fixed point with trailing zeros trimmed (``0.125``, ``-3``, ``12.5``), at
a number of decimals that keeps a given count of significant digits on the array's largest
magnitude, so the rounding error is at most half a unit in that last digit for every value.
Scalars that must survive exactly (a georeferenced origin in the millions, metadata) use
Python's shortest round-trip ``repr``. The same input always gives the same text.
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
"""Scaled magnitudes below this are rounded to int64 units of the last decimal, larger ones
printed exactly with Python's decimal conversion of the values themselves."""
_FLOAT_LIMIT = 10**15
"""Units below this (at most 15 digits) at most :data:`_EXACT_POWER` decimals are printed with
``%g`` of ``units / 10**decimals`` to as many significant digits as the largest has: that
float64 is off the decimal value by at most 2⁻⁵³ of it, far less than half a unit in its 15th
significant digit, so rounding it to those digits gives back exactly the units' digits."""
_EXACT_POWER = 22
"""Largest exponent ``d`` for which ``10.0**d`` is exact in float64."""

_UNIT_TEXT = tuple(f"{i / 255:.4f}".rstrip("0").rstrip(".") for i in range(256))


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
    return decimals_for(float(np.maximum.reduce(np.abs(flat))) if len(flat) else 0.0, significant)


def format_ints(values: np.ndarray | Iterable[int]) -> str:
    """Integers separated by single spaces (any shape, flattened in C order)."""
    flat = np.asarray(values, dtype=np.int64).ravel()
    return ("%d " * len(flat))[:-1] % tuple(flat.tolist())


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
    if not len(flat):
        return ""
    scale = 10.0**decimals
    # the largest scaled magnitude (NaN or infinite for such values, infinite past float64);
    # rounding to units cannot lift a float64 below 2^62 to it
    peak = float(np.maximum.reduce(np.abs(flat))) * scale
    if not peak < _FAST_LIMIT:
        if not np.isfinite(flat).all():
            raise ValueError("cannot format NaN or infinite values")
        return " ".join(_exact_fixed(v, decimals) for v in flat.tolist())
    units = np.rint(flat * scale).astype(np.int64)  # the cast also turns -0.0 into 0
    if decimals == 0:
        return format_ints(units)
    top = round(peak)  # the largest of the units
    if top < _FLOAT_LIMIT and decimals <= _EXACT_POWER:
        # %g drops trailing zeros; it writes an exponent for a value below 1e-4 (not for the
        # largest, with at least one decimal), which then takes the slow way
        template = f"%.{len(str(top))}g "
        text = (template * len(units))[:-1] % tuple((units / scale).tolist())
        if "e" not in text:
            return text
    return " ".join(_units_fixed(u, decimals) for u in units.tolist())


def _units_fixed(units: int, decimals: int) -> str:
    """``units`` × 10^-``decimals`` (``decimals`` ≥ 1) in fixed point, trailing zeros dropped."""
    whole, fraction = divmod(abs(units), 10**decimals)
    text = f"{'-' if units < 0 else ''}{whole}.{fraction:0{decimals}d}"
    return text.rstrip("0").rstrip(".")


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
    flat = np.asarray(values, dtype=np.uint8).ravel()
    return " ".join([_UNIT_TEXT[value] for value in flat.tolist()])


def format_exact(values: Iterable[float]) -> str:
    """Floats with Python's shortest round-trip ``repr`` (full float64 precision), for the few
    numbers that must survive exactly, such as a georeferenced origin."""
    return " ".join([repr(float(v)) for v in values])


SHORT_TEXT = 1 << 12
"""Characters up to which a text of numbers is split into words first (faster for a few
numbers); longer ones are parsed in C."""


def parse_floats(text: str) -> np.ndarray:
    """The whitespace-separated ASCII numbers of ``text`` as float64; a long text parsed in C
    without a Python object per number, so that millions of numbers take little more than
    their array. NaN, ``inf`` and values past float64 (as ``inf``) are parsed as such, for the
    caller to check. ValueError for a word that is not a number.

    >>> parse_floats(" 1 -2.5  3e2 "), parse_floats("  ")
    (array([  1. ,  -2.5, 300. ]), array([], dtype=float64))
    """
    if not text.isascii():
        raise ValueError("not ASCII numbers")
    if len(text) <= SHORT_TEXT:
        return np.array(text.split(), dtype=np.float64)
    if text.isspace():  # numpy reads a text of blanks alone as [-1]
        return np.zeros(0)
    return np.fromstring(text, sep=" ")
