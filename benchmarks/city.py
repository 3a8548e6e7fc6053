"""City-model conversion speed and memory of the CLI, end to end on one core.

Converts every CityGML and CityJSON sample of ``../shared/data`` (skipped when that folder is
absent) and districts made of shifted copies of TUM Munich with ``lodconvert`` in a fresh child
process per run, into X3D and into glTF:

    python benchmarks/city.py                     # writes results/city.md
    python benchmarks/city.py --runs 3 --factors 10,100 --factor-runs 3,1 --max-seconds 600
    python benchmarks/city.py --profile           # cProfile of TUM Munich → x3d and glb
    python benchmarks/city.py --commit HEAD       # lodconvert/ as committed, not the working tree

Per sample file: buildings and city objects in (counted in the file), polygons (``gml:Polygon``
elements in the text, every LoD; CityJSON: surfaces of every geometry, every LoD), the objects
the CLI wrote (its ``--report``), and per output format the wall and CPU time, objects/s, peak
RSS and output size of the child (``objects.convert_once``: pinned with ``taskset -c 0``, peak
from ``wait4``, killed after ``--max-seconds``), medians of ``--runs`` runs.

Districts: TUM Munich's ``cityObjectMember`` elements (the zip is read in memory) copied
``factor`` times on a grid, copy k shifted in x and y by whole multiples of the district's
extent (rounded up to whole metres) so copies do not overlap, with ``_k`` appended to every
``gml:id`` and ``xlink:href`` target of copy k ≥ 1 (copy 0 is the original); written as a plain
``.gml`` in a temporary folder one copy at a time, so this script holds one copy, not the
district. Factor 1 is the unzipped original (the zip's baseline without the zip).

Targets: ≥ 1,000 LoD2 buildings/s end to end on one core (anchors: cjio's glb export about 8
objects/s; pg2b3dm 1,400–3,800 features/s from PostGIS), and the peak RSS of the 100× district
≤ 2× that of TUM Munich.

Stages of each district, each in a fresh child process on the same core (medians of the
district's runs): **parse**, lxml's ``iterparse`` of the document with lodconvert's hardened
parser options, stopping at each ``cityObjectMember`` and freeing it, nothing else done (the
floor any converter through lxml stands on); **read**, lodconvert's CityGML reader yielding
every object with its triangulated LoDs (no chains, no output). Conversion minus read is what
the chains, the writers and the post-write check take.

``--profile`` instead converts TUM Munich in this process under cProfile (pinned to one core,
after an unprofiled warm-up on the SIG3D LoD2 house and an unprofiled run) and prints the top
functions by cumulative and total time; it writes no results file.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import math
import os
import pstats
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objects import (
    MIB,
    ROOT,
    Row,
    add_source_options,
    child_env,
    cpu_call,
    lodconvert_source,
    measure,
    package_dir,
    pin_prefix,
    preamble,
    run_facts,
    tree_digest,
)
from tables import markdown_table, write_results

HERE = Path(__file__).resolve().parent
DATA = ROOT.parent / "shared" / "data"
TUM = DATA / "citygml" / "tum_munich_lod2_v2.zip"
SIG3D_LOD2 = DATA / "citygml" / "sig3d_house_lod0-4" / "Building_LOD2-EPSG25832.gml"
FORMATS = ("x3d", "glb")
TARGET_BUILDINGS_PER_S = 1000.0
TARGET_PEAK_RATIO = 2.0
ANCHORS = "cjio's glb export about 8 objects/s; pg2b3dm 1,400–3,800 features/s from PostGIS"

POLYGON = re.compile(rb"<(?:[\w.-]+:)?Polygon[\s>/]")
"""A ``Polygon`` element's start tag (not ``PolygonPatch``)."""
MEMBER = re.compile(rb"<(?:[\w.-]+:)?cityObjectMember\b[^>]*>\s*<(?:[\w.-]+:)?([\w.-]+)")
"""A ``cityObjectMember`` start tag and the local name of the city object it holds."""
DEPTH = {
    "MultiSurface": 1,
    "CompositeSurface": 1,
    "Solid": 2,
    "MultiSolid": 3,
    "CompositeSolid": 3,
}
"""How deep the surfaces lie in each CityJSON geometry type's ``boundaries``."""


# --- the samples ----------------------------------------------------------------------------


@dataclass
class Sample:
    """One input file and what it holds."""

    path: Path
    kind: str
    buildings: int
    objects: int
    polygons: int
    factor: int = 0
    """Copies of TUM Munich (0 for a sample file)."""
    bytes: int = 0
    """File size (of a district: when written; it is deleted after its runs)."""

    @property
    def name(self) -> str:
        """The path below the data folder (or the file name of a generated district)."""
        return (
            str(self.path.relative_to(DATA)) if self.path.is_relative_to(DATA) else self.path.name
        )


def gml_documents(path: Path) -> Iterator[bytes]:
    """The CityGML documents of a ``.gml`` file or of the ``.gml`` members of a zip."""
    if path.suffix.lower() != ".zip":
        yield path.read_bytes()
        return
    with zipfile.ZipFile(path) as archive:
        for name in archive.namelist():
            if name.lower().endswith((".gml", ".xml")):
                yield archive.read(name)


def citygml_sample(path: Path) -> Sample:
    """Count top-level city objects, buildings among them and ``Polygon`` elements (in the text:
    every LoD, each polygon once however many solids refer to it by ``xlink:href``)."""
    objects = buildings = polygons = 0
    version = None
    for text in gml_documents(path):
        members = MEMBER.findall(text)
        objects += len(members)
        buildings += sum(m == b"Building" for m in members)
        polygons += len(POLYGON.findall(text))
        version = version or re.search(rb"opengis\.net/citygml/(\d\.\d)\"", text)
    label = f"CityGML {version.group(1).decode()}" if version else "CityGML"
    return Sample(path, label, buildings, objects, polygons)


def cityjson_surfaces(geometry: dict[str, Any]) -> int:
    """The surfaces of one CityJSON geometry (0 for a ``GeometryInstance`` or an unknown type)."""
    items = [geometry.get("boundaries", [])]
    for _ in range(DEPTH.get(geometry.get("type", ""), 0)):
        items = [x for item in items for x in item]
    return len(items) if geometry.get("type") in DEPTH else 0


def cityjson_sample(path: Path) -> Sample:
    """Count top-level city objects (no ``parents``), buildings among them, and surfaces of every
    geometry of every city object (every LoD, ``BuildingPart`` included)."""
    model = json.loads(path.read_bytes())
    cityobjects = model.get("CityObjects", {}).values()
    top = [o for o in cityobjects if not o.get("parents")]
    polygons = sum(cityjson_surfaces(g) for o in cityobjects for g in o.get("geometry", []))
    buildings = sum(o.get("type") == "Building" for o in top)
    return Sample(path, f"CityJSON {model.get('version', '?')}", buildings, len(top), polygons)


def samples() -> list[Sample]:
    """Every CityGML (``.gml``, ``.zip``) and CityJSON (``.json``) file of the data folder."""
    found = []
    for path in sorted((DATA / "citygml").rglob("*")):
        if path.suffix.lower() in (".gml", ".zip"):
            found.append(citygml_sample(path))
    for path in sorted((DATA / "cityjson").rglob("*.json")):
        found.append(cityjson_sample(path))
    return found


# --- the districts --------------------------------------------------------------------------


TOKEN = re.compile(
    r'(?P<id>gml:id="|xlink:href="#)(?P<ref>[^"]*)"'
    r"|(?P<open><gml:(?:posList|pos|lowerCorner|upperCorner)\b(?P<attrs>[^>]*)>)(?P<coords>[^<]*)"
)
"""An id or reference to rename, or a coordinate element whose x and y to shift."""
NUMBER = re.compile(r"\d+(\.\d*)?")


@dataclass
class Coordinates:
    """One coordinate list: per tuple the x and y as (whole part, rest of the text) where the
    text is a plain non-negative decimal (else the float), and the other ordinates as text."""

    xy: list[tuple[int | float, str, int | float, str]]
    rest: list[str]


def split_number(text: str) -> tuple[int | float, str]:
    """``"4467672.70"`` → ``(4467672, ".70")``; other forms → ``(float, "")``."""
    if NUMBER.fullmatch(text):
        whole, dot, frac = text.partition(".")
        return int(whole), dot + frac
    return float(text), ""


def shifted(number: int | float, rest: str, offset: int) -> str:
    """A split number plus a whole-metre offset, written with its own decimals."""
    return f"{number + offset}{rest}" if isinstance(number, int) else repr(number + offset)


class Template:
    """TUM Munich's ``cityObjectMember`` elements, split into text, ids and coordinates so that
    shifted, renamed copies can be written one at a time."""

    def __init__(self, document: bytes) -> None:
        text = document.decode("utf-8")
        first = text.index("<cityObjectMember")
        end = text.rindex("</cityObjectMember>") + len("</cityObjectMember>")
        self.head, self.tail = text[:first], text[end:]
        self.parts: list[str | tuple[str, str] | Coordinates] = []
        self.polygons = len(POLYGON.findall(document))
        self.buildings = sum(m == b"Building" for m in MEMBER.findall(document))
        xs: list[float] = []
        ys: list[float] = []
        body, at = text[first:end], 0
        for match in TOKEN.finditer(body):
            self.parts.append(body[at : match.start()])
            at = match.end()
            if match["id"]:
                self.parts += [match["id"], (match["ref"], '"')]
                continue
            dim = re.search(r'srsDimension="(\d)"', match["attrs"])
            step = int(dim.group(1)) if dim else 3
            values = match["coords"].split()
            xy, rest = [], []
            for i in range(0, len(values) - step + 1, step):
                x, y = split_number(values[i]), split_number(values[i + 1])
                xy.append((*x, *y))
                rest.append(" ".join(values[i + 2 : i + step]))
                xs.append(float(values[i]))
                ys.append(float(values[i + 1]))
            self.parts += [match["open"], Coordinates(xy, rest)]
        self.parts.append(body[at:])
        self.extent = (math.ceil(max(xs) - min(xs)), math.ceil(max(ys) - min(ys)))
        self.low = (min(xs), min(ys))
        """The least x and y of the original's coordinates."""

    def copy(self, k: int, dx: int, dy: int) -> Iterator[str]:
        """The text of copy ``k`` shifted by (dx, dy) metres, ids suffixed ``_k`` (k ≥ 1)."""
        suffix = f"_{k}" if k else ""
        for part in self.parts:
            if isinstance(part, str):
                yield part
            elif isinstance(part, tuple):
                yield part[0] + suffix + part[1]
            else:
                yield " ".join(
                    f"{shifted(x, xr, dx)} {shifted(y, yr, dy)} {rest}".rstrip()
                    for (x, xr, y, yr), rest in zip(part.xy, part.rest, strict=True)
                )


def tum_document() -> bytes:
    """The one CityGML document of the TUM Munich zip (read in memory)."""
    (document,) = gml_documents(TUM)
    return document


def write_district(template: Template, factor: int, path: Path) -> Sample:
    """Write ``factor`` shifted copies of the template on a near-square grid as one CityGML file,
    one copy at a time."""
    columns = math.ceil(math.sqrt(factor))
    with path.open("w", encoding="utf-8", buffering=1 << 20) as out:
        out.write(template.head)
        for k in range(factor):
            row, column = divmod(k, columns)
            out.writelines(template.copy(k, column * template.extent[0], row * template.extent[1]))
        out.write(template.tail)
    return Sample(
        path,
        f"CityGML 2.0, {factor}× TUM Munich",
        factor * template.buildings,
        factor * template.buildings,
        factor * template.polygons,
        factor,
        path.stat().st_size,
    )


# --- measuring ------------------------------------------------------------------------------


@dataclass
class Result:
    """A sample's runs in one format, with the objects the CLI reported writing."""

    sample: Sample
    row: Row
    written: int | None
    runs: int

    @property
    def rate(self) -> float:
        """Objects written per second at the median wall time (buildings in when unknown)."""
        count = self.sample.buildings if self.written is None else self.written
        return count / self.row.seconds if self.row.ok else float("nan")


def run_sample(
    sample: Sample, fmt: str, folder: Path, runs: int, args: argparse.Namespace
) -> Result:
    """``runs`` conversions of one sample into one format, in a folder of its own."""
    print(f"{sample.name} ({sample.kind}) → {fmt}", flush=True)
    folder.mkdir(parents=True, exist_ok=True)
    row = measure(
        sample.buildings, fmt, sample.path, folder, runs, args.max_seconds, args.pythonpath
    )
    report = folder / f"out_{sample.buildings}.{fmt}.report.json"
    written = None
    if row.ok and report.exists():
        written = json.loads(report.read_text()).get("totals", {}).get("objects")
    shutil.rmtree(folder, ignore_errors=True)
    return Result(sample, row, written, runs)


def cells(result: Result, max_seconds: float) -> list[str]:
    """Status, times, rate, peak and output cells of a result."""
    row = result.row
    if row.status == "over budget":
        return ["over budget", f"> {max_seconds:g}", "–", "–", "–", "–"]
    if row.status != "ok":
        return [row.status, *["–"] * 5]
    return [
        "ok",
        f"{row.seconds:.2f}",
        f"{row.cpu_seconds:.2f}",
        f"{result.rate:,.1f}",
        f"{row.peak_mib:.0f}",
        f"{row.output_mib:.2f}",
    ]


def speed_verdict(result: Result) -> str:
    """The speed target's verdict on one result."""
    if not result.row.ok:
        return f"not measured ({result.row.status})"
    met = "met" if result.rate >= TARGET_BUILDINGS_PER_S else "NOT met"
    per_cpu = (result.written or result.sample.buildings) / result.row.cpu_seconds
    return f"{met} ({result.rate:,.1f} buildings/s; {per_cpu:,.1f} per CPU second)"


STAGES = ("parse", "read")


def run_stage(stage: str, path: Path) -> dict[str, float]:
    """One stage of ``path`` in this process: its wall and CPU seconds and the objects seen."""
    from lxml import etree

    from lodconvert.io import read_scene
    from lodconvert.io.citygml.source import parser_options
    from lodconvert.limits import DEFAULT_LIMITS

    def parse() -> int:
        options = parser_options(DEFAULT_LIMITS)
        count = 0
        for _, element in etree.iterparse(
            str(path), events=("end",), tag="{*}cityObjectMember", **options
        ):
            count += len(element)
            element.clear(keep_tail=False)
            while element.getprevious() is not None:
                del element.getparent()[0]
        return count

    def read() -> int:
        return sum(1 for _ in read_scene(path).nodes)

    count, wall, cpu = cpu_call(parse if stage == "parse" else read)
    return {"seconds": wall, "cpu_seconds": cpu, "objects": count}


@dataclass
class StageResult:
    """A stage's runs on one district: median seconds of the whole child process (spawn to
    exit, as a conversion's) and of the stage itself within it, objects seen."""

    sample: Sample
    stage: str
    runs: int
    process_seconds: float
    seconds: float
    objects: int


def measure_stage(
    sample: Sample, stage: str, runs: int, args: argparse.Namespace
) -> StageResult | None:
    """``runs`` runs of a stage on a district, each in a fresh child process pinned like the
    conversions; None when a run fails."""
    done: list[tuple[float, float, int]] = []
    command = [*pin_prefix(), sys.executable, __file__, "--stage", stage, str(sample.path)]
    for i in range(runs):
        started = time.perf_counter()
        child = subprocess.run(
            command, capture_output=True, text=True, env=child_env(args.pythonpath), check=False
        )
        process = time.perf_counter() - started
        if child.returncode != 0:
            print(f"  {stage} run {i + 1}/{runs} failed: {child.stderr.strip()[-300:]}")
            return None
        inside = json.loads(child.stdout.strip().splitlines()[-1])
        done.append((process, inside["seconds"], int(inside["objects"])))
        print(f"  {stage} run {i + 1}/{runs}: {process:.2f} s ({inside['seconds']:.2f} s in it)")
    process = sorted(d[0] for d in done)[len(done) // 2]
    inside_s = sorted(d[1] for d in done)[len(done) // 2]
    return StageResult(sample, stage, runs, process, inside_s, done[0][2])


# --- report ---------------------------------------------------------------------------------


def results_text(
    found: list[Result],
    districts: list[Result],
    stages: list[StageResult],
    args: argparse.Namespace,
    command: str,
    load: tuple[float, float],
    elapsed: float,
    digests: tuple[str, str],
    script_peak: float,
) -> str:
    """The results markdown."""
    lines = [
        *preamble("City-model conversion benchmark", args, command, load, elapsed, digests),
        "- Conversion: `lodconvert IN -o out.FMT -q --report out.json` with default options, in a"
        " fresh child process per run; s = wall clock from spawn to exit (interpreter start and"
        " imports included), CPU s = its user + system time; peak = the child's max RSS"
        " (`wait4`); objects/s = objects the CLI wrote (its report) per wall second; medians of"
        f" the runs given (a run over {args.max_seconds:g} s is killed and the configuration's"
        " remaining runs skipped).",
        "- Counts: buildings and objects = top-level city objects in the file (CityGML: children"
        " of `cityObjectMember`; CityJSON: `CityObjects` without `parents`); polygons = CityGML"
        " `Polygon` start tags in the text (every LoD, each once however many solids refer to"
        " it; TIN triangles not counted), CityJSON surfaces of every geometry (every LoD,"
        " `BuildingPart`s included; a surface with holes counts once).",
        f"- Targets: ≥ {TARGET_BUILDINGS_PER_S:,.0f} LoD2 buildings/s end to end on one core"
        f" (anchors: {ANCHORS}); peak RSS of the 100× district ≤ {TARGET_PEAK_RATIO:g}× that of"
        " TUM Munich (the zip).",
        "",
        "## Sample files",
        "",
    ]
    header = ["file", "model", "format", "runs", "buildings in", "objects in", "objects out"]
    header += ["polygons", "status", "median s", "CPU s", "objects/s", "peak MiB", "output MiB"]
    table = []
    for r in found:
        s = r.sample
        counts = [str(r.runs), f"{s.buildings:,}", f"{s.objects:,}"]
        counts += ["–" if r.written is None else f"{r.written:,}", f"{s.polygons:,}"]
        table.append([f"`{s.name}`", s.kind, r.row.fmt, *counts, *cells(r, args.max_seconds)])
    lines += [markdown_table(header, table, 3) if table else f"(no samples: {DATA} is absent)"]
    lines += ["", "## TUM Munich districts", ""]
    tum = {r.row.fmt: r for r in found if r.sample.path == TUM and r.row.ok}
    header = ["district", "format", "runs", "buildings", "polygons", "GML MiB", "status"]
    header += ["median s", "CPU s", "buildings/s", "peak MiB", "output MiB", "peak / TUM zip"]
    table = []
    for r in districts:
        s = r.sample
        ratio = "–"
        if r.row.ok and r.row.fmt in tum:
            ratio = f"{r.row.peak_mib / tum[r.row.fmt].row.peak_mib:.2f}"
        counts = [f"{s.buildings:,}", f"{s.polygons:,}", f"{s.bytes / MIB:,.1f}"]
        line = [f"{s.factor}×", r.row.fmt, str(r.runs), *counts]
        table.append([*line, *cells(r, args.max_seconds), ratio])
    if table:
        lines += [
            "Shifted copies of TUM Munich's district on a grid (whole multiples of its extent in"
            " x and y, fresh `gml:id`s),"
            " written one copy at a time as a plain `.gml`; this script's own peak RSS was"
            f" {script_peak:.0f} MiB.",
            "",
            markdown_table(header, table, 2),
        ]
    else:
        lines += [f"(not made: {TUM} is absent)"]
    if stages:
        lines += ["", "### Where the time goes", "", *stage_table(stages, districts)]
    lines += ["", "## Targets", ""]
    speed = [r for r in found if r.sample.path == TUM] + districts
    for r in speed:
        name = "TUM Munich (zip)" if r.sample.path == TUM else r.sample.kind
        lines.append(f"- Speed, {name} → {r.row.fmt}: {speed_verdict(r)}.")
    for r in districts:
        if r.sample.factor == 100 and r.row.fmt in tum and r.row.ok:
            ratio = r.row.peak_mib / tum[r.row.fmt].row.peak_mib
            met = "met" if ratio <= TARGET_PEAK_RATIO else "NOT met"
            lines.append(
                f"- Memory, 100× district → {r.row.fmt}: {met} ({r.row.peak_mib:.0f} MiB vs"
                f" {tum[r.row.fmt].row.peak_mib:.0f} MiB for TUM Munich, {ratio:.2f}×)."
            )
    lines += ["", "Anchors for the speed target: " + ANCHORS + "."]
    return "\n".join(lines) + "\n"


def stage_table(stages: list[StageResult], districts: list[Result]) -> list[str]:
    """The stages of each district beside its conversions: seconds, buildings/s, and the share
    of the speed target's time budget (buildings / target) that a stage alone takes."""
    converted = {(r.sample.factor, r.row.fmt): r for r in districts if r.row.ok}
    header = ["district", "stage", "runs", "process s", "stage s", "buildings/s"]
    header += ["of the target's budget"]
    table = []
    for result in stages:
        s = result.sample
        budget = s.buildings / TARGET_BUILDINGS_PER_S
        rows = [(result.stage, str(result.runs), f"{result.process_seconds:.2f}", result.seconds)]
        if result.stage == "read":
            for fmt in FORMATS:
                if (r := converted.get((s.factor, fmt))) is not None:
                    rest = r.row.seconds - result.process_seconds
                    rows.append((f"{fmt} minus read", "–", "–", rest))
        for stage, runs, process, seconds in rows:
            rate = f"{s.buildings / seconds:,.0f}" if seconds > 0 else "–"
            line = [f"{s.factor}×", stage, runs, process, f"{seconds:.2f}", rate]
            table.append([*line, f"{seconds / budget:.1f}×"])
    return [
        "Each stage in a fresh child process on the same core: parse, lxml's `iterparse` with"
        " lodconvert's parser options, each `cityObjectMember` freed, nothing else done; read,"
        " lodconvert's CityGML reader yielding every object triangulated, nothing written."
        " Process s: spawn to exit (imports included, as a conversion's); stage s: the stage"
        " alone. \"minus read\" is a conversion's median less the read's process time: the"
        " chains, the writer and the post-write check. The budget is the time the speed"
        f" target allows the district (buildings / {TARGET_BUILDINGS_PER_S:,.0f} per s).",
        "",
        markdown_table(header, table, 2),
    ]


def factor_list(text: str) -> list[int]:
    """``"10,100"`` → ``[10, 100]``."""
    return [int(c) for c in text.split(",") if c.strip()]


def benchmark(args: argparse.Namespace, argv: list[str]) -> int:
    """Convert every sample and district in each format, write the results."""
    started = time.perf_counter()
    load_start = os.getloadavg()[0]
    digest_start = tree_digest(package_dir(args.pythonpath))
    found: list[Result] = []
    districts: list[Result] = []
    stages: list[StageResult] = []
    with tempfile.TemporaryDirectory(prefix="lodconvert-city-") as tmp:
        folder = Path(tmp)
        for i, sample in enumerate(samples() if DATA.is_dir() else []):
            for fmt in FORMATS:
                found.append(run_sample(sample, fmt, folder / f"s{i}_{fmt}", args.runs, args))
        if TUM.is_file():
            template = Template(tum_document())
            for factor, runs in zip(args.factors, args.factor_runs, strict=True):
                gml = folder / f"tum_{factor}x.gml"
                made = time.perf_counter()
                sample = write_district(template, factor, gml)
                print(
                    f"{factor}× district: {sample.buildings:,} buildings, "
                    f"{sample.bytes / MIB:,.1f} MiB (written in "
                    f"{time.perf_counter() - made:.1f} s)",
                    flush=True,
                )
                for fmt in FORMATS:
                    districts.append(
                        run_sample(sample, fmt, folder / f"d{factor}_{fmt}", runs, args)
                    )
                for stage in STAGES:
                    print(f"{factor}× district: {stage}", flush=True)
                    if (result := measure_stage(sample, stage, runs, args)) is not None:
                        stages.append(result)
                gml.unlink()
            del template
    script_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    command, load, elapsed, digests = run_facts(
        __file__, argv, started, load_start, digest_start, args.pythonpath
    )
    text = results_text(
        found, districts, stages, args, command, load, elapsed, digests, script_peak
    )
    write_results(args.out, text)
    return 0


# --- profile --------------------------------------------------------------------------------


def profile(args: argparse.Namespace) -> int:
    """Convert TUM Munich into x3d and glb in this process under cProfile (after a warm-up on
    the SIG3D LoD2 house and an unprofiled run); print the top functions."""
    if not TUM.is_file():
        print(f"skipped: {TUM} is absent")
        return 0
    if args.pythonpath is not None:
        sys.path.insert(0, str(args.pythonpath))
    from lodconvert.cli import main as lodconvert_main

    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    with tempfile.TemporaryDirectory(prefix="lodconvert-city-") as tmp:
        for fmt in FORMATS:
            out = str(Path(tmp) / f"out.{fmt}")
            if SIG3D_LOD2.is_file():
                lodconvert_main([str(SIG3D_LOD2), "-o", out, "-q"])
            _, wall, cpu = cpu_call(lodconvert_main, [str(TUM), "-o", out, "-q"])
            print(f"\n{fmt}: without profiler {wall:.2f} s wall, {cpu:.2f} s CPU", flush=True)
            profiler = cProfile.Profile(time.process_time)
            _, wall, cpu = cpu_call(profiler.runcall, lodconvert_main, [str(TUM), "-o", out, "-q"])
            print(f"=== TUM Munich → {fmt} under cProfile: {wall:.1f} s wall, {cpu:.1f} s CPU")
            for key in ("cumulative", "tottime"):
                stream = io.StringIO()
                stats = pstats.Stats(profiler, stream=stream).strip_dirs().sort_stats(key)
                stats.print_stats(args.profile_top)
                print(f"\n--- top {args.profile_top} by {key} ---\n{stream.getvalue()}", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="runs per sample and format (3)")
    parser.add_argument(
        "--factors", type=factor_list, default=[1, 10, 100], metavar="N,..",
        help="district sizes in copies of TUM Munich (default 1,10,100)",
    )  # fmt: skip
    parser.add_argument(
        "--factor-runs", type=factor_list, default=[3, 3, 1], metavar="R,..",
        help="runs per district size (default 3,3,1)",
    )  # fmt: skip
    parser.add_argument(
        "--max-seconds", type=float, default=600.0, help="kill a run after this long (default 600)"
    )
    parser.add_argument("--out", type=Path, default=HERE / "results" / "city.md")
    parser.add_argument(
        "--profile", action="store_true", help="profile TUM Munich in-process (no results file)"
    )
    parser.add_argument("--profile-top", type=int, default=25, help="functions listed per sort")
    parser.add_argument(
        "--stage", nargs=2, metavar=("STAGE", "PATH"),
        help="run one stage (parse or read) of a CityGML file in this process, print its times",
    )  # fmt: skip
    add_source_options(parser)
    args = parser.parse_args(argv)
    if args.stage is not None:
        if args.stage[0] not in STAGES:
            parser.error(f"--stage takes one of {', '.join(STAGES)}")
        print(json.dumps(run_stage(args.stage[0], Path(args.stage[1]))))
        return 0
    if len(args.factors) != len(args.factor_runs):
        parser.error("--factor-runs needs one number per factor")
    with lodconvert_source(args):
        return profile(args) if args.profile else benchmark(args, argv)


if __name__ == "__main__":
    sys.exit(main())
