"""Hostile CityGML documents, scaled down: work that follows the data (compared at n and 4n,
never against a clock), memory that follows the text read, walks that no nesting or chain of
links turns into a Python recursion error, and coordinates that are skipped with their
object's id and the reason. The one-line errors of the full-size cases run through the command
line in :mod:`tests.test_hostile_input` (:data:`tests.fuzz.cases.CASES`)."""

from __future__ import annotations

import gc
import gzip
import io
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lodconvert.errors import InputError
from lodconvert.io import read_scene
from lodconvert.io.citygml.text_limit import TextLimit
from lodconvert.io.geometry_checks import tally_of
from lodconvert.io.mesh import object_id
from lodconvert.limits import Limits
from lodconvert.model import Mesh, Surface

from .fuzz import hostile_citygml as gml
from .fuzz.worker import child_env, run_cli


def write(folder: Path, name: str, data: bytes) -> Path:
    path = folder / name
    path.write_bytes(data)
    return path


def cpu_seconds(path: Path, **options: object) -> float:
    """CPU time reading every node of ``path``, the collector off (its passes cost what the
    rest of the test process holds, not what the reading does)."""
    gc.disable()
    try:
        start = time.process_time()
        for _ in read_scene(path, **options).nodes:
            pass
        return time.process_time() - start
    finally:
        gc.enable()


# --- work that follows the data -------------------------------------------------------------------


def test_ids_of_objects_named_alike_are_numbered_in_order() -> None:
    taken: set[str] = set()
    assert [object_id("Building", taken) for _ in range(4)] == [
        "Building",
        "Building_2",
        "Building_3",
        "Building_4",
    ]
    taken = {"Building", "Building_2", "Building_3", "Building_5"}
    found = {object_id("Building", taken) for _ in range(3)}
    assert len(found) == 3 and not found & {"Building_2", "Building_3", "Building_5"}


def test_naming_objects_without_ids_is_not_quadratic() -> None:
    """5,000 objects of one name cost about 4× what 1,250 cost (it was 16×: each new name tried
    every number taken before it)."""

    def seconds(count: int) -> float:
        taken: set[str] = set()
        start = time.process_time()
        for _ in range(count):
            object_id("BuildingPart", taken)
        return time.process_time() - start

    seconds(1000)  # warm up
    assert seconds(20_000) < 8 * seconds(5_000)


@pytest.mark.parametrize("parts", [False, True], ids=["empty buildings", "parts"])
def test_objects_without_ids_read_in_linear_time(tmp_path: Path, parts: bool) -> None:
    small = write(tmp_path, "small.gml", gml.without_ids(1_000, parts))
    large = write(tmp_path, "large.gml", gml.without_ids(4_000, parts))
    cpu_seconds(small)  # warm up
    assert cpu_seconds(large) < 8 * cpu_seconds(small)


def test_links_reaching_a_polygon_by_many_paths_are_walked_once(tmp_path: Path) -> None:
    """Composites 16 deep, each linking twice to the next: 65,536 paths to each polygon (a
    walk of each path took seconds and hundreds of MB), read once, in about the time of a
    chain of single links."""
    path = write(tmp_path, "fan.gml", gml.link_chain(16, fan=2))
    (node,) = read_scene(path).nodes
    assert len(node.geometry.faces) == 12  # the cube, once
    single = write(tmp_path, "chain.gml", gml.link_chain(16))
    cpu_seconds(single)  # warm up
    assert cpu_seconds(path) < 8 * cpu_seconds(single) + 0.05


# --- memory that follows the text -----------------------------------------------------------------


def test_a_long_pos_list_takes_a_few_times_its_text(tmp_path: Path) -> None:
    """An 8 MB posList (2.1 million values) raises the reader's peak memory by less than 8× its
    text (a Python string per number took 11–21×)."""
    flat = " ".join(["0.5"] * 2_100_000)
    big = write(tmp_path, "big.gml", gml.document(gml.building(gml.surfaces([*gml.cube(), flat]))))
    small = write(tmp_path, "small.gml", gml.document(gml.box_building()))
    code = (
        "import resource, sys; from lodconvert.io import read_scene\n"
        "def peak(): return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024\n"
        "list(read_scene(sys.argv[1]).nodes); before = peak()\n"
        "list(read_scene(sys.argv[2]).nodes); print(peak() - before)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(small), str(big)],
        capture_output=True,
        text=True,
        check=True,
        env=child_env(),
    )
    assert int(done.stdout) < 8 * len(flat), done.stdout


def test_every_text_is_held_to_the_text_limit(tmp_path: Path) -> None:
    """A description, not only coordinates; also when comments split it (libxml2 joins the
    pieces); a document whose texts are all shorter reads."""
    limits = Limits(xml_text_bytes=50_000)
    for split_by in ("", "<!-- <a> -->", "<![CDATA[<a>]]>", "<?pi <a>?>"):
        data = gml.long_text(60_000, split_by)
        for name, content in (("long.gml", data), ("long.gml.gz", gzip.compress(data))):
            path = write(tmp_path, name, content)
            with pytest.raises(InputError, match="text or tag over the limit of 50,000 bytes"):
                list(read_scene(path, limits=limits).nodes)
    path = write(tmp_path, "short.gml", gml.long_text(40_000, "<!-- -->"))
    (node,) = read_scene(path, limits=limits).nodes
    assert len(node.attributes["description"]) == 40_000


@pytest.mark.parametrize("chunk", [1, 7, 4096])
def test_text_limit_finds_markup_split_across_reads(chunk: int) -> None:
    """Comments, CDATA and tags cut anywhere between two reads are told apart alike."""
    text = b"x" * 40
    joined = b"<a>" + text + b"<!-- <b> -->" + text + b"<![CDATA[<c>]]>" + text + b"</a>"
    tagged = b"<a>" + text + b"<b/>" + text + b"<?p <c>?>" + b"</a>"

    def scanned(data: bytes, limit: int) -> None:
        stream = TextLimit(io.BytesIO(data), limit, "doc.xml")
        while stream.read(chunk):
            pass

    with pytest.raises(InputError, match="over the limit of 100 bytes"):
        scanned(joined, 100)
    scanned(joined, 200)
    scanned(tagged, 100)


# --- nesting and links: no recursion error --------------------------------------------------------


def test_deep_documents_within_a_raised_depth_limit_read(tmp_path: Path) -> None:
    """Nesting past Python's recursion limit reads once ``xml_depth`` allows it (a limit past
    the parser's own depth, 2048, is the parser's)."""
    limits = Limits(xml_depth=2048)
    path = write(tmp_path, "composites.gml", gml.nested_composites(600))
    for depth in (2048, 10**6):
        (node,) = read_scene(path, limits=Limits(xml_depth=depth)).nodes
        assert len(node.geometry.faces) == 12
    path = write(tmp_path, "sets.gml", gml.nested_attribute_sets(1500))
    (node,) = read_scene(path, limits=limits).nodes
    assert node.attributes["generic"] == {"s." * 1500 + "a": "v"}


def test_parts_nested_too_deep_skip_their_building_only(tmp_path: Path) -> None:
    chain = gml.part_chain(40).decode().removeprefix(gml.HEAD).removesuffix(gml.TAIL)
    path = write(tmp_path, "city.gml", gml.document(chain, gml.box_building("good", x=5.0)))
    scene = read_scene(path, limits=Limits(xml_depth=2048))
    assert [node.id for node in scene.nodes] == ["good"]
    (skipped,) = tally_of(scene).skipped
    assert skipped["id"] == "B1" and "parts nested more than 32 deep" in skipped["reason"]


@pytest.mark.parametrize("workers", ["1", "2"])
def test_an_object_nested_past_the_depth_limit_is_skipped_alone(
    tmp_path: Path, workers: str
) -> None:
    """Parts 300 deep and attribute sets 1,000 deep (past ``xml_depth`` 256, within what the
    parser reads): each building one line naming the file and its id, the rest converted, the
    summary counting both (the run failed naming neither)."""
    deep = gml.building(gml.parts(300), "parts")
    sets = gml.building(gml.attribute_sets(1000) + gml.surfaces(gml.cube()), "sets")
    path = write(
        tmp_path,
        "city.gml",
        gml.document(gml.box_building("a"), deep, sets, gml.box_building("b", x=5.0)),
    )
    run = run_cli(path, "-o", tmp_path / "out.glb", "--workers", workers)
    assert run.code == 0, run.stderr
    for name in ("parts", "sets"):
        assert (
            f"lodconvert: warning: {path}: object {name}: nests XML elements deeper than the "
            "limit of 256 (raise it with --limit xml_depth=N) — skipped"
        ) in run.stderr.splitlines()
    assert "(2 object(s), 2 skipped," in run.stderr


# --- coordinates ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "reason"),
    [("nan", "NaN or infinite"), ("inf", "NaN or infinite"), ("1e308", "1e+308")],
)
def test_coordinates_not_finite_or_huge_skip_their_building(
    tmp_path: Path, value: str, reason: str
) -> None:
    scene = read_scene(write(tmp_path, "city.gml", gml.with_coordinate(value)))
    assert [node.id for node in scene.nodes] == ["good"]
    (skipped,) = tally_of(scene).skipped
    assert skipped["id"] == "bad" and reason in skipped["reason"]
    assert tally_of(scene).dropped_faces == 0


def test_no_numpy_warning_reaches_the_command_line(tmp_path: Path) -> None:
    """A tree whose matrix scales it past float64 and a building with an infinite coordinate:
    each skipped with its reason, stderr holding lodconvert's lines alone."""
    text = gml.with_coordinate("inf", gml.scaled_tree("1e300"))
    path = write(tmp_path, "city.gml", text)
    done = subprocess.run(
        [sys.executable, "-m", "lodconvert", str(path), "-o", str(tmp_path / "out.glb"), "-q"],
        capture_output=True,
        text=True,
        env=child_env(),
    )
    assert done.returncode == 0, done.stderr
    lines = done.stderr.strip().splitlines()
    assert "Warning" not in done.stderr, done.stderr
    assert all(line.startswith(("lodconvert: warning: ", "wrote ")) for line in lines), lines
    assert "object bad: has NaN or infinite coordinates" in done.stderr
    assert "object tree: has coordinates up to 1e+300" in done.stderr


@pytest.mark.parametrize(
    ("count", "bad", "workers"),
    [(3, 1, "1"), (3, 0, "1"), (100, 80, "1"), (100, 80, "2")],
    ids=["middle", "first", "later-batch", "later-batch-workers"],
)
def test_a_latitude_beyond_90_skips_its_building_in_our_words(
    tmp_path: Path, count: int, bad: int, workers: str
) -> None:
    """One latitude of 200 in a city in EPSG:4979: that building one line naming it, the rest
    converted, no library warning on stderr. It failed the run where it was the first (the
    frame's centre), had the building after it skipped in its place (the rings' offset taken
    for the points'), or, later, reached the triangulation as infinite points (numpy's
    warnings, the building kept)."""
    path = write(tmp_path, "geo.gml", gml.geographic_city(count, bad))
    run = run_cli(path, "-o", tmp_path / "out.glb", "-q", "--workers", workers)
    assert run.code == 0, run.stderr
    warned, summary = run.stderr.splitlines()
    assert warned == (
        f"lodconvert: warning: {path}: object b{bad}: has latitude 200, beyond ±90° (EPSG:4979) "
        "— skipped"
    )
    assert summary.startswith("wrote ") and f"({count - 1} object(s), 1 skipped," in summary


def test_inflation_stops_at_the_limit_with_work_to_match(tmp_path: Path) -> None:
    """Empty members inflating past ``decompressed_bytes`` stop there: 4× the limit costs
    about 4× the time."""

    def seconds(limit: int) -> float:
        path = write(tmp_path, "members.gml.gz", gml.empty_members_gz(64 << 20))
        start = time.process_time()
        with pytest.raises(InputError, match="inflates past the limit"):
            list(read_scene(path, limits=Limits(decompressed_bytes=limit)).nodes)
        return time.process_time() - start

    seconds(1 << 20)  # warm up
    assert seconds(8 << 20) < 8 * seconds(2 << 20)


@pytest.mark.slow
def test_empty_members_take_no_memory_per_member(tmp_path: Path) -> None:
    """Inflating 4× as many empty members (``<bldg:Building/>``, 320,000 against 80,000) up to
    the limit raises the peak by less than 16 MB (it was some 300 bytes a member: an id taken
    and a skip record each)."""
    path = write(tmp_path, "members.gml.gz", gml.empty_members_gz(17 << 20))

    def peak(limit: str) -> int:
        run = run_cli(path, "-o", tmp_path / "out.glb", "--limit", f"decompressed_bytes={limit}")
        assert run.code == 1 and "inflates past the limit" in run.stderr, run.stderr
        return run.peak_bytes

    assert peak("16M") - peak("4M") < 16 << 20


def test_an_object_with_nothing_in_it_is_counted_not_skipped(tmp_path: Path) -> None:
    """An empty ``<bldg:Building/>`` takes no id and no skip record (no warning line); one
    with content but no geometry is still skipped with its id and the reason."""
    text = gml.document(
        gml.building("", "empty"),
        gml.building("<gml:name>n</gml:name>", "nameonly"),
        gml.box_building("good"),
    )
    scene = read_scene(write(tmp_path, "city.gml", text))
    assert [node.id for node in scene.nodes] == ["good"]
    assert scene.attributes["citygml"]["empty"] == {"Building": 1}
    (skipped,) = tally_of(scene).skipped
    assert skipped["id"] == "nameonly" and "has no surface geometry" in skipped["reason"]


def test_skipped_objects_past_the_listed_ones_are_counted(tmp_path: Path) -> None:
    """3,000 objects with a name but no geometry: the report lists the first 1,000 (id and
    reason, each warned) and counts all 3,000; the rest are one line (they were 3,000 records
    and 3,000 lines, a million of them some 500 MB)."""
    names = [gml.building("<gml:name>n</gml:name>", f"n{i}") for i in range(3_000)]
    path = write(tmp_path, "city.gml", gml.document(*names, gml.box_building("good")))
    report = tmp_path / "report.json"
    run = run_cli(path, "-o", tmp_path / "out.glb", "--report", report)
    assert run.code == 0, run.stderr
    data = json.loads(report.read_text())
    assert len(data["skipped"]) == 1_000 and data["skipped"][-1]["id"] == "n999"
    assert data["totals"]["skipped"] == 3_000 and data["totals"]["objects"] == 1
    assert "2,000 more objects skipped (not listed)" in run.stderr
    assert len(run.stderr.splitlines()) < 1_010
    assert "3,000 skipped" in run.stderr


# --- a building of many parts ---------------------------------------------------------------------


def test_a_building_of_many_parts_is_one_surface_per_colour(tmp_path: Path) -> None:
    """400 parts' cubes join into one surface of the building's LoD (it was one per part: as
    many glTF primitives, and per-part work in every later step); each part keeps its own."""
    path = write(tmp_path, "parts.gml", gml.many_parts(400))
    (node,) = read_scene(path).nodes
    (surface,) = node.lods["lod2"].parts
    assert len(surface.faces) == 400 * 12
    assert np.allclose(surface.bounds, [[0, 0, 0], [799, 1, 1]])
    assert len(node.children) == 400 and len(node.children[7].lods["lod2"].faces) == 12


def test_colours_of_a_mesh_of_many_parts_cost_what_its_faces_cost() -> None:
    """Colours at every face of 4× as many parts cost about 4× (a mask per part made it 16×)."""
    cube = gml_cube_surface()

    def seconds(parts: int) -> float:
        mesh = Mesh([cube] * parts)
        faces = np.arange(mesh.face_count)
        points = mesh.triangles.mean(axis=1)
        start = time.process_time()
        colors = mesh.colors_at(faces, points)
        assert (colors == cube.base_color).all()
        return time.process_time() - start

    seconds(500)  # warm up
    assert seconds(8_000) < 8 * seconds(2_000)


def gml_cube_surface() -> Surface:
    """A one-metre cube's 12 triangles, coloured."""
    corners = np.array([(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
    quads = np.array([(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2)])
    quads = np.vstack([quads, [(1, 3, 7, 5)]])
    faces = np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return Surface(corners, faces, base_color=np.array([200, 100, 50, 255], dtype=np.uint8))


@pytest.mark.slow
@pytest.mark.parametrize(("workers", "per_part"), [(2, 17_000), (1, 17_000)])
@pytest.mark.parametrize("layout", ["row", "grid without ids"])
def test_peak_memory_per_part_is_bounded(
    tmp_path: Path, workers: int, per_part: int, layout: str
) -> None:
    """Converting a building of 4,000 one-metre parts (in a row with ids, or on a grid without)
    peaks less than ``per_part`` bytes a part above one of 1,000, in its largest process
    (100,000 on a grid peaked at some 2.3 GB, now 1.33 GB). Some 13.5 KB a part read by a
    worker, 14.4 KB in one process (that was 15 and 22 KB: the parts' XML elements read were
    kept with the heap pages around them, and the silhouette check and the glTF normals held
    arrays of every face at once)."""

    def peak(parts: int) -> int:
        text = gml.many_parts(parts) if layout == "row" else gml.grid_of_parts(parts, ids=False)
        path = write(tmp_path, f"parts{parts}.gml", text)
        run = run_cli(path, "-o", tmp_path / "out.glb", "-q", "--workers", str(workers))
        assert run.code == 0, run.stderr
        return run.peak_bytes

    assert peak(4_000) - peak(1_000) < 3_000 * per_part


def test_reading_many_parts_frees_each_part_once_read(tmp_path: Path) -> None:
    """Reading a building of 8,000 one-metre parts peaks less than 16 KB a part above one of
    1,000 (some 11.6 KB here: each part is collected, read and freed before the next, and
    its polygons triangulated 4,096 at a time; holding the whole tree and every polygon's
    triangles until the building was triangulated took 19.3 KB)."""
    code = (
        "import sys; from lodconvert.io import read_scene\n"
        "list(read_scene(sys.argv[1]).nodes)\n"
        "print(open('/proc/self/status').read().split('VmHWM:')[1].split()[0])\n"
    )

    def peak(parts: int) -> int:
        path = write(tmp_path, f"parts{parts}.gml", gml.many_parts(parts))
        done = subprocess.run(
            [sys.executable, "-c", code, str(path)],
            capture_output=True,
            text=True,
            check=True,
            env=child_env(),
        )
        return int(done.stdout) * 1024

    assert peak(8_000) - peak(1_000) < 7_000 * 16_000
