"""The daemon's states and the one table of transitions between them.

==============  ===========================================================================
``starting``    taking the hardware lock, recovering interrupted runs, going safe
``idle``        the front-end safe, waiting for a submitted or timed run
``running``     a schedule is running
``observing``   a schedule is running its ``observe`` step (the sky, not calibrators)
``faulted``     the last run failed (front-end safe, run file closed); the queue waits
                until an operator clears the fault
``stopping``    a signal or ``halt``: the current run is being stopped safely
``stopped``     the daemon has stopped
==============  ===========================================================================

Every transition goes through :meth:`StateMachine.go` with a reason, is checked against
:data:`TRANSITIONS` and is logged; a transition the table does not allow is a bug and
raises.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

log = logging.getLogger(__name__)

State = Literal["starting", "idle", "running", "observing", "faulted", "stopping", "stopped"]

TRANSITIONS: dict[State, tuple[State, ...]] = {
    "starting": ("idle", "faulted", "stopping"),
    "idle": ("running", "stopping"),
    "running": ("observing", "idle", "faulted", "stopping"),
    "observing": ("running", "idle", "faulted", "stopping"),
    "faulted": ("idle", "running", "stopping"),
    "stopping": ("stopped",),
    "stopped": (),
}


@dataclass(frozen=True)
class Transition:
    """One change of state: from, to, why, when (Unix seconds)."""

    before: State
    after: State
    reason: str
    at: float


class StateMachine:
    """The daemon's current state, changed only along :data:`TRANSITIONS`.

    ``listeners`` are called with each :class:`Transition` (status lines, followers).
    Thread-safe.
    """

    def __init__(self) -> None:
        self._state: State = "starting"
        self._lock = threading.Lock()
        self.history: list[Transition] = []
        self.listeners: list[Callable[[Transition], None]] = []

    @property
    def state(self) -> State:
        """The current state."""
        return self._state

    def go(self, after: State, reason: str) -> Transition:
        """Move to ``after`` for ``reason``; a transition the table forbids raises."""
        with self._lock:
            before = self._state
            if after not in TRANSITIONS[before]:
                raise RuntimeError(f"no transition {before} -> {after} ({reason})")
            self._state = after
            change = Transition(before, after, reason, time.time())
            self.history.append(change)
        log.info("state %s -> %s: %s", before, after, reason)
        for listener in list(self.listeners):
            listener(change)
        return change

    def can(self, after: State) -> bool:
        """Whether the table allows ``after`` from the current state."""
        return after in TRANSITIONS[self._state]
