"""The viewer page: one HTML file beside an output that shows it switching levels at our cutoffs.

The page holds its own script and the configuration read from the output
(:func:`~.config.page_config`) and loads the output (by a relative URL) and one viewer library:
three.js for glTF or X_ITE for X3D, from a public CDN unless a URL or a local copy of the npm
package is given (``--viewer-lib``). A 3D Tiles tileset gets a CesiumJS page inside its folder
instead (:mod:`.tileset`). Browsers do not let a page opened from a file fetch its neighbours,
so :func:`serve` (``lodconvert view OUT --serve``) serves it on 127.0.0.1, with a library
folder outside the page's under :data:`LIBRARY_MOUNT`. What the page shows and exposes to
scripts (``window.lodconvertViewer``): ``docs/viewer.md``.
"""

from __future__ import annotations

import contextlib
import functools
import html
import json
import os
import re
import sys
import threading
import urllib.parse
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any, ClassVar

from .. import manifest
from ..errors import UsageError
from ..io import output_format
from ..limits import DEFAULT_LIMITS, Limits
from ..sinks import Outputs
from ..version import __version__
from .config import page_config
from .tileset import tileset_config


@dataclass(frozen=True)
class Library:
    """A viewer library: its npm package and the import-map entries the page needs."""

    package: str
    version: str
    imports: tuple[tuple[str, str], ...]
    """(import specifier, path inside the package); a specifier ending in ``/`` maps a folder."""

    @property
    def cdn(self) -> str:
        """The pinned package on the jsDelivr CDN."""
        return f"https://cdn.jsdelivr.net/npm/{self.package}@{self.version}"


LIBRARIES = {
    "gltf": Library(
        "three",
        "0.187.0",
        (("three", "build/three.module.js"), ("three/addons/", "examples/jsm/")),
    ),
    "x3d": Library("x_ite", "15.0.1", (("x_ite", "dist/x_ite.min.mjs"),)),
    "tiles": Library("cesium", "1.145.0", (("cesium", "Build/Cesium/index.js"),)),
}
SCRIPTS = {
    "gltf": ("panel.js", "viewer.js", "gltf.js"),
    "x3d": ("panel.js", "viewer.js", "x3d.js"),
    "tiles": ("panel.js", "tiles.js"),
}
"""The parts of each kind's page script, in order."""
CONTROLS = """\
  <label>distance <input id="distance" type="range" min="0" max="1000" step="1" value="0"></label>
  <label title="A factor on every cutoff: the levels switch at this many times their distances">\
LOD scale
    <input id="lodscale" type="number" min="0" step="any" value="1"></label>
"""
"""The distance slider and LOD scale field of the pages of .x3d and glTF files."""

MIME_TYPES = {
    ".mjs": "text/javascript",
    ".js": "text/javascript",
    ".glb": "model/gltf-binary",
    ".gltf": "model/gltf+json",
    ".x3d": "model/x3d+xml",
}


LIBRARY_MOUNT = "/_lodconvert/viewer-lib"
"""URL path under which :func:`serve` serves a library folder outside the page's folder."""


def page_path(asset: str | Path) -> Path:
    """Where the page of ``asset`` goes by default: beside it, ``.html`` added to its name
    (``a.x3d`` → ``a.x3d.html``, so that the pages of ``a.x3d`` and ``a.glb`` differ)."""
    asset = Path(asset)
    return asset.with_name(f"{asset.name}.html")


def _url(target: Path, start: Path) -> str:
    """Relative URL (``./…`` or ``../…``, as import maps need) of ``target`` seen from the
    folder ``start``; symbolic links are kept, as a web server serving ``start`` follows them."""
    relative = Path(os.path.relpath(os.path.abspath(target), os.path.abspath(start))).as_posix()
    return urllib.parse.quote(relative if relative.startswith("../") else f"./{relative}")


def _outside(library: str | None, page_dir: Path) -> Path | None:
    """``library`` as a folder when it is a local folder outside ``page_dir``: a server of
    ``page_dir`` does not serve it, so the page cannot load it by a relative URL."""
    if library is None or not Path(library).is_dir():
        return None
    return Path(library) if _url(Path(library), page_dir).startswith("../") else None


def library_base(kind: str, library: str | None, page_dir: Path, served: bool = False) -> str:
    """Base URL of the viewer library for a page in ``page_dir``: the CDN by default, a URL as
    given, or a local npm package folder: inside ``page_dir`` as a URL relative to the page,
    outside it :data:`LIBRARY_MOUNT` when the page is ``served`` by :func:`serve` with
    :func:`library_mounts`, and refused otherwise."""
    lib = LIBRARIES[kind]
    if library is None:
        return lib.cdn
    folder = Path(library)
    if folder.is_dir():
        missing = [path for _, path in lib.imports if not (folder / path).exists()]
        if missing:
            raise UsageError(
                f"--viewer-lib {library}: no {missing[0]} there; give the folder of the "
                f"{lib.package} npm package (e.g. node_modules/{lib.package})"
            )
        if _outside(library, page_dir) is None:
            return _url(folder, page_dir)
        if served:
            return LIBRARY_MOUNT
        raise UsageError(
            f"--viewer-lib {library}: outside the page's folder {os.path.abspath(page_dir)}, "
            "so the served page cannot load it; put (or link) it inside that folder, give a "
            "URL, or serve both with 'lodconvert view OUT --serve --viewer-lib DIR'"
        )
    if "://" in library or library.startswith("/"):
        return library.rstrip("/")
    raise UsageError(f"--viewer-lib {library}: not a folder, nor a URL")


def library_mounts(library: str | None, page_dir: Path) -> dict[str, Path]:
    """What :func:`serve` must serve beside ``page_dir`` for a page written with
    ``served=True``: URL path → folder (the library folder, when outside ``page_dir``)."""
    folder = _outside(library, page_dir)
    return {} if folder is None else {LIBRARY_MOUNT: folder}


def _viewer_of(asset: str | Path) -> str | None:
    """The page kind of ``asset``'s format (its registry entry's ``viewer``), if any."""
    try:
        return output_format(asset).viewer
    except UsageError:
        return None


def check_library(asset: str | Path, library: str | None, page: str | Path | None = None) -> None:
    """Raise :class:`~lodconvert.errors.UsageError` unless the page of ``asset`` (which need
    not exist yet), written to be opened from any server of its folder, can use ``library``;
    see :func:`library_base`."""
    kind = _viewer_of(asset)
    if kind is None:
        raise UsageError(f"no viewer page for {Path(asset).suffix or 'files without suffix'}")
    library_base(kind, library, Path(page or page_path(asset)).parent)


def _json_in_html(value: Any) -> str:
    """JSON that is safe inside a ``<script>`` element."""
    return json.dumps(value, separators=(",", ":")).replace("<", "\\u003c")


def _template(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


def render_page(
    asset: Path,
    page: Path,
    library: str | None = None,
    served: bool = False,
    source: Path | None = None,
    limits: Limits = DEFAULT_LIMITS,
) -> str:
    """The HTML of the page at ``page`` showing ``asset`` (``served``: see
    :func:`library_base`); the configuration is read from ``source`` (default ``asset``: a
    staged copy while the run has not committed it), a tileset's within ``limits``."""
    tiles = _viewer_of(asset) == "tiles"
    config = tileset_config(source or asset, limits) if tiles else page_config(source or asset)
    config["asset"] = _url(asset, page.parent)
    kind = config["format"]
    base = library_base(kind, library, page.parent, served)
    imports = {name: f"{base}/{path}" for name, path in LIBRARIES[kind].imports}
    config["library"] = {"package": LIBRARIES[kind].package, "version": LIBRARIES[kind].version}
    if tiles:
        config["library"]["base"] = f"{base}/Build/Cesium/"  # CESIUM_BASE_URL
    what = "tiles" if tiles else "levels"
    fields = {
        "title": html.escape(f"{asset.name} — lodconvert viewer"),
        "asset": html.escape(asset.name),
        "shows": what,
        "summary_title": f"Show or hide the {what}"
        + ("" if tiles else ", the distance slider and the LOD scale"),
        "controls": "" if tiles else CONTROLS,
        "importmap": _json_in_html({"imports": imports}),
        "config": _json_in_html(config),
        "script": "\n".join(_template(name) for name in SCRIPTS[kind]),
    }
    return re.sub(r"\{\{(\w+)\}\}", lambda m: fields[m.group(1)], _template("page.html"))


def write_page(
    asset: str | Path,
    page: str | Path | None = None,
    library: str | None = None,
    served: bool = False,
    limits: Limits = DEFAULT_LIMITS,
) -> Path:
    """Write the viewer page of ``asset`` (atomically; default :func:`page_path`) and return
    its path. Raises :class:`~lodconvert.errors.InputError` for an asset lodconvert did not
    write (or a tileset that cannot be read within ``limits``, that names files outside its
    folder or whose external tilesets form a cycle: :func:`.tileset.tileset_config`) and
    :class:`~lodconvert.errors.UsageError` for a bad ``library`` (one outside the page's
    folder unless ``served``, see :func:`library_base`), both before writing."""
    asset = Path(asset)
    page = Path(page) if page is not None else page_path(asset)
    data = render_page(asset, page, library, served, limits=limits).encode("utf-8")
    with Outputs(inputs=[asset]) as outputs:
        outputs.file(page).write_bytes(data)
        if page.parent == asset.parent and _viewer_of(asset) == "tiles":
            listed = manifest.adding(asset.parent, page.name, data, f"lodconvert {__version__}")
            if listed is not None:  # the tileset's list of its files names the page too
                outputs.file(asset.parent / manifest.NAME).write_bytes(listed)
    return page


class _Handler(SimpleHTTPRequestHandler):
    """Static files with the right types for modules and assets, no caching, no log lines; the
    URL paths in ``mounts`` (and below them) come from their folders instead."""

    extensions_map: ClassVar[dict[str, str]] = {
        **SimpleHTTPRequestHandler.extensions_map,
        **MIME_TYPES,
    }

    def __init__(self, *args: Any, mounts: Mapping[str, Path], **kwargs: Any) -> None:
        self.mounts = mounts
        super().__init__(*args, **kwargs)

    def translate_path(self, path: str) -> str:
        """The file of URL path ``path``: in a mounted folder when under its URL path."""
        bare = path.split("?", 1)[0].split("#", 1)[0]
        for prefix, folder in self.mounts.items():
            if bare == prefix or bare.startswith(f"{prefix}/"):
                inside = super().translate_path(path[len(prefix) :] or "/")
                return os.path.join(folder, os.path.relpath(inside, self.directory))
        return super().translate_path(path)

    def end_headers(self) -> None:
        self.send_header("Cache-Control", "no-store")
        super().end_headers()

    def log_message(self, format: str, *args: Any) -> None:
        """Quiet: the page reports its own problems."""


class _Server(ThreadingHTTPServer):
    """Threads that do not outlive the server; a browser that drops a connection (closing a
    page while it loads) is no error worth a traceback."""

    daemon_threads = True

    def handle_error(self, request: Any, client_address: Any) -> None:
        if not isinstance(sys.exc_info()[1], ConnectionError):
            super().handle_error(request, client_address)


@contextlib.contextmanager
def serve(
    root: str | Path, port: int = 0, mounts: Mapping[str, Path] | None = None
) -> Iterator[str]:
    """Serve the folder ``root`` on 127.0.0.1 (``port`` 0: any free port) from a background
    thread while the ``with`` block runs, and each folder of ``mounts`` (URL path without
    trailing slash → folder) under its URL path; yields the base URL (no trailing slash)."""
    handler = functools.partial(_Handler, directory=str(root), mounts=dict(mounts or {}))
    server = _Server(("127.0.0.1", port), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
        thread.join()


__all__ = [
    "LIBRARIES",
    "LIBRARY_MOUNT",
    "check_library",
    "library_mounts",
    "page_config",
    "page_path",
    "render_page",
    "serve",
    "write_page",
]
