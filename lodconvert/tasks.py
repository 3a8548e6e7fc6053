"""Baking as pure work: a :class:`BakeTask` (a batch of objects, each with its options resolved)
gives a :class:`BakeResult` (each object's chain, or why it was skipped, and its warnings, as
data), and an :class:`Executor` runs tasks and gives their results back in the order the tasks
were submitted: :class:`SerialExecutor` in this process, :class:`PoolExecutor` in worker
processes started with ``spawn``, a bounded window in flight, a dead worker's task run once
more. An executor only calls what :class:`Task` declares, ``run(backend, progress)`` and
``failed(reason)``, so readers and writers ship tasks of their own on it. See
``docs/cluster.md`` (tasks and executors) and ``docs/architecture.md`` (the task contract).
"""

from __future__ import annotations

import io
import itertools
import multiprocessing
import os
import pickle
import queue
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from multiprocessing.reduction import ForkingPickler
from typing import Any, Protocol, Self, TypeVar

from .bake import Backend, get_backend
from .chain import ChainOptions, ChainPlan, Progress
from .errors import InputError, ended
from .heap import tune_heap
from .limits import DEFAULT_LIMITS, Limits
from .model import LodChain, Node, PackedNode, unpacked
from .plans import bake_chain, plan_chain

TASK_SECONDS = 0.1
"""Work a batch is sized for: a process pool costs about 0.1 ms a task, so this keeps the
overhead well under 1 %."""
DEPTH = 2
"""Tasks sent to one worker at most: the one it works on and the next."""
MAX_BATCH = 256
"""Objects a batch holds at most (memory in flight stays small)."""
INPUT_BYTES_PER_WORKER = 6 * 2**20
"""Input a worker process is started for by default: starting one costs about 0.3 CPU s (an
interpreter, imports), and below about 12 MiB of city two of them made a run slower, not faster
(docs/options.md)."""


R = TypeVar("R", covariant=True)


class Task(Protocol[R]):
    """What an executor runs (picklable: it may run in another process): ``run`` gives its
    result as data, ``failed`` the result of a task no worker could run (its workers died).
    Baking (:class:`BakeTask`), reading a city (:mod:`.io.spread`), a LOD-parent cell
    (:mod:`.city.cells`) and a tile's content (:mod:`.io.tiles.task`) are tasks."""

    def run(self, backend: Backend, progress: Progress | None = None) -> R: ...

    def failed(self, reason: str) -> R: ...


Formatter = Callable[[LodChain], Any]
"""What an output format makes of a chain in the worker that baked it (its piece of the
output; ``None``: nothing, the writer formats it), :mod:`.io`'s ``formatter``."""


@dataclass(frozen=True)
class BakeTask:
    """Objects to bake, each with the options to bake it with (γ already decided); with
    ``plan_only``, plan each chain (:func:`~.plans.plan_chain`) and bake nothing; with a
    ``formatter``, each chain's piece of the output is made too, and with ``lean`` (where the
    results are taken, nothing but the writer needs a chain's geometry) a chain whose piece was
    made comes back without its geometry (:meth:`~.model.LodChain.without_geometry`); with
    ``packed`` (where the results are taken, geometry is only passed on to other tasks) every
    chain comes back with its geometry packed (:meth:`~.model.LodChain.packed`)."""

    items: tuple[tuple[Node | PackedNode, ChainOptions], ...]
    limits: Limits = DEFAULT_LIMITS
    plan_only: bool = False
    formatter: Formatter | None = None
    lean: bool = False
    packed: bool = False

    def object_ids(self) -> list[str]:
        """The ids of the task's objects, in order."""
        return [node.id for node, _ in self.items]

    def run(self, backend: Backend, progress: Progress | None = None) -> BakeResult:
        """Bake (or plan) each object with ``backend``; an object whose geometry cannot be
        baked (:class:`~.errors.InputError`) is an outcome with its reason, not an error.
        ``progress`` hears what is being baked as it happens."""
        start = time.perf_counter()
        outcomes = []
        for item, options in self.items:
            node = unpacked(item)
            warnings: list[str] = []
            try:
                chain = plan_chain(node, options) if self.plan_only else bake_chain(
                    node, options, backend, progress=progress, warn=warnings.append,
                    limits=self.limits,
                )  # fmt: skip
            except InputError as exc:
                outcomes.append(Baked(None, str(exc), tuple(warnings)))
                continue
            piece = self.formatter(chain) if self.formatter and node.transform is None else None
            if piece is not None and self.lean:
                chain = chain.without_geometry()
            elif self.packed and isinstance(chain, LodChain):
                chain = chain.packed()
            outcomes.append(Baked(chain, None, tuple(warnings), piece))
        return BakeResult(tuple(outcomes), time.perf_counter() - start)

    def failed(self, reason: str) -> BakeResult:
        """The result of this task when none of its objects could be converted, for
        ``reason``."""
        return BakeResult(tuple(Baked(None, f"{i}: {reason}") for i in self.object_ids()), 0.0)


@dataclass(frozen=True)
class Baked:
    """What became of one object: its chain (or plan), or the ``reason`` it was skipped, and the
    warnings its baking gave, in order."""

    chain: LodChain | ChainPlan | None
    reason: str | None = None
    warnings: tuple[str, ...] = ()
    piece: Any = None
    """The chain's piece of the output (the task's ``formatter``'s), if made."""


@dataclass(frozen=True)
class BakeResult:
    """The outcome of each object of a task, in the task's order, and the seconds it took."""

    outcomes: tuple[Baked, ...]
    seconds: float


class Executor:
    """Runs tasks; their results come back in submission order. Use as a context manager:
    leaving it stops whatever it started."""

    task_seconds = TASK_SECONDS
    """Work a batch of objects is sized for, so that what running a task costs stays small."""

    def results(self, tasks: Iterable[Task[Any]]) -> Iterator[Any]:
        """The result of each of ``tasks``, in order (tasks are taken as they are needed)."""
        raise NotImplementedError

    def close(self) -> None:
        """Stop whatever runs tasks (nothing by default)."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class SerialExecutor(Executor):
    """Each task run in this process when its result is asked for (``--workers 1``)."""

    backend: Backend
    progress: Progress | None = None

    def results(self, tasks: Iterable[Task[Any]]) -> Iterator[Any]:
        """The result of each of ``tasks``, each run as it is taken."""
        for task in tasks:
            yield task.run(self.backend, self.progress)


def _work(conn: Connection, backend_name: str) -> None:
    """A worker process: run the tasks that arrive on ``conn`` in order, send back what it
    heard of progress and then each result (or the exception that ended a task) until ``None``
    arrives. Two threads move tasks and results through ``conn`` meanwhile, so baking goes on
    while the main process is busy elsewhere. Ctrl-C is the main process's to handle: it stops
    the workers."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    tune_heap()
    inbox: queue.SimpleQueue[Task[Any] | _Unreadable | None] = queue.SimpleQueue()
    outbox: queue.SimpleQueue[tuple[str, Any] | None] = queue.SimpleQueue()
    threading.Thread(target=_receive, args=(conn, inbox), daemon=True).start()
    sender = threading.Thread(target=_send, args=(conn, outbox), daemon=True)
    sender.start()
    backend = get_backend(backend_name)  # a GL context, if any, is made here, after spawn

    def progress(text: str) -> None:
        outbox.put(("progress", text))

    while (task := inbox.get()) is not None:
        if isinstance(task, _Unreadable):  # the main process runs it
            outbox.put(("unsendable", task.reason))
            continue
        try:
            outbox.put(("result", task.run(backend, progress)))
        except Exception as exc:  # a bug, not bad input: the main process raises it
            outbox.put(("error", exc))
    outbox.put(None)
    sender.join()


@dataclass(frozen=True)
class _Unreadable:
    """A task this worker could not unpickle (a module changed under it, say), and why."""

    reason: str


def _receive(conn: Connection, inbox: queue.SimpleQueue[Task[Any] | _Unreadable | None]) -> None:
    """Move tasks from ``conn`` to ``inbox`` as they arrive, then ``None`` (no more tasks, or
    the main process is gone); a task that cannot be unpickled here goes as
    :class:`_Unreadable`, for the main process to run."""
    while True:
        task: Task[Any] | _Unreadable | None
        try:
            task = conn.recv()
        except (EOFError, OSError):
            task = None
        except Exception as exc:
            task = _Unreadable(f"{type(exc).__name__}: {exc}")
        inbox.put(task)
        if task is None:
            return


def pickled(message: Any) -> memoryview:
    """``message`` pickled for a pipe, with protocol 5: arrays are written from their own
    memory, not copied into bytes first (2.7× faster for meshes), and the pickle is not copied
    again either."""
    buffer = io.BytesIO()
    ForkingPickler(buffer, 5).dump(message)
    return buffer.getbuffer()


def _send(conn: Connection, outbox: queue.SimpleQueue[tuple[str, Any] | None]) -> None:
    """Send what arrives in ``outbox`` through ``conn`` until ``None`` (or the main process is
    gone); a result that cannot be pickled (nested too deep, say) is sent as ``unsendable``:
    the main process runs its task itself, as it does a task the worker could not unpickle."""
    while (message := outbox.get()) is not None:
        try:
            conn.send_bytes(pickled(message))
        except OSError:
            return
        except Exception as exc:
            conn.send(("unsendable", f"{type(exc).__name__}: {exc}"))


@dataclass
class _Worker:
    """One worker process, its end of the pipe and the tasks sent to it (their numbers, in
    the order it runs them: the first is the one it works on). What is sent to it goes
    through ``outbox`` to a thread that writes it into the pipe, so the main process never
    waits for a busy worker to take a task in."""

    process: Any
    conn: Connection
    held: deque[int] = field(default_factory=deque)
    outbox: queue.SimpleQueue[memoryview | None] = field(default_factory=queue.SimpleQueue)

    def __post_init__(self) -> None:
        threading.Thread(target=_write, args=(self.conn, self.outbox), daemon=True).start()

    def send(self, message: Any) -> None:
        """Send ``message`` (pickled here: :class:`RecursionError` or
        :class:`pickle.PicklingError` for one that cannot be) after what was sent before."""
        self.outbox.put(pickled(message))

    def stop_sending(self) -> None:
        """End the thread that writes into the pipe, once it has written what it holds."""
        self.outbox.put(None)


def _write(conn: Connection, outbox: queue.SimpleQueue[memoryview | None]) -> None:
    """Write what arrives in ``outbox`` into ``conn`` until ``None`` (or the worker is gone:
    the main process learns of that from the worker's sentinel)."""
    while (data := outbox.get()) is not None:
        try:
            conn.send_bytes(data)
        except OSError:
            return


class PoolExecutor(Executor):
    """Tasks run by ``workers`` processes (``spawn``), each baking with its own backend of
    ``backend_name``; at most ``window`` tasks are in flight or waiting to be consumed."""

    def __init__(
        self,
        workers: int,
        backend_name: str,
        progress: Progress | None = None,
        window: int | None = None,
    ) -> None:
        self.workers = workers
        self.backend_name = backend_name
        self.progress = progress
        self.window = window or (DEPTH + 1) * workers
        self._context = multiprocessing.get_context("spawn")
        self._workers: list[_Worker] = []
        self._backend: Backend | None = None
        self._numbers = itertools.count()
        self._tasks: dict[int, Task[Any]] = {}  # by number, until its result is taken
        self._waiting: deque[int] = deque()  # tasks not sent to a worker yet
        self._tries: dict[int, int] = {}
        self._done: dict[int, Any] = {}  # results not taken yet

    def __enter__(self) -> Self:
        """Start the workers now, so that they are ready (imports done, backends made) when the
        first task comes: that happens while the main process reads."""
        while len(self._workers) < self.workers:
            self._workers.append(self._start())
        return self

    def _start(self) -> _Worker:
        ours, theirs = self._context.Pipe()
        process = self._context.Process(
            target=_work, args=(theirs, self.backend_name), daemon=True, name="lodconvert-worker"
        )
        process.start()
        theirs.close()
        return _Worker(process, ours)

    def results(self, tasks: Iterable[Task[Any]]) -> Iterator[Any]:
        """The result of each of ``tasks``, in order; a task whose worker died twice gives a
        result with each of its objects failed. Streams may run at once (a stream's tasks
        drawn from another's results): their tasks share the workers, each task numbered
        across streams, and each stream takes its own results in its own order."""
        pending = iter(tasks)
        order: deque[int] = deque()  # this stream's tasks whose results are not taken yet
        exhausted = False
        try:
            while True:
                while not exhausted and len(order) < self.window:
                    task = next(pending, None)
                    if task is None:
                        exhausted = True
                        break
                    number = next(self._numbers)
                    self._tasks[number] = task
                    self._waiting.append(number)
                    order.append(number)
                if order and order[0] in self._done:
                    number = order.popleft()
                    del self._tasks[number]
                    self._tries.pop(number, None)
                    yield self._done.pop(number)
                    continue
                if exhausted and not order:
                    return
                self._dispatch()
                self._collect()
        except GeneratorExit:  # the results left unread: the other streams go on
            for number in order:
                self._tasks.pop(number, None)
                self._tries.pop(number, None)
                self._done.pop(number, None)
            raise
        except BaseException:  # an error: stop the workers
            self.close()
            raise

    def _dispatch(self) -> None:
        """Give waiting tasks to the workers holding fewest (up to :data:`DEPTH` each, so
        that each has the next at hand), starting workers up to the pool's size; a task that
        cannot be pickled (its data nested too deep) is run here; one whose stream was left
        is dropped."""
        workers, waiting = self._workers, self._waiting
        while waiting:
            if len(workers) < self.workers:
                workers.append(self._start())
            worker = min(workers, key=lambda w: len(w.held))
            if len(worker.held) >= DEPTH:
                return
            number = waiting.popleft()
            task = self._tasks.get(number)
            if task is None:
                continue
            try:
                worker.send(task)
            except (RecursionError, pickle.PicklingError):
                self._done[number] = self._run_here(task)
            else:  # if it died, _collect learns so from its sentinel
                worker.held.append(number)

    def _run_here(self, task: Task[Any]) -> Any:
        """Run ``task`` in this process (with a backend of the pool's kind, made once)."""
        if self._backend is None:
            self._backend = get_backend(self.backend_name)
        return task.run(self._backend, self.progress)

    def _collect(self) -> None:
        """Wait until a busy worker sends something or dies, and take it in: a dead worker's
        first task is charged a try (run again, or after two failed with each object), the
        others it held wait again. The result of a task whose stream was left is dropped."""
        busy = [w for w in self._workers if w.held]
        if not busy:  # every task given out was run here
            return
        ready = wait([w.conn for w in busy] + [w.process.sentinel for w in busy])
        for worker in busy:
            dead = worker.process.sentinel in ready
            if worker.conn in ready:
                try:
                    kind, value = worker.conn.recv()
                except (EOFError, ConnectionResetError):  # it died
                    kind, value, dead = "died", None, True
                if kind == "progress" and self.progress is not None:
                    self.progress(value)
                elif kind == "result":
                    self._keep(worker.held.popleft(), value)
                elif kind == "unsendable":  # its result cannot be pickled: run it here
                    number = worker.held.popleft()
                    if number in self._tasks:
                        self._keep(number, self._run_here(self._tasks[number]))
                elif kind == "error":
                    raise value
                if kind != "died":
                    continue  # if it died too, its sentinel is read on the next wait
            if not dead:
                continue
            worker.process.join()
            self._workers.remove(worker)
            first = worker.held.popleft()
            self._waiting.extendleft(reversed(worker.held))
            self._tries[first] = self._tries.get(first, 0) + 1
            if self._tries[first] < 2:
                self._waiting.appendleft(first)
            elif first in self._tasks:
                self._keep(first, self._tasks[first].failed(_death(worker.process.exitcode)))

    def _keep(self, number: int, result: Any) -> None:
        """Keep ``result`` of task ``number`` for its stream, unless that stream was left."""
        if number in self._tasks:
            self._done[number] = result

    def close(self) -> None:
        """End every worker: idle ones are told to, busy ones terminated; all are waited for."""
        workers, self._workers[:] = list(self._workers), []
        for worker in workers:
            if not worker.held:
                worker.send(None)
            else:
                worker.process.terminate()
            worker.stop_sending()
        for worker in workers:
            worker.process.join()
            worker.conn.close()


def _death(code: int | None) -> str:
    """Why a task failed when its worker died with exit ``code`` twice."""
    return f"the worker process converting it died twice ({ended(code)})"


def default_workers(input_bytes: int) -> int:
    """Worker processes for inputs of ``input_bytes`` in all: one for each
    :data:`INPUT_BYTES_PER_WORKER`, up to the cores this process may run on (at least one: the
    main process)."""
    wanted = -(-input_bytes // INPUT_BYTES_PER_WORKER)
    return max(1, min(len(os.sched_getaffinity(0)), wanted))


def batches(
    items: Iterable[tuple[Node | PackedNode, ChainOptions]],
    per_object: list[float],
    limits: Limits,
    plan_only: bool = False,
    formatter: Formatter | None = None,
    seconds: float = TASK_SECONDS,
    lean: bool = False,
    packed: bool = False,
) -> Iterator[BakeTask]:
    """``items`` as tasks of about ``seconds`` of work each, judged by ``per_object`` (a
    one-item list: seconds an object takes so far, updated by the caller; 0: not known yet, a
    task of one object); ``plan_only``, ``formatter``, ``lean`` and ``packed`` as
    :class:`BakeTask` has them."""  # fmt: skip
    batch: list[tuple[Node | PackedNode, ChainOptions]] = []
    for item in items:
        batch.append(item)
        wanted = int(seconds / per_object[0]) if per_object[0] > 0 else 1
        if len(batch) >= max(1, min(MAX_BATCH, wanted)):
            yield BakeTask(tuple(batch), limits, plan_only, formatter, lean, packed)
            batch = []
    if batch:
        yield BakeTask(tuple(batch), limits, plan_only, formatter, lean, packed)
