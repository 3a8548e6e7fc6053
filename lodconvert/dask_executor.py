"""Tasks run on a dask.distributed cluster (``--scheduler ADDRESS``): :class:`DaskExecutor`
submits each task to the scheduler, with a bounded window of tasks in flight, and gives the
results back in submission order, as :class:`~.tasks.PoolExecutor` does. A task travels as
data, pickled here, so workers need no shared file system (a range of a city file is read
by the worker where it can open the file: :mod:`.io.citygml.ranges`); a task whose workers
died past the scheduler's retries fails as the task says; progress comes back with each
result; no wait on the scheduler is unbounded (:data:`REQUEST_SECONDS`). What runs where:
``docs/cluster.md``.

Needs the ``dask`` extra (``pip install '.[dask]'`` in a clone); :mod:`.tasks` does not.
"""

from __future__ import annotations

import contextlib
import json
import pickle
import threading
import time
import uuid
import warnings
from collections import deque
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, Self

from distributed import Client, Future, KilledWorker
from distributed.comm import registry

from .bake import Backend, get_backend
from .chain import Progress
from .errors import LodConvertError, UsageError
from .tasks import DEPTH, Executor, Task

CONNECT_SECONDS = 10.0
"""How long connecting to the scheduler may take before the run fails."""
ANSWER_SECONDS = 10.0
"""How long the scheduler may take to answer once connected before the run fails."""
REQUEST_SECONDS = CONNECT_SECONDS + ANSWER_SECONDS
"""How long a request to the scheduler may take (the client's start: connecting, the handshake,
the scheduler's identity; a count of its workers): dask bounds connecting, but neither the
handshake that follows nor a reply on a connection it holds, so a listener that accepts and
never answers held the run forever."""
WORKERS_SECONDS = 20.0
"""How long the run waits for a first worker, and for one to come back once all are gone."""
POLL_SECONDS = 2.0
"""How often a wait for a result looks whether the cluster still has workers."""
STAFF_POLL_SECONDS = 0.1
"""How often the wait for a first worker asks the scheduler (as dask's own wait does)."""
TASK_SECONDS = 0.3
"""Work a batch of objects is sized for: a task costs the scheduler, the worker and this
process about 6 ms of CPU in all (2 workers on 2 busy cores), so 2 % of its work."""

_local = threading.local()


def scheduler_address(text: str) -> str:
    """The scheduler address of ``--scheduler text``: an address (``tcp://host:port``, or of
    another scheme dask connects through: ``tls``, ``ws``, ``wss``, a plugin's) as it is, or
    the ``address`` of a scheduler file (``dask scheduler --scheduler-file``);
    :class:`UsageError` for a file that is absent or not one, and for an address dask cannot
    connect to."""
    if "://" in text:
        return _checked(text, text)
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
    return _checked(address, f"{text}: its address {address}")


def _checked(address: str, named: str) -> str:
    """``address`` if dask can connect through its scheme here and reads where it leads (a
    host and port; an ``inproc://`` address of this process); else :class:`UsageError` naming
    it as ``named``."""
    scheme, location = address.split("://", 1)
    try:
        backend = registry.get_backend(scheme)
    except ValueError:
        known = ", ".join(f"{name}://" for name in sorted(registry.backends))
        raise UsageError(
            f"{named}: not a dask scheduler address (dask knows {known})", "scheduler"
        ) from None
    try:
        backend.get_connector()
    except Exception:  # a scheme whose support is not installed (ucx://)
        raise UsageError(
            f"{named}: dask cannot connect through {scheme}:// here", "scheduler"
        ) from None
    try:
        backend.get_address_host(location)
    except ValueError as exc:
        raise UsageError(f"{named}: not a dask scheduler address ({exc})", "scheduler") from None
    return address


def _backend(name: str) -> Backend:
    """This worker thread's backend called ``name``, made at its first task (a GL context is
    current in the thread that made it)."""
    made: dict[str, Backend] = _local.__dict__.setdefault("backends", {})
    if name not in made:
        made[name] = get_backend(name)
    return made[name]


def _run(payload: bytes, backend_name: str) -> tuple[Any, tuple[str, ...]]:
    """Run the pickled task ``payload`` on a worker, with the worker thread's backend; its
    result and what it told of its progress, in order."""
    task: Task[Any] = pickle.loads(payload)
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
        address when neither comes in time, or what answers is no dask scheduler)."""
        address = self.address = scheduler_address(self.scheduler)
        self._client = _connected(address)
        try:
            threads = self._first_threads()
        except BaseException:
            self.close()
            raise
        if self.window is None:
            self.window = (DEPTH + 1) * threads
        return self

    def _first_threads(self) -> int:
        """The cluster's worker threads, once it has any (:class:`LodConvertError` when none
        joins in :data:`WORKERS_SECONDS`)."""
        deadline = time.monotonic() + WORKERS_SECONDS
        while not (threads := self._threads()):
            if time.monotonic() > deadline:
                raise LodConvertError(
                    f"the dask scheduler has no worker (none joined in {WORKERS_SECONDS:g} s)",
                    self.address,
                )
            time.sleep(STAFF_POLL_SECONDS)
        return threads

    def _threads(self) -> int:
        """The cluster's worker threads now; :class:`LodConvertError` when the scheduler is
        lost or does not answer in :data:`REQUEST_SECONDS`."""
        assert self._client is not None, "use DaskExecutor as a context"
        try:
            return sum(self._client.nthreads(callback_timeout=REQUEST_SECONDS).values())
        except TimeoutError:
            raise LodConvertError(
                f"the dask scheduler stopped answering (nothing in {REQUEST_SECONDS:g} s)",
                self.address,
            ) from None
        except OSError:
            raise LodConvertError("lost the dask scheduler", self.address) from None

    def results(self, tasks: Iterable[Task[Any]]) -> Iterator[Any]:
        """The result of each of ``tasks``, in order; a task the scheduler gave up on (its
        workers died) gives a result with each of its objects failed."""
        client = self._client
        assert client is not None and self.window is not None, "use DaskExecutor as a context"
        run = uuid.uuid4().hex
        pending = iter(tasks)
        flight: deque[tuple[Task[Any], Future | None]] = deque()
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

    def _submitted(self, client: Client, task: Task[Any], key: str) -> Future | None:
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

    def _run_here(self, task: Task[Any]) -> Any:
        """Run ``task`` in this process (with a backend of the cluster's kind, made once)."""
        if self._backend is None:
            self._backend = get_backend(self.backend_name)
        return task.run(self._backend, self.progress)

    def _result(self, task: Task[Any], future: Future) -> Any:
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
        if self._threads():
            return None
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
            _close(client)


class _Client(Client):
    """A dask client whose start ends within :data:`REQUEST_SECONDS`; one whose start failed
    is closed at once (else ``Client.__del__`` closes it at exit, and prints a traceback when
    that fails)."""

    def start(self, **kwargs: Any) -> None:
        try:
            super().start(callback_timeout=REQUEST_SECONDS, **kwargs)
        except BaseException:
            _close(self)
            raise


def _connected(address: str) -> Client:
    """A client of the scheduler at ``address``; :class:`LodConvertError` naming it when it
    cannot be reached, does not answer, or answers as no dask scheduler does."""
    try:
        return _Client(address, timeout=CONNECT_SECONDS, set_as_default=False)
    except TimeoutError:  # connected, then nothing came back in time
        raise LodConvertError(
            f"the dask scheduler does not answer (nothing in {REQUEST_SECONDS:g} s)", address
        ) from None
    except OSError as exc:
        raise LodConvertError(
            f"cannot reach the dask scheduler ({_first_line(exc)})", address
        ) from None
    except Exception as exc:  # not dask's protocol, or not a scheduler's answer (a worker's)
        raise LodConvertError("what answers there is not a dask scheduler", address) from exc


def _close(client: Client) -> None:
    """Close ``client``, giving it :data:`ANSWER_SECONDS` (its scheduler may be gone)."""
    with contextlib.suppress(Exception):
        client.close(timeout=ANSWER_SECONDS)


def _first_line(exc: BaseException) -> str:
    """The first line of ``exc``'s message (its type's name when it has none)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
