"""Tasks run on a dask.distributed cluster (``--scheduler ADDRESS``): :class:`DaskExecutor`
submits each task to the scheduler, with a bounded window of tasks in flight, and gives the
results back in submission order, as :class:`~.tasks.PoolExecutor` does.

A task travels as data (a batch's nodes and options, or a run of a city's members as bytes,
pickled here: the scheduler passes the bytes on without reading them), so workers on other
machines need no shared file system. Each worker thread makes its backend once, at its first
task (a GL context only inside the worker). The scheduler re-runs a task whose worker died
(dask's ``distributed.scheduler.allowed-failures`` times); once it gives up, the task fails as
the task says (a batch's objects reported, a run of members read in the main process) and the
run goes on. What a task tells of its progress comes back with its result, and is told here
when that result is taken: no message of its own crosses the cluster.

Needs the ``dask`` extra (``pip install '.[dask]'`` in a clone); :mod:`.tasks` does not.
"""

from __future__ import annotations

import json
import pickle
import threading
import time
import uuid
import warnings
from collections import deque
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Self

from distributed import Client, Future, KilledWorker

from .bake import Backend, get_backend
from .chain import Progress
from .errors import LodConvertError, UsageError
from .tasks import DEPTH, BakeResult, BakeTask, Executor

CONNECT_SECONDS = 10.0
"""How long connecting to the scheduler may take before the run fails."""
WORKERS_SECONDS = 20.0
"""How long the run waits for a first worker, and for one to come back once all are gone."""
POLL_SECONDS = 2.0
"""How often a wait for a result looks whether the cluster still has workers."""
TASK_SECONDS = 0.3
"""Work a batch of objects is sized for: a task costs the scheduler, the worker and this
process about 6 ms of CPU in all (2 workers on 2 busy cores), so 2 % of its work."""

_local = threading.local()


def scheduler_address(text: str) -> str:
    """The scheduler address of ``--scheduler text``: an address (``tcp://host:port``, any
    ``scheme://``) as it is, or the ``address`` of a scheduler file (``dask scheduler
    --scheduler-file``); :class:`UsageError` for a file that is absent or not one."""
    if "://" in text:
        return text
    path = Path(text)
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UsageError(
            f"{text}: neither a scheduler address (tcp://host:port) nor a readable scheduler "
            f"file ({exc.strerror or exc})",
            "scheduler",
        ) from None
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise UsageError(f"{text}: a scheduler file must be JSON", "scheduler") from None
    address = record.get("address") if isinstance(record, dict) else None
    if not isinstance(address, str) or "://" not in address:
        raise UsageError(f"{text}: the scheduler file names no address", "scheduler")
    return address


def _backend(name: str) -> Backend:
    """This worker thread's backend called ``name``, made at its first task (a GL context is
    current in the thread that made it)."""
    made: dict[str, Backend] = _local.__dict__.setdefault("backends", {})
    if name not in made:
        made[name] = get_backend(name)
    return made[name]


def _run(payload: bytes, backend_name: str) -> tuple[BakeResult, tuple[str, ...]]:
    """Run the pickled task ``payload`` on a worker, with the worker thread's backend; its
    result and what it told of its progress, in order."""
    task: BakeTask = pickle.loads(payload)
    heard: list[str] = []
    return task.run(_backend(backend_name), heard.append), tuple(heard)


class DaskExecutor(Executor):
    """Tasks run by the workers of the dask scheduler at ``scheduler`` (an address or a
    scheduler file), each baking with its own backend of ``backend_name``; ``progress`` hears
    what each task told of its progress when its result is taken; at most ``window`` tasks
    (default: :data:`~.tasks.DEPTH` + 1 per worker thread) are in flight or waiting to be
    consumed."""

    task_seconds = TASK_SECONDS

    def __init__(
        self,
        scheduler: str,
        backend_name: str,
        progress: Progress | None = None,
        window: int | None = None,
    ) -> None:
        self.scheduler = scheduler
        self.backend_name = backend_name
        self.progress = progress
        self.window = window
        self.address = scheduler
        self._client: Client | None = None
        self._backend: Backend | None = None

    def __enter__(self) -> Self:
        """Connect to the scheduler and wait for a worker (:class:`LodConvertError` naming the
        address when neither comes in time)."""
        address = self.address = scheduler_address(self.scheduler)
        try:
            self._client = Client(address, timeout=CONNECT_SECONDS, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise LodConvertError(
                f"cannot reach the dask scheduler ({_first_line(exc)})", address
            ) from None
        try:
            self._client.wait_for_workers(1, timeout=WORKERS_SECONDS)
        except TimeoutError:
            self.close()
            raise LodConvertError(
                f"the dask scheduler has no worker (none joined in {WORKERS_SECONDS:g} s)", address
            ) from None
        if self.window is None:
            self.window = (DEPTH + 1) * max(1, sum(self._client.nthreads().values()))
        return self

    def results(self, tasks: Iterable[BakeTask]) -> Iterator[BakeResult]:
        """The result of each of ``tasks``, in order; a task the scheduler gave up on (its
        workers died) gives a result with each of its objects failed."""
        client = self._client
        assert client is not None and self.window is not None, "use DaskExecutor as a context"
        run = uuid.uuid4().hex
        pending = iter(tasks)
        flight: deque[tuple[BakeTask, Future | None]] = deque()
        number = 0
        try:
            while True:
                while len(flight) < self.window and (task := next(pending, None)) is not None:
                    key = f"lodconvert-{type(task).__name__.lower()}-{run}-{number}"
                    flight.append((task, self._submitted(client, task, key)))
                    number += 1
                if not flight:
                    return
                task, future = flight.popleft()
                yield self._result(task, future) if future is not None else self._run_here(task)
        finally:
            if flight:
                client.cancel([future for _, future in flight if future is not None])

    def _submitted(self, client: Client, task: BakeTask, key: str) -> Future | None:
        """``task`` pickled and submitted under ``key``; ``None`` for a task that cannot be
        pickled (its data nested too deep), which is run here when its turn comes. A task's
        data is sent once, in its task, so dask's advice against large graphs (over 10 MB: a
        run of members, a CityJSON file's vertices) is not given."""
        try:
            payload = pickle.dumps(task, protocol=pickle.HIGHEST_PROTOCOL)
        except (RecursionError, pickle.PicklingError):
            return None
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "Sending large graph", UserWarning)
            return client.submit(_run, payload, self.backend_name, key=key)

    def _run_here(self, task: BakeTask) -> BakeResult:
        """Run ``task`` in this process (with a backend of the cluster's kind, made once)."""
        if self._backend is None:
            self._backend = get_backend(self.backend_name)
        return task.run(self._backend, self.progress)

    def _result(self, task: BakeTask, future: Future) -> BakeResult:
        """The result of ``task`` from ``future``: waited for while the cluster has workers,
        the task's objects failed when its workers died, an error when the scheduler is lost or
        left without workers; what the task told of its progress is told to ``progress``."""
        since = None
        while True:
            try:
                result, heard = future.result(timeout=POLL_SECONDS)
            except KilledWorker as exc:
                tries = exc.allowed_failures + 1
                return task.failed(f"the dask workers converting it died ({tries} tries)")
            except TimeoutError:
                if future.done() and future.status != "finished":  # the task's own error
                    raise
                if not future.done():  # else it finished just after the wait: take it
                    since = self._still_staffed(since)
                continue
            except Exception:
                if future.cancelled():  # by the client, when the scheduler is gone
                    raise LodConvertError("lost the dask scheduler", self.address) from None
                raise
            if self.progress is not None:
                for text in heard:
                    self.progress(text)
            return result

    def _still_staffed(self, since: float | None) -> float | None:
        """``None`` when the cluster has workers; else since when it has none (``since``, or
        now), or :class:`LodConvertError` once that is :data:`WORKERS_SECONDS` ago, or when
        the scheduler does not answer."""
        try:
            if self._client.nthreads():
                return None
        except OSError:
            raise LodConvertError("lost the dask scheduler", self.address) from None
        now = time.monotonic()
        if since is not None and now - since > WORKERS_SECONDS:
            raise LodConvertError(
                f"the dask scheduler has had no worker for {WORKERS_SECONDS:g} s", self.address
            )
        return since if since is not None else now

    def close(self) -> None:
        """Disconnect from the scheduler (the cluster's workers stay up)."""
        client, self._client = self._client, None
        if client is not None:
            client.close()


def _first_line(exc: BaseException) -> str:
    """The first line of ``exc``'s message (its type's name when it has none)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
