"""A step kind the run layer can execute: the language's kind plus its executor.

Every standard kind (:mod:`reach_receiver.run.steps`) is a :class:`RunnableKind`: one
class that declares the step's fields, parser, description, duration, interlock effect
and what it does with the instruments. A site, a test or a later issue adds a kind by
writing one such class and registering it
(:meth:`~reach_receiver.schedule.kinds.KindRegistry.with_kinds`).
"""

from __future__ import annotations

from typing import TypeVar

from reach_receiver.schedule.kinds import StepKind
from reach_receiver.schedule.steps import Step

from .context import RunContext

S = TypeVar("S", bound=Step)


class RunnableKind(StepKind[S]):
    """A step kind with an executor."""

    def execute(self, step: S, run: RunContext) -> None:
        """Do the step with the run's instruments, recording what it measures in the store.

        Raise a :class:`~reach_receiver.errors.ReceiverError` on a fault; the runner then
        puts the front-end in its safe state and closes the run file with the reason.
        """
        raise NotImplementedError
