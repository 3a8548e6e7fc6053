"""What the stages of one run share (:class:`RunContext`): the executor that bakes and its
backend, where progress, warnings and steps go, the clock, the limits, whether a broken object
fails the run, and the objects skipped so far (docs/architecture.md)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from .bake import Backend
from .clock import Clock
from .limits import DEFAULT_LIMITS, Limits
from .tasks import Executor, SerialExecutor

Message = Callable[[str], None]
Step = Callable[[str, int, "int | None"], None]
"""``step(stage, done, total)``: ``done`` of ``total`` (``None``: unknown) items finished."""


def quiet(_: str) -> None:
    """Discard a message."""


def no_step(stage: str, done: int, total: int | None) -> None:
    """Discard a progress count."""


@dataclass
class RunContext:
    """The executor (and its backend) that bakes, what hears of progress, warnings and steps,
    the clock of the stages, the limits, ``strict`` (a broken object fails the run) and the
    objects skipped so far (``skipped``: id and reason)."""

    executor: Executor
    backend: Backend
    progress: Message = quiet
    warn: Message = quiet
    step: Step = no_step
    clock: Clock = field(default_factory=Clock)
    limits: Limits = DEFAULT_LIMITS
    strict: bool = False
    skipped: list[dict[str, str]] = field(default_factory=list)

    @classmethod
    def here(cls, backend: Backend, **fields: object) -> RunContext:
        """A context baking in this process with ``backend`` (the other fields as given)."""
        progress = fields.get("progress", quiet)
        return cls(SerialExecutor(backend, progress), backend, **fields)  # type: ignore[arg-type]
