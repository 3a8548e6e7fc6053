"""Checks every reader applies to the geometry it hands over, so that nothing downstream meets
coordinates or indices it cannot handle.

A reader calls, per file, :meth:`InputTally.count` (vertices and faces against the run's
:class:`~lodconvert.limits.Limits`) and, per part of an object, :func:`checked_vertices` (3-D,
finite, of a magnitude the outputs hold) and :func:`kept_faces` (indices in range; faces without
area dropped and counted). Per object it calls :func:`check_extent` on the world bounds, and
:meth:`InputTally.skip` for an object left with no face; a file left with none is an error
(:meth:`InputTally.nothing_left`).
Every problem is an :class:`~lodconvert.errors.InputError` of one line naming the file.

The tally travels with the :class:`~lodconvert.model.Scene` (:func:`attach_tally`,
:func:`tally_of`) so that the run's report can say what was dropped and skipped.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..limits import Limits
from ..model import Scene
from .numbers import GEOMETRY_DIGITS

MAX_MAGNITUDE = 1e15
"""Largest coordinate magnitude read: float64 still spaces values 1/8 apart there, so origins
and placements keep sub-metre precision in any unit, and float32 (glTF buffers, relative to an
object's centre) holds any object within it."""
MIN_EXTENT = 1e-8
"""Smallest object (longest side of its bounds): below it, ``GEOMETRY_DIGITS`` significant
digits need more decimals than any viewer parses reliably."""
MIN_RELATIVE_EXTENT = float(np.finfo(np.float64).eps) * 10.0**GEOMETRY_DIGITS
"""Smallest object relative to its largest coordinate magnitude: below it, float64 holds fewer
than ``GEOMETRY_DIGITS`` significant digits across the object, the precision the outputs keep."""
SLIVER = 1e-12
"""A face is taken as without area when the sine of its angle at the first corner is below
this (exactly zero in exact arithmetic, up to float64 rounding)."""
_CHUNK = 1 << 20
"""Faces checked at once (bounds the check's working memory to some 100 MB)."""
SKIPPED_LISTED = 1000
"""Skipped objects listed by id and reason per input; past them, skipped objects are only
counted (:attr:`InputTally.unlisted`), so a file of millions of broken objects keeps a short
report."""
TALLY_KEY = "input_checks"
"""Key of the :class:`InputTally` in :attr:`Scene.attributes`."""


@dataclass
class InputTally:
    """What the checks of one input file counted: vertices and faces read (against ``limits``),
    faces dropped (in all, and by the id of each object read) and objects skipped (``id``,
    ``reason``: the first :data:`SKIPPED_LISTED`, the rest counted in :attr:`unlisted`)."""

    source: str
    limits: Limits
    vertices: int = 0
    faces: int = 0
    dropped_faces: int = 0
    dropped_by_object: dict[str, int] = field(default_factory=dict)
    skipped: list[dict[str, str]] = field(default_factory=list)
    unlisted: int = 0
    """Objects skipped past the :data:`SKIPPED_LISTED` listed."""
    warnings: list[str] = field(default_factory=list)
    """What was read otherwise than the file says (a texture image missing), a whole line
    each: the first :data:`SKIPPED_LISTED`, the rest counted in :attr:`unlisted_warnings`."""
    unlisted_warnings: int = 0

    @property
    def skipped_count(self) -> int:
        """Objects skipped, listed or not."""
        return len(self.skipped) + self.unlisted

    def add_skipped(self, object_id: str, reason: str) -> None:
        """Record object ``object_id`` as skipped for ``reason`` (a whole line, naming it):
        listed while fewer than :data:`SKIPPED_LISTED` are, else counted."""
        if len(self.skipped) < SKIPPED_LISTED:
            self.skipped.append({"id": object_id, "reason": reason})
        else:
            self.unlisted += 1

    def warn(self, text: str) -> None:
        """Record the warning ``text`` (listed while fewer than :data:`SKIPPED_LISTED` are)."""
        if len(self.warnings) < SKIPPED_LISTED:
            self.warnings.append(text)
        else:
            self.unlisted_warnings += 1

    def count(self, vertices: int, faces: int, declared: bool = False) -> None:
        """Add ``vertices`` and ``faces`` read (or, ``declared``, claimed by a header before
        anything is read) and raise :class:`InputError` when the file goes over a limit."""
        total_v, total_f = self.vertices + vertices, self.faces + faces
        verb = "declares" if declared else "holds"
        for name, value in (("vertices", total_v), ("faces", total_f)):
            limit = getattr(self.limits, name)
            if value > limit:
                raise InputError(
                    f"{verb} {value:,} {name}, over the limit of {limit:,} "
                    f"(raise it with --limit {name}=N)",
                    self.source,
                )
        if not declared:
            self.vertices, self.faces = total_v, total_f

    def skip(self, object_id: str, dropped: int) -> None:
        """Record that object ``object_id`` is left out: all its ``dropped`` faces had no
        area (they are counted in :attr:`dropped_faces` where they are dropped)."""
        reason = f"all its {dropped:,} faces have no area (zero area or a repeated vertex)"
        self.add_skipped(object_id, str(InputError(reason, object_id)))

    def nothing_left(self) -> InputError:
        """The error for a file none of whose faces has area."""
        return InputError(
            f"has no face with area: all {self.dropped_faces:,} faces have zero area or a "
            "repeated vertex",
            self.source,
        )


def attach_tally(scene: Scene, tally: InputTally) -> Scene:
    """``scene`` with ``tally`` kept in its attributes (for the run's report)."""
    scene.attributes[TALLY_KEY] = tally
    return scene


def tally_of(scene: Scene) -> InputTally | None:
    """The tally a reader attached to ``scene``, if any."""
    tally = scene.attributes.get(TALLY_KEY)
    return tally if isinstance(tally, InputTally) else None


def checked_vertices(vertices: Any, where: str) -> np.ndarray:
    """``vertices`` as an (n, 3) float64 array; :class:`InputError` naming ``where`` unless
    they are 3-D, finite and within :data:`MAX_MAGNITUDE`."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        width = v.shape[1] if v.ndim == 2 else v.ndim
        raise InputError(f"has {width}-D vertices; 3-D vertices (x y z) are needed", where)
    if not np.isfinite(v).all():
        raise InputError("has NaN or infinite vertex coordinates", where)
    check_magnitude(float(np.abs(v).max(initial=0.0)), where)
    return v


def check_magnitude(largest: float, where: str) -> None:
    """:class:`InputError` when a coordinate of magnitude ``largest`` is beyond
    :data:`MAX_MAGNITUDE`."""
    if not largest <= MAX_MAGNITUDE:
        raise InputError(
            f"has coordinates up to {largest:.3g} in magnitude; lodconvert writes at most "
            f"{MAX_MAGNITUDE:.0e} (float32 outputs and float64 origins lose precision beyond it): "
            "scale the model down",
            where,
        )


def check_extent(bounds: np.ndarray, where: str) -> None:
    """:class:`InputError` when an object of world ``bounds`` ((2, 3): min, max) is too small
    for the outputs to hold its shape: below :data:`MIN_EXTENT` across, or below
    :data:`MIN_RELATIVE_EXTENT` of its distance from the origin."""
    largest = float(np.abs(bounds).max())
    check_magnitude(largest, where)
    extent = float((bounds[1] - bounds[0]).max())
    if extent < MIN_EXTENT:
        raise InputError(
            f"spans only {extent:.3g}; lodconvert writes objects at least {MIN_EXTENT:.0e} "
            "across: scale the model up",
            where,
        )
    if extent < MIN_RELATIVE_EXTENT * largest:
        raise InputError(
            f"spans only {extent:.3g} at coordinates of {largest:.3g}: float64 holds fewer than "
            f"{GEOMETRY_DIGITS} significant digits across it; move it nearer the origin",
            where,
        )


def kept_faces(vertices: np.ndarray, faces: Any, where: str) -> tuple[np.ndarray, int]:
    """The faces (an (m, 3) int64 array) that have area, and how many were dropped for having
    none (zero area or a repeated vertex). :class:`InputError` naming ``where`` when a face is
    not a triangle or refers to a vertex that does not exist."""
    f = np.asarray(faces)
    if f.size == 0:
        return np.zeros((0, 3), dtype=np.int64), 0
    if f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu":
        raise InputError(f"has faces of shape {f.shape} ({f.dtype}), not triangles", where)
    f = f.astype(np.int64, copy=False)
    n = len(vertices)
    bad = (f < 0) | (f >= n)
    if bad.any():
        example = int(f[bad][0])
        raise InputError(
            f"has {int(bad.any(axis=1).sum()):,} face(s) referring to vertices that do not "
            f"exist (index {example}; {n:,} vertices, 0 to {n - 1:,})",
            where,
        )
    keep = faces_with_area(vertices, f)
    dropped = int(len(f) - keep.sum())
    return (f[keep] if dropped else f), dropped


def faces_with_area(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Whether each of ``faces`` ((m, 3) int64, valid indices) has area: three distinct
    vertices, not (nearly exactly) on a line. Checked in chunks of :data:`_CHUNK` faces."""
    if len(faces) <= _CHUNK:
        return _with_area(vertices, faces)
    return np.concatenate(
        [_with_area(vertices, faces[at : at + _CHUNK]) for at in range(0, len(faces), _CHUNK)]
    )


def _with_area(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Whether each face has area: three distinct vertices, not (nearly exactly) on a line."""
    distinct = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
    distinct &= faces[:, 0] != faces[:, 2]
    corner = vertices[faces[:, 0]]
    a, b = vertices[faces[:, 1]] - corner, vertices[faces[:, 2]] - corner
    cross = np.cross(a, b)
    area2 = np.einsum("ij,ij->i", cross, cross)
    scale = np.einsum("ij,ij->i", a, a) * np.einsum("ij,ij->i", b, b)
    return distinct & (area2 > SLIVER**2 * scale)
