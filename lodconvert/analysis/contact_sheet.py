"""Contact sheets: the source and every level of a chain side by side from a few views, as the
silhouette metric sees them (both covered grey, level only red, source only blue), with a
legend strip and a helper to stack sheets."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from ..model import LodChain, Surface
from ..ranges import REFERENCE_VIEW, ReferenceView
from .evaluate import DEFAULT_DISTANCES, silhouette_scores
from .render import fibonacci_directions
from .silhouette import SilhouetteRenderer

SHEET_VIEWS = 3
SHEET_TILE = 240
SHEET_FONT_PX = 13
SHEET_COLORS = {
    "both": (150, 150, 150),
    "level only": (220, 40, 40),
    "source only": (40, 90, 230),
}


def _coloured(reference: np.ndarray, level: np.ndarray) -> np.ndarray:
    """RGB image (h, w, 3) uint8: both covered grey, level only red, reference only blue."""
    image = np.full((*reference.shape, 3), 255, dtype=np.uint8)
    image[reference & level] = SHEET_COLORS["both"]
    image[level & ~reference] = SHEET_COLORS["level only"]
    image[reference & ~level] = SHEET_COLORS["source only"]
    return image


def _crop_box(masks: list[np.ndarray], margin: int) -> tuple[int, int, int]:
    """A square (top, left, side) around everything covered in ``masks`` (each (views, h, w)),
    ``margin`` pixels wider on every side."""
    covered = np.any(np.stack(masks), axis=(0, 1))
    rows, cols = np.flatnonzero(covered.any(axis=1)), np.flatnonzero(covered.any(axis=0))
    if len(rows) == 0:
        return 0, 0, max(covered.shape)
    side = int(max(rows[-1] - rows[0], cols[-1] - cols[0])) + 1 + 2 * margin
    top = int((rows[0] + rows[-1]) // 2 - side // 2)
    left = int((cols[0] + cols[-1]) // 2 - side // 2)
    return top, left, side


def contact_sheet(
    renderer: SilhouetteRenderer,
    reference: Surface,
    chain: LodChain,
    diagonals: float = DEFAULT_DISTANCES[0],
    views: int = SHEET_VIEWS,
    tile: int = SHEET_TILE,
    view: ReferenceView = REFERENCE_VIEW,
) -> Image.Image:
    """The source and every level of ``chain`` side by side (columns) from ``views`` Fibonacci
    directions (rows), at ``diagonals`` α, as the metric sees them: each level's silhouette
    against the source's, both grey, level only red, source only blue. Tiles are the
    renderer's pixels around the object, enlarged (nearest neighbour) to ``tile`` pixels.
    Captions give each column's count and its F over the views shown."""
    directions = fibonacci_directions(views)
    distance = diagonals * chain.alpha
    center = np.asarray(chain.center, dtype=np.float64)
    geometry = renderer.mesh(reference.vertices, reference.faces)
    source = renderer.render(geometry, center, distance, directions)
    geometry.release()
    columns = [(f"source\n{len(reference.vertices):,} vertices", source)]
    for level in chain.levels:
        geometry = renderer.level(level)
        size = renderer.declared_pixel_size(level, distance, view)
        masks = renderer.render(geometry, center, distance, directions, size or 1.0)
        geometry.release()
        f = silhouette_scores(source, masks)["f"]
        unit = "points" if level.is_points else "vertices"
        columns.append((f"{level.name} {level.count:,} {unit}\nF {f:.3f}", masks))
    top, left, side = _crop_box([masks for _, masks in columns], margin=4)
    font = ImageFont.load_default(size=SHEET_FONT_PX)
    caption = 3 * SHEET_FONT_PX
    sheet = Image.new("RGB", (tile * len(columns), caption + tile * views), "white")
    draw = ImageDraw.Draw(sheet)
    # Padded by one side all round, so the crop window never leaves the image.
    pad = ((0, 0), (side, side), (side, side))
    window = np.s_[top + side : top + 2 * side, left + side : left + 2 * side]
    source_window = np.pad(source, pad)[:, window[0], window[1]]
    for c, (text, masks) in enumerate(columns):
        draw.multiline_text((c * tile + 6, 4), text, fill="black", font=font, spacing=2)
        cropped = np.pad(masks, pad)[:, window[0], window[1]]
        for r in range(views):
            rgb = _coloured(source_window[r], cropped[r])
            image = Image.fromarray(rgb).resize((tile, tile), Image.Resampling.NEAREST)
            sheet.paste(image, (c * tile, caption + r * tile))
    return sheet


def legend(width: int, renderer: SilhouetteRenderer, diagonals: float) -> Image.Image:
    """A strip explaining a contact sheet's colours and scale."""
    font = ImageFont.load_default(size=SHEET_FONT_PX)
    strip = Image.new("RGB", (width, 2 * SHEET_FONT_PX + 8), "white")
    draw = ImageDraw.Draw(strip)
    x = 6
    for name, color in SHEET_COLORS.items():
        draw.rectangle((x, 6, x + SHEET_FONT_PX, 6 + SHEET_FONT_PX), fill=tuple(color))
        x += SHEET_FONT_PX + 4
        draw.text((x, 4), name, fill="black", font=font)
        x += int(draw.textlength(name, font=font)) + 16
    note = (
        f"{diagonals:g} diagonals away, {renderer.width} x {renderer.height} px at "
        f"{renderer.fov_y_deg:g}°, points at their declared size"
    )
    draw.text((x, 4), note, fill="black", font=font)
    return strip


def stack_images(images: Sequence[Image.Image]) -> Image.Image:
    """``images`` one below the other on white, left-aligned."""
    width = max(image.width for image in images)
    out = Image.new("RGB", (width, sum(image.height for image in images)), "white")
    y = 0
    for image in images:
        out.paste(image, (0, y))
        y += image.height
    return out
