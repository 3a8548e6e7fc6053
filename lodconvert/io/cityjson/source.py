"""Reading a CityJSON file: opening it (through gzip for ``.gz``), parsing its JSON, checking that
it is CityJSON of a version read, its CRS, its vertices (scaled and translated by its
``transform``), and the :class:`Context` its geometry is read against."""

from __future__ import annotations

import gc
import gzip
import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from ...errors import InputError
from ...limits import Limits
from ...model import Mesh
from ...semantics import DEFAULT_PALETTE, Palette
from ..archive import open_member
from ..crs import Crs
from ..geometry_checks import InputTally, checked_vertices

_VERSIONS = ("1.", "2.")


@dataclass
class Context:
    """What the geometry of a file (or a CityJSONSeq feature) is read against."""

    tally: InputTally
    vertices: np.ndarray
    declared: Crs | None
    """The CRS the vertices were given in (None where the file names none)."""
    materials: list[dict[str, Any]] = field(default_factory=list)
    templates: list[dict[str, Any]] = field(default_factory=list)
    template_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    shared: dict[int, tuple[str, Mesh] | None] = field(default_factory=dict)
    """Template index → its (lod, Mesh), read once, or None when it holds no face."""
    counted: set[int] = field(default_factory=set)
    """Ids of the templates' meshes already counted against the limits (each counts once; they
    live as long as ``shared``, so no other mesh takes their id, as the meshes of objects
    already handed on, and freed, do)."""
    palette: Palette = DEFAULT_PALETTE
    """Colours of the semantic classes."""

    @property
    def crs(self) -> str | None:
        """The CRS of the metric vertices, as nodes record it: a geographic CRS's local frame
        (once vertices have set it), else the declared CRS's name."""
        return self.declared.scene_crs if self.declared is not None else None


def open_text(path: Path, limits: Limits) -> IO[str]:
    """``path`` opened as UTF-8 text, through gzip when it ends in ``.gz``; of a ``.zip``, the
    one file it holds, capped at ``limits.decompressed_bytes`` (:mod:`..archive`)."""
    name = path.name.lower()
    if name.endswith(".zip"):
        return io.TextIOWrapper(io.BufferedReader(open_member(path, limits)), encoding="utf-8")
    if name.endswith(".gz"):
        return gzip.open(path, "rt", encoding="utf-8")
    return path.open(encoding="utf-8")


def load_document(path: Path, limits: Limits) -> dict[str, Any]:
    """The JSON object of a ``.json`` file; :class:`InputError` unless it is CityJSON."""
    try:
        with open_text(path, limits) as handle:
            text = handle.read(limits.decompressed_bytes + 1)
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot be read ({exc})", str(path)) from None
    if len(text) > limits.decompressed_bytes:
        raise InputError(
            f"is larger than the limit of {limits.decompressed_bytes:,} bytes "
            "(raise it with --limit decompressed_bytes=N)",
            str(path),
        )
    collecting = gc.isenabled()
    gc.disable()  # JSON makes no cycles; full passes would scan the growing document again
    try:
        data = parsed(text, str(path))
    finally:
        if collecting:
            gc.enable()
    return cityjson_object(data, "CityJSON", str(path))


def parsed(text: str, where: str) -> Any:
    """``text`` parsed as JSON; :class:`InputError` saying it is not CityJSON otherwise."""
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise InputError(f"is not CityJSON (not valid JSON: {exc})", where) from None


def cityjson_object(data: Any, kind: str, where: str) -> dict[str, Any]:
    """``data`` when it is a JSON object of ``type`` ``kind`` (of a version read, for a
    ``CityJSON`` object); :class:`InputError` otherwise."""
    if not isinstance(data, dict):
        raise InputError(f"is not CityJSON (a JSON {type(data).__name__}, not an object)", where)
    if data.get("type") != kind:
        raise InputError(f"is not CityJSON (its type is {data.get('type')!r}, not {kind!r})", where)
    version = str(data.get("version", ""))
    if kind == "CityJSON" and not version.startswith(_VERSIONS):
        raise InputError(f"is CityJSON {version or 'of no version'}; 1.1 and 2.0 are read", where)
    if not isinstance(data.get("CityObjects", {}), dict):
        raise InputError("is not CityJSON (its CityObjects is not an object)", where)
    return data


def declared_crs(metadata: Any, override: str | None, where: str) -> Crs | None:
    """The CRS the vertices of file ``where`` are given in: ``override`` (the user's ``--crs``)
    wins over ``metadata.referenceSystem`` (URL or URN of an EPSG code, which becomes
    ``EPSG:<code>``; other forms are kept as given); None where neither names one."""
    system = metadata.get("referenceSystem") if isinstance(metadata, dict) else None
    if override is not None:
        system = override
    return Crs.of(str(system), where) if system else None


def vertices_of(values: Any, transform: Any, where: str, crs: Crs | None = None) -> np.ndarray:
    """A vertex list in float64 metres: scaled and translated by ``transform`` where given,
    then, for a geographic ``crs``, projected onto its local frame (which the first vertices
    projected centre)."""
    try:
        v = np.asarray(values if values else np.zeros((0, 3)), dtype=np.float64)
        if isinstance(transform, dict):
            v = v * np.asarray(transform["scale"], dtype=np.float64) + np.asarray(
                transform["translate"], dtype=np.float64
            )
    except (ValueError, TypeError, KeyError) as exc:
        raise InputError(f"has malformed vertices or transform ({exc})", where) from None
    v = checked_vertices(v.reshape(-1, 3) if v.size == 0 else v, where)
    return crs.to_metric(v) if crs is not None else v


def context_of(
    data: dict[str, Any], tally: InputTally, declared: Crs | None, palette: Palette
) -> Context:
    """The context of a CityJSON document: vertices (in metres), materials, templates (whose
    vertices are offsets in metres from their reference points, never projected)."""
    where = tally.source
    tally.count(len(data.get("vertices") or ()), 0, declared=True)
    appearance = data.get("appearance") or {}
    templates = data.get("geometry-templates") or {}
    return Context(
        tally=tally,
        vertices=vertices_of(data.get("vertices"), data.get("transform"), where, declared),
        declared=declared,
        materials=list(appearance.get("materials") or []),
        templates=list(templates.get("templates") or []),
        template_vertices=vertices_of(templates.get("vertices-templates"), None, where),
        palette=palette,
    )
