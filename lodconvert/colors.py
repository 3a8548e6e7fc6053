"""Colour conversions, format-free. A :class:`~lodconvert.model.Surface` and a point level hold
sRGB RGBA bytes; glTF stores linear values (``baseColorFactor``, ``COLOR_0``), so writers and
readers convert here: sRGB bytes ↔ linear floats, and colour values of any type → bytes."""

from __future__ import annotations

import numpy as np


def _srgb_table() -> np.ndarray:
    c = np.arange(256) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


SRGB_TO_LINEAR = _srgb_table()
"""Linear value in [0, 1] of each sRGB byte."""
_SRGB_MIDPOINTS = (SRGB_TO_LINEAR[1:] + SRGB_TO_LINEAR[:-1]) / 2.0


def linear_rgba(rgba: np.ndarray) -> np.ndarray:
    """sRGB RGBA bytes (..., 4) → linear float64 in [0, 1] (alpha is linear already: /255)."""
    out = SRGB_TO_LINEAR[rgba]
    out[..., 3] = rgba[..., 3] / 255.0
    return out


def linear_rgba16(rgba: np.ndarray) -> np.ndarray:
    """sRGB RGBA bytes (..., 4) → linear values as normalised unsigned shorts (glTF's
    ``COLOR_0`` as lodconvert writes it)."""
    return np.rint(np.clip(linear_rgba(rgba), 0.0, 1.0) * 65535.0).astype(np.uint16)


def srgb_rgba(linear: np.ndarray) -> np.ndarray:
    """Linear RGBA floats (..., 4) → sRGB bytes: the nearest byte, so that :func:`linear_rgba`
    followed by any encoding finer than the byte spacing round-trips exactly."""
    out = np.searchsorted(_SRGB_MIDPOINTS, np.clip(linear, 0.0, 1.0)).astype(np.uint8)
    out[..., 3] = np.clip(np.rint(linear[..., 3] * 255.0), 0, 255).astype(np.uint8)
    return out


def normalized(values: np.ndarray) -> np.ndarray:
    """Normalised integers (divided by their type's largest value) or floats as float64."""
    if values.dtype.kind in "ui":
        return values / float(np.iinfo(values.dtype).max)
    return values.astype(np.float64)


def _unit_rgba(values: object | None) -> np.ndarray | None:
    """Colour values (one or many; RGB or RGBA; integers or floats 0..1) as float64 RGBA in
    [0, 1], or ``None`` when there are none."""
    if values is None:
        return None
    c = np.asarray(values)
    if c.ndim == 0 or c.shape[-1] not in (3, 4):
        return None
    c = np.clip(np.nan_to_num(normalized(c)), 0.0, 1.0)
    if c.shape[-1] == 3:
        c = np.concatenate([c, np.ones((*c.shape[:-1], 1))], axis=-1)
    return c


def srgb_bytes(values: object | None, linear: bool) -> np.ndarray | None:
    """Colour values as sRGB RGBA bytes (converted from linear when ``linear``), or ``None``
    when there are none."""
    unit = _unit_rgba(values)
    if unit is None:
        return None
    if not linear:
        return np.rint(unit * 255.0).astype(np.uint8)
    return srgb_rgba(unit)


D65_WHITE = np.array([0.95047, 1.0, 1.08883])
"""CIE XYZ of the D65 white point (sRGB's), Y = 1."""
_SRGB_TO_XYZ = np.array(
    [[0.4124564, 0.3575761, 0.1804375], [0.2126729, 0.7151522, 0.0721750],
     [0.0193339, 0.1191920, 0.9503041]]
)  # fmt: skip


def lab(rgba: np.ndarray) -> np.ndarray:
    """sRGB bytes (..., 3 or 4; alpha ignored) → CIE L*a*b* (D65) float64 (..., 3)."""
    xyz = SRGB_TO_LINEAR[rgba[..., :3]] @ _SRGB_TO_XYZ.T / D65_WHITE
    eps, kappa = 216 / 24389, 24389 / 27
    f = np.where(xyz > eps, np.cbrt(xyz), (kappa * xyz + 16) / 116)
    return np.stack(
        [116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])],
        axis=-1,
    )


def delta_e(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """CIE76 colour difference of sRGB bytes ``a`` and ``b`` (..., 3 or 4): the Euclidean
    distance of their :func:`lab` values."""
    return np.linalg.norm(lab(a) - lab(b), axis=-1)


def delta_e_2000(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """CIEDE2000 colour difference of sRGB bytes ``a`` and ``b`` (..., 3 or 4)."""
    return ciede2000(lab(a), lab(b))


def ciede2000(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """CIEDE2000 colour difference of CIE L*a*b* colours (..., 3), with kL = kC = kH = 1
    (Sharma, Wu and Dalal's formulation)."""
    (l1, a1, b1), (l2, a2, b2) = np.moveaxis(first, -1, 0), np.moveaxis(second, -1, 0)
    mean_c = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2
    g = 0.5 * (1 - np.sqrt(mean_c**7 / (mean_c**7 + 25.0**7)))
    a1, a2 = a1 * (1 + g), a2 * (1 + g)
    c1, c2 = np.hypot(a1, b1), np.hypot(a2, b2)
    h1 = np.degrees(np.arctan2(b1, a1)) % 360
    h2 = np.degrees(np.arctan2(b2, a2)) % 360
    dl, dc = l2 - l1, c2 - c1
    dh = h2 - h1
    dh = np.where(dh > 180, dh - 360, np.where(dh < -180, dh + 360, dh))
    dh = np.where(c1 * c2 == 0, 0.0, dh)
    dhh = 2 * np.sqrt(c1 * c2) * np.sin(np.radians(dh / 2))
    ml, mc = (l1 + l2) / 2, (c1 + c2) / 2
    mh = (h1 + h2) / 2
    mh = np.where(np.abs(h1 - h2) > 180, np.where(h1 + h2 < 360, mh + 180, mh - 180), mh)
    mh = np.where(c1 * c2 == 0, h1 + h2, mh)
    rad = np.radians(mh)
    t = 1 - 0.17 * np.cos(rad - np.radians(30)) + 0.24 * np.cos(2 * rad)
    t += 0.32 * np.cos(3 * rad + np.radians(6)) - 0.20 * np.cos(4 * rad - np.radians(63))
    sl = 1 + 0.015 * (ml - 50) ** 2 / np.sqrt(20 + (ml - 50) ** 2)
    sc, sh = 1 + 0.045 * mc, 1 + 0.015 * mc * t
    rt = (
        -2
        * np.sqrt(mc**7 / (mc**7 + 25.0**7))
        * np.sin(np.radians(60 * np.exp(-(((mh - 275) / 25) ** 2))))
    )
    return np.sqrt((dl / sl) ** 2 + (dc / sc) ** 2 + (dhh / sh) ** 2 + rt * (dc / sc) * (dhh / sh))
