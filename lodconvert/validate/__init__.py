"""Checks of the files lodconvert writes: ``lodconvert validate`` and the converter's last step.

:func:`validate_file` returns a list of :class:`Finding` s; the converter calls
:func:`check_written` on its staged file before committing it. The rules belong to each
format's registry entry (``check``): :mod:`lodconvert.io.x3d.check` (structure of what we emit,
optionally the official XSD) and :mod:`lodconvert.io.gltf.check` (GLB framing, accessors,
``MSFT_lod``).
"""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

from ..errors import InputError, LodConvertError
from ..io import CheckOptions, own_format
from ..io.findings import ERROR, WARNING, Finding, Findings, errors_of, failure_of
from ..limits import DEFAULT_LIMITS, Limits


def validate_file(
    path: str | Path,
    x3d_schema: str | Path | None = None,
    kind: str | None = None,
    limits: Limits = DEFAULT_LIMITS,
    contents: bool = True,
) -> list[Finding]:
    """Check ``path`` and return its findings (empty when it passes).

    ``kind`` is the format suffix (``.x3d``, ``.glb``, ``.gltf``, ``.json``; default:
    ``path``'s suffix). ``x3d_schema`` is an XSD file (or a folder holding ``x3d-4.0.xsd``)
    that X3D documents are validated against too; ``limits`` bound what a tileset's check
    reads (``tileset_json_bytes``); without ``contents``, a tileset's tile contents are not
    read (their makers checked them). Raises :class:`LodConvertError` only when that schema
    cannot be loaded; every problem of the file itself is a finding.
    """
    path = Path(path)
    kind = (kind or path.suffix).lower()
    findings = Findings(path)
    try:
        check = own_format(path.with_name(f"file{kind}"), role="check").check
    except InputError:
        check = None
        findings.error("FORMAT", f"cannot validate {kind or 'a file without suffix'}")
    if check is None:
        return findings.items
    if not path.is_file():
        findings.error("READ", "no such file")
    elif path.stat().st_size == 0:
        findings.error("EMPTY", "the file is empty")
    else:
        check(path, findings, CheckOptions(x3d_schema, limits, contents))
    return findings.items


def check_written(written: Path, target: str | Path, contents: bool = True) -> None:
    """Raise a one-line :class:`LodConvertError` naming ``target`` when ``written`` (a freshly
    written temporary file in ``target``'s format) has an error finding; without
    ``contents``, as :func:`validate_file` takes it."""
    _fail_on_errors(validate_file(written, kind=Path(target).suffix, contents=contents), target)


def streamed_check(target: str | Path) -> bool:
    """Whether ``target``'s format is checked reading its file once, from its start, as a
    stream (:func:`check_stream`; its registry entry's ``checked_as_streamed``)."""
    return own_format(Path(target), role="check").checked_as_streamed


def check_stream(stream: BinaryIO, target: str | Path) -> None:
    """:func:`check_written` of a file whose format is checked as a stream
    (:func:`streamed_check`), read from ``stream``."""
    findings = Findings(Path(target))
    own_format(Path(target), role="check").check(stream, findings, None)
    _fail_on_errors(findings.items, target)


def _fail_on_errors(findings: list[Finding], target: str | Path) -> None:
    """Raise a one-line :class:`LodConvertError` naming ``target`` for the first error of
    ``findings`` (and how many more), if any."""
    failure = failure_of(findings)
    if failure is not None:
        raise LodConvertError(failure, str(target))


__all__ = [
    "ERROR",
    "WARNING",
    "Finding",
    "check_stream",
    "check_written",
    "errors_of",
    "streamed_check",
    "validate_file",
]
