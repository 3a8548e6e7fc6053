"""``lodconvert view OUT``: write the viewer page of an output (and optionally serve it)."""

from __future__ import annotations

import argparse
import threading
import urllib.parse

from ...limits import DEFAULT_LIMITS
from ...viewer import library_mounts, serve, write_page
from ..console import Console
from ..options import EXIT_OK, add_limit_option, add_viewer_lib_option

DESCRIPTION = (
    "Write a self-contained HTML page beside an .x3d, .glb or .gltf written by lodconvert that "
    "shows it switching levels at its cutoffs, with a readout of each object's level and "
    "distance; for a 3D Tiles DIR/tileset.json, a CesiumJS page inside DIR with the tiles "
    "selected and the tile and building under the pointer. The page loads its viewer library "
    "(X_ITE for X3D, three.js for glTF, CesiumJS for tilesets) from a CDN "
    "unless --viewer-lib names another URL or a local copy of the npm package: one inside the "
    "page's folder, or anywhere with --serve, which then serves it too."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``lodconvert view``."""
    parser.add_argument(
        "asset", metavar="OUT", help="an .x3d, .glb, .gltf or DIR/tileset.json lodconvert wrote"
    )
    parser.add_argument(
        "-o", "--output", metavar="HTML", help="page to write (default: OUT.html, e.g. a.glb.html)"
    )
    add_viewer_lib_option(parser)
    parser.add_argument(
        "--serve",
        action="store_true",
        help="then serve the page's folder (and a --viewer-lib folder outside it) on 127.0.0.1 "
        "and print the page's URL (Ctrl-C stops)",
    )
    parser.add_argument("--port", type=int, default=0, help="port for --serve (default: any)")
    add_limit_option(parser, "tileset_json_bytes=64M")
    parser.add_argument("-q", "--quiet", action="store_true", help="print errors only")


def run(args: argparse.Namespace, console: Console) -> int:
    """Write the page; with --serve, serve its folder (and the library's) until interrupted."""
    limits = DEFAULT_LIMITS.with_text(args.limit)
    page = write_page(args.asset, args.output, args.viewer_lib, served=args.serve, limits=limits)
    console.info(f"wrote {page}")
    if args.serve:
        mounts = library_mounts(args.viewer_lib, page.parent)
        with serve(page.parent, args.port, mounts) as base:
            print(f"{base}/{urllib.parse.quote(page.name)}", flush=True)
            threading.Event().wait()  # until Ctrl-C, which the command line reports
    return EXIT_OK
