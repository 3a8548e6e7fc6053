"""Reading a CityJSON file: its bytes (what a ``.gz`` or ``.zip`` inflates to, counted before
any is kept) read in chunks up to the limit, its JSON parsed and checked to be CityJSON of a
version read, its CRS, and the :class:`Context` its geometry is read against (vertices:
:mod:`.vertices`)."""

from __future__ import annotations

import gc
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from ...limits import Limits
from ...model import Mesh
from ...semantics import DEFAULT_PALETTE, Palette
from ..archive import inflation_error, open_compressed
from ..crs import Crs
from ..geometry_checks import InputTally
from ..images import Images
from .jsonkind import json_kind
from .vertices import top_level, vertices_of

_VERSIONS = ("1.", "2.")
CHUNK = 1 << 20
"""Bytes read (inflated) at a time."""


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
    textures: list[Any] = field(default_factory=list)
    """The ``appearance.textures`` of the file (or feature)."""
    texture_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    """Its ``appearance.vertices-texture``, (n, 2) float64 (NaN where not two numbers)."""
    images: Images | None = None
    """The images its textures name, with the theme read (``images.theme``)."""
    theme: str | None = None
    """The appearance theme asked for (``--appearance-theme``), else None: the first met."""

    def theme_of(self, themes: Any) -> Any:
        """The entry of ``themes`` (a geometry's ``texture`` or ``material`` object) in the
        theme asked for, else its first (as the geometry lists them, whichever process reads
        it); None where it has none of it. The themes met are noted in :attr:`images`."""
        if not isinstance(themes, dict) or not themes:
            return None
        name = self.theme if self.theme is not None else next(iter(themes))
        if self.images is not None:
            self.images.themes += [each for each in themes if each not in self.images.themes]
            self.images.theme = self.images.theme or name
        return themes.get(name)

    @property
    def crs(self) -> str | None:
        """The CRS of the metric vertices, as nodes record it: a geographic CRS's local frame
        (once vertices have set it), else the declared CRS's name."""
        return self.declared.scene_crs if self.declared is not None else None


def is_compressed(path: Path) -> bool:
    """Whether ``path`` is a ``.gz`` or a ``.zip``, read as what it inflates to."""
    return path.name.lower().endswith((".gz", ".zip"))


def too_large(path: Path, limit: int) -> InputError:
    """The error for a file past ``limit`` bytes (what it inflates to, for ``.gz``/``.zip``)."""
    if is_compressed(path):
        return inflation_error(limit, str(path))
    return InputError(
        f"is larger than the limit of {limit:,} bytes (decompressed_bytes; "
        "raise it with --limit decompressed_bytes=N)",
        str(path),
    )


def unreadable(path: Path, exc: Exception) -> InputError:
    """The error for a file that cannot be read (or inflated) at all."""
    return InputError(f"cannot be read ({exc})", str(path))


def read_bytes(path: Path, limits: Limits) -> bytearray:
    """The bytes of ``path`` (what it inflates to, for ``.gz``/``.zip``:
    :func:`..archive.open_compressed`) in a buffer of their size, read :data:`CHUNK` bytes at
    a time. :class:`InputError` when they pass ``limits.decompressed_bytes``, known before any
    is kept: a compressed file is inflated once to count its bytes (a chunk held at a time),
    then again into the buffer."""
    limit = limits.decompressed_bytes
    try:
        size = _inflated_size(path, limits) if is_compressed(path) else path.stat().st_size
        if size > limit:
            raise too_large(path, limit)
        buffer = bytearray(size)
        filled = 0
        with open_compressed(path, limits) as stream:
            while chunk := stream.read(CHUNK):
                if filled + len(chunk) > limit:  # grown since it was measured
                    raise too_large(path, limit)
                buffer[filled : filled + len(chunk)] = chunk
                filled += len(chunk)
        del buffer[filled:]
    except (OSError, EOFError, zlib.error) as exc:
        raise unreadable(path, exc) from None
    return buffer


def _inflated_size(path: Path, limits: Limits) -> int:
    """How many bytes compressed ``path`` inflates to, counted a chunk at a time (none kept);
    :class:`InputError` once they pass ``limits.decompressed_bytes``."""
    size = 0
    with open_compressed(path, limits) as stream:
        while chunk := stream.read(CHUNK):
            size += len(chunk)
    return size


def load_document(path: Path, limits: Limits, tally: InputTally) -> dict[str, Any]:
    """The JSON object of a ``.json`` file (its ``vertices`` an array, see :func:`parsed`);
    :class:`InputError` unless it is CityJSON within the limits."""
    buffer = read_bytes(path, limits)
    try:
        text = buffer.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise unreadable(path, exc) from None
    del buffer
    collecting = gc.isenabled()
    gc.disable()  # JSON makes no cycles; full passes would scan the growing document again
    try:
        data = parsed(text, str(path), tally)
    finally:
        if collecting:
            gc.enable()
    return cityjson_object(data, "CityJSON", str(path))


def parsed(text: str, where: str, tally: InputTally | None = None) -> Any:
    """``text`` parsed as JSON; :class:`InputError` saying it is not CityJSON otherwise. A
    top-level ``vertices`` of rows of three numbers is parsed a chunk of text at a time into
    an (n, 3) float64 array (:func:`~.vertices.top_level`), its rows counted against
    ``tally``'s limits before it is allocated."""
    try:
        return top_level(text, tally)
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


def member(data: dict[str, Any], key: str, kind: type, where: str) -> Any:
    """``data[key]`` when it is of JSON type ``kind`` (``dict``: an object, ``list``: an
    array), an empty one when absent or null; :class:`InputError` for any other value."""
    value = data.get(key)
    if value is None:
        return kind()
    if not isinstance(value, kind):
        name = "an object" if kind is dict else "an array"
        raise InputError(f"has {key!r} of JSON {json_kind(value)}, not {name}", where)
    return value


def context_of(
    data: dict[str, Any],
    tally: InputTally,
    declared: Crs | None,
    palette: Palette,
    images: Images | None = None,
    theme: str | None = None,
) -> Context:
    """The context of a CityJSON document: vertices (in metres), materials, textures (their
    images read through ``images``), templates (whose vertices are offsets in metres from
    their reference points, never projected)."""
    where = tally.source
    vertices = vertices_of(data.get("vertices"), data.get("transform"), where, declared)
    tally.count(len(vertices), 0, declared=True)
    templates = member(data, "geometry-templates", dict, where)
    return Context(
        tally=tally,
        vertices=vertices,
        declared=declared,
        materials=materials_of(data, where),
        templates=member(templates, "templates", list, where),
        template_vertices=vertices_of(templates.get("vertices-templates"), None, where),
        palette=palette,
        textures=textures_of(data, where),
        texture_vertices=texture_vertices_of(data, where),
        images=images,
        theme=theme,
    )


def textures_of(data: dict[str, Any], where: str) -> list[Any]:
    """The ``appearance.textures`` of a document or a feature (empty where it has none)."""
    return list(member(member(data, "appearance", dict, where), "textures", list, where))


def texture_vertices_of(data: dict[str, Any], where: str) -> np.ndarray:
    """The ``appearance.vertices-texture`` of a document or a feature as (n, 2) float64; a
    row that is not two finite numbers is NaN (the surfaces using it are warned of)."""
    rows = member(member(data, "appearance", dict, where), "vertices-texture", list, where)
    try:
        fast = np.array(rows, dtype=np.float64)
        if fast.ndim == 2 and fast.shape[1] == 2:
            return fast
    except (TypeError, ValueError, OverflowError):
        pass
    out = np.full((len(rows), 2), np.nan)
    for k, row in enumerate(rows):
        if (
            isinstance(row, list)
            and len(row) == 2
            and all(isinstance(v, int | float) and not isinstance(v, bool) for v in row)
        ):
            out[k] = row
    return out


def materials_of(data: dict[str, Any], where: str) -> list[Any]:
    """The ``appearance.materials`` of a document or a feature (empty where it has none)."""
    return list(member(member(data, "appearance", dict, where), "materials", list, where))
