"""Reading a city in worker processes: a CityGML document cut into its root's children by a
byte scan and read a run of members per task gives the nodes, ids, skips, counts and errors of
reading it in one process."""

from __future__ import annotations

import functools
import gzip
import io
import json
import pickle
import signal
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from lxml import etree

from lodconvert.bake import get_backend
from lodconvert.context import RunContext
from lodconvert.errors import InputError
from lodconvert.io import read_scene, spread
from lodconvert.io.citygml import members as members_module
from lodconvert.io.citygml.members import Members
from lodconvert.io.citygml.parallel import ReadResult
from lodconvert.io.citygml.ranges import MarksResult, MarksTask, RangeResult
from lodconvert.io.cityjson.parallel import ObjectsTask
from lodconvert.io.geometry_checks import tally_of
from lodconvert.io.reopened import NewlinesResult
from lodconvert.io.spread import TASK_SECONDS
from lodconvert.limits import DEFAULT_LIMITS, Limits
from lodconvert.model import Mesh, Node, Scene, unpacked
from lodconvert.tasks import Executor, PoolExecutor

from .conftest import SHARED, shared_data
from .test_citygml import HEAD, box, building, tree
from .test_cityjson import _features, delft, multi_lod

ROOT = HEAD.replace(">", ' xmlns:veg="http://www.opengis.net/citygml/vegetation/2.0">', 1)
ENVELOPE = (
    '<gml:boundedBy><gml:Envelope srsName="urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::7837">'
    "<gml:lowerCorner>0 0 0</gml:lowerCorner><gml:upperCorner>1 1 1</gml:upperCorner>"
    "</gml:Envelope></gml:boundedBy>"
)


def _city(*members: str) -> str:
    return f'<?xml version="1.0" encoding="UTF-8"?>\n{ROOT}{ENVELOPE}{"".join(members)}</CityModel>'


def _anonymous(x: float) -> str:
    """A building without a ``gml:id`` (its id is its type, numbered in document order)."""
    return building("x", box(x)).replace(' gml:id="x"', "", 1)


def _own_prefix(gml_id: str, x: float) -> str:
    """A building whose member declares the building namespace under a prefix of its own."""
    text = building(gml_id, box(x)).replace("bldg:", "b2:")
    return text.replace(
        "<cityObjectMember>",
        '<cityObjectMember xmlns:b2="http://www.opengis.net/citygml/building/2.0">',
        1,
    )


def _tricky() -> str:
    """A member with an end tag of its own name in a comment, in CDATA and in an attribute
    value, beside a processing instruction."""
    text = building("tricky", box(300.0))
    return text.replace(
        "<bldg:lod2MultiSurface>",
        "<!-- </cityObjectMember> --><?note </cityObjectMember>?>"
        '<gen:stringAttribute xmlns:gen="http://www.opengis.net/citygml/generics/2.0" '
        'name="a>b"><gen:value><![CDATA[</cityObjectMember>]]></gen:value>'
        "</gen:stringAttribute><bldg:lod2MultiSurface>",
        1,
    )


def _town() -> str:
    """Buildings, trees linking a crown defined in an earlier member, ids taken twice, a
    building whose coordinates cannot be read, one linking a polygon of another member (left
    unresolved, as links resolve within an object), members of their own namespace prefixes."""
    bad = building("bad", [*box(500.0), "0 0 0 10 0 0 10 ten 0 0 0 0"])
    return _city(
        *(building(f"b{i}", box(20.0 * i)) for i in range(6)),
        tree(0, (700.0, 0.0, 0.0), crown=""),
        building("dup", box(200.0)),
        _anonymous(220.0),
        tree(1, (710.0, 3.0, 1.0)),
        bad,
        building("linker", box(280.0), extra='<gml:surfaceMember xlink:href="#b0_0"/>'),
        _tricky(),
        building("dup", box(240.0)),
        _anonymous(260.0),
        *(_own_prefix(f"p{i}", 400.0 + 20.0 * i) for i in range(3)),
        tree(2, (720.0, 6.0, 2.0)),
    )


def _mesh(mesh: Mesh | None) -> Any:
    if mesh is None:
        return None
    return [
        (part.vertices.tobytes(), part.faces.tobytes(), part.base_color.tobytes())
        for part in mesh.parts
    ]


def _facts(node: Node) -> Any:
    """What a node holds, comparable."""
    return (
        node.id,
        node.type,
        node.attributes,
        node.crs,
        _mesh(node.geometry),
        {label: _mesh(mesh) for label, mesh in node.lods.items()},
        [_facts(child) for child in node.children],
    )


def _parked_facts(scene: Scene) -> list[Any]:
    """The facts of each node of ``scene`` with geometry as it waits to be baked (workers give
    them parked and packed, :class:`~lodconvert.model.PackedNode`)."""
    return [_facts(unpacked(node).parked()) for node in scene.with_geometry()]


class _Kills:
    """A task whose unpickling kills the process doing it (a worker taking it), and that
    fails as ``task`` fails."""

    def __init__(self, task: Any) -> None:
        self.task = task

    def __reduce__(self) -> tuple[Any, tuple[int]]:
        return signal.raise_signal, (signal.SIGKILL,)

    def failed(self, reason: str) -> Any:
        return self.task.failed(reason)


def _read_of(result: Any) -> Any:
    """What a worker read: a run's result, or a range's (:class:`RangeResult`; nothing for
    the marks of appearances, :class:`MarksResult`, or a count of line breaks,
    :class:`NewlinesResult`)."""
    if isinstance(result, MarksResult | NewlinesResult):
        return ReadResult()
    return result.read if isinstance(result, RangeResult) else result


def _two_workers() -> Executor:
    return PoolExecutor(2, "numpy")


def _read(
    path: Path,
    spread: bool,
    killer: int | None = None,
    workers: Callable[[], Executor] = _two_workers,
    limits: Limits = DEFAULT_LIMITS,
) -> tuple[Scene, list[Any], list[Any], list[str]]:
    """The scene of ``path`` read in one process or by ``workers`` (default: two worker
    processes), each member a task (``killer``: that task kills the workers that take it)
    under ``limits``; the facts of its nodes, the workers' results and what was told of
    reading in this process."""
    results: list[Any] = []
    told: list[str] = []
    if not spread:
        scene = read_scene(path, limits=limits)
        return scene, _parked_facts(scene), results, told
    with workers() as executor:
        watched = _Watched(executor, killer, results)
        context = RunContext(watched, get_backend("numpy"), progress=told.append)  # type: ignore[arg-type]
        scene = read_scene(path, context=context, limits=limits)
        facts = _parked_facts(scene)
    return scene, facts, results, told


@dataclass
class _Here:
    """An executor whose results are ``results``' and whose tasks are sized for ``task_seconds``."""

    results: Callable[[Iterable[Any]], Iterator[Any]]
    task_seconds: float


@dataclass
class _Watched:
    """``executor``'s results, each kept in ``kept`` (task ``killer`` made to kill the
    workers that take it)."""

    executor: Executor
    killer: int | None
    kept: list[Any]
    task_seconds: float = TASK_SECONDS

    def results(self, tasks: Iterable[Any]) -> Iterator[Any]:
        sent = (_Kills(task) if i == self.killer else task for i, task in enumerate(tasks))
        for result in self.executor.results(sent):
            self.kept.append(result)
            yield result


@pytest.fixture
def one_member_a_task(monkeypatch: pytest.MonkeyPatch) -> None:
    """Tasks of one member, line or object each (so that a small file makes many)."""
    monkeypatch.setattr(spread.Sizer, "wanted", lambda self: 1)


@pytest.mark.usefixtures("one_member_a_task")
@pytest.mark.parametrize("suffix", [".gml", ".gml.gz"])
def test_a_town_read_by_workers_is_the_town_read_in_one_process(
    tmp_path: Path, suffix: str
) -> None:
    text = _town().encode()
    path = tmp_path / f"town{suffix}"
    path.write_bytes(gzip.compress(text) if suffix.endswith(".gz") else text)
    one, one_facts, _, _ = _read(path, spread=False)
    two, two_facts, results, told = _read(path, spread=True)
    assert two_facts == one_facts
    ids = [facts[0] for facts in one_facts]
    assert ids[:6] == [f"b{i}" for i in range(6)]
    named = ["dup", "Building", "tricky", "dup_2", "Building_2", "p0"]
    assert [i for i in ids if i in named] == named
    assert tally_of(two).skipped == tally_of(one).skipped
    assert [entry["id"] for entry in tally_of(two).skipped] == ["bad"]
    assert two.attributes["citygml"] == one.attributes["citygml"]
    assert one.attributes["citygml"]["unresolved_links"] == {"linker": 1}  # across members
    assert two.crs == one.crs == "EPSG:25832"
    by_workers = sum(len(_read_of(result).nodes) for result in results)
    assert by_workers >= 10  # buildings read by workers (from ranges of the file, or as bytes)
    assert told == [f"{path}: implicit geometry is read in the main process"]


def _errors_read_both_ways(path: Path) -> list[str]:
    """The error reading ``path`` gives in one process, then with workers."""
    errors = []
    for workers in (False, True):
        with pytest.raises(InputError) as caught:
            _read(path, workers)
        errors.append(str(caught.value))
    return errors


@pytest.mark.usefixtures("one_member_a_task")
def test_a_document_broken_in_a_late_member_fails_as_in_one_process(tmp_path: Path) -> None:
    text = _city(*(building(f"b{i}", box(20.0 * i)) for i in range(5)))
    path = tmp_path / "broken.gml"
    path.write_text(text.replace('<bldg:Building gml:id="b3">', '<bldg:Building gml:id="b3"<'))
    errors = _errors_read_both_ways(path)
    assert errors[0] == errors[1]
    assert "is not well-formed XML (attributes construct error, line 2, column" in errors[0]


def _lying_gz(text: bytes, trailer: slice) -> bytes:
    """``text`` gzip-compressed, the trailer's CRC (``slice(-8, -4)``) or size
    (``slice(-4, None)``) off by one."""
    data = bytearray(gzip.compress(text))
    data[trailer] = ((int.from_bytes(data[trailer], "little") + 1) % (1 << 32)).to_bytes(
        4, "little"
    )
    return bytes(data)


@pytest.mark.usefixtures("one_member_a_task")
@pytest.mark.parametrize("trailer", [slice(-8, -4), slice(-4, None)], ids=["crc", "size"])
@pytest.mark.parametrize("make", ["gml", "lines", "objects"])
def test_a_gz_whose_trailer_lies_fails_as_in_one_process(
    tmp_path: Path, make: str, trailer: slice
) -> None:
    """A ``.gz`` whose trailer gives a CRC or size its data does not have: one error, the
    same with workers as in one process (with workers it was ``BadGzipFile``)."""
    if make == "gml":
        source = tmp_path / "city.gml"
        source.write_text(_city(*(building(f"b{i}", box(20.0 * i)) for i in range(5))))
    else:
        source = ten_lines(tmp_path) if make == "lines" else ten_objects(tmp_path)
    path = source.with_name(source.name + ".gz")
    path.write_bytes(_lying_gz(source.read_bytes(), trailer))
    errors = _errors_read_both_ways(path)
    assert errors[0] == errors[1]
    assert errors[0].startswith(f"{path}: cannot be read (")


@pytest.mark.parametrize("chunk", [7, 1 << 20])
def test_members_are_cut_past_comments_cdata_instructions_text_and_nesting(
    monkeypatch: pytest.MonkeyPatch, chunk: int
) -> None:
    monkeypatch.setattr(members_module, "CHUNK", chunk)
    nested = building("n", box(0.0)).replace(
        "<bldg:Building", "<cityObjectMember/><bldg:Building", 1
    )
    text = _city(
        "<!-- a comment between members -->",
        _tricky(),
        "\n<?pi?> stray text > ",
        nested,
        "<featureMember/>",
    ).encode()
    found = Members(io.BytesIO(text))
    pieces = list(found)
    assert [name for name, _ in pieces] == [
        "boundedBy", "cityObjectMember", "cityObjectMember", "featureMember"
    ]  # fmt: skip
    assert found.prolog.endswith(ROOT.encode()) and found.root_end == b"</CityModel>"
    for name, piece in pieces:
        alone = etree.fromstring(found.prolog + piece + found.root_end)
        assert len(alone) == 1 and etree.QName(alone[0]).localname == name
    whole = etree.fromstring(text)
    together = etree.fromstring(found.prolog + b"".join(p for _, p in pieces) + found.root_end)
    assert [e.tag for e in together.iter(etree.Element)] == [
        e.tag for e in whole.iter(etree.Element)
    ]


def ten_lines(folder: Path) -> Path:
    """A CityJSONSeq file in ``folder``: ten buildings and, as its line 6, a line that is no
    feature."""
    document = json.loads(multi_lod().read_text())
    header = {key: document[key] for key in ("type", "version", "transform")}
    lines = [json.dumps({**header, "CityObjects": {}, "vertices": []})]
    lines += [json.dumps(feature) for feature in _features(document)]
    lines.insert(5, '{"type": "CityJSONFeature", "CityObjects": 3}')
    path = folder / "ten.city.jsonl"
    path.write_text("\n".join(lines) + "\n")
    return path


def ten_objects(folder: Path) -> Path:
    """A CityJSON file in ``folder``: ten buildings, one of them (2128302) naming a vertex
    that is not there."""
    document = json.loads(multi_lod().read_text())
    broken = document["CityObjects"]["2128302"]["geometry"][0]
    broken["boundaries"] = [[[[len(document["vertices"]) + 5, 0, 1]]]]
    path = folder / "ten.city.json"
    path.write_text(json.dumps(document))
    return path


@pytest.mark.usefixtures("one_member_a_task")
def test_a_sequence_read_by_workers_is_the_sequence_read_in_one_process(tmp_path: Path) -> None:
    """A CityJSONSeq file of ten buildings, a line that is no feature among them: a line a
    task, the same nodes, the same line reported; what the workers read comes back packed."""
    path = ten_lines(tmp_path)
    one, one_facts, _, _ = _read(path, spread=False)
    two, two_facts, results, _ = _read(path, spread=True)
    assert two_facts == one_facts and len(one_facts) == 10
    read = [_read_of(result) for result in results]
    assert sum(len(result.nodes) for result in read) >= 8
    assert {type(node).__name__ for result in read for node in result.nodes} == {"PackedNode"}
    assert tally_of(two).skipped == tally_of(one).skipped
    assert [entry["id"] for entry in tally_of(two).skipped] == ["line 6"]


@pytest.mark.usefixtures("one_member_a_task")
def test_a_sequence_line_too_long_is_skipped_by_workers_as_in_one_process(tmp_path: Path) -> None:
    """A feature line past ``sequence_line_bytes`` among ten: the same nodes and the same line
    reported by number, with workers and in one process."""
    path = ten_lines(tmp_path)
    lines = path.read_bytes().splitlines()
    lines.insert(3, b'{"type": "CityJSONFeature", "x": "' + b"x" * 30_000 + b'"}')
    path.write_bytes(b"\n".join(lines) + b"\n")
    limits = Limits(sequence_line_bytes=20_000)
    one, one_facts, _, _ = _read(path, spread=False, limits=limits)
    two, two_facts, results, _ = _read(path, spread=True, limits=limits)
    assert two_facts == one_facts and len(one_facts) == 10
    assert sum(len(_read_of(result).nodes) for result in results) >= 8
    assert tally_of(two).skipped == tally_of(one).skipped
    assert [entry["id"] for entry in tally_of(two).skipped] == ["line 4", "line 7"]


@pytest.mark.usefixtures("one_member_a_task")
def test_a_cityjson_file_read_by_workers_is_the_file_read_in_one_process(tmp_path: Path) -> None:
    """Ten buildings of a ``.json`` file, an object a task (parts joined to their building
    in the main process), one building naming a vertex that is not there: the same nodes,
    the same object reported, the scene's size known once read."""
    path = ten_objects(tmp_path)
    one, one_facts, _, _ = _read(path, spread=False)
    two, two_facts, results, _ = _read(path, spread=True)
    assert two_facts == one_facts and len(one_facts) == 9
    assert sum(sum(n is not None for n in result.nodes) for result in results) >= 8
    assert tally_of(two).skipped == tally_of(one).skipped
    assert [entry["id"] for entry in tally_of(two).skipped] == ["2128302"]
    assert two.size == one.size == 9


@pytest.mark.usefixtures("one_member_a_task")
def test_cityjson_objects_alone_come_back_packed_and_parts_are_joined_here(
    tmp_path: Path,
) -> None:
    """The node of an object with neither parts nor a parent comes back from its worker packed
    (the main process parks it as it came, never unpickling it); a building with a part and
    the part come back as nodes, and the part is joined to its building here: the nodes are
    those of one process."""
    document = json.loads(multi_lod().read_text())
    objects = document["CityObjects"]
    whole, part = [key for key in objects if key != "2128302"][3:5]
    objects[part]["type"] = "BuildingPart"
    objects[part]["parents"] = [whole]
    objects[whole]["children"] = [part]
    path = tmp_path / "parts.city.json"
    path.write_text(json.dumps(document))
    _, one_facts, _, _ = _read(path, spread=False)
    _, two_facts, results, _ = _read(path, spread=True)
    assert two_facts == one_facts and len(one_facts) == 9
    kinds = {n.id: type(n).__name__ for r in results for n in r.nodes if n is not None}
    assert kinds.pop(whole) == kinds.pop(part) == "Node"
    assert set(kinds.values()) == {"PackedNode"} and len(kinds) >= 7


class _Shipped(Executor):
    """Each task and its result pickled and unpickled, as to and from a worker, in this
    process; the tasks kept, each with its bytes."""

    def __init__(self) -> None:
        self.sent: list[tuple[Any, int]] = []

    def results(self, tasks: Iterable[Any]) -> Iterator[Any]:
        for task in tasks:
            data = pickle.dumps(task, protocol=pickle.HIGHEST_PROTOCOL)
            self.sent.append((task, len(data)))
            yield pickle.loads(pickle.dumps(pickle.loads(data).run()))


@pytest.mark.usefixtures("one_member_a_task")
def test_a_cityjson_task_carries_only_the_vertices_its_objects_use() -> None:
    """Delft read by workers, an object a task: the nodes of one process, and each task ships
    the rows of the vertex list its object uses, not the whole list (which made every task as
    large as the file's vertices)."""
    _, one_facts, _, _ = _read(delft(), spread=False)
    shipped = _Shipped()
    _, two_facts, _, _ = _read(delft(), spread=True, workers=lambda: shipped)
    assert two_facts == one_facts
    tasks = [(task, size) for task, size in shipped.sent if isinstance(task, ObjectsTask)]
    assert len(tasks) > 1
    whole = tasks[0][0].vertices.count
    rows = [len(task.vertices.rows) for task, _ in tasks]
    assert all(task.vertices.used is not None for task, _ in tasks)
    assert len(tasks) > 500 and max(rows) < whole / 20 and sum(rows) < 2 * whole
    assert sum(size for _, size in tasks) < 10 * 24 * whole  # the list once a task: 569×


@pytest.mark.usefixtures("one_member_a_task")
@pytest.mark.parametrize(
    "boundaries",
    [[[[[10**6, 0, 1]]]], [[[["0", 1, 2]]]], [[[None]]], [[[[0.5, 1, 2]]]], "nested"],
    ids=["missing-vertex", "text-index", "null-ring", "fractional-index", "text"],
)
def test_an_object_with_bad_boundaries_read_by_workers_is_skipped_as_in_one_process(
    tmp_path: Path, boundaries: Any
) -> None:
    """An object whose boundaries are not nested lists of vertex indices is skipped for the
    same reason as in one process (its task ships every row then), the others read alike."""
    document = json.loads(multi_lod().read_text())
    document["CityObjects"]["2128302"]["geometry"][0]["boundaries"] = boundaries
    path = tmp_path / "broken.city.json"
    path.write_text(json.dumps(document))
    one, one_facts, _, _ = _read(path, spread=False)
    two, two_facts, _, _ = _read(path, spread=True, workers=_Shipped)
    assert two_facts == one_facts and len(one_facts) == 9
    assert tally_of(two).skipped == tally_of(one).skipped
    assert [entry["id"] for entry in tally_of(two).skipped] == ["2128302"]


def _degrees(ring: str) -> str:
    """A ring of metres (x y z) as latitude, longitude and height near Tokyo."""
    values = [float(v) for v in ring.split()]
    points = zip(values[0::3], values[1::3], values[2::3], strict=True)
    return " ".join(f"{35.68 + y * 1e-5!r} {139.76 + x * 1e-5!r} {z!r}" for x, y, z in points)


@pytest.mark.usefixtures("one_member_a_task")
def test_a_geographic_city_read_by_workers_is_projected_on_the_frame_of_one_process(
    tmp_path: Path,
) -> None:
    """Buildings in EPSG:6697 (latitude, longitude): the frame is centred on the first, read
    by a worker before the others are sent, and the others are projected onto it."""
    envelope = ENVELOPE.replace("EPSG::25832,crs:EPSG::7837", "EPSG::6697")
    towns = [building(f"g{i}", [_degrees(r) for r in box(30.0 * i)]) for i in range(5)]
    path = tmp_path / "tokyo.gml"
    path.write_text(_city(*towns).replace(ENVELOPE, envelope))
    one, one_facts, _, _ = _read(path, spread=False)
    two, two_facts, results, _ = _read(path, spread=True)
    assert two_facts == one_facts and len(one_facts) == 5
    assert sum(len(_read_of(result).nodes) for result in results) == 5
    assert two.crs == one.crs and "+proj=tmerc" in str(two.crs)


@pytest.mark.usefixtures("one_member_a_task")
@pytest.mark.parametrize("name", ["town.gml", "ten.city.json"])
def test_a_task_whose_workers_die_is_read_in_the_main_process(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    if name.endswith(".gml"):
        path.write_text(_town())
    else:
        path.write_bytes(multi_lod().read_bytes())
    _, one_facts, _, _ = _read(path, spread=False)
    _, two_facts, _, told = _read(path, spread=True, killer=1)
    assert two_facts == one_facts
    assert any("died twice (signal SIGKILL)" in line and "main process" in line for line in told)


@pytest.mark.parametrize("inside", ["{}", "<!--{}-->"], ids=["text", "comment"])
def test_a_long_member_is_scanned_in_time_linear_in_its_bytes(
    monkeypatch: pytest.MonkeyPatch, inside: str
) -> None:
    """A member of 16 MiB (of text, or a comment) read 4 KiB at a time is cut out in about
    a second at most (copying the bytes held, or looking at the comment again, for each
    chunk read took minutes)."""
    monkeypatch.setattr(members_module, "CHUNK", 4096)
    long = inside.format("x" * (16 << 20))
    text = _city(f"<cityObjectMember><a>{long}</a></cityObjectMember>").encode()
    start = time.process_time()  # CPU, not wall: a loaded machine slows the clock, not the work
    assert [len(member) for _, member in Members(io.BytesIO(text))][1] > 16 << 20
    assert time.process_time() - start < 3.0


def _run_here(kept: list[Any], tasks: Iterable[Any]) -> Iterator[Any]:
    """Run each of ``tasks`` in this process, keeping it in ``kept``."""
    for task in tasks:
        kept.append(task)
        yield task.run()


@pytest.mark.parametrize(
    "path", [SHARED / "data/citygml/potsdam_lod1_v1.gml", SHARED / "data/cityjson/delft.city.json"]
)
def test_a_city_is_read_in_tasks_of_the_work_its_executor_is_sized_for(
    monkeypatch: pytest.MonkeyPatch, path: Path
) -> None:
    """A dask cluster's tasks hold three times the work of a pool's (its tasks cost more):
    its reading tasks too, a third as many, and the city read is the same."""
    path = shared_data(path)
    made = spread.Sizer.__init__

    def timed(self: spread.Sizer, least: int = spread.MIN_BYTES, most: int = 1 << 30) -> None:
        """A sizer that reads a byte in a µs, or an object in 5 ms, with no floor."""
        made(self, 1, most)
        self.seconds_per_byte = 1e-6 if least == spread.MIN_BYTES else 5e-3

    monkeypatch.setattr(spread.Sizer, "__init__", timed)
    monkeypatch.setattr(spread.Sizer, "took", lambda self, seconds, size: None)
    counts, read = [], []
    for seconds in (0.1, 0.3):
        tasks: list[Any] = []
        here = _Here(functools.partial(_run_here, tasks), seconds)
        scene = read_scene(path, context=RunContext(here, get_backend("numpy"), progress=print))  # type: ignore[arg-type]
        read.append(_parked_facts(scene))
        counts.append(sum(not isinstance(task, MarksTask) for task in tasks))
    assert read[0] == read[1]
    assert counts[0] >= 10
    assert abs(counts[0] / counts[1] - 3) < 0.5
