"""Far levels of a textured city against their textured source, as a viewer sees them: N
copies of the PLATEAU building (``textured_district.py``) baked with LOD parents of 250 m and
1 km (far levels of blocks, and of simplified meshes), every level drawn in its own colours,
unlit, textures sampled with mipmaps (``lodconvert.analysis.albedo``), from the guard's 24
views of the upper hemisphere at the level's switch-in distance, with the reference view's
focal length (1080 px, 45°), with mipmaps alone and supersampled (each pixel the mean of
those drawn under it). Per tier, the mean CIEDE2000 ΔE of the pixels both show, roofs and walls
apart by the source's face there ("pixels"), of those where the far level shows a face of the
same kind ("same kind": its colours where the geometries agree), and the ΔE of the mean
colours of those pixels ("means"), each a mean over a tier's levels with its largest; and how
far the source's own pixels of each kind lie from their mean colour ("spread": about what a
level in one colour for roofs and one for walls lies from them, were its geometry the
source's, as the tier :data:`FLOOR` draws):

    python benchmarks/texture_colours.py               # 20 copies: results/texture_colours.md
    python benchmarks/texture_colours.py --supersample 1   # mipmaps alone (13 s, not 3 min)

Tiers: ``LOD1`` (each building's LoD1 against its textured LoD2), its floor (:data:`FLOOR`),
``blocks`` and ``mesh``
(each cell's far level against its buildings' finest levels), and ``mesh, baked texture`` (the
simplified far meshes with a texture baked from their buildings' as LOD1 and blocks take one,
in place of their vertex colours), with each level's bytes as a ``.glb`` holds it
uncompressed.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from tables import markdown_table, one_core_facts, write_results
from textured_district import district

HERE = Path(__file__).resolve().parent
FLOOR = "LOD2 in its class means"
"""The tier of each building's textured LoD2 with each face in its roof's or walls' mean colour
over their areas (:func:`in_class_means`): what those two colours give per pixel with no
geometric error, where the LOD1 and block tiers carry textures baked from the source's."""
SUPERSAMPLE = "1,64"
"""Pixels drawn per pixel compared, a side, each a table's rows (each compared pixel their
mean in linear light; at most 2,048 drawn a side): 1 compares what mipmaps alone give, which
for a building a few pixels wide blend whole regions of its texture atlas into each pixel."""


def tiers(
    path: Path, kind: str, renderer: Any, directions: np.ndarray, supersample: int
) -> dict[str, list[dict]]:
    """Per tier, each level's rendered ΔE (and its switch-in distance)."""
    from lodconvert.analysis.albedo import class_delta_e_rendered
    from lodconvert.bake import get_backend
    from lodconvert.bake.far_textures import in_source_textures
    from lodconvert.bakery import iter_chains
    from lodconvert.chain import ChainOptions
    from lodconvert.city.far_mesh import finest_mesh, merge
    from lodconvert.city.hlod import HlodOptions
    from lodconvert.context import RunContext
    from lodconvert.io import read_scene
    from lodconvert.model import CellChain

    hlod = HlodOptions((250.0, 1000.0), kind)
    items = iter_chains(read_scene(path), ChainOptions(), RunContext.here(get_backend("numpy")),
                        hlod=hlod)  # fmt: skip
    cells = [cell for item in items if isinstance(item, CellChain) for cell in item.cells()]
    found: dict[str, list[dict]] = {}
    if kind == "blocks":
        for chain in {id(c): c for cell in cells for c in cell.objects()}.values():
            meshes = [(k, lv) for k, lv in enumerate(chain.levels) if lv.mesh is not None]
            lod1 = [(k, lv) for k, lv in meshes if lv.name == "LOD1" and k > 0]
            if not lod1:
                continue
            k, level = lod1[0]
            distance = chain.cutoffs[k - 1]
            errors = class_delta_e_rendered(renderer, meshes[0][1].mesh, level.mesh, distance,
                                            directions, supersample)  # fmt: skip
            row = {"distance": distance, "bytes": level_bytes(level.mesh), **errors}
            found.setdefault("LOD1", []).append(row)
            flat = in_class_means(meshes[0][1].mesh)
            errors = class_delta_e_rendered(renderer, meshes[0][1].mesh, flat, distance,
                                            directions, supersample)  # fmt: skip
            row = {"distance": distance, "bytes": level_bytes(flat), **errors}
            found.setdefault(FLOOR, []).append(row)
    for cell in cells:
        assert cell.far.mesh is not None
        source = merge([finest_mesh(chain) for chain in cell.objects()]).translated(-cell.origin)
        distance = cell.cutoffs[0]
        levels = {kind: cell.far.mesh}
        if kind == "mesh":  # its vertex colours against a texture baked as LOD1's and blocks'
            pixel = distance / ChainOptions().view.focal_px
            levels["mesh, baked texture"] = in_source_textures(cell.far.mesh, source, pixel)
        for tier, mesh in levels.items():
            errors = class_delta_e_rendered(renderer, source, mesh, distance, directions,
                                            supersample)  # fmt: skip
            row = {"distance": distance, "bytes": level_bytes(mesh), **errors}
            found.setdefault(tier, []).append(row)
    return found


def in_class_means(mesh: Any) -> Any:
    """``mesh`` with each face in one flat colour: its roof's mean colour over the roof's area
    where the face is a roof, else its walls' (:func:`~lodconvert.city.prisms.prism_colors`,
    a prism's colours where its source has no texture), a face's own corners apart from its
    neighbours'."""
    from lodconvert.analysis.albedo import STEEP
    from lodconvert.city.prisms import prism_colors
    from lodconvert.model import Mesh, Surface

    roof, wall = prism_colors(mesh)
    tri = mesh.triangles
    across = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    roofs = across[:, 2] > STEEP * np.linalg.norm(across, axis=1)
    colours = np.where(roofs[:, None], roof, wall).astype(np.uint8)
    faces = np.arange(3 * len(tri), dtype=np.int64).reshape(-1, 3)
    surface = Surface(tri.reshape(-1, 3), faces, vertex_colors=np.repeat(colours, 3, axis=0))
    return Mesh([surface])


def level_bytes(mesh: Any) -> int:
    """Bytes of ``mesh`` in a ``.glb`` as lodconvert writes a level without compression:
    positions (3 floats), vertex colours (4 shorts) or texture coordinates (2 floats), 32-bit
    indices and its images (JPEG for a photograph)."""
    from lodconvert.io.images import encoded

    total = 0
    for part in mesh.parts:
        total += len(part.vertices) * 12 + len(part.faces) * 12
        if part.vertex_colors is not None:
            total += len(part.vertices) * 8
        if part.texture is not None:
            total += len(part.vertices) * 8 + len(encoded(part.texture, part.photographic)[0])
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--copies", type=int, default=20)
    parser.add_argument(
        "--supersample",
        default=SUPERSAMPLE,
        help="pixels drawn per pixel compared, a side; several: each compared (1,64)",
    )
    parser.add_argument("--out", type=Path, default=HERE / "results" / "texture_colours.md")
    args = parser.parse_args()
    from lodconvert.analysis.albedo import AlbedoRenderer
    from lodconvert.views import guard_views, towards_camera

    directions = np.stack([towards_camera(a, e) for a, e in guard_views()])
    start = time.process_time()
    found: dict[tuple[str, int], list[dict]] = {}
    scales = [int(k) for k in str(args.supersample).split(",")]
    with (
        tempfile.TemporaryDirectory(prefix="texture_colours_") as tmp,
        AlbedoRenderer() as renderer,
    ):
        source = district(args.copies, Path(tmp), textured=True)
        for scale in scales:
            for kind in ("blocks", "mesh"):
                for tier, rows in tiers(source, kind, renderer, directions, scale).items():
                    found.setdefault((tier, scale), []).extend(rows)
        name = renderer.renderer_name
    rows = []
    for (tier, scale), levels in found.items():
        distances = [r["distance"] for r in levels]
        drawn = "mipmaps alone" if scale == 1 else f"{scale}× supersampled"
        row = [tier, drawn, f"{len(levels)}", f"{min(distances):,.0f}–{max(distances):,.0f}",
               f"{np.mean([r['bytes'] for r in levels]):,.0f}"]  # fmt: skip
        for key in ("roof", "wall", "roof_same", "wall_same", "roof_mean", "wall_mean"):
            values = [r[key] for r in levels if not math.isnan(r[key])]
            row += [f"{np.mean(values):.1f}", f"{max(values):.1f}"]
        for key in ("roof_spread", "wall_spread"):
            row.append(f"{np.nanmean([r[key] for r in levels]):.1f}")
        rows.append(row)
    header = ["tier", "drawn", "levels", "switch-in m", "bytes a level", "roof pixels ΔE", "max",
              "wall pixels ΔE", "max", "roof, same kind", "max", "wall, same kind", "max",
              "roof means ΔE", "max", "wall means ΔE", "max", "source roof spread",
              "source wall spread"]  # fmt: skip
    text = "\n".join(
        [
            f"# Far levels of {args.copies} textured PLATEAU copies against their textures, drawn",
            "",
            *one_core_facts(
                f"python benchmarks/texture_colours.py --copies {args.copies} "
                f"--supersample {args.supersample}",
                time.process_time() - start,
            ),
            f"- Renderer: {name}",
            "",
            __doc__.split("\n\n")[0].replace("\n", " "),
            "",
            markdown_table(header, rows, 2),
            "",
            "Drawn: with mipmaps alone, a pixel on a building a few pixels wide samples coarse "
            "mipmaps, which blend whole regions of its texture atlas (walls, roof and unused "
            "texels) into one colour; supersampled, each pixel compared is the mean, in linear "
            "light, of the pixels drawn under it, each of a texture's own texels (at most 2,048 "
            "a side in all): what the surfaces under the pixel show.",
            "",
        ]
    )
    write_results(args.out, text)
    print(text)


if __name__ == "__main__":
    main()
