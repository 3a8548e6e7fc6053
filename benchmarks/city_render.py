"""Walks and flights through cities, frame by frame: ProxyPrismLOD's range against prism
switching, and Lee, Kim & Kim's LOD parent with its line-of-sight LOD scale.

    python benchmarks/city_render.py              # writes results/city_render.md
    python benchmarks/city_render.py --quick      # 3 short walks, the 1× and 10× districts
    python benchmarks/city_render.py --factors 1,10 --flight-frames 20 --only parent

Counting is :mod:`lodconvert.analysis.city_select`'s and drawing
:mod:`lodconvert.analysis.city_render`'s: per frame the vertices + points and draw calls (one
per level part) each mode submits — machine-independent, from the camera positions alone —
and, where an EGL context can be made, the frame time of drawing them on a 1920×1080
framebuffer with moderngl; nothing is extrapolated.

**ProxyPrismLOD** (Polys, Singh & Sforza 2016, Tables I–II). A 20×20 grid of square plots
(:data:`PLOT_SIDE` m) holds 100 each of four buildings, assigned to plots and turned by
quarter turns at random (seed ``--seed``): the SIG3D house (its five files read together: LoD4
… LoD1) and three made here — a gabled slab, a tower, an L-shaped block — each with LoD3-like
detail (windows standing out of the façades), LoD2 (walls and roof) and a prism LOD1 (the
blocks' footprints extruded to the roof's top, given as the source's lod1: the prism lodconvert
derives follows the finest geometry's outline, windows included, and would be heavier than
LoD2). LoD3 is there so that the scripted buildings switch inside the grid: a LoD2-finest
chain switches only at Y(1.0) = α·β·γ, beyond the grid for them. Each model is
baked once with γ = the plot radius (half the plot side, what lodconvert derives from the
spacing) and placed by its chain's ``transform``. ``--paths`` random straight walks of
``--duration`` s at 20 m/s, :data:`WALK_ALTITUDE` m above the street and pitched
:data:`WALK_PITCH_DEG`° down, are sampled every simulated 1/30 s and drawn with range and with
prism switching (frustum culling on in both), at 45° and 75° vertical field of view.

**LOD parent** (Lee, Kim & Kim 2018, Figs. 6–7). TUM Munich (the zip) and districts of shifted
copies of it (``benchmarks/city.py``'s ``write_district``; ``--factors``, default 1 and 100) are
baked with
``iter_chains(..., hlod=HlodOptions((250, 1000), "auto"))``; the one-tier configuration (250 m
cells) is that bake's finest tier, which :func:`lodconvert.city.cell_bake.bake_cell` makes from the
cells' own members alone, as a ``(250,)`` bake would (``tests/test_city_render.py`` holds the two
equal). Flights at each ``--altitudes`` cross the district along x through its middle,
pitched :data:`FLIGHT_PITCH_DEG`° down, ``--flight-frames`` evenly spaced positions each, in
the modes of :data:`PARENT_MODES`, with and without the LOD scale ``s`` (every cutoff times
``s``, :func:`~lodconvert.analysis.line_of_sight.lod_scale`).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import importlib.metadata
import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from city import DATA, TUM, Template, factor_list, tum_document, write_district
from objects import ROOT, cpu_model, source_state, versions
from tables import markdown_table, write_results

from lodconvert.analysis.city_cameras import flight_cameras, random_walks, walk_cameras
from lodconvert.analysis.city_draw import CityDraw, city_draw
from lodconvert.analysis.city_render import CityRenderer, PathStats, walk
from lodconvert.analysis.city_select import Mode
from lodconvert.analysis.line_of_sight import (
    REFERENCE_ALTITUDE,
    REFERENCE_FOV_DEG,
    REFERENCE_LOS,
    REFERENCE_PITCH_DEG,
    lod_scale,
    los_average,
)
from lodconvert.bake import get_backend
from lodconvert.bakery import iter_chains
from lodconvert.chain import ChainOptions
from lodconvert.city.hlod import HlodOptions
from lodconvert.context import RunContext
from lodconvert.errors import LodConvertError
from lodconvert.inputs import merged
from lodconvert.io import read_scene
from lodconvert.model import CellChain, LodChain, Mesh, Node, Surface
from lodconvert.plans import bake_chain

HERE = Path(__file__).resolve().parent
SIG3D = DATA / "citygml" / "sig3d_house_lod0-4"
GRID = 20
"""Plots per side of the ProxyPrismLOD city."""
PLOT_SIDE = 30.0
"""Side of a square plot, metres; γ = half of it."""
SPEED = 20.0
"""Walking speed, m/s."""
FRAME_STEP = 1.0 / 30.0
"""Simulated seconds between two frames of a walk."""
WALK_ALTITUDE = 50.0
WALK_PITCH_DEG = 15.0
FOVS = (45.0, 75.0)
PAPER_PRISM = {45.0: 2.36, 75.0: 3.96, "max": 7.46}
"""ProxyPrismLOD's mean FPS gain of prisms over ranges, % per FOV, and its largest."""
HLOD_SIZES = (250.0, 1000.0)
FLIGHT_PITCH_DEG = 45.0
FLIGHT_FOV_DEG = 45.0
TARGET_CALL_RATIO = 5.0
"""LOD parents must draw at most 1/5 of per-building LOD's draw calls at the highest altitude."""
TARGET_F = 0.95
UNITY_HLOD = "Unity's HLOD system reports 5,642 → 952 draw calls (5.9× fewer)"
PRISM_MODES = (Mode("range"), Mode("prism", switching="prism"))
PARENT_MODES = (
    Mode("no LOD", culling=False, lod=False),
    Mode("frustum culling", lod=False),
    Mode("culling + LOD"),
    Mode("culling + LOD, scaled", los_scale=True),
    Mode("+ LOD parent 250 m", tiers=1),
    Mode("+ LOD parent 250 m, scaled", tiers=1, los_scale=True),
    Mode("+ LOD parents 250/1000 m", tiers=2),
    Mode("+ LOD parents 250/1000 m, scaled", tiers=2, los_scale=True),
)
"""The LOD-parent flight's modes; "scaled": every cutoff times the LOD scale."""


def log(text: str) -> None:
    """Progress on stderr."""
    print(text, file=sys.stderr, flush=True)


# --- the four building models -------------------------------------------------------------------


def boxes(low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8n, 3) and outward faces (12n, 3) of n axis-aligned boxes (n, 3) corners."""
    low, high = np.atleast_2d(low).astype(float), np.atleast_2d(high).astype(float)
    corner = np.array([[i & 1, i >> 1 & 1, i >> 2 & 1] for i in range(8)], dtype=bool)
    vertices = np.where(corner[None], high[:, None], low[:, None]).reshape(-1, 3)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return vertices, (faces[None] + 8 * np.arange(len(low))[:, None, None]).reshape(-1, 3)


def surface(pieces: Sequence[tuple[np.ndarray, np.ndarray]], rgb: tuple[int, int, int]) -> Surface:
    """One coloured part from (vertices, faces) pieces."""
    offsets = np.cumsum([0] + [len(v) for v, _ in pieces[:-1]])
    vertices = np.concatenate([v for v, _ in pieces])
    faces = np.concatenate([f + o for (_, f), o in zip(pieces, offsets, strict=True)])
    return Surface(vertices, faces, base_color=np.array([*rgb, 255], dtype=np.uint8))


def gable(x0: float, y0: float, x1: float, y1: float, eaves: float, ridge: float) -> tuple:
    """A gabled roof over a rectangle, its ridge along x: (vertices, faces)."""
    ym = (y0 + y1) / 2.0
    v = [(x0, y0, eaves), (x1, y0, eaves), (x1, y1, eaves), (x0, y1, eaves)]
    v += [(x0, ym, ridge), (x1, ym, ridge)]
    faces = [(0, 1, 5), (0, 5, 4), (2, 3, 4), (2, 4, 5), (0, 4, 3), (1, 2, 5), (0, 3, 2), (0, 2, 1)]
    return np.array(v, dtype=float), np.array(faces)


def windows(low: np.ndarray, high: np.ndarray, floors: int) -> tuple[np.ndarray, np.ndarray]:
    """Windows (1.2 × 1.4 m, 0.25 m deep) standing out of the four façades of a block, one per
    3 m bay and floor: (vertices, faces)."""
    lows, highs = [], []
    for axis in (0, 1):
        along = np.arange(low[axis] + 1.5, high[axis] - 1.0, 3.0)
        for side, out in ((low[1 - axis], -0.25), (high[1 - axis], 0.25)):
            for z in 1.0 + 3.0 * np.arange(floors):
                a = np.zeros((len(along), 3))
                a[:, axis], a[:, 1 - axis], a[:, 2] = along - 0.6, side, z
                b = a.copy()
                b[:, axis] += 1.2
                b[:, 1 - axis] += out
                b[:, 2] += 1.4
                lows.append(np.minimum(a, b))
                highs.append(np.maximum(a, b))
    return boxes(np.concatenate(lows), np.concatenate(highs))


def scripted(name: str, blocks: list[tuple[np.ndarray, np.ndarray]], roof: tuple) -> Node:
    """A building of ``blocks`` (low, high corners) and a ``roof`` piece: LoD3 walls, roof and
    windows; LoD2 walls and roof; LOD1 the prism of the blocks' footprints up to the roof's
    top."""
    walls = surface([boxes(low, high) for low, high in blocks], (225, 215, 190))
    top = surface([roof], (170, 70, 50))
    floors = [int(high[2] // 3) for _, high in blocks]
    glass = surface([windows(lo, hi, n) for (lo, hi), n in zip(blocks, floors, strict=True)],
                    (60, 90, 120))  # fmt: skip
    height = float(roof[0][:, 2].max())
    prism = [boxes(low, np.array([high[0], high[1], height])) for low, high in blocks]
    lods = {"lod3": Mesh([walls, top, glass]), "lod2": Mesh([walls, top])}
    lods["lod1"] = Mesh([surface(prism, (200, 200, 200))])
    return Node(name, geometry=lods["lod3"], type="Building", lods=lods)


def scripted_models() -> list[Node]:
    """The slab, the tower and the L-shaped block, footprints centred on the origin."""
    a = np.array
    slab = scripted("slab", [(a([-12, -4, 0]), a([12, 4, 12]))], gable(-12, -4, 12, 4, 12, 15))
    tower = scripted(
        "tower", [(a([-5, -5, 0]), a([5, 5, 36]))], boxes(a([-2, -2, 36]), a([2, 2, 39]))
    )
    l_block = scripted(
        "l_block",
        [(a([-11, -11, 0]), a([11, -3, 12])), (a([-11, -3, 0]), a([-3, 11, 12]))],
        boxes(a([[-11, -11, 12], [-11, -3, 12]]), a([[11, -3, 12.5], [-3, 11, 12.5]])),
    )
    return [slab, tower, l_block]


def sig3d_house() -> Node:
    """The SIG3D house from its five files, its footprint centred on the origin, base at 0."""
    files = sorted(SIG3D.glob("Building_LOD*-EPSG25832.gml"))
    (node,) = merged([read_scene(path) for path in files]).with_geometry()
    low, high = node.geometry.bounds
    shift = -np.array([(low[0] + high[0]) / 2.0, (low[1] + high[1]) / 2.0, low[2]])
    lods = {label: mesh.translated(shift) for label, mesh in node.lods.items()}
    return replace(node, id="sig3d", geometry=node.geometry.translated(shift), lods=lods)


def placed(chain: LodChain, name: str, x: float, y: float, quarter_turns: int) -> LodChain:
    """``chain`` turned about the vertical axis by quarter turns and moved to (x, y)."""
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][quarter_turns % 4]
    matrix = np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)
    return replace(chain, object_id=name, transform=matrix)


def prism_city(seed: int) -> tuple[CityDraw, list[LodChain], list[str]]:
    """The 20×20 plots with 100 of each model; the city, the models' chains and their names."""
    options = ChainOptions(gamma=PLOT_SIDE / 2.0)
    models = [sig3d_house(), *scripted_models()]
    chains = [bake_chain(node, options, get_backend("numpy")) for node in models]
    rng = np.random.default_rng(seed)
    kinds = rng.permutation(np.repeat(np.arange(len(chains)), GRID * GRID // len(chains)))
    turns = rng.integers(0, 4, GRID * GRID)
    plots = []
    for k, (kind, turn) in enumerate(zip(kinds, turns, strict=True)):
        row, column = divmod(k, GRID)
        x, y = (column + 0.5) * PLOT_SIDE, (row + 0.5) * PLOT_SIDE
        plots.append(placed(chains[kind], f"{models[kind].id}_{k}", x, y, int(turn)))
    return city_draw(plots), chains, [node.id for node in models]


# --- experiment 1: range against prism ----------------------------------------------------------


@dataclass
class PrismRun:
    """Every walk at one field of view: the statistics per mode, per walk."""

    fov: float
    walks: list[dict[str, PathStats]]

    def ratios(self) -> list[float | None]:
        """FPS ratio prism / range per walk (median range frame time / median prism's)."""
        out = []
        for stats in self.walks:
            by_range, by_prism = stats["range"].median_ms, stats["prism"].median_ms
            out.append(by_range / by_prism if by_range and by_prism else None)
        return out


def run_prism(
    args: argparse.Namespace, renderer: CityRenderer | None
) -> tuple[list[PrismRun], dict[str, Any]]:
    """Experiment 1: the city, every walk at every field of view, in both switchings."""
    started = time.perf_counter()
    city, chains, names = prism_city(args.seed)
    rng = np.random.default_rng(args.seed)
    area, ground = city.bounds[:, :2], float(city.bounds[0, 2])
    walks = random_walks(rng, area, args.paths, SPEED * args.duration, WALK_ALTITUDE, ground)
    if renderer is not None:
        renderer.load(city)
    runs = []
    for fov in FOVS:
        results = []
        for i, (start, end) in enumerate(walks):
            cameras = walk_cameras(start, end, SPEED, FRAME_STEP, WALK_PITCH_DEG, fov)
            log(f"prism: FOV {fov:g}°, walk {i + 1}/{len(walks)} ({len(cameras)} frames)")
            results.append(walk(city, cameras, PRISM_MODES, renderer=renderer))
        runs.append(PrismRun(fov, results))
    facts = {
        "models": list(zip(names, chains, strict=True)),
        "objects": city.objects,
        "walks": walks,
        "seconds": time.perf_counter() - started,
    }
    return runs, facts


def model_text(names_chains: list[tuple[str, LodChain]]) -> list[str]:
    """A table of the four models' levels and cutoffs."""
    rows = []
    for name, chain in names_chains:
        levels = ", ".join(
            f"{lv.name} {lv.kind} {lv.count} v / {len(lv.mesh.parts) if lv.mesh else 1} calls"
            for lv in chain.levels
        )
        cutoffs = ", ".join(f"{c:.0f}" for c in chain.cutoffs)
        rows.append([name, f"{chain.alpha:.1f}", levels, cutoffs])
    return [
        markdown_table(["model", "α m", "levels (vertices / draw calls)", "cutoffs m"], rows, 3)
    ]


def ms(value: float | None) -> str:
    """A frame time in ms, or a dash."""
    return "–" if value is None else f"{value:.2f}"


def counts(stats: PathStats) -> list[str]:
    """Median and maximum vertices + points and draw calls."""
    r = stats.record()
    return [
        f"{r['vertices_median']:,.0f} / {r['vertices_max']:,}",
        f"{r['calls_median']:,.0f} / {r['calls_max']:,}",
    ]


def prism_text(runs: list[PrismRun], facts: dict[str, Any], timed: bool) -> list[str]:
    """Experiment 1's section."""
    lines = [
        "## ProxyPrismLOD: range against prism switching",
        "",
        f"{facts['objects']} buildings on {GRID}×{GRID} plots of {PLOT_SIDE:g} m (γ ="
        f" {PLOT_SIDE / 2:g} m), 100 of each model; {len(facts['walks'])} walks of"
        f" {len(runs[0].walks[0]['range'].calls)} frames ({SPEED:g} m/s, a frame every"
        f" {FRAME_STEP * 1e3:.1f} simulated ms), {WALK_ALTITUDE:g} m above the street, pitched"
        f" {WALK_PITCH_DEG:g}° down; {facts['seconds']:.0f} s in all.",
        "",
        *model_text(facts["models"]),
        "",
    ]
    header = ["walk", "range ms", "range 5 % low", "prism ms", "prism 5 % low", "FPS prism/range"]
    header += ["range vertices med / max", "range calls med / max"]
    header += ["prism vertices med / max", "prism calls med / max"]
    for run in runs:
        rows = []
        for i, (stats, ratio) in enumerate(zip(run.walks, run.ratios(), strict=True)):
            r, p = stats["range"], stats["prism"]
            row = [str(i + 1), ms(r.median_ms), ms(r.low_ms), ms(p.median_ms), ms(p.low_ms)]
            row.append("–" if ratio is None else f"{ratio:.3f}")
            rows.append(row + counts(r) + counts(p))
        lines += [f"### Vertical field of view {run.fov:g}°", "", markdown_table(header, rows, 1)]
        lines += ["", *prism_summary(run, timed), ""]
    return lines


def prism_summary(run: PrismRun, timed: bool) -> list[str]:
    """The mean and largest FPS gain against the paper's, and the counts behind them."""
    extra = [
        statistics.mean(
            p / r - 1.0 for r, p in zip(s["range"].vertices, s["prism"].vertices, strict=True) if r
        )
        for s in run.walks
    ]
    count_text = (
        f"prisms submit {100 * statistics.mean(extra):+.2f} % vertices + points per frame on"
        f" average (per walk {min(extra) * 100:+.2f} … {max(extra) * 100:+.2f} %)"
    )
    ratios = [r for r in run.ratios() if r is not None]
    paper = (
        f"the paper: {PAPER_PRISM[run.fov]:+.2f} % on average, up to {PAPER_PRISM['max']:+.2f} %"
    )
    if not (timed and ratios):
        return [f"- FOV {run.fov:g}°: frame times not measured; {count_text} ({paper})."]
    mean = 100 * (statistics.mean(ratios) - 1.0)
    best = 100 * (max(ratios) - 1.0)
    worst = 100 * (min(ratios) - 1.0)
    return [
        f"- FOV {run.fov:g}°: FPS prism/range {mean:+.2f} % on average over the walks"
        f" ({worst:+.2f} … {best:+.2f} %); {paper}. Counts: {count_text}."
    ]


# --- experiment 2: LOD parents ------------------------------------------------------------------


@dataclass
class District:
    """A baked district and its flights: statistics per altitude and mode, LOD scale per
    altitude."""

    name: str
    city: CityDraw
    bake_seconds: float
    flights: dict[float, dict[str, PathStats]]
    scales: dict[float, float]


def district_items(
    factor: int, template: Template | None, folder: Path
) -> list[LodChain | CellChain]:
    """The district of ``factor`` copies of TUM Munich baked into two tiers of LOD parents."""
    path = TUM
    if factor > 1:
        assert template is not None
        path = folder / f"tum_{factor}x.gml"
        write_district(template, factor, path)
    try:
        scene = read_scene(path)
        hlod = HlodOptions(HLOD_SIZES, "auto")
        return list(
            iter_chains(scene, ChainOptions(), RunContext.here(get_backend("numpy")), hlod=hlod)
        )
    finally:
        if path != TUM:
            path.unlink()


def run_district(
    factor: int,
    template: Template | None,
    folder: Path,
    args: argparse.Namespace,
    renderer: CityRenderer | None,
) -> District:
    """Bake one district and fly over it at every altitude in every mode."""
    started = time.perf_counter()
    log(f"parent: baking the {factor}× district")
    city = city_draw(district_items(factor, template, folder))
    baked = time.perf_counter() - started
    log(f"parent: {city.objects:,} buildings, {len(city.cell_ids)} cells in {baked:.0f} s")
    if renderer is not None:
        renderer.load(city)
    area, ground = city.bounds[:, :2], float(city.bounds[0, 2])
    flights, scales = {}, {}
    for altitude in args.altitudes:
        cameras = flight_cameras(
            area, altitude, FLIGHT_PITCH_DEG, args.flight_frames, FLIGHT_FOV_DEG, ground
        )
        scales[altitude] = lod_scale(altitude, FLIGHT_PITCH_DEG, FLIGHT_FOV_DEG)
        log(f"parent: {factor}×, flight at {altitude:g} m (s = {scales[altitude]:.2f})")
        flights[altitude] = walk(city, cameras, PARENT_MODES, scales[altitude], renderer)
    name = "TUM Munich" if factor == 1 else f"{factor}× TUM Munich"
    return District(name, city, baked, flights, scales)


def cell_f_text(city: CityDraw, cells: np.ndarray) -> str:
    """Min and median silhouette F of the far levels of ``cells`` and how many reach 0.95."""
    f = city.cell_f[cells]
    f = f[np.isfinite(f)]
    if not len(f):
        return "no cell"
    return (
        f"F min {f.min():.3f}, median {np.median(f):.3f}, {int((f >= TARGET_F).sum())} of"
        f" {len(f)} ≥ {TARGET_F}"
    )


def target_lines(district: District) -> list[str]:
    """The LOD-parent target at the highest altitude, for one and two tiers, both scalings."""
    top = max(district.flights)
    stats = district.flights[top]
    city = district.city
    lines = []
    for tiers, label in ((1, "+ LOD parent 250 m"), (2, "+ LOD parents 250/1000 m")):
        used = np.flatnonzero(city.cell_tier <= tiers)
        for suffix, base in (("", "culling + LOD"), (", scaled", "culling + LOD, scaled")):
            parent = stats[label + suffix]
            lod = statistics.median(stats[base].calls)
            calls = statistics.median(parent.calls)
            ratio = lod / calls if calls else math.inf
            shown = np.array(sorted(parent.far_cells), dtype=np.int64)
            met = "met" if ratio >= TARGET_CALL_RATIO else "NOT met"
            lines.append(
                f"- {district.name}, {top:g} m, {label}{suffix}: {lod:,.0f} → {calls:,.0f} draw"
                f" calls (median), {ratio:.1f}× fewer — {met}; far levels of all"
                f" {len(used)} cells: {cell_f_text(city, used)}; of the {len(shown)} shown:"
                f" {cell_f_text(city, shown)}."
            )
    return lines


def spread(values: np.ndarray) -> str:
    """Minimum, quartiles and maximum of some distances, metres."""
    return " / ".join(f"{v:,.0f}" for v in np.percentile(values, [0, 25, 50, 75, 100]))


def switch_lines(city: CityDraw) -> list[str]:
    """Where the cells switch to their far level and the buildings to their coarsest level
    (minimum / quartiles / maximum): what a flight must see beyond for a far level to show."""
    levels = (city.level_parts > 0).sum(axis=1)
    last = np.take_along_axis(city.cutoffs, np.maximum(levels - 2, 0)[:, None], axis=1)[:, 0]
    coarsest = np.where(levels >= 2, last, 0.0)
    lines = [f"- buildings' switch to their coarsest level, m: {spread(coarsest)}"]
    for tier in sorted(set(city.cell_tier.tolist())):
        switch = city.cell_cutoffs[city.cell_tier == tier, 0]
        lines.append(f"- tier-{tier} cells' switch to their far level, m: {spread(switch)}")
    return lines


def district_text(district: District, timed: bool) -> list[str]:
    """One district's section: bake facts, a table per altitude."""
    city = district.city
    tiers = {t: int((city.cell_tier == t).sum()) for t in sorted(set(city.cell_tier.tolist()))}
    lines = [
        f"### {district.name}",
        "",
        f"{city.objects:,} buildings; cells per tier {tiers}; made and baked (district GML"
        f" written, read, levels, cells) in {district.bake_seconds:.0f} s."
        f" {cell_f_text(city, np.arange(len(city.cell_ids)))} (over every cell, both tiers).",
        "",
        *switch_lines(city),
        "",
    ]
    header = ["mode", "ms", "5 % low ms", "vertices + points med / max", "calls med / max"]
    for altitude, stats in district.flights.items():
        rows = []
        for mode in PARENT_MODES:
            s = stats[mode.name]
            rows.append([mode.name, ms(s.median_ms), ms(s.low_ms), *counts(s)])
        lines += [
            f"**{altitude:g} m** (LOD scale s = {district.scales[altitude]:.3f},"
            f" {len(stats[PARENT_MODES[0].name].calls)} positions)",
            "",
            markdown_table(header, rows, 1),
            "",
        ]
    if not timed:
        lines.append("(frame times not measured)")
    return lines


def scale_table(altitudes: Sequence[float]) -> str:
    """LOS average and LOD scale per altitude at the flights' pitch and field of view."""
    rows = []
    for h in altitudes:
        los = los_average(h, FLIGHT_PITCH_DEG, FLIGHT_FOV_DEG)
        scale = lod_scale(h, FLIGHT_PITCH_DEG, FLIGHT_FOV_DEG)
        rows.append([f"{h:g}", f"{los:,.0f}", f"{scale:.3f}"])
    return markdown_table(["altitude m", "mean line of sight m", "LOD scale s"], rows, 0)


# --- report -------------------------------------------------------------------------------------


def software() -> str:
    """Python and package versions, moderngl included."""
    with contextlib.suppress(importlib.metadata.PackageNotFoundError):
        return f"{versions()}, moderngl {importlib.metadata.version('moderngl')}"
    return versions()


def header_lines(
    renderer_name: str | None, date: str, command: str, elapsed: float, load: tuple
) -> list[str]:
    """Title, start date, machine, software, command and the method."""
    gl = (
        f"{renderer_name} (Mesa's software rasteriser on the CPU: no GPU; frame times are this"
        " machine's, not a GPU's, and nothing is extrapolated)"
        if renderer_name and "llvmpipe" in renderer_name
        else renderer_name or "none (`--no-gl`, or no EGL context): counts only, no frame times"
    )
    return [
        "# City render benchmark: range vs prism switching, LOD parents and the LOD scale",
        "",
        f"- Date: {date}",
        f"- Machine: {cpu_model()}, {os.cpu_count()} CPUs; load average (1 min) {load[0]:.1f}"
        f" at the start, {load[1]:.1f} at the end",
        f"- GL renderer: {gl}",
        f"- Software: {software()}; source: {source_state(None, None)}",
        f"- Command: `{command}` ({elapsed:.0f} s)",
        "- Frames: 1920×1080, depth test, unlit vertex colours, one draw call per level part"
        " (a mesh level's surfaces, a point level); per frame the vertices + points and draw"
        " calls the mode selects (machine-independent) and the time from a finished pipeline"
        " through clear and draws to `ctx.finish()` (selection not included), after one"
        " untimed frame per mode; modes interleaved frame by frame. *ms* = median frame time;"
        " *5 % low* = the 95th-percentile frame time (the 5th-percentile frame rate).",
        "- Switching: *range* = distance from the viewer to the chain centre against the"
        " cutoffs (X3D LOD); *prism* = the smallest of the boxes (the finest level's"
        " axis-aligned box grown by each cutoff on every side) holding the viewer (nested X3D"
        " ProximitySensors). Frustum culling by bounding spheres (α/2) in every mode but"
        " *no LOD*.",
    ]


def parent_text(districts: list[District], timed: bool, altitudes: Sequence[float]) -> list[str]:
    """Experiment 2's section."""
    lines = [
        "## LOD parents and the LOD scale",
        "",
        f"Flights along x through the district's middle at {FLIGHT_PITCH_DEG:g}° below the"
        f" horizontal, {FLIGHT_FOV_DEG:g}° vertical field of view; the centre of the view sweeps"
        " the district from its west edge to its east edge. LOD parents: a cell in the frustum"
        " at least its switch distance (`cutoffs[0]`) away draws its far level instead of its"
        " members; nearer, its members are resolved (finer cells, then buildings with their"
        " own levels and culling); outside the frustum (bounding sphere) it is culled whole."
        " *scaled*: every cutoff, buildings' and cells', times the LOD scale s.",
        "",
        "**LOD scale** (`lodconvert.analysis.line_of_sight.lod_scale`): s = mean line of sight /"
        f" reference, the mean over the vertical field of view of the ray's distance to the"
        f" ground (h / sin φ, rays beyond 20 km or above the horizon counted as 20 km); the"
        f" reference is the mean line of sight at {REFERENCE_ALTITUDE:g} m, pitched"
        f" {REFERENCE_PITCH_DEG:g}°, {REFERENCE_FOV_DEG:g}° field of view ({REFERENCE_LOS:.0f} m),"
        " where s = 1:",
        "",
        scale_table(altitudes),
        "",
        f"**Target**: at the highest altitude, LOD parents draw ≤ 1/{TARGET_CALL_RATIO:g} of"
        f" per-building LOD's draw calls with far levels of silhouette F ≥ {TARGET_F}"
        f" ({UNITY_HLOD})."
        " F is each cell's far level against its members' finest geometry at its switch-in"
        " distance, as the planner measured it (`facts['silhouette_f'][facts['kind']]`).",
        "",
    ]
    for district in districts:
        lines += target_lines(district)
    lines.append("")
    for district in districts:
        lines += district_text(district, timed)
    return lines


def parse_args(argv: list[str]) -> argparse.Namespace:
    """The command line; ``--quick`` lowers the defaults it is given with."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", action="store_true", help="3 walks of 3 s; 1× and 10×; 8 positions"
    )
    parser.add_argument("--only", choices=("prism", "parent"), help="run one experiment")
    parser.add_argument("--seed", type=int, default=2016, help="plots and walks (2016)")
    parser.add_argument("--paths", type=int, help="random walks (10; quick 3)")
    parser.add_argument("--duration", type=float, help="seconds per walk (12; quick 3)")
    parser.add_argument(
        "--factors", type=factor_list, metavar="N,..",
        help="districts in copies of TUM Munich (1,100; quick 1,10)",
    )  # fmt: skip
    parser.add_argument(
        "--altitudes", type=lambda t: [float(v) for v in t.split(",")],
        default=[100.0, 300.0, 600.0, 1200.0, 2500.0, 5000.0], metavar="H,..",
        help="flight altitudes, m",
    )  # fmt: skip
    parser.add_argument("--flight-frames", type=int, help="positions per flight (24; quick 8)")
    parser.add_argument("--no-gl", action="store_true", help="count only, draw nothing")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "city_render.md")
    args = parser.parse_args(argv)
    defaults = {"paths": (10, 3), "duration": (12.0, 3.0), "flight_frames": (24, 8)}
    defaults["factors"] = ([1, 100], [1, 10])
    for key, (full, quick) in defaults.items():
        if getattr(args, key) is None:
            setattr(args, key, quick if args.quick else full)
    return args


def make_renderer(no_gl: bool) -> CityRenderer | None:
    """A renderer, or None (counts only) without EGL or with ``--no-gl``."""
    if no_gl:
        return None
    try:
        return CityRenderer()
    except LodConvertError as exc:
        log(f"no frame times: {exc}")
        return None


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    started, load_start = time.perf_counter(), os.getloadavg()[0]
    date = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    renderer = make_renderer(args.no_gl)
    timed = renderer is not None
    name = renderer.renderer_name if renderer is not None else None
    body: list[str] = []
    try:
        if args.only != "parent":
            runs, facts = run_prism(args, renderer)
            body += ["", *prism_text(runs, facts, timed)]
        if args.only != "prism" and TUM.is_file():
            template = Template(tum_document()) if max(args.factors) > 1 else None
            with tempfile.TemporaryDirectory(prefix="lodconvert-city-render-") as tmp:
                districts = [
                    run_district(f, template, Path(tmp), args, renderer) for f in args.factors
                ]
            body += ["", *parent_text(districts, timed, args.altitudes)]
    finally:
        if renderer is not None:
            renderer.release()
    command = "python " + " ".join([os.path.relpath(__file__, ROOT), *argv])
    load = (load_start, os.getloadavg()[0])
    head = header_lines(name, date, command, time.perf_counter() - started, load)
    write_results(args.out, "\n".join([*head, *body]) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
