"""Reading and baking on a dask.distributed cluster (``--scheduler ADDRESS``): the bytes of one
worker on a 2-worker ``LocalCluster``, a city read by its workers as in one process, the
workers' progress told as with one worker, broken objects reported the same, a task over dask's
10 MB sent without its warning, a killed worker's task run again and then reported, a result
that comes as its wait times out taken, an unreachable scheduler, one that does not answer
or is none, and a bad address or scheduler file failing the run in one line, an interrupted
run cancelling its tasks and leaving nothing."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import trimesh

from lodconvert.bake import get_backend
from lodconvert.bakery import iter_chains
from lodconvert.chain import ChainOptions
from lodconvert.context import RunContext
from lodconvert.errors import LodConvertError
from lodconvert.io.citygml.ranges import MarksResult, RangeResult
from lodconvert.io.geometry_checks import tally_of
from lodconvert.limits import DEFAULT_LIMITS
from lodconvert.model import Scene
from lodconvert.tasks import Executor, PoolExecutor, SerialExecutor, batches

from .conftest import ROOT, SHARED, shared_data
from .fuzz import hostile_citygml
from .test_cli import assert_one_line_error
from .test_parallel_reading import (
    _read,
    _read_of,
    _town,
    one_member_a_task,  # noqa: F401  (a fixture)
    ten_lines,
    ten_objects,
)
from .test_workers import TUM, _KillsItsWorker, _lodconvert, _messages, _scene, _untimed

pytestmark = pytest.mark.slow  # a LocalCluster per module, and connection timeouts

distributed = pytest.importorskip("distributed")
dask = pytest.importorskip("dask")

from lodconvert import dask_executor  # noqa: E402  (needs distributed)
from lodconvert.dask_executor import DaskExecutor  # noqa: E402

CITYJSON = SHARED / "data" / "cityjson" / "multi_lod_10bldg.city.json"


@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    """Two worker processes of one thread on 127.0.0.1; the scheduler gives a task up after
    its second worker dies (as ``--workers`` does) and sends each worker one task at a time."""
    settings = {
        "distributed.scheduler.allowed-failures": 1,
        "distributed.scheduler.worker-saturation": 1.0,
    }
    with (
        dask.config.set(settings),
        distributed.LocalCluster(
            processes=True,
            n_workers=2,
            threads_per_worker=1,
            host="127.0.0.1",
            dashboard_address=":0",
        ) as local,
    ):
        yield local


@pytest.fixture(scope="module")
def address(cluster: Any) -> str:
    return cluster.scheduler_address


CASES = [
    pytest.param(CITYJSON, ".x3d", (), "objectstask", id="cityjson-x3d"),
    pytest.param(TUM, ".glb", (), "readtask", id="tum-glb"),
    pytest.param(
        TUM, ".x3d", ("--hlod", "250", "--switching", "prism"), "readtask", id="tum-hlod-prism"
    ),
]


@pytest.mark.parametrize(("source", "suffix", "options", "reads"), CASES)
def test_a_cluster_writes_the_bytes_of_one_worker(
    source: Path, suffix: str, options: tuple[str, ...], reads: str, address: str, tmp_path: Path
) -> None:
    """The city is read on the cluster too (tasks of ``reads``), with the same outcome."""
    shared_data(source)
    runs = {}
    with distributed.Client(address, set_as_default=False) as client:
        client.get_task_stream()  # the scheduler records the tasks run from now on
        started = time.time()
        for where in (("--workers", "1"), ("--scheduler", address)):
            out, report = tmp_path / f"{where[0][2:]}{suffix}", tmp_path / f"{where[0][2:]}.json"
            run = _lodconvert(source, "-o", out, "--report", report, *where, *options)
            assert run.returncode == 0, run.stderr
            runs[where[0]] = (out.read_bytes(), json.loads(report.read_text()), run.stderr)
        ran = {t["key"].split("-")[1] for t in client.get_task_stream(start=started)}
    one, cluster = runs["--workers"], runs["--scheduler"]
    assert cluster[0] == one[0]
    assert _untimed(cluster[1]) == _untimed(one[1])
    assert _messages(cluster[2]) == _messages(one[2])
    cells = {"celltask"} if "--hlod" in options else set()
    assert ran == {reads, "baketask", *cells}  # the kinds of task in their keys


def _baking_lines(stderr: str) -> list[str]:
    """What ``-v`` told of each level baked (without the time it was told at)."""
    return [line.split(maxsplit=1)[1] for line in stderr.splitlines() if ": baking " in line]


def test_the_workers_progress_is_told_as_with_one_worker(address: str, tmp_path: Path) -> None:
    """``-v`` tells each level of points the cluster's workers bake, in the order of one
    worker."""
    source = tmp_path / "sphere.ply"
    trimesh.creation.icosphere(subdivisions=3).export(source)
    told = {}
    for where in (("--workers", "1"), ("--scheduler", address)):
        out = tmp_path / f"{where[0][2:]}.x3d"
        run = _lodconvert(source, source, "-o", out, "-v", *where)
        assert run.returncode == 0, run.stderr
        told[where[0]] = _baking_lines(run.stderr)
    assert told["--scheduler"] == told["--workers"]
    assert told["--workers"] == [f"sphere: baking LOD{i}" for i in (3, 2, 1)] * 2


def _write_town(folder: Path) -> Path:
    """The town of :mod:`.test_parallel_reading` as a file in ``folder``."""
    path = folder / "town.gml"
    path.write_text(_town())
    return path


CITIES = {"town.gml": _write_town, "ten.city.jsonl": ten_lines, "ten.city.json": ten_objects}


def _cluster(address: str) -> Callable[[], Executor]:
    return lambda: DaskExecutor(address, "numpy")


@pytest.mark.usefixtures("one_member_a_task")
@pytest.mark.parametrize("name", list(CITIES))
def test_a_city_read_by_the_cluster_is_the_city_read_in_one_process(
    name: str, address: str, tmp_path: Path
) -> None:
    """CityGML members (from ranges of the file: the workers open it), CityJSONSeq lines,
    CityJSON objects, each a task: the same nodes, ids and skipped objects; the town's
    implicit geometry is read in the main process."""
    path = CITIES[name](tmp_path)
    one, one_facts, _, _ = _read(path, spread=False)
    two, two_facts, results, told = _read(path, spread=True, workers=_cluster(address))
    assert two_facts == one_facts
    assert tally_of(two).skipped == tally_of(one).skipped != []
    read = [_read_of(result) for result in results]
    assert sum(sum(node is not None for node in r.nodes) for r in read) >= 8
    ranged = [r for r in results if not isinstance(r, MarksResult)]
    assert all(isinstance(r, RangeResult) for r in ranged) == name.endswith(".gml")
    implicit = [f"{path}: implicit geometry is read in the main process"]
    assert told == (implicit if name.endswith(".gml") else [])


@pytest.mark.usefixtures("one_member_a_task")
def test_a_run_of_members_whose_workers_die_is_read_in_the_main_process(
    address: str, tmp_path: Path
) -> None:
    path = _write_town(tmp_path)
    _, one_facts, _, _ = _read(path, spread=False)
    _, two_facts, _, told = _read(path, spread=True, killer=1, workers=_cluster(address))
    assert two_facts == one_facts
    died = f"{path}: the dask workers converting it died (2 tries); its run is read in the main"
    assert any(line.startswith(died) for line in told)


@pytest.mark.parametrize("sizes", ["20", "20,80"])
def test_a_cluster_writes_the_tileset_of_one_worker(
    address: str, tmp_path: Path, sizes: str
) -> None:
    """Tiles and cells (of one tier or two) are tasks on the cluster that bakes: the same
    files as made in one process."""
    shared_data(CITYJSON)
    files = []
    for where in (("--workers", "1"), ("--scheduler", address)):
        out = tmp_path / where[0][2:] / "tileset.json"
        options = ("--crs", "EPSG:7415", "--hlod", sizes, "--levels", "2", *where)
        run = _lodconvert(CITYJSON, "-o", out, *options)
        assert run.returncode == 0, run.stderr
        paths = sorted(p for p in out.parent.rglob("*") if p.is_file())
        files.append({str(p.relative_to(out.parent)): p.read_bytes() for p in paths})
    assert files[0] == files[1]
    assert sum(name.endswith(".glb") for name in files[0]) > 2


def _closed_port() -> int:
    """A port on 127.0.0.1 that nothing listens on."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_an_unreachable_scheduler_fails_in_seconds_naming_it(tmp_path: Path) -> None:
    address = f"tcp://127.0.0.1:{_closed_port()}"
    started = time.monotonic()
    run = _lodconvert(shared_data(CITYJSON), "-o", tmp_path / "out.x3d", "--scheduler", address)
    assert time.monotonic() - started < 30
    assert run.returncode == 1, run.stderr
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith(f"lodconvert: error: {address}: cannot reach the dask scheduler")
    assert "Traceback" not in run.stderr
    assert list(tmp_path.iterdir()) == []


def test_an_unreachable_scheduler_fails_before_the_input_is_read(tmp_path: Path) -> None:
    """The scheduler is reached first: a building of 100,000 parts (a minute's reading) is
    not read when its cluster cannot be reached."""
    district = tmp_path / "parts.gml"
    district.write_bytes(hostile_citygml.many_parts(100_000))
    address = f"tcp://127.0.0.1:{_closed_port()}"
    out = tmp_path / "out"
    out.mkdir()
    started = time.monotonic()
    run = _lodconvert(district, "-o", out / "out.glb", "--scheduler", address)
    assert time.monotonic() - started < 30
    assert run.returncode == 1, run.stderr
    assert "cannot reach the dask scheduler" in run.stderr.strip().splitlines()[-1]
    assert list(out.iterdir()) == []


def test_a_scheduler_file_gives_the_address(address: str, tmp_path: Path) -> None:
    scheduler_file = tmp_path / "scheduler.json"
    scheduler_file.write_text(json.dumps({"type": "Scheduler", "address": address}))
    out = tmp_path / "out.x3d"
    run = _lodconvert(shared_data(CITYJSON), "-o", out, "--scheduler", scheduler_file, "-q")
    assert run.returncode == 0, run.stderr
    assert out.stat().st_size > 0


NOT_DASK = "not a dask scheduler address (dask knows inproc://, tcp://, tls://"


@pytest.mark.parametrize(
    ("text", "options", "says"),
    [
        ("absent.json", (), "absent.json: neither a scheduler address"),
        ("notes.txt", (), "notes.txt: a scheduler file must be JSON"),
        ("other.json", (), "other.json: the scheduler file names no address"),
        ("tcp://127.0.0.1:1", ("--workers", "2"), "--workers is for this machine's processes"),
        ("file:///etc/passwd", (), f"--scheduler file:///etc/passwd: {NOT_DASK}"),
        ("ftp://127.0.0.1:21", (), f"--scheduler ftp://127.0.0.1:21: {NOT_DASK}"),
        ("ftp.json", (), f"ftp.json: its address ftp://127.0.0.1:21: {NOT_DASK}"),
        ("tcp://127.0.0.1", (), "tcp://127.0.0.1: not a dask scheduler address (missing port"),
    ],
    ids=["absent", "not-json", "no-address", "with-workers", "file", "ftp", "ftp-file", "no-port"],
)
def test_a_bad_scheduler_option_is_a_usage_error(
    text: str, options: tuple[str, ...], says: str, tmp_path: Path
) -> None:
    """One line, exit 2, at once (an address of a scheme dask does not know printed dask's
    ValueError, and a traceback from ``Client.__del__`` 20 s later)."""
    (tmp_path / "notes.txt").write_text("tcp://127.0.0.1:8786\n")
    (tmp_path / "other.json").write_text('{"type": "Scheduler"}')
    (tmp_path / "ftp.json").write_text('{"address": "ftp://127.0.0.1:21"}')
    before = sorted(tmp_path.iterdir())
    value = text if "://" in text else tmp_path / text
    run = _lodconvert(
        shared_data(CITYJSON), "-o", tmp_path / "out.x3d", "--scheduler", value, *options
    )
    assert_one_line_error(run, 2, says)
    assert sorted(tmp_path.iterdir()) == before


@contextlib.contextmanager
def _listener(answer: bytes) -> Iterator[str]:
    """A TCP listener on 127.0.0.1 that accepts every connection, sends ``answer`` on it
    (nothing: it stays silent) and keeps it open; its address."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        server.settimeout(0.1)  # so that the loop sees when to stop
        done = threading.Event()
        accepted: list[socket.socket] = []

        def serve() -> None:
            while not done.is_set():
                try:
                    connection, _ = server.accept()
                except TimeoutError:
                    continue
                accepted.append(connection)
                connection.sendall(answer)

        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        try:
            yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
        finally:
            done.set()
            thread.join()
            for connection in accepted:
                connection.close()


def _lodconvert_to_its_end(*args: object) -> subprocess.CompletedProcess[str]:
    """``lodconvert ARGS`` run to its end (a run still going after 300 s, a safety net, fails
    the test)."""
    command = [sys.executable, "-m", "lodconvert", *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, cwd=ROOT, timeout=300)


def test_a_listener_that_never_answers_fails_the_run_in_one_line(tmp_path: Path) -> None:
    """A listener that accepts the connection and says nothing (a hung scheduler, a web
    server waiting for a request): dask bounds connecting but not the handshake that
    follows, which waited forever."""
    with _listener(b"") as address:
        run = _lodconvert_to_its_end(
            shared_data(CITYJSON), "-o", tmp_path / "out.x3d", "--scheduler", address
        )
    says = f"lodconvert: error: {address}: the dask scheduler does not answer (nothing in 20 s)"
    assert_one_line_error(run, 1, says)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("what", ["web-server", "worker"])
def test_what_is_not_a_dask_scheduler_fails_the_run_in_one_line(
    what: str, cluster: Any, tmp_path: Path
) -> None:
    """A web server's answer (dask read its first bytes as a length, and ran out of memory)
    and a dask worker's (it has no identity of a scheduler) end the run with one line."""
    with contextlib.ExitStack() as stack:
        if what == "worker":
            address = next(iter(cluster.scheduler_info["workers"]))
        else:
            address = stack.enter_context(_listener(b"HTTP/1.1 400 Bad Request\r\n\r\n"))
        run = _lodconvert_to_its_end(
            shared_data(CITYJSON), "-o", tmp_path / "out.x3d", "--scheduler", address
        )
    says = f"lodconvert: error: {address}: what answers there is not a dask scheduler"
    assert_one_line_error(run, 1, says)
    assert list(tmp_path.iterdir()) == []


def _baked(scene: Scene, executor: Executor) -> tuple[list[Any], list[str], list[dict[str, str]]]:
    """The chains, warnings and skipped objects of ``scene`` baked by ``executor``."""
    warnings: list[str] = []
    skipped: list[dict[str, str]] = []
    with executor:
        chains = list(
            iter_chains(
                scene,
                ChainOptions(),
                RunContext(executor, get_backend("numpy"), warn=warnings.append, skipped=skipped),
            )
        )
    return chains, warnings, skipped


def _levels(chains: list[Any]) -> list[tuple[str, list[int]]]:
    """Each chain's object and its levels' counts."""
    return [(chain.object_id, [level.count for level in chain.levels]) for chain in chains]


def test_a_broken_object_in_a_batch_is_reported_as_with_one_worker(address: str) -> None:
    one = _baked(_scene(broken="obj5"), SerialExecutor(get_backend("numpy")))
    cluster = _baked(_scene(broken="obj5"), DaskExecutor(address, "numpy"))
    assert _levels(cluster[0]) == _levels(one[0])
    assert len(cluster[0]) == 7
    assert cluster[1] == one[1] and any("obj5" in w and "skipped" in w for w in cluster[1])
    assert (
        cluster[2]
        == one[2]
        == [{"id": "obj5", "reason": "obj5: has NaN or infinite vertex coordinates"}]
    )


def test_a_cluster_is_sent_batches_of_three_times_the_work_of_a_pools() -> None:
    """A dask task costs milliseconds of CPU (a process pool's a tenth of one), so the
    cluster's batches hold 0.3 s of work, not 0.1 s: a third as many tasks."""
    items = [(node, ChainOptions()) for node in _scene().nodes] * 8
    per_object = [1 / 64]  # seconds an object took so far
    for executor, sizes in ((DaskExecutor, [19, 19, 19, 7]), (PoolExecutor, [6] * 10 + [4])):
        made = batches(items, per_object, DEFAULT_LIMITS, seconds=executor.task_seconds)
        assert [len(task.items) for task in made] == sizes


def test_a_task_over_ten_megabytes_is_sent_without_a_warning(
    address: str, recwarn: pytest.WarningsRecorder
) -> None:
    """A task holding more than dask's 10 MB for a graph (a long run of members, a large
    CityJSON file's vertices) is sent once, as it is: dask's advice is not printed."""
    scene = _scene()
    scene.nodes[2].attributes["notes"] = "x" * (11 << 20)
    chains, _, skipped = _baked(scene, DaskExecutor(address, "numpy"))
    assert len(chains) == 8 and skipped == []
    assert [str(w.message) for w in recwarn if "large graph" in str(w.message)] == []


def _kill_first_taker(marker: str) -> None:
    """Kill the process unpickling this (a worker taking the task) unless ``marker`` exists;
    create it first, so that the task's next try runs."""
    try:
        os.close(os.open(marker, os.O_CREAT | os.O_EXCL))
    except FileExistsError:
        return
    signal.raise_signal(signal.SIGKILL)


class _KillsItsFirstWorker:
    """An attribute whose first unpickling kills the worker doing it."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, tuple[str]]:
        return _kill_first_taker, (str(self.marker),)


def test_a_task_whose_worker_is_killed_runs_again_with_the_same_result(
    address: str, tmp_path: Path
) -> None:
    one = _baked(_scene(), SerialExecutor(get_backend("numpy")))
    scene = _scene()
    scene.nodes[3].attributes["trap"] = _KillsItsFirstWorker(tmp_path / "killed")
    cluster = _baked(scene, DaskExecutor(address, "numpy"))
    assert (tmp_path / "killed").exists()  # a worker was killed
    assert _levels(cluster[0]) == _levels(one[0])
    assert cluster[2] == []


def test_a_task_whose_workers_are_killed_twice_is_reported_and_the_rest_convert(
    address: str,
) -> None:
    scene = _scene()
    scene.nodes[0].attributes["trap"] = _KillsItsWorker()
    chains, warnings, skipped = _baked(scene, DaskExecutor(address, "numpy"))
    assert [c.object_id for c in chains] == [f"obj{i}" for i in range(1, 8)]
    assert [entry["id"] for entry in skipped] == ["obj0"]
    assert "the dask workers converting it died (2 tries)" in skipped[0]["reason"]
    assert any("obj0" in w and "skipped" in w for w in warnings)


def _scheduler_tasks(client: Any) -> list[str]:
    """The keys of the tasks the scheduler holds."""
    return client.run_on_scheduler(lambda dask_scheduler: list(dask_scheduler.tasks))


@pytest.mark.parametrize(
    ("sig", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)], ids=["sigterm", "sigint"]
)
def test_an_interrupted_run_cancels_its_tasks_and_leaves_nothing(
    address: str, tmp_path: Path, sig: signal.Signals, code: int
) -> None:
    command, out = _slow_spheres(tmp_path, address)
    with distributed.Client(address, set_as_default=False) as client:
        with subprocess.Popen(command, stderr=subprocess.PIPE, text=True, cwd=ROOT) as run:
            _until_baking(client, run)
            assert any(out.parent.iterdir())  # its staged output exists
            run.send_signal(sig)
            assert run.stderr is not None
            rest = run.stderr.read()
            assert run.wait() == code, rest
        assert "Traceback" not in rest
        assert list(out.parent.iterdir()) == []
        deadline = time.monotonic() + 10
        while _scheduler_tasks(client):  # cancelled: the scheduler forgets them
            assert time.monotonic() < deadline, _scheduler_tasks(client)
            time.sleep(0.1)


def _slow_spheres(tmp_path: Path, scheduler: str) -> tuple[list[str], Path]:
    """A command line baking two spheres slowly (seconds a level) on ``scheduler``, and the
    output it writes into a folder of its own."""
    source = tmp_path / "sphere.ply"
    trimesh.creation.icosphere(subdivisions=5).export(source)
    out = tmp_path / "out" / "spheres.glb"
    out.parent.mkdir()
    command = [
        *(sys.executable, "-m", "lodconvert", str(source), str(source), "-o", str(out)),
        *("--resolution", "1024,512,256", "--no-mesh", "--levels", "3", "--scheduler", scheduler),
    ]
    return command, out


def _until_baking(client: Any, run: subprocess.Popen[str]) -> None:
    """Wait until a worker of ``client``'s cluster runs a task of ``run``."""
    deadline = time.monotonic() + 60
    while not any(client.processing().values()):
        assert run.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)


@contextlib.contextmanager
def _dask_command(*args: object) -> Iterator[subprocess.Popen[bytes]]:
    """``dask ARGS`` (as the README starts a scheduler or a worker) running, killed at the
    end."""
    command = [sys.executable, "-m", "dask", *map(str, args)]
    with subprocess.Popen(command, stderr=subprocess.DEVNULL, cwd=ROOT) as process:
        try:
            yield process
        finally:
            process.kill()


@contextlib.contextmanager
def _baking_on_a_cluster(
    tmp_path: Path, scheduler_file: Path
) -> Iterator[tuple[subprocess.Popen[bytes], subprocess.Popen[str], Path]]:
    """A scheduler and one worker on 127.0.0.1 (their address in ``scheduler_file``) and a
    run baking slow spheres on them, once it bakes: the scheduler's process, the run's and
    its output."""
    with (
        _dask_command("scheduler", "--host", "127.0.0.1", "--port", 0, "--no-dashboard",
                      "--scheduler-file", scheduler_file) as scheduler,
        _dask_command("worker", "--scheduler-file", scheduler_file, "--nthreads", 1,
                      "--no-dashboard"),
        distributed.Client(scheduler_file=str(scheduler_file), timeout=30) as client,
    ):  # fmt: skip
        client.wait_for_workers(1, timeout=30)
        command, out = _slow_spheres(tmp_path, str(scheduler_file))
        with subprocess.Popen(command, stderr=subprocess.PIPE, text=True, cwd=ROOT) as run:
            _until_baking(client, run)
            yield scheduler, run, out


def test_a_scheduler_lost_mid_run_ends_it_with_one_line(tmp_path: Path) -> None:
    scheduler_file = tmp_path / "scheduler.json"
    with _baking_on_a_cluster(tmp_path, scheduler_file) as (scheduler, run, out):
        scheduler.kill()
        assert run.stderr is not None
        stderr = run.stderr.read()
        assert run.wait(60) == 1, stderr
    address = json.loads(scheduler_file.read_text())["address"]
    assert stderr.splitlines() == [f"lodconvert: error: {address}: lost the dask scheduler"]
    assert list(out.parent.iterdir()) == []


def test_a_scheduler_that_stops_answering_mid_run_ends_it_with_one_line(tmp_path: Path) -> None:
    """A scheduler stopped (SIGSTOP: its connections stay open, nothing answers) while the
    run waits for its batches: each look whether the cluster still has workers is bounded
    (it waited forever)."""
    scheduler_file = tmp_path / "scheduler.json"
    with _baking_on_a_cluster(tmp_path, scheduler_file) as (scheduler, run, out):
        scheduler.send_signal(signal.SIGSTOP)
        try:
            _, stderr = run.communicate(timeout=300)  # a safety net
        finally:
            run.kill()
            scheduler.send_signal(signal.SIGCONT)
    address = json.loads(scheduler_file.read_text())["address"]
    says = f"lodconvert: error: {address}: the dask scheduler stopped answering (nothing in 20 s)"
    assert run.returncode == 1 and stderr.splitlines() == [says], stderr
    assert list(out.parent.iterdir()) == []


def test_a_scheduler_without_workers_fails_naming_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(dask_executor, "WORKERS_SECONDS", 0.5)
    with (
        distributed.LocalCluster(
            processes=False, n_workers=0, host="127.0.0.1", protocol="tcp", dashboard_address=":0"
        ) as empty,
        pytest.raises(LodConvertError) as failed,
        DaskExecutor(empty.scheduler_address, "numpy"),
    ):
        pass
    assert str(failed.value) == (
        f"{empty.scheduler_address}: the dask scheduler has no worker (none joined in 0.5 s)"
    )


class _LateFuture:
    """A future whose task finishes just after its first wait timed out."""

    status = "pending"

    def done(self) -> bool:
        return self.status == "finished"

    def result(self, timeout: float) -> tuple[str, tuple[str, ...]]:
        if self.status == "pending":
            self.status = "finished"
            raise TimeoutError(f"timed out after {timeout} s.")
        return "its result", ()


def test_a_result_that_comes_just_after_a_wait_timed_out_is_taken() -> None:
    """A task that finishes between a wait's timeout and the look at its state is taken, not
    an error (it failed runs of a loaded machine with ``TimeoutError: timed out after 2 s.``)."""
    executor = DaskExecutor("tcp://127.0.0.1:1", "numpy")
    assert executor._result(None, _LateFuture()) == "its result"  # type: ignore[arg-type]
